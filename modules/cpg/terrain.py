"""Sensing a change of terrain while walking, and switching to the new terrain's parameters (thesis §5.8, L1759-1766).

"Inertial sensors are used to detect the change of terrain slope during walking. Detection occurs when the torso reaches
previously defined threshold in Sagittal plane, this threshold was defined with taking into account the oscillation
range of the torso in walking on flat terrain" (L1759). Then "switching occurs gradually between a neuron of success map
responsible for walking on [the old terrain] into a neuron of success map responsible for walking on [the new one]"
(L1766). The thesis gives the rule, not the threshold (digest §7.17: mean +- 1.5 x half range of the flat walk's torso
pitch, measured per walk).

A **detector** is a signal the controller senses every tick, one or more columns per batch copy; a **watch** measures
that signal's band on the walk itself (its mean +- k x its half range over ``measure`` s from ``after``, never narrower
than the detector's ``floor``) and fires, once per copy, the first tick the signal leaves it ("outside", any column), or
falls to its low edge ("below"), or reaches its high edge ("above"); a given threshold replaces the measured band. The
detectors (issue 29 compares them, ``docs/results/chapter5.md``):

- ``torso``: the torso's pitch to the vertical (the thesis's, L1759; the circuit input ``terrain_input``);
- ``pitch_rate``: the gyro's pitch rate (the circuit input ``torso_pitch_rate``);
- ``phase_pitch``: the torso pitch against its own band at the same phase of the gait cycle (8 phases of the left hip
  pitch's rhythm generator, its cycle from one rise of V_E - V_F through 0 to the next): the gait's swing of the torso
  is not part of the band;
- ``foot_slope``: the slope each foot senses under it (``ankle_adaptation``: the sole's pitch in the world in flat
  stance, from the inertial pitch and the leg's joint angles);
- ``ankle_error``: each ankle pitch's command minus its measured angle (the ground forcing the foot);
- ``time``: no sensing, fires at ``after`` (a switch at a given time: the switch itself, on flat ground).

The **terrain switch** (``TerrainSwitch``) watches one detector and, when it fires, moves the group gain multipliers,
sigma_s and theta_MLR from their values then to the new condition's, at once or linearly over ``seconds``. Watches
without a switch (``CPGNetwork.watch_terrain``) only record when they would have fired, to compare detectors on the
same walks. Everything here is per batch copy and pure numpy; the network calls it once per control tick.
``TerrainSwitching`` is this seam's part of ``CPGNetwork`` (network.py): arming, ticking and reading it.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .events import per_copy

E, F = 0, 1

#: the detectors a watch may read (see the module docstring)
DETECTORS = ("torso", "pitch_rate", "phase_pitch", "foot_slope", "ankle_error", "time")
#: the narrowest half band of each detector (its unit): below it the measured band would be the detector's noise.
#: Chosen here (issue 29): foot_slope 0.035 rad (2 deg: the estimate's spread walking the flat, 0.9 deg s.d. per
#: stance, calibrated by docs/calibration/humanoid_terrain.py); the others 0 (the thesis's rule as it stands). A trial's
#: ``foot_slope_floor`` replaces the feet's: 3 deg ends nearly every false alarm on chapter 5's flat walks but detects
#: the uphill later with the thesis's neuron (docs/experiments/chapter5_floor.sh; docs/results/chapter5.md)
FLOORS = {"torso": 0.0, "pitch_rate": 0.0, "phase_pitch": 0.0, "foot_slope": 0.035, "ankle_error": 0.0, "time": 0.0}
PHASES = 8  # phase_pitch: bins of the gait cycle


@dataclass(frozen=True)
class TerrainSwitchEvent:
    """A terrain switch that happened (§5.8, L1759-1766): at ``time`` (s of CPG time, the start of the tick) the input
    ``input`` was ``value`` (rad for the torso pitch; per switched copy, an array, when copies differ), ``when``
    ("above", "below" or "outside") ``threshold`` (a number, or (low, high) for "outside"), and the parameters started
    to move from ``old`` to ``new`` (names: ``gain_pitch``, ``gain_roll``: multipliers of the groups' gains;
    ``sigma_s``, ``theta_mlr``), ``mode`` "at_once" (in that tick) or "gradual" (linearly, reaching ``new`` at ``time +
    seconds``). ``copies``: which batch copies switched. ``detector``: what sensed the change (``DETECTORS``)."""

    time: float
    input: str
    value: float | np.ndarray
    threshold: float | tuple
    when: str
    mode: str
    seconds: float
    old: dict[str, float | np.ndarray]
    new: dict[str, float]
    copies: np.ndarray
    detector: str = "torso"
    torso: float | np.ndarray = float("nan")  # the watched torso input's value then (rad), whatever the detector

    @property
    def end_time(self) -> float:
        """s: when the parameters reach their new values (``time`` for "at_once")."""
        return self.time + self.seconds


@dataclass(frozen=True)
class TerrainThreshold:
    """What an armed terrain switch watches for (§5.8), once known: from ``since`` s of CPG time on, the input ``input``
    (rad for the torso pitch) at or below ``low``, at or above ``high``, or either ("outside"), per batch copy (NaN on
    a side not watched; the first column of a detector with several). ``measured``: the window (start, end) in s the
    band was measured over (digest §7.17), or None for a given threshold."""

    input: str
    when: str
    since: float
    low: np.ndarray
    high: np.ndarray
    measured: tuple[float, float] | None


@dataclass(frozen=True)
class DetectorEvent:
    """A watch fired (issue 29's comparison of detectors): ``detector`` left its band at ``time`` (s of CPG time) in
    the batch copies ``copies``, its signal then ``value`` (the column furthest out), the band ``low``, ``high``."""

    detector: str
    time: float
    value: float | np.ndarray
    low: float | np.ndarray
    high: float | np.ndarray
    copies: np.ndarray


class Detector:
    """A signal sensed every tick, (batch, columns), in the unit of its input."""

    name = ""

    def __init__(self, network) -> None:
        self.network = network

    def signal(self, phi: np.ndarray) -> np.ndarray:
        raise NotImplementedError

    def bin(self) -> np.ndarray | None:
        """Which band each copy compares with this tick (phase_pitch), or None: one band."""
        return None


class InputDetector(Detector):
    """A circuit input as it is (the torso pitch, the gyro's pitch rate)."""

    def __init__(self, network, name: str, input: str) -> None:
        super().__init__(network)
        self.name, self.input = name, network.circuit.inputs.index(input)

    def signal(self, phi):
        return phi[:, self.input : self.input + 1]


class PhasePitch(InputDetector):
    """The torso pitch, banded per phase of the gait cycle (``PHASES`` bins of the left hip pitch RG's cycle)."""

    def __init__(self, network, input: str, joint: str = "hip_pitch_l") -> None:
        super().__init__(network, "phase_pitch", input)
        self.column = 2 * network.circuit.joint_index(joint)
        b = network.batch
        self.rise = np.full(b, np.nan)  # s: the last rise of V_E - V_F through 0
        self.period = np.full(b, np.nan)  # s: the last full cycle
        self.previous = np.zeros(b)

    def bin(self):
        net = self.network
        v = net.y[:, 0, self.column + E] - net.y[:, 0, self.column + F]
        rising = (self.previous < 0) & (v >= 0)
        self.previous = v.copy()
        if rising.any():
            self.period = np.where(rising & np.isfinite(self.rise), net.time - self.rise, self.period)
            self.rise = np.where(rising, net.time, self.rise)
        phase = (net.time - self.rise) / self.period
        known = np.isfinite(phase)
        out = np.full(net.batch, -1)
        out[known] = np.clip((phase[known] * PHASES).astype(int), 0, PHASES - 1)
        return out


class FootSlope(Detector):
    """Each foot's sensed slope (``ankle_adaptation``'s estimates), rad."""

    name = "foot_slope"

    def signal(self, phi):
        return self.network.slope_estimate_all()


class AnkleError(Detector):
    """Each adapted ankle's command (last tick's) minus its measured angle, rad."""

    name = "ankle_error"

    def __init__(self, network) -> None:
        super().__init__(network)
        circuit = network.circuit
        names = list(circuit.ankle_adaptation.feet) if circuit.ankle_adaptation else ["ankle_pitch_l", "ankle_pitch_r"]
        self.joints = np.array([circuit.joint_index(n) for n in names])
        self.inputs = np.array([circuit.inputs.index(circuit.joints[j].angle_input) for j in self.joints])

    def signal(self, phi):
        command = self.network.command_all()[:, self.joints]
        return command - phi[:, self.inputs]


class Clock(Detector):
    """No sensing (``time``): the watch fires at its ``after``."""

    name = "time"

    def signal(self, phi):
        return np.zeros((self.network.batch, 1))


def make_detector(network, name: str, torso_input: str) -> Detector:
    """The detector ``name`` (``DETECTORS``) of ``network``; ``torso_input``: the torso pitch's input name. ValueError
    naming what the circuit lacks."""
    circuit = network.circuit
    if name == "torso":
        return InputDetector(network, "torso", torso_input)
    if name == "pitch_rate":
        if "torso_pitch_rate" not in circuit.inputs:
            raise ValueError(f"switch_detector 'pitch_rate': expected circuit {circuit.name} to have the input "
                             "'torso_pitch_rate' (the gyro)")  # fmt: skip
        return InputDetector(network, "pitch_rate", "torso_pitch_rate")
    if name == "phase_pitch":
        return PhasePitch(network, torso_input)
    if name in ("foot_slope", "ankle_error"):
        if circuit.ankle_adaptation is None:
            raise ValueError(f"switch_detector {name!r}: expected circuit {circuit.name} to have an ankle_adaptation")
        return FootSlope(network) if name == "foot_slope" else AnkleError(network)
    if name == "time":
        return Clock(network)
    raise ValueError(f"switch_detector: expected one of {list(DETECTORS)}; got {name!r}")


class Watch:
    """A detector's band, measured on the walk (or given), and when each copy first left it (see the module
    docstring). ``band`` = (k, seconds): measured over ``seconds`` from ``after``, then watched; ``threshold``: a given
    level (one column), watched from ``after``. ``floor``: the band's narrowest half (default the detector's
    ``FLOORS``)."""

    def __init__(self, detector: Detector, when: str, after: float, band=None, threshold=None, floor=None) -> None:
        b = detector.network.batch
        self.detector, self.when, self.above = detector, when, when == "above"
        self.band = band
        self.floor = FLOORS[detector.name] if floor is None else float(floor)  # the narrowest half band
        self.fired = np.zeros(b, dtype=bool)
        self.bins = PHASES if isinstance(detector, PhasePitch) else 1
        if band is not None:
            self.measured_from, self.measured_to = float(after), float(after) + float(band[1])
            self.after = self.measured_to
            self.known = False
            self.low = self.high = self.total = self.count = None  # per (copy, bin, column), at the first sample
        else:
            self.after, self.known = float(after), True
            self.measured_from = self.measured_to = None
            level = np.full((b, self.bins, 1), float(threshold if threshold is not None else np.nan))
            self.lower = level if when != "above" else np.full_like(level, np.nan)
            self.upper = level if when == "above" else np.full_like(level, np.nan)

    def _rows(self, bins: np.ndarray | None) -> tuple[np.ndarray, np.ndarray]:
        b = self.detector.network.batch
        return np.arange(b), np.zeros(b, dtype=int) if bins is None else np.maximum(bins, 0)

    def update(self, phi: np.ndarray, time: float, dt: float) -> np.ndarray | None:
        """This tick (``time``: its start, s; ``dt``: its length): measure, or watch. Which copies fire now, or None."""
        detector = self.detector
        value = detector.signal(phi)
        bins = detector.bin()
        rows, where = self._rows(bins)
        if not self.known:
            if self.low is None:
                shape = (len(rows), self.bins, value.shape[1])
                self.low, self.high = np.full(shape, np.inf), np.full(shape, -np.inf)
                self.total, self.count = np.zeros(shape), np.zeros(shape[:2] + (1,))
            if time >= self.measured_from - 1e-9:
                ok = rows if bins is None else rows[bins >= 0]
                at = where[ok]
                self.low[ok, at] = np.minimum(self.low[ok, at], value[ok])
                self.high[ok, at] = np.maximum(self.high[ok, at], value[ok])
                self.total[ok, at] += value[ok]
                self.count[ok, at] += 1
            if time + 1e-9 >= self.measured_to - dt:  # the window's last tick: the band is known
                k, floor = self.band[0], self.floor
                mean = self.total / np.maximum(self.count, 1)
                half = np.maximum(k * (self.high - self.low) / 2, floor)
                unseen = self.count == 0  # a phase never seen: never fires there
                mean, half = np.where(unseen, np.nan, mean), np.where(unseen, np.nan, half)
                self.lower = mean - half if self.when != "above" else np.full_like(mean, np.nan)
                self.upper = mean + half if self.when != "below" else np.full_like(mean, np.nan)
                self.known = True
            return None
        if time < self.after - 1e-9:
            return None
        if detector.name == "time":
            due = ~self.fired
        else:
            lower, upper = self.lower[rows, where], self.upper[rows, where]  # (batch, columns)
            with np.errstate(invalid="ignore"):
                out = (value <= lower) | (value >= upper)
            due = out.any(axis=1) & ~self.fired
            if bins is not None:
                due &= bins >= 0
        self.value = value
        self._where = where
        return due if due.any() else None

    def edges(self) -> tuple[np.ndarray, np.ndarray]:
        """(low, high) per copy: the first column's band, the first bin's (NaN on a side not watched)."""
        return self.lower[:, 0, 0], self.upper[:, 0, 0]

    def reading(self, due: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """At a firing: per firing copy, the column furthest out of its band, its value and that band (low, high)."""
        rows = np.flatnonzero(due)
        where = self._where[rows]
        value = self.value[rows]
        lower, upper = self.lower[rows, where], self.upper[rows, where]
        with np.errstate(invalid="ignore"):
            distance = np.nan_to_num(np.maximum(lower - value, value - upper), nan=-np.inf)
        column = np.argmax(distance, axis=1)
        pick = np.arange(len(rows))
        return value[pick, column], lower[pick, column], upper[pick, column]


class TerrainSwitch:
    """An armed terrain switch (``CPGNetwork.arm_terrain_switch``): its watch and its progress per batch copy."""

    def __init__(self, network, watch: Watch, input_name: str, mode, seconds, gains, sigma_s, joints, theta_mlr):
        b = network.batch
        self.network, self.watch, self.input_name = network, watch, input_name
        self.mode = mode
        self.seconds = float(seconds) if mode == "gradual" else 0.0
        self.gains = dict(gains)  # group -> its new multiplier
        self.sigma_s = sigma_s  # its new value, or None: unchanged
        idx = network._joint_indices(joints)
        self.sigma_columns = np.concatenate([2 * idx + E, 2 * idx + F])
        self.theta_mlr = theta_mlr  # its new value (4.9, the signs of §7.6), or None: unchanged
        self.theta_e, self.theta_f = 2 * idx + E, 2 * idx + F
        self.old_theta = np.zeros((b, len(idx)))
        self.fired = np.zeros(b, dtype=bool)
        self.done = np.zeros(b, dtype=bool)
        self.start = np.zeros(b)  # s: each copy's switch time
        self.old_gains = {group: np.ones(b) for group in self.gains}  # each copy's values at its switch
        self.old_sigma = np.zeros((b, len(self.sigma_columns)))
        #: (time s, the largest change of any joint's command the switch made in that tick, rad) per moving tick
        self.jumps: list[tuple[float, float]] = []

    def threshold(self) -> TerrainThreshold | None:
        """What it watches for, once known."""
        w = self.watch
        if not w.known:
            return None
        low, high = w.edges()
        measured = (w.measured_from, w.measured_to) if w.band is not None else None
        return TerrainThreshold(self.input_name, w.when, w.after, low.copy(), high.copy(), measured)

    def tick(self, phi: np.ndarray, time: float, dt: float) -> bool:
        """Fire in the copies whose detector left its band (from ``after`` on, once), then move their parameters
        toward the new values. True when every copy has switched and arrived (nothing more to do)."""
        net, w = self.network, self.watch
        due = w.update(phi, time, dt)
        if due is not None:
            due &= ~self.fired
            w.fired |= due
            if due.any():
                self._start(due, time, phi)
        moving = self.fired & ~self.done
        if not moving.any():
            return False
        rows = np.flatnonzero(moving)
        if self.mode == "gradual":
            fraction = np.clip((time - self.start[rows]) / self.seconds + 1e-9, 0.0, 1.0)
        else:
            fraction = np.ones(len(rows))
        before = net.command_all()[rows]
        for group, new in self.gains.items():
            old = self.old_gains[group][rows]
            net._set_gains(group, old + fraction * (new - old), rows)
        if self.sigma_s is not None:
            old = self.old_sigma[rows]
            value = old + fraction[:, None] * (self.sigma_s - old)
            cells = np.ix_(rows, self.sigma_columns)
            net.sigma_s[cells] = value
            net.sigma_in[cells] = value
            net.sigma_out[cells] = value
            net._update_coefficients()
        if self.theta_mlr is not None:
            old = self.old_theta[rows]
            value = old + fraction[:, None] * (self.theta_mlr - old)
            net.theta_mlr_signed[np.ix_(rows, self.theta_e)] = -value
            net.theta_mlr_signed[np.ix_(rows, self.theta_f)] = value
            net._update_pattern_formation()
            net._outputs(net._sensory)  # the PF and MN at this state under the new theta_MLR
        self.jumps.append((time, float(np.max(np.abs(net.command_all()[rows] - before)))))
        self.done[rows] = fraction >= 1.0
        return bool(self.done.all())

    def _start(self, due: np.ndarray, time: float, phi: np.ndarray) -> None:
        """The copies ``due`` switch now: keep their current values (the old ones) and record the event."""
        net, w = self.network, self.watch
        self.fired |= due
        self.start[due] = time
        for group in self.gains:
            self.old_gains[group][due] = net.gain_multipliers[group][due]
        self.old_sigma[due] = net.sigma_s[np.ix_(np.flatnonzero(due), self.sigma_columns)]
        self.old_theta[due] = net.theta_mlr_signed[np.ix_(np.flatnonzero(due), self.theta_f)]
        old = {f"gain_{group}": per_copy(self.old_gains[group][due]) for group in self.gains}
        new = {f"gain_{group}": float(v) for group, v in self.gains.items()}
        if self.sigma_s is not None:
            old["sigma_s"] = per_copy(self.old_sigma[due])
            new["sigma_s"] = float(self.sigma_s)
        if self.theta_mlr is not None:
            old["theta_mlr"] = per_copy(self.old_theta[due])
            new["theta_mlr"] = float(self.theta_mlr)
        if w.detector.name == "time":
            value, threshold = float(time), float(w.after)
        else:
            value, low, high = w.reading(due)
            value = per_copy(value)
            if w.when == "outside":
                threshold = (per_copy(low), per_copy(high))
            else:
                threshold = per_copy(high if w.above else low)
        net.terrain_switch_events.append(
            TerrainSwitchEvent(
                time=time,
                input=self.input_name,
                value=value,
                threshold=threshold,
                when=w.when,
                mode=self.mode,
                seconds=self.seconds,
                old=old,
                new=new,
                copies=due.copy(),
                detector=w.detector.name,
                torso=per_copy(phi[due, net.circuit.inputs.index(self.input_name)]),
            )
        )


class Watcher:
    """Watches without a switch: when each detector would have fired (``CPGNetwork.watch_terrain``)."""

    def __init__(self, watches: list[Watch]) -> None:
        self.watches = watches
        #: the firings so far, in order
        self.events: list[DetectorEvent] = []

    def tick(self, phi: np.ndarray, time: float, dt: float) -> None:
        for w in self.watches:
            if w.fired.all():
                continue
            due = w.update(phi, time, dt)
            if due is None:
                continue
            w.fired |= due
            value, low, high = w.reading(due) if w.detector.name != "time" else (np.full(due.sum(), time),) * 3
            self.events.append(
                DetectorEvent(w.detector.name, time, per_copy(value), per_copy(low), per_copy(high), due.copy())
            )


class TerrainSwitching:
    """``CPGNetwork``'s terrain switch (§5.8) and watched detectors: arming them per trial, and reading them."""

    def _reset_terrain(self) -> None:
        """A trial's start: no terrain switch armed, no detector watched."""
        self._terrain: TerrainSwitch | None = None  # an armed terrain switch (§5.8), until it has done its work
        self._watcher: Watcher | None = None  # detectors watched without switching (watch_terrain)
        self._terrain_detector: str | None = None
        self._switch_jumps: list[tuple[float, float]] = []
        #: the terrain switches so far (§5.8): at most one per copy and trial
        self.terrain_switch_events: list[TerrainSwitchEvent] = []
        #: the armed terrain switch's threshold once known (given, or measured on the walk), kept after it fired
        self.terrain_threshold: TerrainThreshold | None = None

    def _terrain_tick(self, phi: np.ndarray, control_dt: float) -> None:
        """The armed terrain switch's tick (``TerrainSwitch.tick``): its threshold once known, the jumps it made."""
        terrain = self._terrain
        if terrain.tick(phi, self.time, control_dt):
            self._terrain = None  # every copy has switched and arrived: nothing more per tick
        if self.terrain_threshold is None:  # measured on the walk: known from the window's last tick on
            self.terrain_threshold = terrain.threshold()
        if terrain.jumps:
            self._switch_jumps.extend(terrain.jumps)
            terrain.jumps.clear()

    #: what ``arm_terrain_switch`` takes
    TERRAIN_SWITCH_MODES = ("at_once", "gradual")
    TERRAIN_SWITCH_WHEN = ("above", "below", "outside")

    def arm_terrain_switch(
        self,
        input: str,
        threshold: float | None,
        when: str,
        mode: str = "at_once",
        seconds: float = 0.0,
        after: float = 0.0,
        gains: dict[str, float] | None = None,
        sigma_s: float | None = None,
        sigma_joints: list[str] | None = None,
        band: tuple[float, float] | None = None,
        theta_mlr: float | None = None,
        detector: str = "torso",
        floors: dict[str, float] | None = None,
    ) -> None:
        """Switch parameters once this trial when the terrain changes (§5.8, L1759-1766): from ``after`` s on, the first
        tick whose ``input`` (e.g. the torso pitch, rad) is at or ``when`` ("above", "below") ``threshold`` starts
        moving the group gain multipliers ``gains`` (group -> new value) and the RG's sigma_s of ``sigma_joints``
        (default all; None: unchanged) from their values at that tick to the new ones: ``mode`` "at_once" in that
        tick, "gradual" linearly over ``seconds`` (the thesis's "switching occurs gradually", L1766). Per batch copy.
        ``band`` = (k, seconds) instead of a ``threshold``: the threshold is measured on the walk itself, the input's
        mean +- k x its half range (- below, + above, either for "outside") over ``seconds`` from ``after`` (digest
        §7.17's rule, "defined with taking into account the oscillation range of the torso", L1759), and detection
        starts once it is known.
        ``theta_mlr`` (None: unchanged) moves the descending theta_MLR (4.9) of ``sigma_joints`` the same way.
        ``detector`` (terrain.py ``DETECTORS``): what is watched, ``input`` itself ("torso", the thesis's) or another
        sensed signal (issue 29), whose band is measured the same way; "time" fires at ``after``. ``floors``
        (detector -> its unit) replaces a detector's narrowest half band (``FLOORS``) this trial.
        ``reset`` disarms it; the switches are in ``terrain_switch_events``."""
        band, threshold = self._check_terrain_switch(input, threshold, when, mode, seconds, gains, band, detector)
        floor = (floors or {}).get(detector)
        watch = Watch(make_detector(self, detector, input), when, after, band=band, threshold=threshold, floor=floor)
        self._terrain = TerrainSwitch(self, watch, input, mode, seconds, gains or {}, sigma_s, sigma_joints, theta_mlr)
        self._terrain_detector = detector
        self.terrain_threshold = self._terrain.threshold()  # a given threshold: known from the start

    def _check_terrain_switch(self, input, threshold, when, mode, seconds, gains, band, detector) -> tuple:
        """``arm_terrain_switch``'s arguments checked (ValueError naming the trial parameter); returns (band,
        threshold) as the watch takes them (none for the "time" detector)."""
        if input not in self.circuit.inputs:
            raise ValueError(
                f"terrain switch input: expected one of the inputs of circuit {self.circuit.name} "
                f"{self.circuit.inputs}; got {input!r}"
            )
        if when not in self.TERRAIN_SWITCH_WHEN:
            raise ValueError(f"switch_when: expected one of {list(self.TERRAIN_SWITCH_WHEN)}; got {when!r}")
        if mode not in self.TERRAIN_SWITCH_MODES:
            raise ValueError(f"terrain_switch: expected one of {list(self.TERRAIN_SWITCH_MODES)}; got {mode!r}")
        if mode == "gradual" and not seconds > 0:
            raise ValueError(f"switch_seconds: expected a duration in s > 0 for a gradual switch; got {seconds!r}")
        for group in gains or {}:
            self._check_gain_group(group, f"next_gain_{group}")
        if band is not None and not (band[0] >= 0 and band[1] > 0):
            raise ValueError(f"switch_band: expected (k >= 0, seconds > 0); got {band!r}")
        if detector not in DETECTORS:
            raise ValueError(f"switch_detector: expected one of {list(DETECTORS)}; got {detector!r}")
        if detector == "time":
            band, threshold = None, 0.0
        elif band is None and threshold is None:
            raise ValueError("terrain switch: expected a threshold, or a band to measure it by")
        if detector not in ("torso", "time") and band is None:
            raise ValueError(f"switch_detector {detector!r}: expected a band (switch_band) measured on the walk")
        if when == "outside" and band is None and detector != "time":
            raise ValueError("switch_when 'outside': expected a band (switch_band) to leave; got a threshold")
        return band, threshold

    def watch_terrain(
        self, detectors, band: tuple[float, float], after: float, torso_input: str = "torso_pitch", floors=None
    ):
        """Watch ``detectors`` (terrain.py ``DETECTORS``) this trial without switching: each measures its band (k,
        seconds) from ``after`` s and records when it first leaves it (``detector_events``), to compare detectors on
        the same walk (issue 29). ``floors`` as ``arm_terrain_switch``'s. ``reset`` stops watching."""
        floors = floors or {}
        watches = [
            Watch(make_detector(self, name, torso_input), "outside", after, band=band, floor=floors.get(name))
            for name in detectors
        ]
        self._watcher = Watcher(watches) if watches else None

    @property
    def terrain_detector(self) -> str | None:
        """What the armed (or fired) terrain switch watches this trial (terrain.py ``DETECTORS``), or None."""
        return self._terrain_detector

    @property
    def detector_events(self) -> list:
        """The watched detectors' firings this trial (``watch_terrain``), in order."""
        return self._watcher.events if self._watcher is not None else []

    @property
    def terrain_switch_jumps(self) -> list[tuple[float, float]]:
        """(time s, rad) for every tick the terrain switch moved parameters: the largest change of any joint's command
        the switch itself made in that tick (the state held; continuity of the switch, issue 29)."""
        return list(self._switch_jumps)
