"""Scenario files: schema, validation, and the resolved plan the runtime launches.

A scenario names its modules (each by implementation and parameters), the
parameter space Omega (unit axes mapped to physical controller/body parameters),
and a protocol (``learn``, ``sweep`` or ``exploit``). ``load`` validates all of it
before anything starts: unknown keys, types, ranges, implementations, module
parameters, and the message wiring. Every problem is reported as
``FILE: key.path: expected ..., got ... (did you mean ...?)``.
"""

from __future__ import annotations

import copy
import zlib
from dataclasses import dataclass, field
from pathlib import Path
from typing import Annotated, Any, Literal

import numpy as np
import yaml
from pydantic import BaseModel, ConfigDict, Field, ValidationError, model_validator

from . import messages as m
from .body import Body, Controller
from .module import Module
from .registry import ImplError, nearest, resolve


class Strict(BaseModel):
    model_config = ConfigDict(frozen=True, extra="forbid")


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


class ModuleSpec(Strict):
    impl: str = Field(description="registered name, 'package.module:Class' or 'path/file.py:Class'")
    params: dict[str, Any] = {}
    restart: Literal["never", "on-failure"] = "never"
    max_restarts: int = Field(3, ge=0, le=100)
    workers: int = Field(1, ge=1, le=64, description="bodies: processes serving trials in parallel")
    colocate: bool = Field(False, description="controllers: run inside each body worker's process")


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


class SweepProtocol(Strict):
    """Every point of the grid over Omega (``steps`` per axis), no learning."""

    kind: Literal["sweep"]


class ExploitProtocol(Strict):
    """Walk with parameters taken from a learnt success map, switching neurons by condition."""

    kind: Literal["exploit"]
    maps: str = Field(description="ACC checkpoint (.npz) from a learn run")
    condition: str = Field(description="the axis of Omega that is the condition (e.g. slope)")
    trials: int = Field(1, ge=1, le=10_000)


Protocol = Annotated[LearnProtocol | SweepProtocol | ExploitProtocol, Field(discriminator="kind")]


class Record(Strict):
    body_every: int = Field(1, ge=0, description="log the body's motion on every k-th trial (0: never)")
    decisions: bool = True


class Timeouts(Strict):
    ready: float = Field(60.0, gt=0, description="s for every module to come alive")
    request: float = Field(30.0, gt=0, description="s for a brain module to answer")
    trial: float = Field(300.0, gt=0, description="s of wall time for one trial")
    tick: float = Field(
        10.0,
        gt=0,
        description="s of wall time for a controller to answer one tick (or a reset); "
        "a trial whose controller is later than this is interrupted and retried",
    )


class Lockstep(Strict):
    """How a body worker and its controller process exchange their ticks (see sfl_brain.placement
    and sfl_brain.host.SpinThenSleep)."""

    spin_us: float = Field(
        200.0,
        ge=0,
        le=100_000,
        description="us the body polls for each command before it sleeps; it measures its ticks and "
        "polls only while that is faster (0: always sleep)",
    )
    pin_cpus: Literal["never", "auto", "always"] = Field(
        "never",
        description="a core of its own for each body worker and controller process: never = leave it "
        "to the OS scheduler, auto = only if a core is left over for the rest of the run, "
        "always = whenever there are as many cores",
    )


class ScenarioModel(Strict):
    name: str = Field(pattern=r"^[A-Za-z0-9_.-]+$")
    description: str = ""
    seed: int = Field(0, ge=0, lt=2**32)
    protocol: Protocol
    space: list[Axis] = Field(min_length=1, max_length=8)
    conditions: dict[str, float | int | str | bool] = {}
    modules: dict[str, ModuleSpec] = Field(min_length=1)
    record: Record = Record()
    timeouts: Timeouts = Timeouts()
    lockstep: Lockstep = Lockstep()


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
    text = repr(value)
    return text if len(text) <= 60 else text[:57] + "..."


def _fields_at(model: type[BaseModel], loc: tuple) -> list[str]:
    """Valid keys at ``loc`` inside ``model`` (for did-you-mean on unknown keys)."""
    current: Any = model
    for part in loc:
        if isinstance(current, type) and issubclass(current, BaseModel):
            f = current.model_fields.get(str(part))
            if f is None:
                # discriminated union branch names (e.g. protocol 'learn') appear in loc
                return []
            current = f.annotation
        else:
            args = getattr(current, "__args__", ())
            models = [a for a in args if isinstance(a, type) and issubclass(a, BaseModel)]
            branch = next((a for a in models if str(part) in a.model_fields), None)
            if branch is None:
                branch = next(
                    (
                        a
                        for a in models
                        if a.model_fields.get("kind") is not None
                        and str(part) in str(a.model_fields["kind"].annotation)
                    ),
                    None,
                )
                if branch is not None:
                    current = branch
                    continue
                if models:
                    current = models[0]
                    f = current.model_fields.get(str(part))
                    current = f.annotation if f else None
                    continue
                continue
            current = branch.model_fields[str(part)].annotation
    while not (isinstance(current, type) and issubclass(current, BaseModel)):
        args = [a for a in getattr(current, "__args__", ()) if isinstance(a, type) and issubclass(a, BaseModel)]
        if not args:
            return []
        current = args[0]
    return list(current.model_fields)


def problems_from(exc: ValidationError, model: type[BaseModel], prefix: tuple = ()) -> list[Problem]:
    out = []
    for err in exc.errors():
        loc = tuple(err["loc"])
        # drop discriminator tags pydantic inserts ('learn', 'function-after[...]')
        clean = tuple(p for p in loc if not (isinstance(p, str) and ("[" in p or p in ("learn", "sweep", "exploit"))))
        path = _dotted(prefix + clean)
        kind = err["type"]
        given = err.get("input")
        if kind == "extra_forbidden":
            valid = _fields_at(model, clean[:-1])
            out.append(Problem(path, f"unknown key; expected one of {sorted(valid)}", nearest(str(clean[-1]), valid)))
        elif kind == "missing":
            out.append(Problem(path, "required key is missing"))
        elif kind == "literal_error":
            allowed = err.get("ctx", {}).get("expected", "")
            options = [o.strip().strip("'") for o in allowed.replace(" or ", ",").split(",") if o.strip()]
            out.append(Problem(path, f"expected one of {allowed}; got {_short(given)}", nearest(str(given), options)))
        elif kind == "union_tag_invalid":
            ctx = err.get("ctx", {})
            tags = [t.strip().strip("'") for t in str(ctx.get("expected_tags", "")).split(",")]
            out.append(
                Problem(
                    path + ".kind" if path else "kind",
                    f"expected one of {ctx.get('expected_tags')}; got {_short(ctx.get('tag'))}",
                    nearest(str(ctx.get("tag")), tags),
                )
            )
        else:
            msg = err["msg"]
            if msg.startswith("Value error, "):
                msg = msg[len("Value error, ") :]
            out.append(Problem(path, f"{msg[0].lower() + msg[1:]}; got {_short(given)}"))
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
    def lockstep_processes(self) -> list[str]:
        """The processes that exchange a message every control tick: each body worker, followed
        by its controller's process unless the controller is colocated in the body worker."""
        controller_of = {i.routes[m.MotorCommand.TAG]: i.name for i in self.instances if m.MotorCommand.TAG in i.routes}
        return [name for body in self.bodies for name in (body, controller_of.get(body)) if name]

    def to_physical(self, unit: np.ndarray) -> dict[str, dict[str, float]]:
        """Map a unit vector to {'controller': {...}, 'body': {...}} physical parameters."""
        out: dict[str, dict[str, Any]] = {"controller": {}, "body": {}}
        for key, value in self.scenario.conditions.items():
            owner, _, param = key.partition(".")
            out[owner][param] = value
        for u, axis in zip(unit, self.scenario.space, strict=True):
            owner, _, param = axis.target.partition(".")
            out[owner][param] = float(axis.low + float(u) * (axis.high - axis.low))
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
}

#: which registered implementation provides a message kind, for hints
HINT_IMPL = {"acc": "acc", "vigilance": "vigilance", "ofc": "ofc", "body": "analytic", "controller": "reflex"}


def instance_seed(seed: int, name: str) -> int:
    """A module's seed: derived from the run seed and its scenario name (not its worker index)."""
    return int(np.random.SeedSequence([seed, zlib.crc32(name.encode())]).generate_state(1)[0])


def _set_path(raw: dict, dotted: str, value: Any) -> None:
    parts = dotted.split(".")
    node = raw
    for part in parts[:-1]:
        if isinstance(node, list):
            node = node[int(part)]
            continue
        if part not in node or not isinstance(node[part], dict | list):
            node[part] = {}
        node = node[part]
    if isinstance(node, list):
        node[int(parts[-1])] = value
    else:
        node[parts[-1]] = value


def apply_overrides(raw: dict, overrides: list[str], file: str) -> dict:
    """Apply ``KEY.PATH=VALUE`` overrides (VALUE parsed as YAML)."""
    raw = copy.deepcopy(raw)
    for item in overrides:
        key, sep, text = item.partition("=")
        if not sep or not key:
            raise ScenarioError(file, [Problem("--set", f"expected KEY.PATH=VALUE; got {item!r}")])
        try:
            value = yaml.safe_load(text)
            _set_path(raw, key.strip(), value)
        except (yaml.YAMLError, ValueError, IndexError, TypeError) as exc:
            raise ScenarioError(file, [Problem(key, f"cannot set {text!r}: {exc}")]) from None
    return raw


def read_yaml(path: Path) -> dict:
    try:
        text = path.read_text()
    except OSError as exc:
        raise ScenarioError(str(path), [Problem("", f"cannot read: {exc.strerror}")]) from None
    try:
        raw = yaml.safe_load(text)
    except yaml.YAMLError as exc:
        mark = getattr(exc, "problem_mark", None)
        where = f"line {mark.line + 1}, column {mark.column + 1}: " if mark else ""
        raise ScenarioError(
            str(path), [Problem("", f"{where}not valid YAML: {getattr(exc, 'problem', exc)}")]
        ) from None
    if not isinstance(raw, dict):
        raise ScenarioError(str(path), [Problem("", f"expected a mapping at the top; got {type(raw).__name__}")])
    return raw


def load(path: str | Path, overrides: list[str] = (), seed: int | None = None) -> Plan:
    """Read, validate and resolve a scenario file. Raises :class:`ScenarioError`."""
    path = Path(path)
    raw = apply_overrides(read_yaml(path), list(overrides), str(path))
    if seed is not None:
        raw["seed"] = seed
    return build_plan(raw, str(path), path.parent)


def build_plan(raw: dict, file: str, base_dir: Path) -> Plan:
    try:
        scenario = ScenarioModel.model_validate(raw)
    except ValidationError as exc:
        raise ScenarioError(file, problems_from(exc, ScenarioModel)) from None
    problems: list[Problem] = []
    classes: dict[str, tuple[type[Module], str, dict]] = {}
    dim = len(scenario.space)
    for name, spec in scenario.modules.items():
        where = f"modules.{name}"
        try:
            cls, reference = resolve(spec.impl, base_dir)
        except ImplError as exc:
            problems.append(Problem(f"{where}.impl", str(exc), exc.suggestion))
            continue
        params = dict(spec.params)
        if "dim" in cls.Params.model_fields and params.get("dim") is None:
            params["dim"] = dim
        try:
            validated = cls.Params.model_validate(params)
        except ValidationError as exc:
            problems.extend(problems_from(exc, cls.Params, (where, "params")))
            continue
        if spec.workers > 1 and not issubclass(cls, Body):
            problems.append(Problem(f"{where}.workers", f"expected 1 for a non-body module; got {spec.workers}"))
        if spec.colocate and not issubclass(cls, Controller):
            problems.append(Problem(f"{where}.colocate", "only controllers can be colocated with a body"))
        classes[name] = (cls, reference, validated.model_dump(mode="json"))

    if problems:
        raise ScenarioError(file, problems)

    # --- wiring: every message the protocol or a body sends has exactly one handler -------------
    providers: dict[str, str] = {}
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
    kind = scenario.protocol.kind
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
    bodies = [n for n, (c, _, _) in classes.items() if issubclass(c, Body)]
    controllers = [n for n, (c, _, _) in classes.items() if issubclass(c, Controller)]
    if len(bodies) > 1:
        problems.append(Problem("modules", f"expected one body; got {bodies}"))
    if len(controllers) > 1:
        problems.append(Problem("modules", f"expected at most one controller; got {controllers}"))
    body_name = bodies[0] if bodies else ""
    controller_name = controllers[0] if controllers else ""
    if body_name:
        body_cls = classes[body_name][0]
        if body_cls.COMMANDS and not controller_name:
            problems.append(
                Problem(
                    f"modules.{body_name}",
                    f"body `{body_cls.__name__}` sends `controller.sensors` and needs a "
                    "controller; no module handles it",
                    "controller: {impl: reflex}",
                )
            )
        if controller_name:
            ctrl_cls = classes[controller_name][0]
            if not body_cls.COMMANDS:
                problems.append(
                    Problem(
                        f"modules.{controller_name}",
                        f"body `{body_name}` takes no commands; a controller is not used",
                    )
                )
            else:
                missing = [s for s in ctrl_cls.REQUIRED_SENSORS if s not in body_cls.SENSORS]
                if missing:
                    problems.append(
                        Problem(
                            f"modules.{controller_name}",
                            f"controller `{ctrl_cls.__name__}` reads sensors {missing} that body "
                            f"`{body_name}` ({body_cls.__name__}) does not provide; "
                            f"it provides {list(body_cls.SENSORS)}",
                        )
                    )
                if tuple(ctrl_cls.COMMANDS) != tuple(body_cls.COMMANDS):
                    problems.append(
                        Problem(
                            f"modules.{controller_name}",
                            f"controller `{ctrl_cls.__name__}` commands {list(ctrl_cls.COMMANDS)}; body "
                            f"`{body_name}` expects {list(body_cls.COMMANDS)}",
                        )
                    )

    # --- targets of axes and conditions exist ----------------------------------------------------
    owners = {
        "body": classes[body_name][0] if body_name else None,
        "controller": classes[controller_name][0] if controller_name else None,
    }
    targets = [(f"space.{i}.target", a.target) for i, a in enumerate(scenario.space)]
    targets += [(f"conditions.{k}", k) for k in scenario.conditions]
    for where, target in targets:
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
    if kind == "exploit":
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
        if not maps.is_absolute() and not maps.exists():
            maps = base_dir / maps
        if not maps.exists():
            problems.append(Problem("protocol.maps", f"expected an ACC checkpoint file; {maps} does not exist"))
        else:  # the module answering Exploit starts from these maps
            exploit_by = providers.get(m.Exploit.TAG)
            if exploit_by in classes and "restore" in classes[exploit_by][0].Params.model_fields:
                cls_, ref_, params_ = classes[exploit_by]
                classes[exploit_by] = (cls_, ref_, {**params_, "restore": str(maps.resolve())})
    if problems:
        raise ScenarioError(file, problems)

    # --- instances --------------------------------------------------------------------------------
    instances: list[Instance] = []
    routes = {tag: name for tag, name in providers.items()}
    body_instances: list[str] = []
    for name, spec in scenario.modules.items():
        cls, reference, params = classes[name]
        if name == controller_name:
            continue  # created with each body worker
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
                spec.restart,
                spec.max_restarts,
                dict(routes),
            )
            if name == body_name:
                body_instances.append(inst_name)
                if controller_name:
                    cspec = scenario.modules[controller_name]
                    ccls, cref, cparams = classes[controller_name]
                    cname = controller_name if count == 1 else f"{controller_name}.{k}"
                    ctrl = Instance(
                        cname,
                        controller_name,
                        ccls,
                        cref,
                        cparams,
                        instance_seed(scenario.seed, controller_name),
                        cspec.restart,
                        cspec.max_restarts,
                        {m.MotorCommand.TAG: inst_name},
                    )
                    inst.routes[m.SensorFrame.TAG] = cname
                    if cspec.colocate:
                        inst.colocated = ctrl
                    else:
                        instances.append(ctrl)
            instances.append(inst)
    return Plan(file, scenario, raw, instances, providers, body_instances, body_name)
