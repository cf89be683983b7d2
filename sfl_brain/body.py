"""Bodies, low-level controllers and the lockstep trial loop that joins them.

A :class:`Body` is a simulated robot: it starts a trial from a request, senses,
takes one control tick of commands, and says when the trial is over and how it
went. A :class:`Controller` turns one tick of sensor values into one tick of
commands. :meth:`Body.trial` runs them in lockstep through a *link*: the
controller itself in the same process (:class:`InProcessLink`), or the same
controller in another process (``sfl_brain.runtime.ticklink.SocketLink`` or ``BusLink``). The loop
is the same either way, so both give identical trial records.

NaN or an infinity in a tick's sensor values, in a controller's command or in a
trial's outcome ends the trial with :class:`~sfl_brain.messages.NonFiniteError`,
naming the body or controller, the message and the value (``values[3] (knee_r)``);
the trial request then gets an error reply and the run stops ``failed``.
"""

from __future__ import annotations

import math
import time
from typing import Any, ClassVar, Protocol

import numpy as np
from pydantic import Field

from .messages import (
    _F8,
    Ack,
    ControllerReset,
    Message,
    MotorCommand,
    NonFiniteError,
    SensorFrame,
    TrialRequest,
    TrialResult,
    check_finite,
    first_nonfinite,
    message_name,
)
from .module import Module, ModuleParams, on
from .signals import Signal, WiringError, names, wiring
from .telemetry import FAILURE, SUCCESS, Event, rates_of, series


def check_number(name: str, value: Any, low: float, high: float) -> float:
    """``value`` as a float within [low, high]; ValueError naming ``name`` otherwise (for ``check_trial_param``)."""
    if isinstance(value, bool) or not isinstance(value, int | float):
        raise ValueError(f"{name}: expected a number; got {value!r}")
    if not math.isfinite(value) or not low <= value <= high:
        raise ValueError(f"{name}: expected a number in [{low:g}, {high:g}]; got {value!r}")
    return float(value)


def walking_efficiency(mass: float, speed: float, energy: float) -> float:
    """(5.7)-(5.8): the kinetic energy at the mean speed, m v^2 / 2 (kg, m/s), over the energy spent (J); 0 when
    nothing was spent."""
    return 0.5 * mass * speed**2 / energy if energy > 0 else 0.0


class ControllerLink(Protocol):
    """How a body reaches its controller during a trial."""

    def reset(self, msg: ControllerReset) -> None: ...

    def step(self, frame: SensorFrame) -> MotorCommand: ...


class InProcessLink:
    """A controller hosted in the body's own process (composition, as ROS 2 components)."""

    def __init__(self, controller: Controller) -> None:
        self.controller = controller

    def reset(self, msg: ControllerReset) -> None:
        self.controller.handle(msg)

    def step(self, frame: SensorFrame) -> MotorCommand:
        command = self.controller.handle(frame, checked=True)  # Body.trial checked its sensors
        # a command is checked where it lands (see Module.handle): one sum for a short vector
        if not _finite_vector(getattr(command, "values", None)) and isinstance(command, Message):
            check_finite(command, self.controller, "replied")
        return command


def _finite_vector(values: Any) -> bool:
    """True when ``values`` is a vector whose plain sum is finite, which proves every value finite
    (NaN and infinities propagate through a sum; see ``messages.all_finite``). False says only
    that the exact check must decide (an overflowing sum, not a vector)."""
    try:
        return math.isfinite(sum(values.tolist()))
    except (AttributeError, TypeError):
        return False


class BodyParams(ModuleParams):
    control_dt: float = Field(0.01, gt=0, le=0.1, description="control tick, s of simulated time")
    duration: float = Field(10.0, gt=0, le=600, description="trial length, s of simulated time")


class Body(Module):
    """Base of simulated bodies. Subclasses fill the five trial hooks."""

    Params: ClassVar[type[BodyParams]] = BodyParams
    #: the sensor values of one tick, in the order :meth:`sense` lays them out (name, unit, bounds,
    #: meaning); empty for bodies that need no controller
    SENSORS: ClassVar[tuple[Signal, ...]] = ()
    #: the command values of one tick, in the order :meth:`actuate` takes them
    COMMANDS: ClassVar[tuple[Signal, ...]] = ()
    #: parameters a trial request may set on the body (checked by ``sfl check``)
    TRIAL_PARAMS: ClassVar[tuple[str, ...]] = ()
    #: the recording's default layout for a run of this body (``sfl_brain.recording.rrlog.LAYOUTS``): "walker" (a planar
    #: walker's y-up pictures) or "humanoid" (3-D boxes, z up, with the terrain switch over the torso pitch)
    LAYOUT: ClassVar[str] = "walker"
    #: the unit of each metric :meth:`outcome` reports ("" for counts, flags and ratios): the ``m_<metric>`` columns
    #: of ``trials.parquet`` carry it in their schema (a metric not named here has none)
    METRICS: ClassVar[dict[str, str]] = {}

    def __init__(self, params: BodyParams | None = None, *, seed: int = 0) -> None:
        super().__init__(params, seed=seed)
        self.link: ControllerLink | None = None
        self.worker = "body"
        #: pace the trial to wall-clock time (``sfl run --realtime``)
        self.realtime = False
        #: True during a trial the scenario records (``record.body_every``): buffer what ``log_trial`` will emit
        self.logging = False

    @classmethod
    def check_trial_param(cls, name: str, value: Any) -> None:
        """Raise ValueError (its message says what is expected) if ``value`` cannot be the trial parameter ``name``;
        ``sfl check`` calls it for every value a scenario can give (space bounds, conditions), before anything starts.
        The default accepts anything ``TRIAL_PARAMS`` names."""

    # --- the trial hooks ----------------------------------------------------
    def start_trial(self, request: TrialRequest) -> None:
        """Build the world for a trial from ``request.body_params`` and seed ``request.seed``."""
        raise NotImplementedError

    def sense(self) -> np.ndarray:
        """Sensor values of the current tick, laid out as ``SENSORS``."""
        raise NotImplementedError

    def actuate(self, command: np.ndarray) -> None:
        """Apply one tick of commands and advance the simulation by ``control_dt``."""
        raise NotImplementedError

    @property
    def done(self) -> bool:
        """True when the trial is over (time out, fall, goal)."""
        raise NotImplementedError

    def outcome(self) -> tuple[bool, float, dict]:
        """(success, quality eta, metrics) of the finished trial."""
        raise NotImplementedError

    def log_trial(self, trial_id: int) -> None:
        """Emit what was buffered during a logged trial to ``self.telemetry`` (optional).

        Called at the end of a trial during which ``self.logging`` was True; times on ``sim_time``
        (this trial starts at ``trial_id * duration``), sampled as ``self.telemetry.rates`` asks.
        """

    def log_outcome(self, trial_id: int, elapsed: float, success: bool, metrics: dict) -> None:
        """Mark a logged trial's start and end on ``sim_time``, coloured by its outcome: an event
        each (``trial/events``) and a marker at 1 (``trial/success``) or 0 (``trial/failure``)."""
        t0 = trial_id * self.params.duration
        verdict, colour = ("success", SUCCESS) if success else ("failure", FAILURE)
        shown = ", ".join(
            f"{k} {v:.3g}" if isinstance(v, float) else f"{k} {v}"
            for k, v in metrics.items()
            if not isinstance(v, dict)
        )
        sink = self.telemetry
        sink.emit(Event("trial/events", trial_id, t0, f"trial {trial_id} starts", color=colour))
        sink.emit(
            Event(
                "trial/events",
                trial_id,
                t0 + elapsed,
                f"trial {trial_id}: {verdict} after {elapsed:.2f} s" + (f" ({shown})" if shown else ""),
                level="INFO" if success else "WARN",
                color=colour,
            )
        )
        sink.emit(
            series(f"trial/{verdict}", trial_id, [t0, t0 + elapsed], [float(success)] * 2, color=colour, points=True)
        )

    # --- the loop ------------------------------------------------------------
    def _check_sensors(self, values: Any, trial_id: int, tick: int) -> None:
        """Raise NonFiniteError naming this body and the sensor of the first NaN or infinity."""
        bad = first_nonfinite(values)
        if bad is None:
            return  # all finite (the quick sum overflowed)
        where, value = bad
        i = where[1:-1]
        if i.isdigit() and int(i) < len(self.SENSORS):
            where += f" ({names(self.SENSORS)[int(i)]})"
        raise NonFiniteError(
            message_name(SensorFrame), "values" + where, value, self, "sensed", {"trial_id": trial_id, "tick": tick}
        )

    def _controller_name(self) -> str:
        """How errors name the controller behind ``self.link``."""
        controller = getattr(self.link, "controller", None)
        if isinstance(controller, str):  # a SocketLink or BusLink: the controller's instance name
            return f"controller {controller!r}"
        if controller is not None:
            return f"{type(controller).__name__} {controller.entity!r}"
        return "the controller"

    @on(TrialRequest)
    def trial(self, request: TrialRequest) -> TrialResult:
        """Run one trial in lockstep with the controller behind ``self.link``."""
        self.logging = bool(request.log and self.telemetry is not None)
        tick = 0
        self.start_trial(request)
        if self.COMMANDS:
            if self.link is None:
                raise RuntimeError(f"{type(self).__name__} needs a controller and has none")
            self.link.reset(
                ControllerReset(
                    trial_id=request.trial_id,
                    seed=request.seed,
                    params=request.controller_params,
                    sensors=list(names(self.SENSORS)),
                    commands=list(names(self.COMMANDS)),
                    log=self.logging,
                    t0=request.trial_id * self.params.duration,
                    dt=self.params.control_dt,
                )
            )
            step_wall = time.perf_counter()
            dt = self.params.control_dt
            step = self.link.step
            while not self.done:
                values = self.sense()
                if not _finite_vector(values):
                    self._check_sensors(values, request.trial_id, tick)
                frame = SensorFrame(trial_id=request.trial_id, tick=tick, values=values)
                try:
                    command = step(frame)
                except NonFiniteError as exc:
                    if exc.module is None:  # decoded from a controller in another process
                        raise exc.named(self._controller_name(), "sent") from None
                    raise
                if command.trial_id != request.trial_id or command.tick != tick:
                    raise RuntimeError(
                        f"controller answered trial {command.trial_id} tick {command.tick}, "
                        f"expected trial {request.trial_id} tick {tick}"
                    )
                self.actuate(command.values)
                tick += 1
                if self.realtime:
                    step_wall += dt
                    delay = step_wall - time.perf_counter()
                    if delay > 0:
                        time.sleep(delay)
        success, quality, metrics = self.outcome()
        if self.logging:
            self.log_outcome(request.trial_id, tick * self.params.control_dt, bool(success), metrics)
            self.log_trial(request.trial_id)
        return TrialResult(
            trial_id=request.trial_id,
            success=bool(success),
            quality=float(quality),
            metrics=metrics,
            worker=self.worker,
            sim_s=tick * self.params.control_dt,
        )


class Controller(Module):
    """Base of low-level controllers: one tick of sensors in, one tick of commands out.

    A controller names the signals it reads and writes; its body declares them (units, bounds).
    They are matched by name (:func:`sfl_brain.signals.wiring`), once per body layout: ``step``
    gets the sensors in ``READS`` order whatever the body's order, and its ``WRITES`` values are
    put in the body's command order. A body with sensors the controller does not read is fine; a
    sensor it lacks, or a command that one end has and the other has not, is an error that names
    both ends (``sfl check`` finds it before anything starts).
    """

    #: names of the sensors ``step`` reads, in the order it takes them
    READS: ClassVar[tuple[str, ...]] = ()
    #: names of the commands ``step`` returns, in its own order (the body's must be the same set)
    WRITES: ClassVar[tuple[str, ...]] = ()
    #: learnt parameters a trial may set (checked by ``sfl check``)
    TRIAL_PARAMS: ClassVar[tuple[str, ...]] = ()
    #: names of the neuron activities :meth:`neurons` returns (shown on logged trials, at
    #: ``neurons/<name>``)
    NEURONS: ClassVar[tuple[str, ...]] = ()
    #: the trial being controlled, as its :class:`ControllerReset` (``trial_id``, ``seed``, ``dt``: s of simulated
    #: time per control tick, ``t0``: its start on ``sim_time``, ``log``, ``params``); set before :meth:`configure`
    trial: ControllerReset | None = None
    #: the tick :meth:`step` is computing (0 first; -1 before the trial's first tick): its time is ``tick * trial.dt``
    tick: int = -1
    #: a logged trial's neuron activities: (rows, ticks, trial_id, t0, dt, every); None when not logging
    _neuron_log = None

    @classmethod
    def check_trial_param(cls, name: str, value: Any) -> None:
        """Raise ValueError (its message says what is expected) if ``value`` cannot be the trial parameter ``name``;
        ``sfl check`` calls it for every value a scenario can give (space bounds, conditions), before anything starts.
        The default accepts anything ``TRIAL_PARAMS`` names."""

    def configure(self, params: dict, seed: int) -> None:
        """Start of a trial: take the learnt parameters, reset the neurons."""
        raise NotImplementedError

    def neurons(self) -> np.ndarray:
        """Activities of ``NEURONS`` after the last step (only called on logged trials)."""
        return np.empty(0)

    def step(self, sensors: np.ndarray) -> np.ndarray:
        """One control tick: sensor values (``READS`` order) -> command values (``WRITES`` order)."""
        raise NotImplementedError

    _wired_for: tuple | None = None
    _read_index: np.ndarray | None = None
    _write_index: np.ndarray | None = None

    @classmethod
    def signals(cls, params: ModuleParams) -> tuple[tuple[str, ...], tuple[str, ...]]:
        """(reads, writes) of a controller with these parameters: ``READS``, ``WRITES`` unless a
        controller's signals depend on its parameters (the CPG's on its circuit file)."""
        return cls.READS, cls.WRITES

    @classmethod
    def wire(
        cls, sensors, commands, body: str = "the body", params: ModuleParams | None = None
    ) -> tuple[np.ndarray | None, np.ndarray | None]:
        """Index maps (None: the same order) from ``body``'s ``sensors`` to what the controller reads
        and from what it writes to the body's ``commands`` (Signals or names); :class:`WiringError`
        naming both ends on a mismatch."""
        me = f"controller `{cls.__name__}`"
        reads, writes = cls.signals(params if params is not None else cls.Params())
        read = wiring(sensors, reads, provider=body, consumer=me, what="reads sensors")
        extra = [n for n in writes if n not in names(commands)]
        if extra:
            raise WiringError(
                f"{me} writes commands {extra} that {body} does not take; it takes {list(names(commands))}"
            )
        write = wiring(writes, names(commands), provider=me, consumer=body, what="takes commands")
        return read, write

    @on(ControllerReset)
    def on_controller_reset(self, msg: ControllerReset) -> Ack:
        layout = (tuple(msg.sensors), tuple(msg.commands))
        if layout != self._wired_for:  # once per body layout, not per trial
            self._read_index, self._write_index = self.wire(*layout, params=self.params)
            self._wired_for = layout
        self._trial_id = msg.trial_id
        self.flush_neurons()  # the previous logged trial, if any
        self._neuron_log = None
        rates = rates_of(self.telemetry)
        if msg.log and self.NEURONS and self.telemetry is not None and rates.neurons:
            self._neuron_log = ([], [], msg.trial_id, msg.t0, msg.dt, rates.signal_every(msg.dt))
        self.trial, self.tick = msg, -1
        self.configure(dict(msg.params), msg.seed)
        return Ack()

    @on(SensorFrame)
    def on_sensor_frame(self, frame: SensorFrame) -> MotorCommand:
        self.tick = frame.tick
        read = self._read_index
        values = self.step(frame.values if read is None else frame.values[read])
        neuron_log = self._neuron_log
        if neuron_log is not None and frame.tick % neuron_log[5] == 0:  # sampled as the sink asks
            neuron_log[0].append(self.neurons())
            neuron_log[1].append(frame.tick)
        if type(values) is not np.ndarray or values.dtype != _F8:
            # a step that returns a list or float32 still sends a float64 vector (the packed layout)
            values = np.asarray(values, dtype=_F8)
        if self._write_index is not None:
            values = values[self._write_index]
        return MotorCommand(trial_id=frame.trial_id, tick=frame.tick, values=values)

    def flush_neurons(self) -> None:
        """Emit a logged trial's neuron activities as :class:`~sfl_brain.telemetry.Scalars` at
        ``neurons/<name>``: the activity after tick i's step at ``t0 + (i + 1) dt`` on ``sim_time``
        (when the body's state after that tick is sampled too)."""
        log_, self._neuron_log = self._neuron_log, None
        if not log_ or not log_[0] or self.telemetry is None:
            return
        rows, ticks, trial_id, t0, dt, _ = log_
        trace = np.stack(rows)
        times = t0 + dt * (np.asarray(ticks) + 1)
        for j, name in enumerate(self.NEURONS):
            self.telemetry.emit(series(f"neurons/{name}", trial_id, times, trace[:, j]))

    def close(self) -> None:
        self.flush_neurons()
