"""One conformance check for every module implementation (in the spirit of Gymnasium's ``check_env``).

``check_module(cls)`` verifies the contract: a frozen, validated parameter schema whose
defaults construct; at least one handler, each for a registered message type; ``reset(seed)``
is deterministic (same seed, same replies to the same messages); messages survive the codec.
It raises ``AssertionError`` naming the module and what failed.
"""

from __future__ import annotations

import numpy as np
from pydantic import ValidationError

from . import messages as m
from .body import Body, Controller, InProcessLink
from .module import Module


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


def _replies(cls: type[Module], seed: int) -> list:
    module = cls(cls.Params(), seed=seed)
    if isinstance(module, Body):
        request = m.TrialRequest(trial_id=0, seed=seed, body_params={}, controller_params={}, log=False)
        if module.COMMANDS:
            from sfl_brain.modules.controllers.open_loop import OpenLoopController

            module.params = module.Params(**{**module.params.model_dump(), "duration": 0.2})
            module.link = InProcessLink(OpenLoopController())
        result = m.decode(m.encode(module.handle(request)))
        module.close()
        return [result]
    if isinstance(module, Controller):
        module.handle(
            m.ControllerReset(
                trial_id=0,
                seed=seed,
                params={},
                sensors=list(cls.REQUIRED_SENSORS),
                commands=list(cls.COMMANDS),
            )
        )
        frame = m.SensorFrame(trial_id=0, tick=0, values=np.zeros(len(cls.REQUIRED_SENSORS)))
        reply = module.handle(frame)
        assert len(reply.values) == len(cls.COMMANDS), f"{cls.__name__}: {len(reply.values)} commands"
        return [reply]
    return [m.decode(m.encode(module.handle(msg))) for msg in sample_messages(module)]


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
    if issubclass(cls, Body):
        assert len(set(cls.SENSORS)) == len(cls.SENSORS), f"{name}: duplicate sensor names"
    if issubclass(cls, Controller):
        assert cls.COMMANDS, f"{name}: a controller declares its COMMANDS"
    first, second, other = _replies(cls, 3), _replies(cls, 3), _replies(cls, 4)
    assert len(first) == len(second)
    for a, b in zip(first, second, strict=True):
        assert _same(a, b), f"{name}: same seed gave different replies: {a} vs {b}"
    assert other is not None
