"""Scenario files: schema, validation, and the resolved plan the runtime launches.

A scenario names its modules (each by implementation and parameters), the
parameter space Omega (unit axes mapped to physical controller/body parameters),
and a protocol (``learn``, ``sweep`` or ``exploit``). ``load`` validates all of it
before anything starts: unknown keys, types, ranges, implementations, module
parameters, and the message wiring. Every problem is reported as
``FILE: key.path: expected ..., got ... (did you mean ...?)``.

Scenario files may come from anyone, so reading one is guarded (see ``docs/reliability.md``): at
most ``MAX_BYTES``, strict UTF-8, a safe YAML loader with limits on nesting and on values (also
after expanding aliases), no duplicate keys, no tags beyond plain values, lists and mappings;
types are strict (no text or true/false read as a number) and numbers finite; and ``sfl check``
runs what would fail at start: importing each implementation, the size of maps, trial parameters
the body can check (terrains), restart policies.
"""

from __future__ import annotations

import copy
import inspect
import json
import math
import os
import re
import typing
import zlib
from dataclasses import dataclass, field
from pathlib import Path
from typing import Annotated, Any, Literal

import numpy as np
import yaml
from pydantic import BaseModel, ConfigDict, Field, ValidationError, model_validator
from yaml.constructor import ConstructorError
from yaml.nodes import MappingNode, ScalarNode, SequenceNode

from .. import messages as m
from ..body import Body, Controller
from ..module import Module
from ..proposers import NEEDS, PROPOSERS, CMAParams, RandomParams, SafeBOParams, SFLParams, TPEParams
from ..registry import ImplError, nearest, resolve
from ..signals import WiringError


class Strict(BaseModel):
    """Base of the scenario's models: frozen, unknown keys rejected, no coercion (``"40"`` and
    ``true`` are not integers; an integer is a fine float), finite numbers only."""

    model_config = ConfigDict(frozen=True, extra="forbid", strict=True, allow_inf_nan=False)


class Axis(Strict):
    """One axis of Omega: unit coordinate u in [0, 1] -> low + u (high - low) on ``target``."""

    name: str
    target: str = Field(description="'controller.<param>' or 'body.<param>'")
    low: float
    high: float
    steps: int = Field(11, ge=2, le=10_000, description="grid points for the sweep protocol")
    unit: str = ""

    @model_validator(mode="after")
    def _order(self):
        if not self.high > self.low:
            raise ValueError(f"high ({self.high}) must be greater than low ({self.low})")
        return self

    def to_physical(self, u):
        """The physical value(s), in ``unit``, of unit coordinate(s) ``u`` in [0, 1]: the one place
        a learnt or drawn point becomes a parameter (trial requests, records, exploit tables)."""
        if np.ndim(u) == 0:
            return float(self.low + float(u) * (self.high - self.low))
        return self.low + np.asarray(u, dtype=float) * (self.high - self.low)


class ModuleSpec(Strict):
    impl: str = Field(description="registered name, 'package.module:Class' or 'path/file.py:Class'")
    params: dict[str, Any] = {}
    restart: Literal["never", "on-failure"] | None = Field(
        None,
        description="on-failure: restart a body worker or controller that dies or hangs, and retry its trial (the "
        "default for them: they hold no state between trials); never: its death fails the run (the default, and the "
        "only choice, for brain modules, whose learnt state a restart would lose)",
    )
    max_restarts: int = Field(3, ge=0, le=100)
    workers: int = Field(1, ge=1, le=64, description="bodies: processes serving trials in parallel")
    colocate: bool = Field(False, description="controllers: run inside each body worker's process")


Proposer = Annotated[SFLParams | RandomParams | CMAParams | TPEParams | SafeBOParams, Field(discriminator="kind")]


class LearnProtocol(Strict):
    """The success-failure learning cycle (Fig. 3.5 / 5.6)."""

    kind: Literal["learn"]
    trials: int = Field(ge=1, le=1_000_000, description="trial budget: go decisions")
    batch: int = Field(64, ge=1, le=65_536, description="candidates drawn and evaluated per request")
    max_decisions: int = Field(
        2_000_000, ge=1, description="decision cap: a run that reaches it before its trials ends `stalled`"
    )
    stall_decisions: int = Field(
        100_000, ge=1, description="a run with this many no-go decisions in a row ends `stalled` (no progress)"
    )
    prune_failure_map: bool = True
    proposer: Proposer = Field(
        default_factory=SFLParams,
        description="what chooses each trial's parameters: sfl (the default: draws gated by ACC and vigilance; "
        "batch, max_decisions and stall_decisions are its), random, cma, tpe or safe_bo (sfl_brain.proposers)",
    )


class SweepProtocol(Strict):
    """Every point of the grid over Omega (``steps`` per axis), no learning."""

    kind: Literal["sweep"]


class ExploitProtocol(Strict):
    """Walk with parameters taken from a learnt success map, switching neurons by condition."""

    kind: Literal["exploit"]
    maps: str = Field(description="ACC checkpoint (.npz) from a learn run")
    condition: str = Field(description="the axis of Omega that is the condition (e.g. slope)")
    trials: int = Field(1, ge=1, le=10_000)


#: a trial parameter's value, as a scenario gives it (a number, a word, a switch)
TrialValue = float | int | str | bool


class PoincareAnalysis(Strict):
    """``sfl report``: the Poincaré return map of the torso's pitch on every logged trial (E4.5, L1401-1413;
    :mod:`sfl_brain.report.poincare`). Needs the body logged on every trial at every tick (``record.body_every: 1``,
    ``record.signals_hz: 0``) and its series ``body/torso/pitch``, ``body/torso/pitch_rate``."""

    kind: Literal["poincare"]


class TraceAnalysis(Strict):
    """``sfl report``: recorded series of the first logged trials of each condition against time, with the times of
    recorded events marked (e.g. the torso pitch and a pattern switch)."""

    kind: Literal["trace"]
    series: list[str] = Field(min_length=1, max_length=8, description="entity paths, e.g. body/torso/pitch")
    events: list[str] = Field([], max_length=8, description="event entity paths marked on it")
    trials: int = Field(2, ge=1, le=20, description="logged trials drawn per condition")
    where: dict[str, TrialValue] = Field({}, description="only logged trials with these grid values")


class PatternSpaceAnalysis(Strict):
    """``sfl report``: the trajectory of each joint in the pattern space of L1430-1435 (Fig. 4.23): the energy (4.15)
    of the joint's rhythm generator, its two cells' potential difference V_E - V_F, over a sliding ``window`` (one
    gait cycle) against time, on the first logged trials of each condition; and the point of every joint before the
    first marked event (the push) and ``after`` s later, one axis per joint (L1298). Needs the controller's neuron
    activities in the recording (``record.neurons``, at ``<module>/neurons/<joint>/<E|F>/RG_V``)."""

    kind: Literal["pattern_space"]
    window: float = Field(gt=0, le=60, description="s: the energy's sliding window, one gait cycle")
    after: float = Field(2.0, gt=0, le=600, description="s after the first marked event: where the after point is")
    joints: list[str] = Field([], max_length=64, description="joints drawn, in this order; [] = every recorded RG")
    module: str = Field("controller", description="the scenario's module whose RG neurons are read")
    events: list[str] = Field(
        ["body/events", "controller/events/pattern_switch"],
        min_length=1,
        max_length=8,
        description="event entity paths marked on it; the first in a trial is the push the points are taken about",
    )
    trials: int = Field(1, ge=1, le=20, description="logged trials drawn per condition")
    where: dict[str, TrialValue] = Field({}, description="only logged trials with these grid values")


class CommandJumpAnalysis(Strict):
    """``sfl report``: how much a terrain switch itself changed the joint commands (issue 29): for every logged trial
    of each condition, the largest change of any joint's command the switch made in one tick (the controller's
    ``terrain_switch/command_jump`` series, rad), against ``limit``."""

    kind: Literal["command_jump"]
    limit: float = Field(0.02, gt=0, le=10, description="rad: the most a switch may change a command in one tick")
    module: str = Field("controller", description="the scenario's module whose switch is read")


class DetectionAnalysis(Strict):
    """``sfl report``: the terrain detectors watched on every logged trial (issue 29; the controller's
    ``events/detector``) against when a foot first touched the next piece of ground (the body's
    ``events/terrain``): per condition and detector, walks it fired on, its latency, those within ``latency`` s and
    before the torso pitch fell below ``pitch_below`` deg, and those that fired before the change."""

    kind: Literal["detection"]
    latency: float = Field(0.5, gt=0, le=60, description="s after the foot meets the new ground: fired in time")
    pitch_below: float = Field(-5.0, ge=-90, le=90, description="deg: the torso pitch a detection must come before")
    module: str = Field("controller", description="the scenario's module whose detectors are read")


Analysis = Annotated[
    PoincareAnalysis | TraceAnalysis | PatternSpaceAnalysis | CommandJumpAnalysis | DetectionAnalysis,
    Field(discriminator="kind"),
]


class ConditionsProtocol(Strict):
    """A set of trials under named conditions, for experiments that compare conditions rather than learn (E4.3-E4.7,
    E5.3): every condition runs every point of ``grid`` (trial parameters varied together, every combination),
    ``repeats`` times, each repeat from its own start (trial seed). Repeat r has the same seed in every condition and
    at every grid point, so that two conditions are compared on the same starts (paired trials). A condition and a
    grid key name trial parameters as axes do (``body.push_force``, ``controller.phase_reset``); the scenario's own
    ``conditions`` apply to every trial first."""

    kind: Literal["conditions"]
    conditions: dict[str, dict[str, TrialValue]] = Field(
        min_length=1, max_length=64, description="name -> the trial parameters of that condition ({} = as the scenario)"
    )
    grid: dict[str, list[TrialValue]] = Field(
        {}, max_length=8, description="trial parameter -> the values to run; every combination, in the order given"
    )
    repeats: int = Field(1, ge=1, le=10_000, description="starts (trial seeds) per condition and grid point")
    judge: Literal["success", "upright"] = Field(
        "success",
        description="what a trial survived means in the records and reports: the body's success, or upright = the "
        "body reports no fall (metric `fell`)",
    )
    compare: list[Annotated[list[str], Field(min_length=2, max_length=2)]] = Field(
        [], max_length=64, description="pairs of conditions that sfl report tests against each other (exact tests)"
    )
    pool: list[str] = Field(
        [], max_length=8, description="grid keys sfl report pools over in its summary (e.g. body.push_phase)"
    )
    metrics: list[str] = Field(
        [],
        max_length=16,
        description="body metrics (or `quality`) sfl report summarises per condition (mean and spread)",
    )
    analyses: list[Analysis] = Field([], max_length=8, description="what sfl report draws from the recording")
    best_of: dict[str, str] = Field(
        {},
        max_length=16,
        description="name -> a learn run's folder: a condition's value @NAME.AXIS is that run's best parameter on AXIS "
        "(the success neuron nearest its highest-reward trial, L1584)",
    )
    follow: dict[str, str] = Field(
        {},
        max_length=16,
        description="trial parameter -> the grid or condition key whose value it takes in every trial (e.g. "
        "controller.switch_at: body.push_time, a switch at the push)",
    )

    @property
    def trials(self) -> int:
        """Trials the protocol runs: conditions x grid points x repeats."""
        return len(self.conditions) * math.prod(len(v) for v in self.grid.values()) * self.repeats


def conditions_problems(proto: ConditionsProtocol) -> list[Problem]:
    """What the schema cannot say about a conditions protocol: names, references between its keys, its size."""
    out = []
    for name in proto.conditions:
        if not re.fullmatch(r"[A-Za-z0-9_.-]{1,64}", name):
            out.append(Problem(f"protocol.conditions.{name}", "expected a name of letters, digits, _ . - (at most 64)"))
    for key, values in proto.grid.items():
        if not values:
            out.append(Problem(f"protocol.grid.{key}", "expected at least one value; got []"))
    names = list(proto.conditions)
    for i, pair in enumerate(proto.compare):
        for k, name in enumerate(pair):
            if name not in proto.conditions:
                out.append(
                    Problem(
                        f"protocol.compare.{i}.{k}",
                        f"expected one of the conditions {names}; got {name!r}",
                        nearest(name, names),
                    )
                )
        if pair[0] == pair[1]:
            out.append(Problem(f"protocol.compare.{i}", f"expected two different conditions; got {list(pair)}"))
    for i, key in enumerate(proto.pool):
        if key not in proto.grid:
            out.append(
                Problem(
                    f"protocol.pool.{i}",
                    f"expected a key of the grid {list(proto.grid)}; got {key!r}",
                    nearest(key, list(proto.grid)),
                )
            )
    given = set(proto.grid) | {k for values in proto.conditions.values() for k in values}
    for target, source in proto.follow.items():
        if source not in given:
            out.append(
                Problem(
                    f"protocol.follow.{target}",
                    f"expected a key of the grid or of a condition {sorted(given)}; got {source!r}",
                    nearest(source, sorted(given)),
                )
            )
        if target in given:
            out.append(Problem(f"protocol.follow.{target}", "is set by the grid or a condition already"))
    for i, analysis in enumerate(proto.analyses):  # a value not in the grid is allowed: a cut-down run draws none
        for key in getattr(analysis, "where", {}):
            if key not in proto.grid:
                grid = list(proto.grid)
                path = f"protocol.analyses.{i}.where.{key}"
                out.append(Problem(path, f"expected a key of the grid {grid}; got {key!r}", nearest(key, grid)))
    if proto.trials > MAX_CONDITION_TRIALS:
        out.append(
            Problem(
                "protocol",
                f"expected at most {MAX_CONDITION_TRIALS} trials (conditions x grid points x repeats); "
                f"got {proto.trials}",
            )
        )
    return out


#: the most trials a conditions protocol may ask for
MAX_CONDITION_TRIALS = 1_000_000


Protocol = Annotated[LearnProtocol | SweepProtocol | ExploitProtocol | ConditionsProtocol, Field(discriminator="kind")]


class Record(Strict):
    """What a run keeps beyond its trial records, and how much of a logged trial the recording shows
    (the rates reach every module process; see sfl_brain.telemetry.Rates and docs/recording.md)."""

    body_every: int = Field(1, ge=0, description="log the body's motion on every k-th trial (0: never)")
    decisions: bool = True
    signals_hz: float = Field(
        25.0,
        ge=0,
        le=10_000,
        description="samples per simulated second of a logged trial's joint angles, motor commands, contacts "
        "and neuron activities (0: every control tick)",
    )
    pictures_hz: float = Field(
        25.0, ge=0, le=10_000, description="pictures of the body per simulated second of a logged trial (0: every tick)"
    )
    neurons: bool = Field(True, description="show the controller's neuron activities on logged trials")


class Timeouts(Strict):
    """How long a run waits. A module process on this machine is waited for while it makes progress or is denied the
    CPU: each of these times counts only the time it had the CPU and did nothing with it (runtime.liveness), so a
    busy machine, a nice level, a stop and continue (SIGSTOP/SIGCONT, a suspended laptop) make a run slower, never
    fail it. Past its time, a process is hung."""

    ready: float = Field(
        60.0,
        gt=0,
        description="s a module process may have the CPU without coming alive (and `sfl check`: s of wall time for "
        "importing a module's implementation)",
    )
    request: float = Field(
        30.0,
        gt=0,
        description="s a brain module may have the CPU without answering a request: it is hung, the run fails naming "
        "it (`sfl run --resume RUN_DIR` goes on)",
    )
    trial: float = Field(
        300.0,
        gt=0,
        description="s a body worker and its controller process may have the CPU without a tick: hung, killed and "
        "restarted, the trial retried; for a worker on another machine (sfl worker), s of wall time for one trial",
    )
    tick: float = Field(
        10.0,
        gt=0,
        description="s a controller process may have the CPU without answering one tick (or a reset): hung, the trial "
        "is interrupted and retried, the controller restarted",
    )
    lease: float = Field(
        3.0,
        ge=0.5,
        le=3600,
        description="s a worker on another machine (sfl worker) may be silent before the run gives it up and retries "
        "its trial elsewhere (its Zenoh lease: a process there cannot be seen, only heard)",
    )


class Lockstep(Strict):
    """How a body worker and its controller process exchange their ticks (see sfl_brain.runtime.placement
    and sfl_brain.runtime.host.SpinThenSleep)."""

    spin_us: float = Field(
        200.0,
        ge=0,
        le=100_000,
        description="us the body polls for each command before it sleeps, when it may use more than one core "
        "(pin_cpus never, or nothing pinned); it measures its ticks and polls only while that is faster "
        "(0: always sleep)",
    )
    pin_cpus: Literal["never", "auto", "always"] = Field(
        "auto",
        description="auto = each body worker and its controller process share a core of their own and block "
        "(no polling), brain modules on the other cores, when the run may use more than one core and has "
        "a core per pair; always = also with more pairs than cores (pairs share cores in turn); "
        "never = leave every process to the OS scheduler",
    )
    link: Literal["socket", "zenoh"] = Field(
        "socket",
        description="what carries a body worker's frames and its controller process's commands: socket = a Unix "
        "socket of their own (two system calls a message; Linux; elsewhere zenoh), zenoh = a Zenoh session of "
        "their own on the lowlatency transport; requests, replies and liveliness stay on the run's Zenoh mesh",
    )


class ScenarioModel(Strict):
    name: str = Field(pattern=r"^[A-Za-z0-9_.-]+$")
    description: str = ""
    seed: int = Field(0, ge=0, lt=2**32)
    protocol: Protocol
    space: list[Axis] = Field([], max_length=8, description="Omega's axes (every protocol but conditions needs one)")
    conditions: dict[str, float | int | str | bool] = {}
    modules: dict[str, ModuleSpec] = Field(min_length=1)
    record: Record = Record()
    timeouts: Timeouts = Timeouts()
    lockstep: Lockstep = Lockstep()

    @model_validator(mode="after")
    def _space_needed(self):
        if not self.space and self.protocol.kind != "conditions":
            raise ValueError(f"space: expected at least one axis for protocol {self.protocol.kind!r}; got none")
        return self


# --------------------------------------------------------------------------------------------
# Errors
# --------------------------------------------------------------------------------------------


@dataclass
class Problem:
    path: str
    message: str
    suggestion: str | None = None

    def render(self, file: str) -> str:
        hint = f" (did you mean `{self.suggestion}`?)" if self.suggestion else ""
        where = f"{self.path}: " if self.path else ""
        return f"{file}: {where}{self.message}{hint}"


class ScenarioError(Exception):
    """One or more problems in a scenario file; ``str()`` lists them all."""

    def __init__(self, file: str, problems: list[Problem]) -> None:
        self.file = file
        self.problems = problems
        super().__init__("\n".join(p.render(file) for p in problems))


def _dotted(loc: tuple) -> str:
    return ".".join(str(x) for x in loc)


def _short(value: Any) -> str:
    """A value as the user wrote it in YAML (true, null, .inf), cut to 60 characters."""
    if value is None or isinstance(value, bool):
        text = {None: "null", True: "true", False: "false"}[value]
    elif isinstance(value, float) and not math.isfinite(value):
        text = ".nan" if math.isnan(value) else (".inf" if value > 0 else "-.inf")
    else:
        text = repr(value)
    return text if len(text) <= 60 else text[:57] + "..."


#: what a pydantic type error expected, in words
EXPECTED = {
    "int_type": "an integer",
    "int_from_float": "an integer",
    "float_type": "a number",
    "bool_type": "true or false",
    "string_type": "text",
    "list_type": "a list",
    "tuple_type": "a list",
    "dict_type": "a mapping",
    "model_type": "a mapping",
    "model_attributes_type": "a mapping",
    "finite_number": "a finite number",
}


def _unquoted(given: Any, kind: str) -> str | None:
    """The number a quoted string would be without its quotes (for did-you-mean), if it is one."""
    if not isinstance(given, str) or kind not in ("int_type", "float_type"):
        return None
    try:
        number = int(given) if kind == "int_type" else float(given)
    except ValueError:
        return None
    return given.strip() if math.isfinite(number) else None


def _models_of(annotation) -> list[type[BaseModel]]:
    """The models an annotation holds: itself, or those inside a list, dict, union or Annotated."""
    if isinstance(annotation, type) and issubclass(annotation, BaseModel):
        return [annotation]
    return [m for arg in typing.get_args(annotation) for m in _models_of(arg)]


def _fields_at(model: type[BaseModel], loc: tuple) -> list[str]:
    """Valid keys at ``loc`` inside ``model`` (for did-you-mean on unknown keys). ``loc`` keeps the kind tags of
    discriminated unions (``protocol.conditions.analyses.0.trace``), which choose the branch; without one, the
    keys of every branch."""
    current: Any = model
    for part in loc:
        if isinstance(current, type) and issubclass(current, BaseModel):
            f = current.model_fields.get(str(part))
            if f is None:
                return []
            current = f.annotation
            continue
        models = _models_of(current)
        tagged = [
            m
            for m in models
            if "kind" in m.model_fields and str(part) in typing.get_args(m.model_fields["kind"].annotation)
        ]
        named = [m for m in models if str(part) in m.model_fields]
        if tagged:  # a discriminated union's kind tag
            current = tagged[0]
        elif named:
            current = named[0].model_fields[str(part)].annotation
        elif len(models) == 1:  # a list index or a dict key: the item's model
            current = models[0]
    models = _models_of(current)
    return (
        sorted({name for m in models for name in m.model_fields})
        if len(models) > 1
        else (list(models[0].model_fields) if models else [])
    )


#: parts pydantic inserts into an error's location: validators and unions (not keys of the file)
_SCHEMA_PART = re.compile(
    r"^(function-(after|before|wrap|plain)|tagged-union|union|nullable|lax-or-strict|json-or-python|chain|"
    r"definition-ref|constrained-\w+|list|dict|tuple|set|frozenset)\[.*\]$"
)
_UNION_MEMBERS = ("float", "int", "str", "bool")


def _clean_loc(loc: tuple, kind: str) -> tuple:
    """An error's location as a key path of the file: without validator names, the protocol's
    kind tag (``protocol.learn.trials``) and, for a type error, the member type of a union
    (``conditions.body.x.float``)."""
    out: list = []
    for part in loc:
        if isinstance(part, str) and _SCHEMA_PART.match(part):
            continue
        if len(out) == 1 and out[0] == "protocol" and part in ("learn", "sweep", "exploit", "conditions"):
            continue
        if (
            len(out) >= 2
            and out[-2] == "analyses"
            and part in ("poincare", "trace", "pattern_space", "command_jump", "detection")
        ):  # an analysis's kind tag
            continue
        if out == ["protocol", "proposer"] and part in PROPOSERS:  # a proposer's kind tag
            continue
        out.append(part)
    if kind in EXPECTED and len(out) > 1 and out[-1] in _UNION_MEMBERS:
        out.pop()
    return tuple(out)


def problems_from(exc: ValidationError, model: type[BaseModel], prefix: tuple = ()) -> list[Problem]:
    out = []
    type_errors: dict[str, list] = {}  # path -> type errors there (a union gives one per member)
    for err in exc.errors():
        kind = err["type"]
        clean = _clean_loc(tuple(err["loc"]), kind)
        path = _dotted(prefix + clean)
        given = err.get("input")
        if kind in EXPECTED and path in type_errors:
            type_errors[path].append(kind)
            continue
        if kind == "extra_forbidden":
            tagged = tuple(p for p in err["loc"] if not (isinstance(p, str) and _SCHEMA_PART.match(p)))
            valid = _fields_at(model, tagged[:-1])
            out.append(Problem(path, f"unknown key; expected one of {sorted(valid)}", nearest(str(clean[-1]), valid)))
        elif kind == "missing":
            out.append(Problem(path, "required key is missing"))
        elif kind == "literal_error":
            allowed = err.get("ctx", {}).get("expected", "")
            options = [o.strip().strip("'") for o in allowed.replace(" or ", ",").split(",") if o.strip()]
            out.append(Problem(path, f"expected one of {allowed}; got {_short(given)}", nearest(str(given), options)))
        elif kind == "union_tag_not_found":  # a protocol without its kind
            ctx = err.get("ctx", {})
            out.append(
                Problem(
                    _dotted((*prefix, *clean, ctx.get("discriminator", "kind").strip("'"))), "required key is missing"
                )
            )
        elif kind == "union_tag_invalid":
            ctx = err.get("ctx", {})
            tags = [t.strip().strip("'") for t in str(ctx.get("expected_tags", "")).split(",")]
            discriminator = str(ctx.get("discriminator", "kind")).strip("'")
            # the tag as written (pydantic's context has it as a string: an empty value would read 'None')
            tag = given.get(discriminator) if isinstance(given, dict) else ctx.get("tag")
            out.append(
                Problem(
                    path + ".kind" if path else "kind",
                    f"expected one of {ctx.get('expected_tags')}; got {_short(tag)}",
                    nearest(str(tag), tags) if tag is not None else None,
                )
            )
        elif kind in EXPECTED:
            type_errors[path] = [kind]
            out.append(Problem(path, f"expected {EXPECTED[kind]}; got {_short(given)}", _unquoted(given, kind)))
        else:
            msg = err["msg"]
            if msg.startswith("Value error, "):
                msg = msg[len("Value error, ") :]
            got = "" if isinstance(given, dict) else f"; got {_short(given)}"  # a whole model: too long
            out.append(Problem(path, f"{msg[0].lower() + msg[1:]}{got}"))
    for problem in out:  # a union: one problem naming every type it takes
        kinds = [EXPECTED[k].replace("true or false", "true/false") for k in type_errors.get(problem.path, ())]
        kinds = [k for k in dict.fromkeys(kinds) if not (k == "an integer" and "a number" in kinds)]
        if len(kinds) > 1 and problem.message.startswith("expected "):
            got = problem.message.split("; got ", 1)[1]
            problem.message = f"expected {', '.join(kinds[:-1])} or {kinds[-1]}; got {got}"
    return out


# --------------------------------------------------------------------------------------------
# The plan: what the runtime launches
# --------------------------------------------------------------------------------------------


@dataclass
class Instance:
    """One process to launch (or one module hosted inside a body worker)."""

    name: str  # instance name on the bus, e.g. 'body.1'
    spec_name: str  # key in the scenario's modules
    cls: type[Module]
    reference: str  # importable 'pkg.mod:Class' or '/abs/file.py:Class'
    params: dict
    seed: int
    restart: str
    max_restarts: int
    routes: dict[str, str] = field(default_factory=dict)  # message tag -> instance that handles it
    colocated: Instance | None = None  # a controller hosted inside this body worker


@dataclass
class Plan:
    file: str
    scenario: ScenarioModel
    raw: dict
    instances: list[Instance]
    providers: dict[str, str]  # message tag -> module spec name
    bodies: list[str]  # instance names of body workers
    body_spec: str

    @property
    def dim(self) -> int:
        return len(self.scenario.space)

    @property
    def body_class(self) -> type:
        """The class of the run's body (every body worker runs the same ``modules.body``)."""
        return next(i.cls for i in self.instances if i.name in self.bodies)

    @property
    def lockstep_processes(self) -> list[str]:
        """The processes that exchange a message every control tick: each body worker, followed
        by its controller's process unless the controller is colocated in the body worker."""
        controller_of = {i.routes[m.MotorCommand.TAG]: i.name for i in self.instances if m.MotorCommand.TAG in i.routes}
        return [name for body in self.bodies for name in (body, controller_of.get(body)) if name]

    @property
    def trial_seconds(self) -> float | None:
        """Simulated seconds from one trial's start to the next on ``sim_time``: the (longest) ``duration`` of the
        run's bodies; None when no body has one."""
        durations = [
            i.cls.Params.model_validate(i.params).duration
            for i in self.instances
            if "duration" in getattr(i.cls.Params, "model_fields", {}) and i.name in self.bodies
        ]
        return max(durations) if durations else None

    def to_physical(self, unit: np.ndarray) -> dict[str, dict[str, float]]:
        """Map a unit vector to {'controller': {...}, 'body': {...}} physical parameters."""
        out: dict[str, dict[str, Any]] = {"controller": {}, "body": {}}
        for key, value in self.scenario.conditions.items():
            owner, _, param = key.partition(".")
            out[owner][param] = value
        for u, axis in zip(unit, self.scenario.space, strict=True):
            owner, _, param = axis.target.partition(".")
            out[owner][param] = axis.to_physical(u)
        return out


PROTOCOL_NEEDS: dict[str, list[tuple[type[m.Message], str]]] = {
    "learn": [
        (m.Evaluate, "to evaluate candidates against the success and failure maps"),
        (m.Learn, "to teach the maps each trial"),
        (m.Finish, "to prune and checkpoint the maps"),
        (m.VigilanceStart, "to get the vigilance threshold"),
        (m.TrialDone, "to update the vigilance after each trial"),
        (m.Rejected, "to report runs of no-go decisions"),
        (m.Grade, "to grade successful trials"),
        (m.TrialRequest, "to run trials on a body"),
    ],
    "sweep": [(m.TrialRequest, "to run trials on a body")],
    "exploit": [(m.Exploit, "to read the success map"), (m.TrialRequest, "to run trials on a body")],
    "conditions": [(m.TrialRequest, "to run trials on a body")],
}

#: which registered implementation provides a message kind, for hints
HINT_IMPL = {"acc": "acc", "vigilance": "vigilance", "ofc": "ofc", "body": "analytic", "controller": "reflex"}


def trial_param_check(cls: type, params: Any = None):
    """``cls.check_trial_param`` as a function of (name, value); given the module's ``params`` when it takes them (a
    controller whose trial parameters name its own presets, e.g. the CPG's pattern switches)."""
    check = getattr(cls, "check_trial_param", None)
    if check is None or params is None:
        return check
    try:
        takes_params = "params" in inspect.signature(check).parameters
    except (TypeError, ValueError):
        takes_params = False
    return (lambda name, value: check(name, value, params=params)) if takes_params else check


def instance_seed(seed: int, name: str) -> int:
    """A module's seed: derived from the run seed and its scenario name (not its worker index)."""
    return int(np.random.SeedSequence([seed, zlib.crc32(name.encode())]).generate_state(1)[0])


# --------------------------------------------------------------------------------------------
# Reading a file: size, encoding, a safe YAML loader with limits
# --------------------------------------------------------------------------------------------

#: a scenario file is read only up to this many bytes (the shipped ones are under 2 kB; pure-Python
#: YAML scans about 1 MB of text a second, so this bounds a hostile file to well under a second)
MAX_BYTES = 256 * 1024
#: nesting of mappings and lists, also after expanding aliases (the shipped scenarios nest 5 deep)
MAX_DEPTH = 32
#: YAML values (nodes) in a file, also after expanding aliases: each alias counts its anchor's again
#: (the shipped scenarios have under 100; PyYAML composes about 10 000 a second on a busy machine)
MAX_NODES = 5_000
#: digits of an integer (Python refuses to read more than 4300)
MAX_DIGITS = 100

_TAG = "tag:yaml.org,2002:"
_MERGE = _TAG + "merge"
_SCALAR_TAGS = {_TAG + t for t in ("str", "int", "float", "bool", "null")}
_KINDS = {ScalarNode: "a plain value", SequenceNode: "a list", MappingNode: "a mapping"}


class _YAMLLimit(yaml.MarkedYAMLError):
    """A limit of :class:`SafeLoader` was hit; ``path`` is the key path where it was."""

    def __init__(self, problem: str, mark, path: str = "") -> None:
        super().__init__(problem=problem, problem_mark=mark)
        self.path = path


def _show_tag(tag: str) -> str:
    return "!!" + tag[len(_TAG) :] if tag.startswith(_TAG) else tag


def _join(path: str, key: Any) -> str:
    return f"{path}.{key}" if path else str(key)


class SafeLoader(yaml.SafeLoader):
    """PyYAML's SafeLoader with limits for files from strangers.

    Nesting at most ``MAX_DEPTH`` and at most ``MAX_NODES`` values, both counted again for every
    alias (no billion laughs, no recursive aliases); duplicate keys are errors naming the key path
    and line (PyYAML keeps the last silently); keys are text; only the tags of plain values, lists
    and mappings (and ``<<`` merge keys); integers of at most ``MAX_DIGITS`` digits. Dates stay text.
    """

    yaml_implicit_resolvers = {
        first: [(tag, regexp) for tag, regexp in resolvers if tag != _TAG + "timestamp"]
        for first, resolvers in yaml.SafeLoader.yaml_implicit_resolvers.items()
    }

    def __init__(self, text: str) -> None:
        super().__init__(text)
        self._depth = 0
        self._composed = 0
        self._paths: dict[int, str] = {}  # node id -> key path where it first appears
        self._explicit: dict[int, set[int]] = {}  # mapping node id -> ids of keys written in it

    # --- while scanning: PyYAML's scanner slows down quadratically with open brackets ------------
    def fetch_flow_collection_start(self, TokenClass):
        if self.flow_level >= MAX_DEPTH:
            raise _YAMLLimit(f"nested more than {MAX_DEPTH} deep", self.get_mark())
        super().fetch_flow_collection_start(TokenClass)

    # --- while composing: nesting and count, before anything deeper is parsed ------------------
    def compose_node(self, parent, index):
        self._depth += 1
        self._composed += 1
        try:
            if self._depth > MAX_DEPTH:
                raise _YAMLLimit(f"nested more than {MAX_DEPTH} deep", self.peek_event().start_mark)
            if self._composed > MAX_NODES:
                raise _YAMLLimit(f"more than {MAX_NODES} values", self.peek_event().start_mark)
            return super().compose_node(parent, index)
        finally:
            self._depth -= 1

    def get_single_node(self):
        node = super().get_single_node()
        if node is not None:
            self._inspect(node, 1, "", set(), {})
        return node

    # --- after composing: every node once, aliases expanded by size ----------------------------
    def _inspect(self, node, depth: int, path: str, active: set[int], memo: dict) -> tuple[int, int]:
        """Check ``node`` and return (values, height) of its expansion."""
        key = id(node)
        if key in active:
            raise _YAMLLimit("an alias refers to its own anchor (a recursive structure)", node.start_mark, path)
        if depth > MAX_DEPTH:
            raise _YAMLLimit(f"nested more than {MAX_DEPTH} deep (after expanding aliases)", node.start_mark, path)
        if key not in memo:
            self._paths.setdefault(key, path)
            active.add(key)
            memo[key] = self._measure(node, depth, path, active, memo)
            active.discard(key)
        size, height = memo[key]
        if depth - 1 + height > MAX_DEPTH:
            raise _YAMLLimit(f"nested more than {MAX_DEPTH} deep (after expanding aliases)", node.start_mark, path)
        return size, height

    def _measure(self, node, depth: int, path: str, active: set[int], memo: dict) -> tuple[int, int]:
        expected = {ScalarNode: _SCALAR_TAGS, SequenceNode: {_TAG + "seq"}, MappingNode: {_TAG + "map"}}
        if node.tag not in expected[type(node)]:
            raise _YAMLLimit(
                f"tag `{_show_tag(node.tag)}` is not allowed; expected plain values, lists and mappings",
                node.start_mark,
                path,
            )
        if isinstance(node, ScalarNode):
            digits = sum(c.isdigit() for c in node.value)
            if node.tag == _TAG + "int" and digits > MAX_DIGITS:
                raise _YAMLLimit(f"an integer of {digits} digits; expected at most {MAX_DIGITS}", node.start_mark, path)
            return 1, 1
        if isinstance(node, SequenceNode):
            children = [(_join(path, i), item) for i, item in enumerate(node.value)]
        else:
            children = []
            explicit = set()
            for key_node, value in node.value:
                if key_node.tag == _MERGE:
                    children.append((path, value))
                    continue
                if not isinstance(key_node, ScalarNode) or key_node.tag != _TAG + "str":
                    shown = key_node.value if isinstance(key_node, ScalarNode) else _KINDS[type(key_node)]
                    read_as = _show_tag(key_node.tag).removeprefix("!!")
                    raise _YAMLLimit(
                        f"key {shown!r} is read as {read_as}; expected a text key (quote it: '{shown}')"
                        if isinstance(key_node, ScalarNode)
                        else f"a key is {shown}; expected a text key",
                        key_node.start_mark,
                        path,
                    )
                explicit.add(id(key_node))
                children.append((_join(path, key_node.value), value))
            self._explicit[id(node)] = explicit
        size, height = 1, 1
        for child_path, child in children:
            child_size, child_height = self._inspect(child, depth + 1, child_path, active, memo)
            size += child_size + 1
            height = max(height, child_height + 1)
            if size > MAX_NODES:
                raise _YAMLLimit(
                    f"expands to more than {MAX_NODES} values (aliases count their anchor's again)",
                    node.start_mark,
                    path,
                )
        return size, height

    # --- constructing: duplicate keys, and any error with its line --------------------------
    def construct_mapping(self, node, deep=False):
        if not isinstance(node, MappingNode):
            raise ConstructorError(None, None, f"expected a mapping; got {_KINDS.get(type(node))}", node.start_mark)
        explicit = self._explicit.get(id(node), set())
        self.flatten_mapping(node)  # merge keys: their pairs first, then the ones written here
        path = self._paths.get(id(node), "")
        mapping: dict = {}
        written: dict = {}  # key -> line where it was written in this mapping
        for key_node, value_node in node.value:
            key = self.construct_object(key_node, deep=deep)
            try:
                hash(key)
            except TypeError:
                raise ConstructorError(None, None, "a key is not a plain value", key_node.start_mark) from None
            line = key_node.start_mark.line + 1
            if id(key_node) in explicit:
                if key in written:
                    raise _YAMLLimit(
                        f"duplicate key (first at {written[key]}); expected each key once in a mapping",
                        key_node.start_mark,
                        _join(path, key),
                    )
                written[key] = f"line {line}, column {key_node.start_mark.column + 1}"
            mapping[key] = self.construct_object(value_node, deep=deep)
        return mapping

    def construct_object(self, node, deep=False):
        try:
            return super().construct_object(node, deep)
        except (yaml.YAMLError, RecursionError, MemoryError):
            raise
        except Exception as exc:  # e.g. `!!int abc`, `!!bool maybe`
            raise ConstructorError(
                None, None, f"cannot read {_short(node.value)}: {type(exc).__name__}: {exc}", node.start_mark
            ) from None


def _codepoint(character: int | str) -> str:
    return f"U+{character if isinstance(character, int) else ord(character):04X}"


def _where(mark) -> str:
    return f"line {mark.line + 1}, column {mark.column + 1}: " if mark is not None else ""


def parse_yaml(data: bytes, file: str) -> Any:
    """Decode ``data`` as UTF-8 and parse it with :class:`SafeLoader`; raises :class:`ScenarioError`."""
    if len(data) > MAX_BYTES:
        raise ScenarioError(file, [Problem("", f"expected at most {MAX_BYTES} bytes of YAML; got {len(data)}")])
    if data.startswith(b"\xef\xbb\xbf"):
        data = data[3:]  # a UTF-8 byte order mark
    try:
        text = data.decode("utf-8", errors="strict")
    except UnicodeDecodeError as exc:
        line = data.count(b"\n", 0, exc.start) + 1
        column = exc.start - (data.rfind(b"\n", 0, exc.start) + 1) + 1
        raise ScenarioError(
            file,
            [
                Problem(
                    "",
                    f"line {line}, column {column} (byte {exc.start}): expected UTF-8 text; "
                    f"got byte 0x{data[exc.start]:02x} ({exc.reason})",
                )
            ],
        ) from None
    loader = None
    try:
        loader = SafeLoader(text)
        return loader.get_single_data()
    except _YAMLLimit as exc:
        raise ScenarioError(file, [Problem(exc.path, f"{_where(exc.problem_mark)}{exc.problem}")]) from None
    except yaml.MarkedYAMLError as exc:
        mark = exc.problem_mark or exc.context_mark
        what = exc.problem or exc.context
        raise ScenarioError(file, [Problem("", f"{_where(mark)}not valid YAML: {what}")]) from None
    except yaml.reader.ReaderError as exc:
        line = text.count("\n", 0, exc.position) + 1
        column = exc.position - (text.rfind("\n", 0, exc.position) + 1) + 1
        raise ScenarioError(
            file,
            [
                Problem(
                    "",
                    f"line {line}, column {column}: not valid YAML: "
                    f"character {_codepoint(exc.character)} is not allowed",
                )
            ],
        ) from None
    except yaml.YAMLError as exc:
        raise ScenarioError(file, [Problem("", f"not valid YAML: {exc}")]) from None
    except (RecursionError, MemoryError) as exc:  # the limits above should keep these away
        raise ScenarioError(
            file, [Problem("", f"too large or too deeply nested to read ({type(exc).__name__})")]
        ) from None
    finally:
        if loader is not None:
            loader.dispose()


def _non_finite(value: Any, path: str, out: list[Problem], depth: int = 0) -> list[Problem]:
    """Problems for every NaN or infinite number in ``value`` (a parsed scenario)."""
    if depth > 2 * MAX_DEPTH + 2:  # a deep --set path on a deep value: pydantic would refuse it anyway
        out.append(Problem(path, f"expected at most {MAX_DEPTH} levels of nesting"))
    elif isinstance(value, float) and not math.isfinite(value):
        out.append(Problem(path, f"expected a finite number; got {_short(value)}"))
    elif isinstance(value, dict):
        for key, item in value.items():
            _non_finite(item, _join(path, key), out, depth + 1)
    elif isinstance(value, list):
        for i, item in enumerate(value):
            _non_finite(item, _join(path, i), out, depth + 1)
    return out


def read_yaml(path: Path) -> dict:
    """The scenario file at ``path`` as a mapping; raises :class:`ScenarioError`."""
    file = str(path)
    try:
        with open(path, "rb") as f:
            size = os.fstat(f.fileno()).st_size  # 0 for devices and pipes: read() below still stops
            data = b"" if size > MAX_BYTES else f.read(MAX_BYTES + 1)
    except OSError as exc:
        raise ScenarioError(file, [Problem("", f"cannot read: {exc.strerror or exc}")]) from None
    except ValueError as exc:  # e.g. a NUL byte in the path
        raise ScenarioError(file, [Problem("", f"cannot read: {exc}")]) from None
    if size > MAX_BYTES or len(data) > MAX_BYTES:
        has = f"{size} bytes" if size > MAX_BYTES else f"more than {MAX_BYTES} bytes"
        raise ScenarioError(
            file, [Problem("", f"expected a scenario of at most {MAX_BYTES // 1024} KiB; the file has {has}")]
        )
    raw = parse_yaml(data, file)
    if raw is None:
        raise ScenarioError(
            file, [Problem("", "the file is empty; expected a mapping with name, protocol, space, modules")]
        )
    if not isinstance(raw, dict):
        kind = "a list" if isinstance(raw, list) else f"the single value {_short(raw)}"
        raise ScenarioError(
            file, [Problem("", f"expected a mapping with name, protocol, space, modules at the top; got {kind}")]
        )
    return raw


# --------------------------------------------------------------------------------------------
# Overrides (--set KEY.PATH=VALUE)
# --------------------------------------------------------------------------------------------


class _BadOverride(ValueError):
    pass


def _set_path(raw: dict, dotted: str, value: Any) -> None:
    """Set ``raw[a][b]...`` for ``dotted`` 'a.b...': missing mappings are created, list entries must
    exist, and a plain value on the way is an error (not silently replaced)."""
    parts = dotted.split(".")
    if not all(parts):
        raise _BadOverride(f"expected KEY.PATH of dot-separated keys; got {dotted!r}")
    if len(parts) > MAX_DEPTH:
        raise _BadOverride(f"expected a KEY.PATH of at most {MAX_DEPTH} keys; got {len(parts)}")
    node: Any = raw
    for i, part in enumerate(parts):
        parent = ".".join(parts[:i]) or "the scenario"
        if isinstance(node, list):
            if not (part.isdecimal() and int(part) < len(node)):
                valid = f"an index 0..{len(node) - 1}" if node else "no index (it is empty)"
                raise _BadOverride(f"{parent} is a list of {len(node)}; expected {valid}; got {part!r}")
            part = int(part)
        elif not isinstance(node, dict):
            raise _BadOverride(f"{parent} is {_short(node)}, not a mapping or list; cannot set {part!r} in it")
        elif ".".join(parts[i:]) in node or parts[:i] == ["conditions"]:  # keys with dots: body.slope_deg
            node[".".join(parts[i:])] = value
            return
        if i == len(parts) - 1:
            node[part] = value
            return
        child = node[part] if isinstance(node, list) else node.get(part)
        if child is None:
            child = node[part] = {}
        node = child


def apply_overrides(raw: dict, overrides: list[str], file: str) -> dict:
    """Apply ``KEY.PATH=VALUE`` overrides (VALUE parsed as YAML, with the same limits)."""
    raw = copy.deepcopy(raw)
    for item in overrides:
        key, sep, text = item.partition("=")
        key = key.strip()
        if not sep or not key:
            raise ScenarioError(file, [Problem("--set", f"expected KEY.PATH=VALUE; got {item!r}")])
        try:
            value = parse_yaml(text.encode("utf-8", errors="surrogateescape"), f"--set {key}")
            _set_path(raw, key, value)
        except ScenarioError as exc:
            raise ScenarioError(
                file, [Problem(f"--set {key}", p.message, p.suggestion) for p in exc.problems]
            ) from None
        except _BadOverride as exc:
            raise ScenarioError(file, [Problem(f"--set {key}", str(exc))]) from None
    return raw


def load(path: str | Path, overrides: list[str] = (), seed: int | None = None) -> Plan:
    """Read, validate and resolve a scenario file. Raises :class:`ScenarioError`."""
    path = Path(path)
    raw = apply_overrides(read_yaml(path), list(overrides), str(path))
    if seed is not None:
        raw["seed"] = seed
    problems = _non_finite(raw, "", [])
    if problems:
        raise ScenarioError(str(path), problems)
    try:
        return build_plan(raw, str(path), path.parent)
    except (RecursionError, MemoryError) as exc:
        raise ScenarioError(str(path), [Problem("", f"too large to check ({type(exc).__name__})")]) from None


def learnt_values(raw: dict, base_dir: Path) -> tuple[dict, list[Problem]]:
    """A conditions protocol's references to learnt parameters, replaced by their values: a condition's value
    ``"@NAME.AXIS"`` is the physical value on axis AXIS of the best parameters (summary.json ``best.neuron_point``: the
    success neuron nearest the highest-reward trial, L1584) of the learn run ``protocol.best_of.NAME`` (a run folder,
    from the current folder or the scenario's). Returns the scenario with the values in place (what the run folder's
    scenario.yaml keeps) and the problems."""
    protocol = raw.get("protocol") if isinstance(raw, dict) else None
    if not isinstance(protocol, dict) or protocol.get("kind") != "conditions":
        return raw, []
    conditions = protocol.get("conditions")
    runs = protocol.get("best_of") or {}
    if not isinstance(conditions, dict) or not isinstance(runs, dict):
        return raw, []
    out, problems, found = copy.deepcopy(raw), [], {}
    for name, values in conditions.items():
        if not isinstance(values, dict):
            continue
        for key, value in values.items():
            if not (isinstance(value, str) and value.startswith("@")):
                continue
            where = f"protocol.conditions.{name}.{key}"
            run, _, axis = value[1:].partition(".")
            if run not in runs:
                problems.append(
                    Problem(
                        where,
                        f"expected @RUN.AXIS with RUN in protocol.best_of {sorted(runs)}; got {value!r}",
                        nearest(run, sorted(runs)),
                    )
                )
                continue
            if run not in found:
                found[run] = _best_of(runs[run], base_dir)
                if isinstance(found[run], str):  # why the folder gives no parameters: said once, at its first use
                    problems.append(Problem(f"protocol.best_of.{run}", found[run]))
            best = found[run]
            if isinstance(best, str):
                continue
            if axis not in best:
                problems.append(
                    Problem(
                        where,
                        f"expected an axis of {run}'s learn run {sorted(best)}; got {axis!r}",
                        nearest(axis, sorted(best)),
                    )
                )
                continue
            out["protocol"]["conditions"][name][key] = best[axis]
    return out, problems


def _best_of(folder: str, base_dir: Path) -> dict | str:
    """The physical best parameters (axis -> value) of the learn run in ``folder``, or why there are none."""
    given = path = Path(str(folder))
    try:
        if not path.is_absolute() and not path.is_dir():
            path = base_dir / path
        summary = json.loads((path / "summary.json").read_text())
    except (OSError, ValueError):
        where = str(path) if given.is_absolute() else f"{given} (from here or from {base_dir})"
        return (
            f"expected a completed learn run's folder (with summary.json); {where} has none: run the learn run first "
            "or point this key at one"
        )
    if not isinstance(summary, dict) or summary.get("status") != "completed":
        return (
            f"expected a completed learn run; {path} is {summary.get('status') if isinstance(summary, dict) else '?'}"
        )
    best = summary.get("best")
    if not isinstance(best, dict) or not isinstance(best.get("neuron_point"), dict):
        return f"expected best parameters in {path / 'summary.json'} (a learn run with a success); it has none"
    return {k: v for k, v in best["neuron_point"].items() if k != "v_unit" and isinstance(v, int | float)}


def restart_policy(spec: ModuleSpec, cls: type[Module]) -> str:
    """A module's ``restart`` policy: as the scenario says, else ``on-failure`` for body workers and controllers (they
    hold no state between trials: a restart loses nothing) and ``never`` for brain modules (learnt state)."""
    if spec.restart is not None:
        return spec.restart
    return "on-failure" if issubclass(cls, Body | Controller) else "never"


#: a module's resolved class, its reference (``package.module:Class``) and its validated parameters (JSON)
ModuleClass = tuple[type[Module], str, dict]


def build_plan(raw: dict, file: str, base_dir: Path) -> Plan:
    """The plan of the scenario ``raw`` (read from ``file``; relative paths from ``base_dir``): every module resolved
    and its parameters checked, the wiring checked, the instances made. Every problem found at one stage is raised
    together, as a :class:`ScenarioError`, before the next stage."""
    raw, problems = learnt_values(raw, base_dir)
    raise_if(file, problems)
    try:
        scenario = ScenarioModel.model_validate(raw)
    except ValidationError as exc:
        raise ScenarioError(file, problems_from(exc, ScenarioModel)) from None
    classes, problems = module_classes(scenario, base_dir)
    raise_if(file, proposer_problems(scenario) + problems)

    providers, problems = handlers(classes, scenario.protocol.kind)
    body_name, controller_name, pair_problems = lockstep_pair(classes)
    problems += pair_problems
    problems += target_problems(scenario, classes, body_name, controller_name)
    if scenario.protocol.kind == "exploit":
        classes, exploit_problems = with_exploit_maps(scenario, base_dir, classes, providers)
        problems += exploit_problems
    raise_if(file, problems)

    instances, body_instances = make_instances(scenario, classes, providers, body_name, controller_name)
    return Plan(file, scenario, raw, instances, providers, body_instances, body_name)


def raise_if(file: str, problems: list[Problem]) -> None:
    """Raise the ``problems`` found in ``file``, if any, as one :class:`ScenarioError`."""
    if problems:
        raise ScenarioError(file, problems)


def proposer_problems(scenario: ScenarioModel) -> list[Problem]:
    """A learn protocol's proposer whose library is not installed."""
    if scenario.protocol.kind != "learn" or not (library := NEEDS.get(scenario.protocol.proposer.kind)):
        return []
    import importlib.util

    if importlib.util.find_spec(library) is not None:
        return []
    kind = scenario.protocol.proposer.kind
    return [
        Problem(
            "protocol.proposer.kind",
            f"expected a proposer whose library is installed: {kind!r} needs "
            f"{library!r} (pip install 'sfl-brain[baselines]'); got {kind!r}",
        )
    ]


def module_classes(scenario: ScenarioModel, base_dir: Path) -> tuple[dict[str, ModuleClass], list[Problem]]:
    """Each module's class, reference and validated parameters, and the problems of those that have none."""
    classes: dict[str, ModuleClass] = {}
    problems: list[Problem] = []
    for name, spec in scenario.modules.items():
        found = module_class(f"modules.{name}", spec, scenario, base_dir, problems)
        if found is not None:
            classes[name] = found
    return classes, problems


def module_class(
    where: str, spec: ModuleSpec, scenario: ScenarioModel, base_dir: Path, problems: list[Problem]
) -> ModuleClass | None:
    """The module at ``where``: its class resolved, its parameters validated (``dim`` from the space when it takes one
    and the file leaves it out), its restart, workers and colocation checked against its kind. Problems are appended
    to ``problems``; None when there is no class or no valid parameters."""
    try:  # an import that does not finish within timeouts.ready would not start either
        cls, reference = resolve(spec.impl, base_dir, timeout=scenario.timeouts.ready)
    except ImplError as exc:
        problems.append(Problem(f"{where}.impl", str(exc), exc.suggestion))
        return None
    if not (isinstance(cls.Params, type) and issubclass(cls.Params, BaseModel)):
        problems.append(Problem(f"{where}.impl", f"{cls.__name__}.Params is not a pydantic model (ModuleParams)"))
        return None
    if spec.restart == "on-failure" and not issubclass(cls, Body | Controller):
        problems.append(
            Problem(
                f"{where}.restart",
                f"expected 'never' for {cls.__name__}: only bodies and controllers are restarted "
                "(a brain module holds learnt state that a restart would lose); got 'on-failure'",
            )
        )
    params = dict(spec.params)
    if "dim" in cls.Params.model_fields and params.get("dim") is None:
        params["dim"] = len(scenario.space)
    try:  # as JSON: strict (no "40" or true for a number) yet lists for tuples
        validated = cls.Params.model_validate_json(json.dumps(params, allow_nan=False), strict=True)
    except ValidationError as exc:
        problems.extend(problems_from(exc, cls.Params, (where, "params")))
        return None
    except Exception as exc:  # a validator of a module's own that raises something else
        problems.append(Problem(f"{where}.params", f"{cls.__name__}.Params failed: {type(exc).__name__}: {exc}"))
        return None
    if spec.workers > 1 and not issubclass(cls, Body):
        problems.append(Problem(f"{where}.workers", f"expected 1 for a non-body module; got {spec.workers}"))
    if spec.colocate and not issubclass(cls, Controller):
        problems.append(Problem(f"{where}.colocate", "only controllers can be colocated with a body"))
    return cls, reference, validated.model_dump(mode="json")


def handlers(classes: dict[str, ModuleClass], kind: str) -> tuple[dict[str, str], list[Problem]]:
    """Which module handles each message tag (the first, for the tags every body worker or controller handles), and
    the problems: a tag two modules handle, a message protocol ``kind`` sends that no module handles."""
    providers: dict[str, str] = {}
    problems: list[Problem] = []
    for name, (cls, _, _) in classes.items():
        for message_type in cls.handles:
            if message_type.TAG in providers and message_type not in (
                m.ControllerReset,
                m.SensorFrame,
                m.TrialRequest,
            ):
                problems.append(
                    Problem(
                        f"modules.{name}",
                        f"handles `{message_type.TAG}` as does module "
                        f"`{providers[message_type.TAG]}`; expected one handler",
                    )
                )
            providers.setdefault(message_type.TAG, name)
    for message_type, why in PROTOCOL_NEEDS[kind]:
        if message_type.TAG not in providers:
            family = message_type.TAG.split(".")[0]
            problems.append(
                Problem(
                    "modules",
                    f"protocol `{kind}` sends `{message_type.TAG}` ({why}) but no module handles it; "
                    f"modules here: {sorted(classes)}",
                    f"{family}: {{impl: {HINT_IMPL.get(family, family)}}}",
                )
            )
    return providers, problems


def lockstep_pair(classes: dict[str, ModuleClass]) -> tuple[str, str, list[Problem]]:
    """The body's and the controller's module names ("" for none), and the problems of the pair: more than one of
    either, a body that sends commands without a controller or a controller for a body that takes none, a controller
    whose sensors and commands do not fit its body's."""
    problems: list[Problem] = []
    bodies = [n for n, (c, _, _) in classes.items() if issubclass(c, Body)]
    controllers = [n for n, (c, _, _) in classes.items() if issubclass(c, Controller)]
    if len(bodies) > 1:
        problems.append(Problem("modules", f"expected one body; got {bodies}"))
    if len(controllers) > 1:
        problems.append(Problem("modules", f"expected at most one controller; got {controllers}"))
    body_name = bodies[0] if bodies else ""
    controller_name = controllers[0] if controllers else ""
    if not body_name:
        return body_name, controller_name, problems
    body_cls = classes[body_name][0]
    if body_cls.COMMANDS and not controller_name:
        problems.append(
            Problem(
                f"modules.{body_name}",
                f"body `{body_cls.__name__}` sends `controller.sensors` and needs a controller; no module handles it",
                "controller: {impl: reflex}",
            )
        )
    if controller_name and not body_cls.COMMANDS:
        problems.append(
            Problem(f"modules.{controller_name}", f"body `{body_name}` takes no commands; a controller is not used")
        )
    elif controller_name:
        ctrl_cls = classes[controller_name][0]
        try:
            params = ctrl_cls.Params(**classes[controller_name][2])
            ctrl_cls.wire(
                body_cls.SENSORS, body_cls.COMMANDS, body=f"body `{body_name}` ({body_cls.__name__})", params=params
            )
        except WiringError as exc:
            problems.append(Problem(f"modules.{controller_name}", str(exc)))
    return body_name, controller_name, problems


def target_problems(
    scenario: ScenarioModel, classes: dict[str, ModuleClass], body_name: str, controller_name: str
) -> list[Problem]:
    """The problems of every trial parameter the scenario sets (the space's axes, its conditions and a conditions
    protocol's conditions, grid and follow): a target that is not ``body.<param>`` or ``controller.<param>`` of a
    module the scenario has, a parameter the module does not take, a value its check refuses. A conditions protocol's
    own problems come first."""
    problems: list[Problem] = []
    owners = {
        "body": classes[body_name][0] if body_name else None,
        "controller": classes[controller_name][0] if controller_name else None,
    }
    targets = [(f"space.{i}.target", a.target, (a.low, a.high)) for i, a in enumerate(scenario.space)]
    targets += [(f"conditions.{k}", k, (v,)) for k, v in scenario.conditions.items()]
    if scenario.protocol.kind == "conditions":  # a conditions protocol's trial parameters, as the scenario's own
        proto = scenario.protocol
        problems += conditions_problems(proto)
        for i, analysis in enumerate(proto.analyses):
            if analysis.kind == "pattern_space" and not scenario.record.neurons:
                problems.append(
                    Problem(
                        f"protocol.analyses.{i}",
                        "pattern_space reads the controller's RG potentials: expected record.neurons: true; got false",
                    )
                )
        for name, values in proto.conditions.items():
            targets += [(f"protocol.conditions.{name}.{k}", k, (v,)) for k, v in values.items()]
        targets += [(f"protocol.grid.{k}", k, tuple(v)) for k, v in proto.grid.items()]
        values_of: dict[str, list] = {k: list(vs) for k, vs in proto.grid.items()}
        for values in proto.conditions.values():
            for k, v in values.items():
                values_of.setdefault(k, []).append(v)
        targets += [(f"protocol.follow.{t}", t, tuple(values_of[s])) for t, s in proto.follow.items() if s in values_of]
    module_params = {
        owner: (classes[name][0].Params.model_validate(classes[name][2]) if name else None)
        for owner, name in (("body", body_name), ("controller", controller_name))
    }
    for where, target, values in targets:
        owner, dot, param = target.partition(".")
        if not dot or owner not in owners:
            problems.append(Problem(where, f"expected 'body.<param>' or 'controller.<param>'; got {target!r}"))
            continue
        cls = owners[owner]
        if cls is None:
            problems.append(Problem(where, f"targets the {owner}, but the scenario has no {owner} module"))
        elif param not in cls.TRIAL_PARAMS:
            problems.append(
                Problem(
                    where,
                    f"{cls.__name__} takes trial parameters {list(cls.TRIAL_PARAMS)}; got {param!r}",
                    f"{owner}.{nearest(param, cls.TRIAL_PARAMS)}" if nearest(param, cls.TRIAL_PARAMS) else None,
                )
            )
        else:  # values the module can check before a trial (e.g. the walker's terrain profile)
            check = trial_param_check(cls, module_params[owner])  # the bases' default accepts anything
            for value in values if check is not None else ():
                try:
                    check(param, value)
                except Exception as exc:
                    problems.append(Problem(where, str(exc) or type(exc).__name__))
                    break
    return problems


def with_exploit_maps(
    scenario: ScenarioModel, base_dir: Path, classes: dict[str, ModuleClass], providers: dict[str, str]
) -> tuple[dict[str, ModuleClass], list[Problem]]:
    """An exploit protocol's checks (its condition is an axis of the space, its ACC checkpoint exists), and the
    classes with the module answering ``Exploit`` set to start from that checkpoint (``restore``)."""
    problems: list[Problem] = []
    names = [a.name for a in scenario.space]
    if scenario.protocol.condition not in names:
        problems.append(
            Problem(
                "protocol.condition",
                f"expected one of {names}; got {scenario.protocol.condition!r}",
                nearest(scenario.protocol.condition, names),
            )
        )
    maps = Path(scenario.protocol.maps)
    try:
        if not maps.is_absolute() and not maps.is_file():
            maps = base_dir / maps
        found = maps.is_file()
    except (OSError, ValueError):  # a name too long, a NUL byte
        found = False
    if not found:
        problems.append(Problem("protocol.maps", f"expected an ACC checkpoint file; {maps} does not exist"))
        return classes, problems
    exploit_by = providers.get(m.Exploit.TAG)
    if exploit_by in classes and "restore" in classes[exploit_by][0].Params.model_fields:
        cls, reference, params = classes[exploit_by]
        classes = {**classes, exploit_by: (cls, reference, {**params, "restore": str(maps.resolve())})}
    return classes, problems


def make_instances(
    scenario: ScenarioModel,
    classes: dict[str, ModuleClass],
    providers: dict[str, str],
    body_name: str,
    controller_name: str,
) -> tuple[list[Instance], list[str]]:
    """The run's module instances, in the scenario's order (a body's controller just before each body worker, unless
    colocated with it), and the body workers' names (``body``, or ``body.0``, ``body.1``, ... for several)."""
    instances: list[Instance] = []
    body_instances: list[str] = []
    for name, spec in scenario.modules.items():
        if name == controller_name:
            continue  # created with each body worker
        cls, reference, params = classes[name]
        count = spec.workers if name == body_name else 1
        for k in range(count):
            inst_name = name if count == 1 else f"{name}.{k}"
            inst = Instance(
                inst_name,
                name,
                cls,
                reference,
                params,
                instance_seed(scenario.seed, name),
                restart_policy(spec, cls),
                spec.max_restarts,
                dict(providers),
            )
            if name == body_name:
                body_instances.append(inst_name)
                if controller_name:
                    attach_controller(scenario, classes, controller_name, inst, k if count > 1 else None, instances)
            instances.append(inst)
    return instances, body_instances


def attach_controller(
    scenario: ScenarioModel,
    classes: dict[str, ModuleClass],
    controller_name: str,
    body: Instance,
    worker: int | None,
    instances: list[Instance],
) -> None:
    """The controller instance of body worker ``body`` (number ``worker`` of several, or None): routed to that body
    and it to the controller; colocated in the body's process, or appended to ``instances``."""
    cspec = scenario.modules[controller_name]
    ccls, cref, cparams = classes[controller_name]
    ctrl = Instance(
        controller_name if worker is None else f"{controller_name}.{worker}",
        controller_name,
        ccls,
        cref,
        cparams,
        instance_seed(scenario.seed, controller_name),
        restart_policy(cspec, ccls),
        cspec.max_restarts,
        {m.MotorCommand.TAG: body.name},
    )
    body.routes[m.SensorFrame.TAG] = ctrl.name
    if cspec.colocate:
        body.colocated = ctrl
    else:
        instances.append(ctrl)
