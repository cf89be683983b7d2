"""The scenario file's schema: frozen pydantic models with ranges (modules, space, protocols, record, timeouts,
lockstep), unknown keys refused; a conditions protocol's own checks (:func:`conditions_problems`)."""

from __future__ import annotations

import math
import re
from typing import Annotated, Any, Literal

import numpy as np
from pydantic import BaseModel, ConfigDict, Field, model_validator

from ..proposers import CMAParams, RandomParams, SafeBOParams, SFLParams, TPEParams
from ..registry import nearest
from .errors import (
    Problem,
)


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
        "(which success neuron: best_by)",
    )
    best_by: Literal["reward", "wins"] = Field(
        "reward",
        description="the learn runs' neuron best_of takes: reward, the success neuron nearest the highest-reward "
        "trial (L1584); wins, the success neuron that won the most successful trials (its learnt reward breaks ties: "
        "issue 29, a highest-reward trial can be a lucky one in a region that mostly fails)",
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
    and sfl_brain.runtime.ticklink.SpinThenSleep)."""

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
