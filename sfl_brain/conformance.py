"""One conformance check for every module implementation (in the spirit of Gymnasium's ``check_env``).

``check_module(cls)`` verifies the contract: a frozen, validated parameter schema whose
defaults construct; at least one handler, each for a registered message type; ``reset(seed)``
is deterministic (same seed, same replies to the same messages); messages survive the codec.
A body declares its signals as :class:`~sfl_brain.signals.Signal` s with unique names, senses
as many values as it declares, each within its declared bounds, during a short trial driven by
a controller that holds every command at zero; a controller names what it reads and writes
(unique names) and returns one value per command; a module that says it emits no telemetry
(``emits_telemetry = False``) emits none when given a sink. It raises ``AssertionError`` naming the module
and what failed. It imports no module implementation of its own.
"""

from __future__ import annotations

import numpy as np
from pydantic import ValidationError

from . import messages as m
from .body import Body, Controller, InProcessLink
from .module import Module
from .signals import SENSOR_SLACK, Signal, names
from .telemetry import CaptureTelemetry


def sample_messages(module: Module) -> list[m.Message]:
    """Canonical requests for the message types a module handles, in a sensible order."""
    dim = getattr(module.params, "dim", None) or 2
    rng = np.random.default_rng(0)
    samples = {
        m.VigilanceStart: [m.VigilanceStart()],
        m.TrialDone: [
            m.TrialDone(trial_index=1, success=True, n_success=1, n_failure=0),
            m.TrialDone(trial_index=2, success=False, n_success=1, n_failure=1),
        ],
        m.Rejected: [m.Rejected(consecutive=1000)],
        m.Grade: [m.Grade(eta=0.3), m.Grade(eta=0.7), m.Grade(eta=0.5)],
        m.Learn: [
            m.Learn(v=rng.random(dim), success=True, rho=1.0),
            m.Learn(v=rng.random(dim), success=False, rho=1.0),
        ],
        m.Evaluate: [m.Evaluate(candidates=rng.random((8, dim)), s_vig=0.0)],
        m.Exploit: [m.Exploit(axis=0, conditions=np.linspace(0, 1, 3))],
    }
    out = []
    for message_type in type(module).handles:
        out.extend(samples.get(message_type, []))
    return out


class _HoldStill(Controller):
    """The conformance check's own controller: every command at zero, whatever the body."""

    READS = ()

    def configure(self, params: dict, seed: int) -> None:
        pass

    def step(self, sensors: np.ndarray) -> np.ndarray:
        return np.zeros(len(self.WRITES))


class _CheckedLink(InProcessLink):
    """Checks each tick's sensor values against the body's declared signals."""

    def __init__(self, body: type[Body]) -> None:
        hold = type("HoldStill", (_HoldStill,), {"WRITES": names(body.COMMANDS)})
        super().__init__(hold())
        self.body = body
        self.ticks = 0

    def step(self, frame: m.SensorFrame) -> m.MotorCommand:
        cls, values = self.body, frame.values
        assert len(values) == len(cls.SENSORS), (
            f"{cls.__name__}: sensed {len(values)} values, declares {len(cls.SENSORS)}"
        )
        for signal, value in zip(cls.SENSORS, values.tolist(), strict=True):
            slack = SENSOR_SLACK * (signal.high - signal.low)  # joint stops and contacts are soft in physics
            assert signal.low - slack <= value <= signal.high + slack, (
                f"{cls.__name__}: sensor {signal.name} = {value:g} {signal.unit} at tick {frame.tick}, "
                f"outside its declared [{signal.low:g}, {signal.high:g}]"
            )
        self.ticks += 1
        return super().step(frame)


def _replies(cls: type[Module], seed: int, telemetry=None) -> list:
    module = cls(cls.Params(), seed=seed)
    module.telemetry = telemetry
    if isinstance(module, Body):
        request = m.TrialRequest(trial_id=0, seed=seed, body_params={}, controller_params={}, log=False)
        if module.COMMANDS:
            if "duration" in module.Params.model_fields:
                module.params = module.Params(**{**module.params.model_dump(), "duration": 0.2})
            module.link = link = _CheckedLink(cls)
        result = m.decode(m.encode(module.handle(request)))
        module.close()
        if module.COMMANDS:
            assert link.ticks > 0, f"{cls.__name__}: a trial with a controller ran no tick"
        return [result]
    if isinstance(module, Controller):
        reads, writes = cls.signals(module.params)
        module.handle(m.ControllerReset(trial_id=0, seed=seed, params={}, sensors=list(reads), commands=list(writes)))
        replies = []
        for tick in range(3):
            frame = m.SensorFrame(trial_id=0, tick=tick, values=np.zeros(len(reads)))
            reply = m.decode(m.encode(module.handle(frame)))
            assert len(reply.values) == len(writes), (
                f"{cls.__name__}: returned {len(reply.values)} commands for {len(writes)} WRITES"
            )
            replies.append(reply)
        return replies
    return [m.decode(m.encode(module.handle(msg))) for msg in sample_messages(module)]


def _check_signals(cls: type[Module]) -> None:
    name = cls.__name__
    if issubclass(cls, Body):
        for kind in ("SENSORS", "COMMANDS"):
            declared = getattr(cls, kind)
            assert all(isinstance(s, Signal) for s in declared), f"{name}.{kind} must be Signals (name, unit, bounds)"
            assert len(set(names(declared))) == len(declared), f"{name}.{kind}: duplicate names {names(declared)}"
        assert not cls.COMMANDS or cls.SENSORS, f"{name}: a body that takes commands declares its SENSORS"
    if issubclass(cls, Controller):
        reads, writes = cls.signals(cls.Params())
        assert writes, f"{name}: a controller declares the commands it WRITES"
        for kind, declared in (("READS", reads), ("WRITES", writes), ("NEURONS", cls.NEURONS)):
            assert all(isinstance(s, str) for s in declared), f"{name}.{kind} must be names"
            assert len(set(declared)) == len(declared), f"{name}.{kind}: duplicate names"


def _same(a, b) -> bool:
    if isinstance(a, np.ndarray) or isinstance(b, np.ndarray):
        return np.array_equal(np.asarray(a), np.asarray(b))
    if isinstance(a, m.Message):
        return type(a) is type(b) and all(_same(getattr(a, f), getattr(b, f)) for f in a._FIELDS)
    return a == b


def check_module(cls: type[Module]) -> None:
    name = cls.__name__
    assert issubclass(cls, Module), f"{name} is not a Module"
    params = cls.Params()
    try:
        setattr(params, next(iter(cls.Params.model_fields), "x"), None)
        frozen = False
    except (ValidationError, TypeError, AttributeError):
        frozen = True
    assert frozen or not cls.Params.model_fields, f"{name}.Params must be frozen"
    assert cls.Params.model_config.get("extra") == "forbid", f"{name}.Params must reject unknown keys"
    assert cls.handles, f"{name} handles no message"
    tags = m.registered()
    for message_type in cls.handles:
        assert tags.get(message_type.TAG) is message_type, f"{name} handles unregistered {message_type}"
    _check_signals(cls)
    first, second = _replies(cls, 3), _replies(cls, 3)
    assert len(first) == len(second)
    for a, b in zip(first, second, strict=True):
        assert _same(a, b), f"{name}: same seed gave different replies: {a} vs {b}"
    _replies(cls, 4)  # another seed runs too
    if not cls.emits_telemetry:  # its host leaves Rerun unopened: check it has nothing to show, even when asked
        seen = CaptureTelemetry()
        _replies(cls, 3, seen)
        assert not seen.items, f"{name} says emits_telemetry = False but emitted {sorted(seen.paths())}"
