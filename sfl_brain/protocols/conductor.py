"""Protocols a run runs: the learning cycle, the sweep and the exploit walk.

A protocol talks to modules only through messages (``Conductor.call`` for brain modules,
``Conductor.trials`` for bodies), over whatever hosts them (a
:class:`~sfl_brain.protocols.service.ModuleService`: every module in this process, or one process per module
over Zenoh; nothing here imports Zenoh or the supervisor). It publishes one row per decision and
per trial, and its progress, as :mod:`~sfl_brain.events`; the run writes the records, the Rerun
log and the progress bar from them.
"""

from __future__ import annotations

import itertools
import json
import math
import time
from collections import Counter, deque
from collections.abc import Iterable, Iterator
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from .. import messages as m
from ..events import DecisionsMade, Events, Progress, ProgressUpdated, TrialInterrupted, TrialRecorded
from ..proposers import PROPOSERS, Outcome, Proposer
from ..recording.metrics import safe_learning
from ..recording.records import decision_row, plain, point_fields, trial_row
from ..scenario.plan import Plan
from .service import Interrupted, ModuleService, RunError

MAX_TRIAL_RETRIES = 3


def trial_seed(run_seed: int, trial_id: int) -> int:
    """Seed of one trial: the same whichever worker runs it."""
    return int(np.random.SeedSequence([run_seed, 7, trial_id]).generate_state(1)[0])


class Conductor:
    """The protocol's view of the running modules, and where it publishes what it does.

    ``replay``: the trial rows of an interrupted learn run (``sfl run --resume``), which ``run_learn`` replays
    before it goes on. While ``replaying``, nothing is published: the rows are in the records already.
    """

    def __init__(
        self, plan: Plan, modules: ModuleService, events: Events, run_dir: Path, replay: list[dict] | None = None
    ) -> None:
        self.plan = plan
        self.modules = modules
        self.events = events
        self.run_dir = run_dir
        self.providers = plan.providers
        self.replay = list(replay or [])
        self.replaying = False

    def call(self, message: m.Message) -> m.Message:
        return self.call_all(message)[0]

    def call_all(self, *messages: m.Message) -> list[m.Message]:
        """Send independent requests at once (to different modules) and wait for every reply."""
        timeout = self.plan.scenario.timeouts.request
        tickets = [self.modules.submit(self.providers[msg.TAG], msg, timeout) for msg in messages]
        outcomes: dict[int, object] = {}
        while len(outcomes) < len(tickets):
            outcomes.update(self.modules.wait_any([t for t in tickets if t not in outcomes]))
        replies = []
        for ticket in tickets:
            outcome = outcomes[ticket]
            if isinstance(outcome, Exception):  # a brain module's request is never retried
                raise RunError(str(outcome)) from None
            replies.append(outcome)
        return replies

    def trials(self, requests: Iterable[m.TrialRequest]) -> Iterator[tuple[m.TrialRequest, m.TrialResult, float]]:
        """Run trials on the body workers, each worker busy with one at a time.

        Yields (request, result, wall seconds) as trials complete. A trial :class:`Interrupted` by a
        body or controller crash is sent again (to any live worker), not counted as a failure, up to
        ``MAX_TRIAL_RETRIES`` times; any other fault ends the run.
        """
        todo = deque(requests)
        busy: dict[int, tuple[str, m.TrialRequest, float]] = {}
        retries: Counter = Counter()
        timeout = self.plan.scenario.timeouts.trial
        deadline_no_worker = None
        while todo or busy:
            in_use = {w for w, _, _ in busy.values()}
            idle = [w for w in self.modules.workers() if w not in in_use]
            while todo and idle:
                worker = idle.pop(0)
                request = todo.popleft()
                ticket = self.modules.submit(worker, request, timeout)
                busy[ticket] = (worker, request, time.perf_counter())
            if not busy:
                if self.modules.coming():  # a body worker or controller restarting: waited for while it starts
                    deadline_no_worker = None
                else:
                    deadline_no_worker = deadline_no_worker or time.monotonic() + self.plan.scenario.timeouts.ready
                    if time.monotonic() > deadline_no_worker:
                        raise RunError("no body worker is alive to run trials")
                self.modules.wait_for_workers(0.5)
                continue
            deadline_no_worker = None
            for ticket, outcome in self.modules.wait_any(list(busy)):
                worker, request, started = busy.pop(ticket)
                if isinstance(outcome, Interrupted):
                    retries[request.trial_id] += 1
                    if retries[request.trial_id] > MAX_TRIAL_RETRIES:
                        raise RunError(f"trial {request.trial_id} interrupted {MAX_TRIAL_RETRIES + 1} times: {outcome}")
                    self.events.publish(TrialInterrupted(request.trial_id, str(outcome), retries[request.trial_id]))
                    todo.appendleft(request)
                    continue
                if isinstance(outcome, Exception):
                    raise RunError(str(outcome))
                yield request, outcome, time.perf_counter() - started

    def _publish(self, *events) -> None:
        """Publish ``events``, unless the run is replaying recorded trials (they are in the records already)."""
        if not self.replaying:
            for event in events:
                self.events.publish(event)

    def record_decisions(self, rows: list[dict]) -> None:
        self._publish(DecisionsMade(rows))

    def record_trial(
        self,
        progress: Progress,
        trial: int,
        result: m.TrialResult,
        wall: float,
        point: dict | None = None,
        learning: dict | None = None,
    ) -> None:
        """Count a finished trial in ``progress`` and publish its row, then the progress."""
        progress.trials += 1
        progress.successes += int(result.success)
        row = trial_row(trial, result, wall, progress.successes / progress.trials, point, learning)
        progress.last = row
        self._publish(TrialRecorded(row), ProgressUpdated(progress))

    def report_progress(self, progress: Progress) -> None:
        self._publish(ProgressUpdated(progress))

    def trial_request(self, trial_id: int, unit: np.ndarray, log: bool) -> m.TrialRequest:
        physical = self.plan.to_physical(unit)
        return m.TrialRequest(
            trial_id=trial_id,
            seed=trial_seed(self.plan.scenario.seed, trial_id),
            body_params=physical["body"],
            controller_params=physical["controller"],
            log=log,
        )

    def should_log_body(self, trial_id: int) -> bool:
        every = self.plan.scenario.record.body_every
        return every > 0 and trial_id % every == 0

    def point(self, unit: np.ndarray) -> dict:
        """The record fields of a point of the parameter space (unit and physical coordinates)."""
        return point_fields(self.plan.scenario.space, unit)


class Gate:
    """The run's go/no-go decision as a proposer sees it (:class:`sfl_brain.proposers.Gate`): the ACC's
    evaluation against vigilance's current threshold, with every decision recorded and counted."""

    def __init__(self, c: Conductor, progress: Progress) -> None:
        self.c = c
        self.progress = progress
        self.threshold: m.Threshold = c.call(m.VigilanceStart())
        self.decision = 0  # decisions recorded
        self.consecutive_nogo = 0
        self.seconds = 0.0  # wall seconds waiting for the ACC's evaluations

    def evaluate(self, candidates: np.ndarray) -> m.Evaluation:
        started = time.perf_counter()
        evaluation = self.c.call(m.Evaluate(candidates=candidates, s_vig=self.threshold.s_vig))
        self.seconds += time.perf_counter() - started
        return evaluation

    def record(self, candidates: np.ndarray, evaluation: m.Evaluation, tried: int | None, count: int) -> None:
        """Record the first ``count`` decisions, each the ACC's real go/no-go (3.3); ``tried`` starts the next
        trial (a go, but for an ungated optimiser, or a gated one past its veto budget, which may try a no-go)."""
        rows = []
        for i in range(count):
            go = bool(evaluation.go[i])
            trial = self.progress.trials if i == tried else None
            d_s, d_f = evaluation.d_success[i], evaluation.d_failure[i]
            point = self.c.point(candidates[i])
            rows.append(decision_row(self.decision, trial, go, self.threshold.s_vig, d_s, d_f, point))
            self.decision += 1
            self.consecutive_nogo = 0 if go else self.consecutive_nogo + 1
        self.c.record_decisions(rows)
        self.progress.decisions = self.decision
        self.progress.consecutive_nogo = self.consecutive_nogo
        if tried is None:
            self.c.report_progress(self.progress)  # a long run of no-go decisions shows (and warns) while it lasts

    def rejected(self, consecutive: int) -> None:
        self.threshold = self.c.call(m.Rejected(consecutive=consecutive))


def make_proposer(c: Conductor) -> Proposer:
    """The scenario's ``protocol.proposer``, seeded from the run's seed."""
    proto = c.plan.scenario.protocol
    return PROPOSERS[proto.proposer.kind].for_protocol(proto, c.plan.dim, c.plan.scenario.seed)


#: the proposer's checkpoint in the run folder, written after every trial
PROPOSER_CHECKPOINT = "proposer.pkl"


def run_learn(c: Conductor) -> dict:
    """The learning cycle (Fig. 3.5 / 5.6): ask the proposer, decide, trial, learn, tell, record.

    Success-failure learning's proposer draws until ACC and vigilance say go; the others propose without
    the gate (:mod:`sfl_brain.proposers`). The brain modules learn from every trial either way.
    """
    proto = c.plan.scenario.protocol
    proposer = make_proposer(c)
    progress = Progress(planned=proto.trials)
    if proposer.GATED:
        progress.max_decisions, progress.stall_decisions = proto.max_decisions, proto.stall_decisions
    gate = Gate(c, progress)
    reach = body_reach(c.plan)
    n_success = n_failure = 0
    best: tuple[float, int, np.ndarray] | None = None  # (eta, trial, v) of the highest-reward success
    stop_reason = f"trial budget spent ({proto.trials} trials)"
    stalled = False
    trial_decisions: deque[int] = deque(maxlen=20)  # decisions each recent trial took (progress estimate)
    decisions_at_last_trial = 0
    tried: list[dict] = []  # the trial rows, for the run's safe-learning metrics
    asking = telling = 0.0  # seconds in the proposer (benchmarks/proposers.py)
    while progress.trials < proto.trials:
        c.replaying = progress.trials < len(c.replay)  # a resumed run's recorded trials: learnt again, not re-run
        started = time.perf_counter()
        v = proposer.ask(gate)
        asking += time.perf_counter() - started
        if v is None:
            if c.replaying:
                raise RunError(replay_diverged(progress.trials, f"the proposer stopped ({proposer.stop_reason})"))
            stalled, stop_reason = True, proposer.stop_reason
            break
        trial_id = progress.trials
        if c.replaying:
            result, wall = recorded_trial(trial_id, v, c.replay[trial_id])
        else:
            ((request, result, wall),) = c.trials([c.trial_request(trial_id, v, c.should_log_body(trial_id))])
        eta = float(result.quality) if result.success else None
        rho = c.call(m.Grade(eta=result.quality)).rho if result.success else None
        n_success += int(result.success)
        n_failure += int(not result.success)
        s_vig_used, low, high = gate.threshold.s_vig, gate.threshold.low, gate.threshold.high
        if result.success and (best is None or eta > best[0]):
            best = (eta, trial_id, v.copy())  # the highest-reward trial so far (L1584)
        learned, gate.threshold = c.call_all(  # ACC and vigilance learn from the trial in parallel
            m.Learn(v=v, success=result.success, rho=rho if rho is not None else 1.0, eta=eta),
            m.TrialDone(trial_index=trial_id + 1, success=result.success, n_success=n_success, n_failure=n_failure),
        )
        started = time.perf_counter()
        proposer.tell(v, Outcome(result.success, eta, None if result.success else trial_progress(result, reach)))
        if not c.replaying:  # the checkpoint of the trial the records end with is on disk already
            proposer.checkpoint(c.run_dir / PROPOSER_CHECKPOINT)
        telling += time.perf_counter() - started
        progress.s_vig = gate.threshold.s_vig
        trial_decisions.append(gate.decision - decisions_at_last_trial)
        decisions_at_last_trial = gate.decision
        progress.recent_decisions_per_trial = sum(trial_decisions) / len(trial_decisions)
        learning = {
            "decision": gate.decision - 1,
            "rho": rho,
            "n_success": n_success,
            "n_failure": n_failure,
            "ns_nf": n_success / n_failure if n_failure else None,
            "s_vig": s_vig_used,
            "band_low": low,
            "band_high": high,
            "map_change": learned.change,
            "success_winner": learned.success_winner,
            "failure_winner": learned.failure_winner,
        }
        c.record_trial(progress, trial_id, result, wall, c.point(v), learning)
        if c.replaying:
            check_replayed(trial_id, progress.last, c.replay[trial_id])
        tried.append(progress.last)
    c.replaying = False
    maps = (c.run_dir / "acc.npz").resolve()
    finish: m.Ack = c.call(m.Finish(path=str(maps), prune=proto.prune_failure_map))
    return {
        "planned_trials": proto.trials,
        "stalled": stalled,
        "stop_reason": stop_reason,
        "proposer": proto.proposer.kind,
        # wall seconds in the proposer's ask (``gate``: of which waiting for the ACC's evaluations, success-failure
        # learning's decisions and every other proposer's record of what the gate would have said) and in its tell
        # with the checkpoint
        "proposer_seconds": {"ask": asking, "gate": gate.seconds, "tell": telling},
        "safe_learning": {k: v for k, v in safe_learning(tried).items() if not isinstance(v, list)},
        "acc": finish.detail,
        "best": best_parameters(c, maps, best),
    }


def body_reach(plan: Plan) -> tuple[float | None, float | None]:
    """The body's trial ``duration`` (s) and ``finish_line`` (m), where its parameters have them (else None): what
    :func:`trial_progress` measures a failed trial against."""
    body = next(i for i in plan.instances if i.name in plan.bodies)
    params = body.cls.Params.model_validate(body.params)
    return getattr(params, "duration", None), getattr(params, "finish_line", None)


def trial_progress(result: m.TrialResult, reach: tuple[float | None, float | None]) -> float | None:
    """How far a failed trial got, in [0, 1]: the mean of the fraction of the trial's duration it stayed up (metric
    ``time``) and of the finish line it covered (metric ``distance``, forward); None when the body reports neither
    (an optimiser's ``failure_score: graded`` reads it, :meth:`sfl_brain.proposers.Outcome.score`)."""
    fractions = []
    for metric, whole in zip(("time", "distance"), reach, strict=True):
        value = result.metrics.get(metric)
        if isinstance(value, int | float) and not isinstance(value, bool) and whole and math.isfinite(value):
            fractions.append(min(1.0, max(0.0, float(value) / whole)))
    return sum(fractions) / len(fractions) if fractions else None


def replay_diverged(trial: int, what: str) -> str:
    return (
        f"cannot resume: the replay diverged at trial {trial}: {what}; the records after it cannot be those of an "
        "uninterrupted run (was the run made with other code? provenance.json says which)"
    )


def recorded_trial(trial: int, v: np.ndarray, row: dict) -> tuple[m.TrialResult, float]:
    """The outcome a resumed run's records hold for ``trial`` (result, wall seconds), once the replayed proposer
    has asked the point the row was tried at."""
    if not np.array_equal(v, np.asarray(row.get("v_unit"), dtype=float)):
        raise RunError(replay_diverged(trial, f"the proposer asked {v.tolist()}, the records hold {row.get('v_unit')}"))
    metrics = {k.removeprefix("m_"): value for k, value in row.items() if k.startswith("m_")}
    quality = row.get("quality")
    result = m.TrialResult(
        trial_id=trial,
        success=bool(row["success"]),
        quality=float("nan") if quality is None else float(quality),
        metrics=metrics,
        worker=str(row.get("worker", "")),
    )
    return result, float(row.get("wall_ms") or 0.0) / 1e3


def check_replayed(trial: int, row: dict, recorded: dict) -> None:
    """A replayed trial's row must be the recorded one (its decision, vigilance, the maps' change...): else the
    brain modules did not reach the state they had."""
    replayed = json.loads(json.dumps(plain(row)))
    for key in sorted(set(replayed) | set(recorded)):
        if key != "wall_ms" and replayed.get(key) != recorded.get(key):
            raise RunError(replay_diverged(trial, f"{key} is {replayed.get(key)!r}, recorded {recorded.get(key)!r}"))


def best_parameters(c: Conductor, maps: Path, best: tuple[float, int, np.ndarray] | None) -> dict | None:
    """ "After learning, the optimal parameter is presented by the success map neuron that is closed to the trial with
    maximum reward in training set" (L1584): that neuron (index, unit weights, physical values) beside the trial
    (index, eta, unit and physical values). None without a success, or without the maps' checkpoint (an ACC of
    one's own may keep none)."""
    if best is None or not maps.exists():
        return None
    eta, trial, v = best
    with np.load(maps) as data:
        if "success_weights" not in data.files:
            return None
        weights, active = data["success_weights"], data["success_active"]
    candidates = np.flatnonzero(active)
    neuron = int(candidates[np.argmin(np.linalg.norm(weights[candidates] - v, axis=1))])
    axes = c.plan.scenario.space
    return {
        "trial": trial,
        "trial_eta": eta,
        "trial_point": point_fields(axes, v),
        "neuron": neuron,
        "neuron_point": point_fields(axes, weights[neuron]),
    }


def grid_points(plan: Plan) -> np.ndarray:
    """Unit coordinates of the sweep grid (``steps`` points per axis, ends included)."""
    axes = [np.linspace(0.0, 1.0, a.steps) for a in plan.scenario.space]
    return np.array(list(itertools.product(*axes)), dtype=float)


def run_sweep(c: Conductor) -> dict:
    """Evaluate every grid point on the body (no learning), fanned out over the workers."""
    points = grid_points(c.plan)
    progress = Progress(planned=len(points))
    requests = (c.trial_request(i, p, c.should_log_body(i)) for i, p in enumerate(points))
    for request, result, wall in c.trials(requests):
        c.record_trial(progress, request.trial_id, result, wall, c.point(points[request.trial_id]))
    return {"planned_trials": len(points), "stop_reason": f"every grid point run ({len(points)})"}


def run_exploit(c: Conductor) -> dict:
    """Walk with success-map neurons chosen by condition, switching while walking (§3.5.2)."""
    proto = c.plan.scenario.protocol
    axes = [a.name for a in c.plan.scenario.space]
    axis = axes.index(proto.condition)
    spec = c.plan.scenario.space[axis]
    conditions = np.linspace(0.0, 1.0, 41)
    table: m.ExploitTable = c.call(m.Exploit(axis=axis, conditions=conditions))
    # the controller receives the whole table and switches neurons by the sensed condition
    physical_table = {
        "condition": spec.to_physical(table.conditions).tolist(),
        **{
            a.target.partition(".")[2]: a.to_physical(table.weights[:, j]).tolist()
            for j, a in enumerate(c.plan.scenario.space)
            if j != axis and a.target.startswith("controller.")
        },
    }
    progress = Progress(planned=proto.trials)
    base = c.plan.to_physical(np.full(len(axes), 0.5))
    for trial_id in range(proto.trials):
        request = m.TrialRequest(
            trial_id=trial_id,
            seed=trial_seed(c.plan.scenario.seed, trial_id),
            body_params=base["body"],
            controller_params={"switching_table": physical_table},
            log=c.should_log_body(trial_id),
        )
        ((_, result, wall),) = c.trials([request])
        c.record_trial(progress, trial_id, result, wall)
    return {
        "planned_trials": proto.trials,
        "stop_reason": f"trial budget spent ({proto.trials} trials)",
        "switching_table_size": len(conditions),
    }


@dataclass(frozen=True)
class Case:
    """One trial of a conditions protocol: the condition it runs under, its point of the grid (trial parameter ->
    value) and its repeat (which start)."""

    condition: str
    point: dict
    repeat: int


def condition_cases(proto) -> list[Case]:
    """Every trial of a conditions protocol, in the order they are run: condition by condition (as the file lists
    them), the grid's points in order (its last key varying fastest), the repeats of each point."""
    keys = list(proto.grid)
    points = [dict(zip(keys, values, strict=True)) for values in itertools.product(*proto.grid.values())]
    return [Case(name, point, r) for name in proto.conditions for point in points for r in range(proto.repeats)]


def repeat_seed(run_seed: int, repeat: int) -> int:
    """Seed of every trial of repeat ``repeat`` in a conditions protocol: one start per repeat, the same in every
    condition and at every grid point (paired comparisons)."""
    return int(np.random.SeedSequence([run_seed, 11, repeat]).generate_state(1)[0])


def survived(judge: str, result: m.TrialResult) -> bool:
    """A trial's verdict for a conditions protocol: the body's success, or (``upright``) no fall."""
    if judge == "success":
        return bool(result.success)
    fell = result.metrics.get("fell")
    if not isinstance(fell, bool):
        raise RunError(
            f"protocol.judge is 'upright' but the body reports no metric `fell` (true/false); it reports "
            f"{sorted(result.metrics)}"
        )
    return not fell


def run_conditions(c: Conductor) -> dict:
    """A set of trials under named conditions (E4.3-E4.7, E5.3): every condition x grid point x repeat, fanned out
    over the body workers, no learning. Each row holds its condition, repeat, the trial parameters the condition and
    the grid set, and whether the trial ``survived`` (``protocol.judge``)."""
    proto = c.plan.scenario.protocol
    cases = condition_cases(proto)
    progress = Progress(planned=len(cases))
    base: dict[str, dict] = {"body": {}, "controller": {}}
    for key, value in c.plan.scenario.conditions.items():  # the scenario's own conditions: every trial
        owner, _, param = key.partition(".")
        base[owner][param] = value

    def request(trial_id: int, case: Case) -> m.TrialRequest:
        params = {"body": dict(base["body"]), "controller": dict(base["controller"])}
        given = {**proto.conditions[case.condition], **case.point}
        for target, source in proto.follow.items():  # a parameter that takes another's value (follow)
            if source in given:
                given[target] = given[source]
        for key, value in given.items():
            owner, _, param = key.partition(".")
            params[owner][param] = value
        return m.TrialRequest(
            trial_id=trial_id,
            seed=repeat_seed(c.plan.scenario.seed, case.repeat),
            body_params=params["body"],
            controller_params=params["controller"],
            log=c.should_log_body(trial_id),
        )

    requests = (request(i, case) for i, case in enumerate(cases))
    for sent, result, wall in c.trials(requests):
        case = cases[sent.trial_id]
        fields = {"condition": case.condition, "repeat": case.repeat, **proto.conditions[case.condition], **case.point}
        verdict = {"survived": survived(proto.judge, result)}
        c.record_trial(progress, sent.trial_id, result, wall, fields, verdict)
    return {
        "planned_trials": len(cases),
        "stop_reason": f"every condition, grid point and repeat run ({len(cases)} trials)",
    }


PROTOCOLS = {"learn": run_learn, "sweep": run_sweep, "exploit": run_exploit, "conditions": run_conditions}


def finite(x):
    return x if x is None or math.isfinite(x) else None
