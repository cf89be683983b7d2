"""The learning cycle (Fig. 3.5/5.6): ask the proposer for a point through the gate, run the trial on the body,
grade it, tell the proposer, record the row; a resumed run replays its recorded trials first."""

from __future__ import annotations

import json
import math
import time
from collections import deque
from pathlib import Path

import numpy as np

from .. import messages as m
from ..events import Progress
from ..proposers import PROPOSERS, Outcome, Proposer
from ..recording.metrics import safe_learning
from ..recording.records import NOT_REPRODUCIBLE, decision_row, plain, point_fields
from ..scenario.plan import Plan
from .conductor import Conductor
from .service import RunError


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
    budget = c.budget  # where the time goes: the conductor counts the trials and records, this cycle the rest
    progress = Progress(planned=proto.trials)
    with budget.part("decisions"):
        proposer = make_proposer(c)
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
        with budget.part("decisions"):
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
        with budget.part("learning"):
            rho = c.call(m.Grade(eta=result.quality)).rho if result.success else None
        n_success += int(result.success)
        n_failure += int(not result.success)
        s_vig_used, low, high = gate.threshold.s_vig, gate.threshold.low, gate.threshold.high
        if result.success and (best is None or eta > best[0]):
            best = (eta, trial_id, v.copy())  # the highest-reward trial so far (L1584)
        with budget.part("learning"):
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
    with budget.part("learning"):  # the ACC prunes its failure map and saves both
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
        sim_s=float(row.get("sim_s") or 0.0),
        cpu_body_s=row.get("cpu_body_s"),
        cpu_controller_s=row.get("cpu_controller_s"),
    )
    return result, float(row.get("wall_ms") or 0.0) / 1e3


def check_replayed(trial: int, row: dict, recorded: dict) -> None:
    """A replayed trial's row must be the recorded one (its decision, vigilance, the maps' change...): else the
    brain modules did not reach the state they had."""
    replayed = json.loads(json.dumps(plain(row)))
    if "sim_s" not in recorded:  # records written before trial rows had it
        replayed.pop("sim_s", None)
    for key in sorted(set(replayed) | set(recorded)):
        if key not in NOT_REPRODUCIBLE and replayed.get(key) != recorded.get(key):
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
