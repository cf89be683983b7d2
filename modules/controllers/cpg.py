"""The multi-layered multi-pattern CPG of thesis chapter 4 as a controller: its own process, in lockstep with the body.

The network is ``sfl_brain.modules.cpg`` (``CPGNetwork``: rhythm generators (4.1)-(4.8), pattern formation
(4.9)-(4.10), motor neurons (4.11)-(4.12), sensory neurons (4.13), RG-RG couplings); this module only hosts it. Each
control tick the controller takes the body's sensors, advances the network by the tick (``substeps`` RK4 steps:
h = 1 ms at a 10-ms tick, digest §7.2) and sends the joint commands: motor voltages ``v_<joint>`` for a voltage
circuit ((3.6) L874, the planar walker) or target angles ``q_<joint>`` (rad) for a position circuit (the author's NAO
command, digest §5, §7.8). "The digest" is CPG-HUMANOID.md; its sections are cited as §.

What it reads and writes depends on the circuit: it reads the circuit's ``inputs`` (by name: the body may order its
sensors any way and have more) and writes one command per joint (``signals``).

Parameters are data: ``circuit`` names a shipped circuit (``modules/cpg/circuits/*.yaml``) or a YAML file, and
``circuit_overrides`` sets any value in it by key path (``joints.0.rg.sigma_s``, ``couplings.3.weight``; a nested
mapping, as ``--set modules.controller.params.circuit_overrides.joints.0.rg.sigma_s=1`` builds it, is the same). A bad
path or value fails ``sfl check`` naming the circuit's key path. The network is rebuilt from them per process, and
reset per trial.

- ``phase_reset`` (§7.10, E4.3 L1268-1282): how the circuit's phase resets (heel contact -> the leg's RGs) act:
  "circuit" (as the file says; each entry keeps its own ``enabled`` flag and ``mode``), "pulse" (every entry a
  current pulse into its joint's RG), "state" (every entry a jump of its joints' RGs to the stance-onset state it
  stores; an error if one stores none) or "off". ``true`` / ``false`` are "circuit" / "off". A trial may choose
  otherwise (the trial parameter of the same name).
- ``switch`` (§7.11, E4.4 L1284-1324, E4.7 L1430-1437): pattern switching of chosen joints, once per trial, on a time
  (``at``) or on a push detector (the forward rate of ``push_input``, e.g. the pelvis angle, above ``push_rate``).
  The chosen joints take their new pattern (named: plateau, quiescent, ... as ``patterns.PATTERN_POINTS``, or a
  (sigma_s, sigma_f)), V = q = 0, and a kick of +I into RG-F, -I into RG-E for 0.2 s, per joint if given (its sign =
  the switch's direction, L1437), or signed by the way each joint moves (``kick_direction: motion``, issue 23's
  reading of E4.4: each joint kicked in the direction it is moving). A position-commanded joint's command goes on
  from its measured angle (``theta0: continuous``, the default; ``angle``: theta_0 := the measured angle, the rule of
  the author's 2017 scripts, digest §5, which makes the command jump by the reflexes' offset in our circuits).
  ``inhibit`` silences the RG-RG couplings between joint pairs (L1311: hip-knee inhibited, ankle-hip kept). It
  becomes one more entry of the circuit's ``switches``; the network carries it out. On logged trials each switch is a
  telemetry event ``events/pattern_switch``.
- ``switches``: named presets of the same form, all carried by the network and none armed unless a trial names one
  (the trial parameter ``switch``), so that one run can compare conditions trial by trial.
- Trial parameters (what a protocol sets per trial, ``TRIAL_PARAMS``): ``sigma_s``, ``sigma_f`` (E4.2: the
  RG pattern (w1, w2) = (sigma_s, sigma_f) learnt for all joints at once, L1251, "the same pattern in all joints
  exists whenever the coupling circuitry is active", L1286; ``pattern_joints`` restricts them to some joints), the
  descending control ``alpha_mlr``, ``theta_mlr`` of (4.9) (E4.6 L1417-1426), on the same joints; ``phase_reset``
  ("off", "pulse", "state", "circuit"; default: the parameter ``phase_reset``); ``switch`` ("none": no pattern switch
  at all this trial, not even the circuit file's own; a preset's name: that preset only; default: the circuit's own
  switches and the parameter ``switch``); ``switch_at`` (s: the armed time-triggered switch fires at this time
  instead of its ``at``, so a protocol can put the switch where its push is: the conditions protocol's ``follow``);
  ``start_slope_deg`` (the ground slope the trial starts on: the circuit's ``start_slope`` joints start from their
  calibrated pose shifted by it, so that command and pose agree at t = 0 on a ramp).

Chapter 5 (the humanoid learns w1 = MN gain in pitch, w2 = MN gain in roll, w3 = sigma_s, L1631 and Fig. 5.9's
caption; separate maps for flat, 10 deg up and 10 deg down, §5.7; switching while walking, §5.8 L1759-1766):

- ``gain_pitch``, ``gain_roll`` (trial parameters, >= 0; 1 = the calibrated gait): multiply the gain G of every joint
  of the circuit's ``gain_groups`` pitch / roll (theta_cmd = theta_0 + G (MN_E - MN_F)). The digest (§7.8) reads "one
  G for all pitch joints, one for both roll joints"; our gait is calibrated with one G per joint (circuit file), so one
  multiplier per group is the faithful reading. The multiplier scales the drive about its value at rest (the
  reflexes' offset on the trial's first frame; ``CPGNetwork.set_gain_multiplier``): the oscillation grows or shrinks,
  the resting pose stays the calibrated one, as G does in the author's code whose reflexes are off (digest §5); 0
  stands the robot still. w3 is ``sigma_s`` above (sigma_f stays the circuit's, §7.8).
- ``posture_gain`` (1/s, >= 0; 0 = off): the gain of the circuit's ``posture`` term, the torso held about 10 deg from
  the vertical by shifting the ankle pitches' theta_0 (L1764, §7.18; circuit.py ``Posture``); default the circuit's.
- the terrain switch (§5.8): the controller walks with the trial's ``gain_pitch``, ``gain_roll``, ``sigma_s`` and,
  when the terrain changes, moves to ``next_gain_pitch``, ``next_gain_roll``, ``next_sigma_s`` (the new condition's
  best neuron, physical values; one not given stays as it is) and ``next_theta_mlr`` (the new condition's descending
  theta_MLR, (4.9): chapter 5's uphill learns with E4.6's climbing setting). ``terrain_switch``: "off" (default),
  "at_once" (in one tick) or "gradual" (linearly over the module parameter ``switch_seconds``, one cycle of the flat
  gait, §7.17); it fires once, the first tick at or after the module parameter ``terrain_switch_after`` (s: the
  start-up transient must not fire it) when the input ``terrain_input`` (the torso pitch, rad) is at or ``switch_when``
  ("above", "below"; "outside": out of the measured band either way) ``switch_threshold`` (rad), or a threshold the
  walk itself measures: ``switch_band`` k, the input's mean +- k x its half range over the module parameter
  ``switch_measure`` s from ``terrain_switch_after`` (§7.17's rule: mean +- 1.5 x half range of the gait before the
  terrain changes; detection starts once it is known). ``switch_detector`` picks what is watched (terrain.py
  ``DETECTORS``); ``foot_slope_floor`` (rad, >= 0) replaces the feet's slope detector's narrowest half band
  (terrain.py ``FLOORS``: 0.035 rad) this trial, for the switch and for the module's ``terrain_watch``. The thesis
  detects "when the torso reaches previously defined threshold" (L1759): a level, not a rising edge. On logged
  trials the switch is a telemetry event ``events/terrain_switch``; the network keeps it
  (``network.terrain_switch_events``). On a logged trial the threshold (``terrain_switch/band_low``, ``band_high``)
  and the switch (``terrain_switch/at``) are also series in degrees, to be drawn over the body's torso pitch.

On logged trials every neuron is shown on ``sim_time``: per joint and side (E, F) RG V and q, PF and MN, then the
sensory neurons (``CPGNetwork.neuron_names``).
"""

from __future__ import annotations

import importlib.util
import math
import re
from typing import Any, Literal

import numpy as np
from pydantic import Field, ValidationError, field_validator, model_validator
from pydantic_core import InitErrorDetails, PydanticCustomError

from sfl_brain.body import Controller
from sfl_brain.module import ModuleParams
from sfl_brain.modules.cpg import CPGNetwork
from sfl_brain.modules.cpg.circuit import Circuit, apply_overrides, circuit_path, read_circuit_data, validate_circuit
from sfl_brain.modules.cpg.patterns import PATTERN_POINTS
from sfl_brain.modules.cpg.terrain import DETECTORS
from sfl_brain.registry import nearest
from sfl_brain.scenario import ScenarioError
from sfl_brain.telemetry import Event, rates_of, series

#: what a trial may set (see the module docstring)
TRIAL_PARAMS = (
    "sigma_s",
    "sigma_f",
    "alpha_mlr",
    "theta_mlr",
    "phase_reset",
    "switch",
    "switch_at",
    "gain_pitch",
    "gain_roll",
    "posture_gain",
    "terrain_switch",
    "switch_threshold",
    "switch_band",
    "switch_when",
    "next_gain_pitch",
    "next_gain_roll",
    "next_sigma_s",
    "next_theta_mlr",
    "start_slope_deg",
    "ankle_adaptation",
    "start_ramp",
    "switch_detector",
    "foot_slope_floor",
)
#: the group gain multipliers a trial may set (ch. 5's w1, w2): trial parameter -> the circuit's gain group
GAIN_PARAMS = {"gain_pitch": "pitch", "gain_roll": "roll", "next_gain_pitch": "pitch", "next_gain_roll": "roll"}
#: what ``terrain_switch`` and ``switch_when`` take
TERRAIN_SWITCH_MODES = ("off", *CPGNetwork.TERRAIN_SWITCH_MODES)
TERRAIN_SWITCH_WHEN = CPGNetwork.TERRAIN_SWITCH_WHEN
#: how the circuit's phase resets act (``phase_reset``, module and trial parameter)
PHASE_RESET_MODES = CPGNetwork.PHASE_RESET_MODES
#: what a terrain switch may watch (``switch_detector``; ``terrain_watch``), modules/cpg/terrain.py
SWITCH_DETECTORS = DETECTORS
ON_OFF = ("on", "off")


class PatternPoint(ModuleParams):
    """An RG pattern by its two shape parameters (4.5), (4.7); thesis range [0, 5] (Table 4.1)."""

    sigma_s: float = Field(ge=0, description="g_K / g_L (4.7)")
    sigma_f: float = Field(ge=0, description="g_Ca / g_L (4.5)")


class PatternSwitch(ModuleParams):
    """Pattern switching of chosen joints on a trigger, once per trial (digest §7.11; see the module docstring)."""

    trigger: Literal["none", "time", "push"] = Field("none", description="none, a time (at) or a push detector")
    at: float = Field(5.0, ge=0, description="s of trial time, for trigger time")
    push_input: str = Field("pelvis", description="the circuit input whose rate is the push detector (trigger push)")
    push_rate: float = Field(
        1.0,
        gt=0,
        description="per s: the detector fires when push_input rises faster (rad/s for an angle: forward pitch). "
        "Not in the thesis (§0.8, §7.11); chosen here. A 45 N, 0.1 s push on the back (E4.4, L1319) adds about "
        "0.2 rad/s to the 8-link walker's pelvis rate: calibrate it just above flat walking's range, as §7.17 does "
        "for slopes",
    )
    joints: dict[str, Literal["plateau", "quiescent", "almost_oscillator", "oscillator"] | PatternPoint] = Field(
        {}, description="joint -> its new pattern: by name (patterns.PATTERN_POINTS) or {sigma_s, sigma_f}"
    )
    kick: float = Field(
        1.0, description="current into RG-F (RG-E gets its negative) after the switch (§7.11: +-I, I = 1)"
    )
    kick_duration: float = Field(0.2, gt=0, description="s, §7.11")
    joint_kicks: dict[str, float] = Field({}, description="a switched joint's own kick; its sign = direction (L1437)")
    inhibit: list[tuple[str, str]] = Field([], description="joint pairs whose RG-RG couplings are silenced (L1311)")
    theta0: Literal["angle", "continuous"] = Field(
        "continuous",
        description="a position-commanded joint's theta_0 at the switch: continuous (the command goes on from the "
        "measured angle; the thesis switches patterns and says nothing of the offset) or angle (theta_0 := the "
        "measured angle: the author's 2017 scripts, digest §5, whose circuit has no reflexes; here the command jumps "
        "by the reflexes' offset)",
    )
    kick_direction: Literal["fixed", "motion"] = Field(
        "fixed",
        description="fixed: each kick as given; motion (issue 23's E4.4): its magnitude as given, its sign pushing the "
        "joint further the way it moves at the switch (its angle's rate over the last tick)",
    )

    def circuit_entry(self, name: str | None = None, armed: bool = True) -> dict:
        """This switch as an entry of a circuit's ``switches`` (modules/cpg/circuit.py ``Switch``)."""
        joints = {}
        for joint, pattern in self.joints.items():
            sigma_s, sigma_f = (
                PATTERN_POINTS[pattern] if isinstance(pattern, str) else (pattern.sigma_s, pattern.sigma_f)
            )
            joints[joint] = {"sigma_s": float(sigma_s), "sigma_f": float(sigma_f)}
        trigger = (
            {"at": self.at} if self.trigger == "time" else {"input": self.push_input, "rate_above": self.push_rate}
        )
        return {
            "joints": joints,
            **trigger,
            "kick": self.kick,
            "kick_duration": self.kick_duration,
            "joint_kicks": dict(self.joint_kicks),
            "inhibit": [list(pair) for pair in self.inhibit],
            "theta0": self.theta0,
            "kick_direction": self.kick_direction,
            "name": name,
            "armed": armed,
        }


def _invalid(problems: list[tuple[tuple, str]], given: Any) -> ValidationError:
    """A ValidationError with one error per (key path, message): raised in a validator, pydantic puts the field's name
    in front of each path, so ``sfl check`` prints ``modules.controller.params.<field>.<path>: <message>``."""
    return ValidationError.from_exception_data(
        "CPGParams",
        [InitErrorDetails(type=PydanticCustomError("cpg", message), loc=loc, input=given) for loc, message in problems],
    )


def _circuit_problems(exc: ScenarioError) -> list[tuple[tuple, str]]:
    """A circuit's problems as (key path inside the circuit, message with its did-you-mean)."""
    out = []
    for p in exc.problems:
        hint = f" (did you mean `{p.suggestion}`?)" if p.suggestion else ""
        out.append((tuple(p.path.split(".")) if p.path else (), f"{p.message}{hint}"))
    return out


class CPGParams(ModuleParams):
    circuit: str = Field(
        "planar_8link",
        description="a shipped circuit (modules/cpg/circuits) or a YAML file (absolute, or from the cwd)",
    )
    circuit_overrides: dict[str, Any] = Field({}, description="circuit key path -> value (nested mappings merge)")
    phase_reset: Literal["off", "pulse", "state", "circuit"] = Field(
        "circuit",
        description="how the circuit's phase resets act when a trial does not say: as the file says (circuit; also "
        "true), all pulses, all state resets, or off (also false)",
    )
    substeps: int = Field(10, ge=1, le=100, description="RK4 steps per control tick: h = tick / substeps (1 ms, §7.2)")
    kernel: Literal["numpy", "numba"] = Field(
        "numpy",
        description="how the network integrates: numpy, or the same RK4 compiled with numba (the `fast` extra, "
        "pip install -e '.[fast]'; about 3x cheaper, commands within 1e-9 of numpy's; modules/cpg/compiled.py)",
    )
    pattern_joints: list[str] = Field(
        [], description="joints the trial's sigma_s, sigma_f, alpha_mlr, theta_mlr set; empty = all (L1286)"
    )
    switch: PatternSwitch = PatternSwitch()
    switches: dict[str, PatternSwitch] = Field(
        {}, description="named switch presets; a trial arms one by its name (trial parameter switch)"
    )
    terrain_input: str | None = Field(
        None,
        description="the circuit input a terrain switch watches (§5.8: the torso pitch, rad); none: torso_pitch "
        "(checked when a trial switches: the planar circuit has none)",
    )
    terrain_switch_after: float = Field(
        3.0,
        ge=0,
        description="s of trial time before which no terrain switch fires (the start-up transient; not in the thesis)",
    )
    switch_measure: float = Field(
        2.0,
        gt=0,
        description="s from terrain_switch_after over which a trial's switch_band measures the watched input's mean "
        "and half range (three cycles of the shipped flat gait); detection starts after it",
    )
    switch_seconds: float = Field(
        0.667,
        gt=0,
        description="s over which a gradual terrain switch moves the parameters: one cycle of the flat gait (§7.17; "
        "the shipped humanoid gait's period is 0.667 s, 1.5 Hz)",
    )
    terrain_watch: list[Literal[DETECTORS]] = Field(  # type: ignore[valid-type]
        [],
        description="detectors watched on every trial without switching (their bands measured as switch_band's, "
        "watch_band wide): when each would have fired is an event on logged trials (issue 29's comparison)",
    )
    watch_band: float = Field(1.5, ge=0, description="k of the watched detectors' bands: mean +- k x half range")

    @field_validator("phase_reset", mode="before")
    @classmethod
    def _bool_is_circuit_or_off(cls, value: Any) -> Any:
        """``true`` / ``false``, as before the modes existed: "circuit" / "off"."""
        return ("circuit" if value else "off") if isinstance(value, bool) else value

    @field_validator("circuit")
    @classmethod
    def _circuit_loads(cls, name: str) -> str:
        try:
            validate_circuit(read_circuit_data(name), str(circuit_path(name)))
        except ScenarioError as exc:  # the file's own problems, each with its key path in the file
            raise _invalid([((), line) for line in str(exc).splitlines()], name) from None
        return name

    @field_validator("circuit_overrides")
    @classmethod
    def _overrides_apply(cls, overrides: dict, info) -> dict:
        if "circuit" in info.data:  # else the circuit itself failed, reported there
            try:
                apply_overrides(read_circuit_data(info.data["circuit"]), overrides)
            except ScenarioError as exc:
                raise _invalid(_circuit_problems(exc), overrides) from None
        return overrides

    @model_validator(mode="after")
    def _names_exist(self) -> CPGParams:
        circuit = apply_overrides(read_circuit_data(self.circuit), self.circuit_overrides)
        joints, inputs = [j.name for j in circuit.joints], list(circuit.inputs)
        problems: list[tuple[tuple, str]] = []

        def need(loc: tuple, given: str, valid: list[str], what: str) -> None:
            if given not in valid:
                hint = nearest(given, valid)
                tail = f" (did you mean `{hint}`?)" if hint else ""
                problems.append((loc, f"expected one of the {what} {valid}; got {given!r}{tail}"))

        for i, name in enumerate(self.pattern_joints):
            need(("pattern_joints", i), name, joints, f"joints of circuit {circuit.name}")
        switches = [(("switch",), self.switch)] + [(("switches", key), s) for key, s in self.switches.items()]
        for at, s in switches:
            for name in s.joints:
                need((*at, "joints", name), name, joints, f"joints of circuit {circuit.name}")
            for name in s.joint_kicks:
                need((*at, "joint_kicks", name), name, list(s.joints), "joints this switch switches")
            for i, pair in enumerate(s.inhibit):
                for k, name in enumerate(pair):
                    need((*at, "inhibit", i, k), name, joints, f"joints of circuit {circuit.name}")
            if s.trigger != "none" and not s.joints:
                problems.append(((*at, "joints"), f"expected the joints to switch (trigger {s.trigger!r}); got none"))
            if s.trigger == "push":
                need((*at, "push_input"), s.push_input, inputs, f"inputs of circuit {circuit.name}")
            if s.kick_direction == "motion":
                angles = [j.name for j in circuit.joints if j.angle_input is not None]
                for name in (name for name in s.joints if name in joints and name not in angles):
                    problems.append(
                        (
                            (*at, "joints", name),
                            f"expected a joint with an angle_input (kick_direction motion); "
                            f"{name!r} has none in circuit {circuit.name}",
                        )
                    )
        for key, s in self.switches.items():
            if key == "none" or not _NAME.match(key):
                problems.append(
                    (
                        ("switches", key),
                        f"expected a preset name (a letter, then letters, digits, _; not 'none'); got {key!r}",
                    )
                )
            if s.trigger == "none":
                problems.append(
                    (("switches", key, "trigger"), "expected 'time' or 'push' (a preset fires on one); got 'none'")
                )
        if self.terrain_input is not None:  # the default is checked when a trial switches (the planar circuit has none)
            need(("terrain_input",), self.terrain_input, inputs, f"inputs of circuit {circuit.name}")
        lacking = circuit.state_reset_problem()
        if self.phase_reset == "state" and lacking:
            problems.append((("phase_reset",), lacking))
        if self.kernel == "numba" and importlib.util.find_spec("numba") is None:
            problems.append((("kernel",), "expected numba installed for kernel 'numba' (pip install -e '.[fast]')"))
        if problems:
            raise _invalid(problems, self.model_dump(mode="json"))
        return self

    @property
    def watched_input(self) -> str:
        """The input a terrain switch watches: ``terrain_input``, or the torso pitch."""
        return self.terrain_input if self.terrain_input is not None else "torso_pitch"

    def build_circuit(self) -> Circuit:
        """The circuit the controller runs: the file, its overrides, the pattern switch (armed when a trial does not
        choose) and the presets (armed only by the trial that names one, ``CPGController.preset_index``)."""
        data = apply_overrides(read_circuit_data(self.circuit), self.circuit_overrides).model_dump()
        if self.switch.trigger != "none":
            data["switches"].append(self.switch.circuit_entry())
        for key, preset in self.switches.items():
            data["switches"].append(preset.circuit_entry(name=key, armed=False))
        return validate_circuit(data, str(circuit_path(self.circuit)))


_NAME = re.compile(r"^[A-Za-z][A-Za-z0-9_]*$")


def command_names(circuit: Circuit) -> tuple[str, ...]:
    """One command per joint: ``v_<joint>`` (V) for a voltage circuit, ``q_<joint>`` (rad) for a position circuit."""
    prefix = "v" if circuit.command == "voltage" else "q"
    return tuple(f"{prefix}_{j.name}" for j in circuit.joints)


class CPGController(Controller):
    """The MLMP-CPG of ch. 4 (Figs. 4.8-4.12, 4.19; eqs. 4.1-4.13), any circuit; learns sigma_s, sigma_f per trial."""

    Params = CPGParams
    TRIAL_PARAMS = TRIAL_PARAMS

    def __init__(self, params: CPGParams | None = None, *, seed: int = 0) -> None:
        params = params if params is not None else self.Params()
        self.circuit = params.build_circuit()
        self.network = CPGNetwork(self.circuit, kernel=params.kernel)
        self.network.set_phase_reset(params.phase_reset)  # as each trial's configure does, for a network used directly
        #: per instance: the neurons depend on the circuit (see the report on ``Controller.NEURONS``)
        self.NEURONS = tuple(self.network.neuron_names())
        joints = params.pattern_joints or [j.name for j in self.circuit.joints]
        self._pattern_joints = joints
        self._pattern_columns = 2 * np.array([self.circuit.joint_index(n) for n in joints])  # their E cells
        #: preset name -> its index in ``circuit.switches`` (what the trial parameter ``switch`` arms)
        self.preset_index = {s.name: i for i, s in enumerate(self.circuit.switches) if not s.armed and s.name}
        self._control_dt = 0.01
        self._event_log: tuple[int, float] | None = None  # (trial, t0) of a logged trial
        self._terrain_log: list | None = None  # a logged trial's (t, slope estimates, ankle centres) (issue 29)
        self._terrain_every = 1  # ticks between two of its samples
        super().__init__(params, seed=seed)

    @classmethod
    def signals(cls, params: CPGParams) -> tuple[tuple[str, ...], tuple[str, ...]]:
        """Reads the circuit's inputs, writes one command per joint (``command_names``)."""
        circuit = params.build_circuit()
        return tuple(circuit.inputs), command_names(circuit)

    @classmethod
    def check_trial_param(cls, name: str, value, params: CPGParams | None = None) -> None:
        """Raise ValueError if ``value`` cannot be trial parameter ``name`` (``sfl check`` calls this). Without
        ``params`` the type and the allowed strings are checked; with the module's ``params`` also what depends on
        them: that a ``switch`` preset exists, that the circuit's phase resets store states for "state"."""
        needs_circuit = name in ("phase_reset", "posture_gain", "terrain_switch", "ankle_adaptation", *GAIN_PARAMS)
        circuit = params.build_circuit() if params is not None and needs_circuit else None
        presets = list(params.switches) if params is not None else None
        _check_trial_value(name, value, circuit, presets, params.watched_input if params is not None else None)

    def configure(self, params: dict, seed: int) -> None:
        unknown = [k for k in params if k not in TRIAL_PARAMS]
        if unknown:
            hint = nearest(unknown[0], TRIAL_PARAMS)
            tail = f" (did you mean `{hint}`?)" if hint else ""
            raise ValueError(f"CPGController takes trial parameters {list(TRIAL_PARAMS)}; got {unknown}{tail}")
        for name, value in params.items():
            _check_trial_value(name, value, self.circuit, list(self.preset_index), self.params.watched_input)
        _check_terrain_switch(params, self.params.terrain_watch)
        msg = self.trial  # the base sets it before configure (None when configured by hand, e.g. in a test)
        self._control_dt = msg.dt if msg is not None else 0.01
        log = msg is not None and msg.log and self.telemetry is not None
        self._event_log = (msg.trial_id, msg.t0) if log else None
        network = self.network
        network.reset(seed)
        if "sigma_s" in params or "sigma_f" in params:  # E4.2: the learnt pattern (L1251, L1286)
            columns = self._pattern_columns  # a value not given stays the circuit's
            sigma_s = float(params["sigma_s"]) if "sigma_s" in params else network.sigma_s[0, columns]
            sigma_f = float(params["sigma_f"]) if "sigma_f" in params else network.sigma_f[0, columns]
            network.set_pattern(sigma_s, sigma_f, joints=self._pattern_joints)
        if "alpha_mlr" in params or "theta_mlr" in params:  # (4.9) descending control
            network.set_descending(params.get("alpha_mlr"), params.get("theta_mlr"), joints=self._pattern_joints)
        network.set_phase_reset(params.get("phase_reset", self.params.phase_reset))  # §7.10, E4.3
        choice = params.get("switch")  # §7.11, E4.4: None = the circuit's switches and the parameter `switch`
        if choice is not None:
            network.arm_switches([] if choice == "none" else [self.preset_index[choice]])
        if "switch_at" in params:  # the armed switch's time trigger, moved to this trial's time (e.g. its push)
            network.set_switch_time(float(params["switch_at"]))
        if "start_slope_deg" in params:  # circuit start_slope: the start pose shifted by the slope it starts on
            network.set_start_slope(math.radians(float(params["start_slope_deg"])))
        if "ankle_adaptation" in params:  # each ankle's centre follows the sensed slope (issue 29)
            network.set_ankle_adaptation(params["ankle_adaptation"] in ("on", True))
        if "start_ramp" in params:  # alpha_MLR grows from 0 over the trial's first seconds
            network.set_start_ramp(float(params["start_ramp"]))
        for name in ("gain_pitch", "gain_roll"):  # ch. 5's w1, w2 (L1631): multipliers of the groups' gains
            if name in params:
                network.set_gain_multiplier(GAIN_PARAMS[name], float(params[name]))
        if "posture_gain" in params:  # the torso held near 10 deg (L1764)
            network.set_posture_gain(float(params["posture_gain"]))
        floors = {"foot_slope": float(params["foot_slope_floor"])} if "foot_slope_floor" in params else None
        mode = params.get("terrain_switch", "off")
        if mode != "off":  # §5.8: another condition's parameters when the torso pitch says the terrain changed
            p = self.params
            network.arm_terrain_switch(
                p.watched_input,
                float(params["switch_threshold"]) if "switch_threshold" in params else None,
                params.get("switch_when", "outside"),
                mode=mode,
                seconds=p.switch_seconds,
                after=p.terrain_switch_after,
                gains={GAIN_PARAMS[k]: float(params[k]) for k in ("next_gain_pitch", "next_gain_roll") if k in params},
                sigma_s=float(params["next_sigma_s"]) if "next_sigma_s" in params else None,
                theta_mlr=float(params["next_theta_mlr"]) if "next_theta_mlr" in params else None,
                sigma_joints=self._pattern_joints,
                band=(float(params["switch_band"]), p.switch_measure) if "switch_band" in params else None,
                detector=params.get("switch_detector", "torso"),
                floors=floors,
            )
        if self.params.terrain_watch:  # detectors watched without switching (issue 29)
            p = self.params
            network.watch_terrain(
                p.terrain_watch, (p.watch_band, p.switch_measure), p.terrain_switch_after, p.watched_input, floors
            )
        self._terrain_log = [] if log and network.ankle_adaptation else None
        every = rates_of(self.telemetry).signal_every(self._control_dt) if log else 1
        self._terrain_every = every

    def step(self, sensors: np.ndarray) -> np.ndarray:
        network = self.network
        network.advance(sensors, self._control_dt, self.params.substeps)
        if self._terrain_log is not None and network.tick % self._terrain_every == 1 % self._terrain_every:
            self._terrain_log.append((network.time, network.slope_estimate_all()[0], network.ankle_centre_all()[0]))
        return network.command()

    def neurons(self) -> np.ndarray:
        return self.network.neuron_values()

    def flush_neurons(self) -> None:
        """End of a logged trial: its pattern switches as events, then (the base) its neuron activities."""
        log, self._event_log = self._event_log, None
        if log is not None and self.telemetry is not None:
            trial_id, t0 = log
            for event in self.network.switch_events:
                self.telemetry.emit(Event("events/pattern_switch", trial_id, t0 + event.time, switch_text(event)))
            for event in self.network.terrain_switch_events:
                self.telemetry.emit(
                    Event("events/terrain_switch", trial_id, t0 + event.time, terrain_switch_text(event))
                )
            for event in self.network.detector_events:
                self.telemetry.emit(Event("events/detector", trial_id, t0 + event.time, detector_text(event)))
            self._log_terrain_switch(trial_id, t0)
            self._log_terrain(trial_id, t0)
        super().flush_neurons()

    def _log_terrain(self, trial_id: int, t0: float) -> None:
        """A logged trial's ankle adaptation (issue 29) as series in degrees: each foot's slope estimate
        (``terrain/slope_<foot>``) and its ankle's centre shift (``terrain/ankle_centre_<foot>``), at the signal rate;
        and the terrain switch's largest command change per tick while it moves (``terrain_switch/command_jump``,
        rad)."""
        rows, self._terrain_log = self._terrain_log, None
        network = self.network
        if rows:
            times = t0 + np.array([r[0] for r in rows])
            slopes, centres = np.array([r[1] for r in rows]), np.array([r[2] for r in rows])
            for f, joint in enumerate(network.circuit.ankle_adaptation.feet):
                foot = joint.rpartition("_")[2]
                self.telemetry.emit(series(f"terrain/slope_{foot}", trial_id, times, np.degrees(slopes[:, f]), "deg"))
                self.telemetry.emit(
                    series(f"terrain/ankle_centre_{foot}", trial_id, times, np.degrees(centres[:, f]), "deg")
                )
        jumps = network.terrain_switch_jumps
        if jumps:
            self.telemetry.emit(
                series(
                    "terrain_switch/command_jump",
                    trial_id,
                    t0 + np.array([j[0] for j in jumps]),
                    np.array([j[1] for j in jumps]),
                    "rad",
                    color=self.SWITCH_COLOUR,
                    points=True,
                )
            )

    #: the terrain switch's threshold and switch as series beside the body's torso pitch (deg), orange
    SWITCH_COLOUR = (240, 140, 20)
    BAND_STEP = 0.1  # s between two of the threshold's markers

    def _log_terrain_switch(self, trial_id: int, t0: float) -> None:
        """A logged trial's terrain switch (§5.8) as series in degrees: the band its detector watches, from when it is
        known to the trial's end (a marker every ``BAND_STEP`` s; one edge for "below" or "above"), drawn where its
        signal is: over the body's ``torso/pitch`` for the torso detector (``terrain_switch/band_low``, ``band_high``),
        over the sensed slope for the foot_slope detector (``terrain/band_low``, ``band_high``; the other detectors'
        bands are in their events); and the switch, a marker at the torso pitch then (``terrain_switch/at``) and, for
        foot_slope, at the sensed slope that left the band (``terrain/switch``)."""
        known = self.network.terrain_threshold
        if known is None:
            return
        fired = [e for e in self.network.terrain_switch_events if e.copies[0]]
        detector = self.network.terrain_detector
        where = {"torso": "terrain_switch", "foot_slope": "terrain"}.get(detector)
        # dotted (a marker every BAND_STEP s), so that one trial's band is not joined to the next logged trial's
        span = t0 + np.arange(known.since, max(known.since, self.network.time) + 1e-9, self.BAND_STEP)
        for name, edge in (("band_low", known.low), ("band_high", known.high)):
            if where is not None and np.isfinite(edge[0]):
                value = np.full(len(span), math.degrees(float(edge[0])))
                self.telemetry.emit(
                    series(f"{where}/{name}", trial_id, span, value, "deg", color=self.SWITCH_COLOUR, points=True)
                )
        if not fired:
            return
        event = fired[0]
        at = [t0 + event.time]
        torso = event.value if event.detector == "torso" else event.torso
        self.telemetry.emit(
            series(
                "terrain_switch/at",
                trial_id,
                at,
                [math.degrees(float(np.ravel(torso)[0]))],
                "deg",
                color=self.SWITCH_COLOUR,
                points=True,
            )
        )
        if event.detector == "foot_slope":
            value = [math.degrees(float(np.ravel(event.value)[0]))]
            colour = self.SWITCH_COLOUR
            self.telemetry.emit(series("terrain/switch", trial_id, at, value, "deg", color=colour, points=True))


def _check_trial_value(
    name: str, value, circuit: Circuit | None, presets: list[str] | None, terrain_input: str | None = None
) -> None:
    """``check_trial_param`` and ``configure``'s check: ``circuit``, ``presets`` and ``terrain_input`` (the module
    parameter) None when not known."""
    if name in ("terrain_switch", "switch_when"):
        allowed = TERRAIN_SWITCH_MODES if name == "terrain_switch" else TERRAIN_SWITCH_WHEN
        if not isinstance(value, str) or value not in allowed:
            hint = nearest(value, allowed) if isinstance(value, str) else None
            tail = f" (did you mean {hint!r}?)" if hint else ""
            raise ValueError(f"{name}: expected one of {list(allowed)}; got {value!r}{tail}")
        if name == "terrain_switch" and value != "off" and circuit is not None and terrain_input is not None:
            if terrain_input not in circuit.inputs:
                raise ValueError(
                    f"terrain_switch: expected the circuit {circuit.name} to have the input {terrain_input!r} "
                    f"(module parameter terrain_input) to watch; its inputs are {circuit.inputs}"
                )
        return
    if name == "phase_reset":
        if not isinstance(value, str) or value not in PHASE_RESET_MODES:
            hint = nearest(value, PHASE_RESET_MODES) if isinstance(value, str) else None
            tail = f" (did you mean {hint!r}?)" if hint else ""
            raise ValueError(f"phase_reset: expected one of {list(PHASE_RESET_MODES)}; got {value!r}{tail}")
        lacking = circuit.state_reset_problem() if circuit is not None and value == "state" else ""
        if lacking:
            raise ValueError(f"phase_reset: {lacking}")
        return
    if name == "ankle_adaptation":
        if isinstance(value, bool):  # YAML's bare on / off
            value = "on" if value else "off"
        if not isinstance(value, str) or value not in ON_OFF:
            hint = nearest(value, ON_OFF) if isinstance(value, str) else None
            tail = f" (did you mean {hint!r}?)" if hint else ""
            raise ValueError(f"ankle_adaptation: expected one of {list(ON_OFF)}; got {value!r}{tail}")
        if value == "on" and circuit is not None and circuit.ankle_adaptation is None:
            raise ValueError(
                f"ankle_adaptation: expected circuit {circuit.name} to have one (circuit key ankle_adaptation)"
            )
        return
    if name == "switch_detector":
        if not isinstance(value, str) or value not in SWITCH_DETECTORS:
            hint = nearest(value, SWITCH_DETECTORS) if isinstance(value, str) else None
            tail = f" (did you mean {hint!r}?)" if hint else ""
            raise ValueError(f"switch_detector: expected one of {list(SWITCH_DETECTORS)}; got {value!r}{tail}")
        return
    if name == "start_ramp":
        if isinstance(value, bool) or not isinstance(value, int | float) or not math.isfinite(value) or value < 0:
            raise ValueError(f"start_ramp: expected a time in s >= 0; got {value!r}")
        return
    if name == "start_slope_deg":
        if isinstance(value, bool) or not isinstance(value, int | float) or not math.isfinite(value) or abs(value) > 45:
            raise ValueError(f"start_slope_deg: expected a slope in deg within +-45; got {value!r}")
        if circuit is not None and not circuit.start_slope:
            raise ValueError(f"start_slope_deg: circuit {circuit.name} has no start_slope joints to shift")
        return
    if name == "switch_at":
        if isinstance(value, bool) or not isinstance(value, int | float) or not math.isfinite(value) or value < 0:
            raise ValueError(f"switch_at: expected a time in s >= 0; got {value!r}")
        return
    if name == "switch":
        if not isinstance(value, str):
            raise ValueError(f'switch: expected "none" or the name of a preset (a string); got {value!r}')
        if presets is not None and value != "none" and value not in presets:
            hint = nearest(value, presets)
            tail = f" (did you mean {hint!r}?)" if hint else ""
            raise ValueError(f'switch: expected "none" or one of the presets {presets}; got {value!r}{tail}')
        return
    if isinstance(value, bool) or not isinstance(value, int | float) or not math.isfinite(value):
        raise ValueError(f"{name}: expected a finite number; got {value!r}")
    if name == "switch_band" and value < 0:
        raise ValueError(f"switch_band: expected k >= 0 (the threshold: mean +- k x half range); got {value!r}")
    if name == "foot_slope_floor" and not 0 <= value <= math.pi / 2:
        raise ValueError(f"foot_slope_floor: expected a half band in rad within [0, pi/2]; got {value!r}")
    if name in ("sigma_s", "sigma_f", "next_sigma_s") and value < 0:
        raise ValueError(f"{name}: expected a number >= 0 (Table 4.1: [0, 5]); got {value!r}")
    if name in GAIN_PARAMS:
        if value < 0:
            raise ValueError(f"{name}: expected a multiplier of the calibrated gains >= 0 (1: the gait); got {value!r}")
        group = GAIN_PARAMS[name]
        if circuit is not None and group not in circuit.gain_groups:
            raise ValueError(
                f"{name}: expected circuit {circuit.name} to have the gain group {group!r} (circuit key gain_groups); "
                f"it has {list(circuit.gain_groups)}"
            )
    if name == "posture_gain":
        if value < 0:
            raise ValueError(f"posture_gain: expected a gain in 1/s >= 0 (0: off); got {value!r}")
        if circuit is not None and circuit.posture is None:
            raise ValueError(f"posture_gain: expected circuit {circuit.name} to have a posture (circuit key posture)")


def _check_terrain_switch(params: dict, watched: list[str]) -> None:
    """What a terrain switch needs besides each value's own check (``configure``; one value alone cannot say).
    ``watched``: the detectors the module watches without switching (``terrain_watch``)."""
    if params.get("ankle_adaptation") in ("on", True) and "start_slope_deg" in params:
        raise ValueError(
            "start_slope_deg: expected none with ankle_adaptation 'on' (the adaptation senses the slope the trial "
            "starts on); got both"
        )
    mode = params.get("terrain_switch", "off")
    if "foot_slope_floor" in params and "foot_slope" not in watched:
        if mode == "off" or params.get("switch_detector") != "foot_slope":
            raise ValueError(
                "foot_slope_floor: expected the feet's slope detector watched this trial (switch_detector "
                "foot_slope, or foot_slope in the module's terrain_watch); it is not"
            )
    if mode == "off":
        return
    detector = params.get("switch_detector", "torso")
    if detector == "time":  # no threshold: the switch fires at terrain_switch_after
        if "switch_threshold" in params or "switch_band" in params:
            raise ValueError("switch_detector 'time': expected no switch_threshold or switch_band (it senses nothing)")
    elif detector != "torso" and "switch_band" not in params:
        raise ValueError(f"switch_detector {detector!r}: expected switch_band (its band measured on the walk)")
    elif ("switch_threshold" in params) == ("switch_band" in params):
        raise ValueError(
            f"terrain_switch {mode!r}: expected one of switch_threshold (rad) or switch_band (the threshold measured "
            "on the walk: mean +- switch_band x half range, digest §7.17)"
        )
    if "switch_when" not in params and detector != "time":
        raise ValueError(f"terrain_switch {mode!r}: expected the trial parameter switch_when too; got none")
    if not any(k in params for k in ("next_gain_pitch", "next_gain_roll", "next_sigma_s", "next_theta_mlr")):
        raise ValueError(
            f"terrain_switch {mode!r}: expected at least one of next_gain_pitch, next_gain_roll, next_sigma_s, "
            "next_theta_mlr (the new condition's parameters); got none"
        )


def terrain_switch_text(event) -> str:
    """One line saying what a terrain switch did (§5.8)."""

    def number(value) -> str:
        return f"{value:.4g}" if np.ndim(value) == 0 else "[" + ", ".join(f"{v:.4g}" for v in np.ravel(value)) + "]"

    how = "at once" if event.mode == "at_once" else f"gradually over {event.seconds:g} s"
    moves = ", ".join(f"{name} {number(event.old[name])} -> {number(new)}" for name, new in event.new.items())
    detector = getattr(event, "detector", "torso")
    if detector == "time":  # nothing sensed: the switch at its time
        return f"terrain switch ({how}): at {event.time:g} s (switch_detector time); {moves}"
    if event.when == "outside":  # the band (low, high) it left
        band = f"[{number(event.threshold[0])}, {number(event.threshold[1])}]"
    else:
        band = number(event.threshold)
    signal = event.input if detector == "torso" else detector
    where = f"{signal} {number(event.value)} rad {event.when} {band}"
    return f"terrain switch ({how}): {where}; {moves}"


def detector_text(event) -> str:
    """One line saying when a watched detector fired (issue 29)."""

    def number(value) -> str:
        return f"{value:.4g}" if np.ndim(value) == 0 else "[" + ", ".join(f"{v:.4g}" for v in np.ravel(value)) + "]"

    return f"detector {event.detector}: {number(event.value)} outside [{number(event.low)}, {number(event.high)}]"


def switch_text(event) -> str:
    """One line saying what a pattern switch did."""
    names = {point: kind for kind, point in PATTERN_POINTS.items()}
    parts = []
    for joint, point in event.patterns.items():
        kind = names.get(point)
        parts.append(
            f"{joint} -> {kind + ' ' if kind else ''}(sigma_s {point[0]:g}, sigma_f {point[1]:g}), "
            f"kick {event.kicks[joint]:+g}"
        )
    text = f"pattern switch{' ' + event.name if event.name else ''}: " + "; ".join(parts)
    if event.kick_direction == "motion":
        text += " (kicks signed by each joint's motion)"
    if event.inhibited:
        text += "; couplings silenced between " + ", ".join(f"{a}-{b}" for a, b in event.inhibited)
    return text
