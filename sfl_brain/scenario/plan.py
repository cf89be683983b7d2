"""The resolved plan the runtime launches, built from a scenario file (the schema, errors and safe reading are
:mod:`.schema`, :mod:`.errors` and :mod:`.loading`).

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
import zlib
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import yaml
from pydantic import BaseModel, ValidationError

from .. import messages as m
from ..body import Body, Controller
from ..module import Module
from ..proposers import NEEDS
from ..registry import ImplError, nearest, resolve
from ..signals import WiringError
from .errors import (
    Problem,
    ScenarioError,
    problems_from,
)
from .loading import (
    _non_finite,
    apply_overrides,
    read_yaml,
)
from .schema import (
    Axis,
    ModuleSpec,
    ScenarioModel,
    conditions_problems,
)

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
    ``"@NAME.AXIS"`` is the physical value on axis AXIS of the best parameters of the learn run
    ``protocol.best_of.NAME`` (a run folder, from the current folder or the scenario's): with ``protocol.best_by``
    ``reward`` (the default) summary.json's ``best.neuron_point``, the success neuron nearest the highest-reward trial
    (L1584); with ``wins`` the success neuron that won the most successful trials (``acc.npz``). Returns the scenario
    with the values in place (what the run folder's scenario.yaml keeps) and the problems."""
    protocol = raw.get("protocol") if isinstance(raw, dict) else None
    if not isinstance(protocol, dict) or protocol.get("kind") != "conditions":
        return raw, []
    conditions = protocol.get("conditions")
    runs = protocol.get("best_of") or {}
    if not isinstance(conditions, dict) or not isinstance(runs, dict):
        return raw, []
    out, problems, found = copy.deepcopy(raw), [], {}
    by = protocol.get("best_by", "reward")
    if by not in BEST_BY:
        return raw, []  # the schema says what is wrong with it
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
                found[run] = _best_of(runs[run], base_dir, by)
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


#: protocol.best_by's choices (schema.ConditionsProtocol.best_by)
BEST_BY = ("reward", "wins")


def _best_of(folder: str, base_dir: Path, by: str = "reward") -> dict | str:
    """The physical best parameters (axis -> value) of the learn run in ``folder`` (``by``: see ``learnt_values``), or
    why there are none."""
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
    if by == "wins":
        return most_wins(path)
    return {k: v for k, v in best["neuron_point"].items() if k != "v_unit" and isinstance(v, int | float)}


def most_wins(path: Path) -> dict | str:
    """The physical parameters (axis -> value) of the success neuron of the learn run in ``path`` that won the most
    successful trials (``acc.npz`` ``success_wins``; the higher learnt reward, then the lower index, breaks ties), on
    the run's own space (its ``scenario.yaml``), or why there are none."""
    try:
        with np.load(path / "acc.npz") as data:
            weights, wins = np.asarray(data["success_weights"], float), np.asarray(data["success_wins"])
            reward = np.asarray(data["success_reward"], float)
        axes = [Axis.model_validate(a) for a in yaml.safe_load((path / "scenario.yaml").read_text())["space"]]
    except (OSError, ValueError, KeyError, TypeError, yaml.YAMLError) as exc:  # ValidationError is a ValueError
        return f"expected the success map (acc.npz) and the space (scenario.yaml) of a learn run in {path}: {exc}"
    if weights.shape != (len(wins), len(axes)) or reward.shape != wins.shape or not (wins > 0).any():
        return f"expected a success map with a neuron that won a success in {path / 'acc.npz'}"
    order = np.lexsort((np.arange(len(wins)), -np.nan_to_num(reward, nan=-np.inf), -wins))
    values = {a.name: a.to_physical(float(u)) for a, u in zip(axes, weights[int(order[0])], strict=True)}
    if not (np.isfinite(weights).all() and np.isfinite(list(values.values())).all()):
        return f"expected finite weights and bounds in {path / 'acc.npz'} and {path / 'scenario.yaml'}"
    return values


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
