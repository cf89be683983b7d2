"""Safe-learning metrics of a learn run, from its trial rows (issue 22, part 2).

The thesis claims success-failure learning finds good gaits with fewer falls than trying parameters
blindly; these are the numbers that claim is measured by, the same for every proposer:

- failures before the first success, and before ``k`` *distinct* good gaits: a success counts as a new
  gait when its unit-cube point is at least ``distinct`` (Euclidean, in the unit cube of the scenario's
  space) from every gait counted before it; ``None`` when the run never got there (censored);
- failures and falls apart: a failure is any unsuccessful trial (on the planar walker also one that stayed up but
  stalled: under 0.5 m or 4 steps), a fall one whose body reports ``fell`` (metric ``m_fell``);
- failures before the first success whose eta reaches ``target_eta`` (when one is given; ``None`` when none did);
- cumulative failures and the best eta so far, against trials;
- the success rate, and decisions per trial (go/no-go decisions the run made for each trial it ran;
  1 for a proposer without a gate);
- what the early warning said of the points tried: trials whose decision was a no-go (an optimiser without the
  gate tries its point whatever the gate says), and how many of them failed.

Plain Python + numpy: a run writes them into its summary, and ``sfl report`` reads them back per run.
"""

from __future__ import annotations

from collections.abc import Iterable

import numpy as np

#: the defaults: 10 distinct good gaits (docs/results/baselines.md), 0.1 apart in the unit cube
K_GOOD = 10
DISTINCT = 0.1


def trial_rows(rows: Iterable[dict]) -> list[dict]:
    """The ``kind: trial`` rows, in trial order."""
    return sorted((r for r in rows if r.get("kind") == "trial"), key=lambda r: r["trial"])


def distinct_successes(points: np.ndarray, successes: np.ndarray, distinct: float = DISTINCT) -> np.ndarray:
    """Trial indices at which a new distinct good gait was found: a success at least ``distinct`` from every
    gait counted before it."""
    kept: list[np.ndarray] = []
    at: list[int] = []
    for i, (p, ok) in enumerate(zip(points, successes, strict=True)):
        if not ok:
            continue
        if all(np.linalg.norm(p - q) >= distinct for q in kept):
            kept.append(p)
            at.append(i)
    return np.asarray(at, dtype=int)


def safe_learning(
    rows: Iterable[dict], k: int = K_GOOD, distinct: float = DISTINCT, target_eta: float | None = None
) -> dict:
    """The run's safe-learning metrics (module docstring) from its record rows (any kinds)."""
    rows = list(rows)
    trials = trial_rows(rows)
    n = len(trials)
    success = np.array([bool(r["success"]) for r in trials], dtype=bool)
    eta = np.array([float(r["quality"]) if r["success"] else np.nan for r in trials], dtype=float)
    points = np.array([r.get("v_unit") or [] for r in trials], dtype=float).reshape(n, -1) if n else np.zeros((0, 0))
    failures = np.cumsum(~success)
    with np.errstate(invalid="ignore"):
        best = np.fmax.accumulate(eta) if n else eta
    found = distinct_successes(points, success, distinct) if points.shape[1] else np.zeros(0, dtype=int)
    first = int(np.argmax(success)) if success.any() else None
    fell = np.array([r.get("m_fell") is True for r in trials], dtype=bool)
    reached = np.flatnonzero(success & (eta >= target_eta)) if target_eta is not None else np.zeros(0, dtype=int)
    # the decision that started each trial: its real go/no-go (every proposer's, gated or not)
    tried_go = {r["trial"]: bool(r["go"]) for r in rows if r.get("kind") == "decision" and r.get("trial") is not None}
    no_go = np.array([tried_go.get(r["trial"]) is False for r in trials], dtype=bool)
    decisions = [r.get("decision") for r in trials]
    last_decision = decisions[-1] if decisions and decisions[-1] is not None else None
    return {
        "trials": n,
        "k": k,
        "distinct": distinct,
        "failures": int(failures[-1]) if n else 0,
        "successes": int(success.sum()),
        "success_rate": float(success.mean()) if n else None,
        "failures_before_first_success": int(failures[first]) if first is not None else None,
        "failures_before_k": int(failures[found[k - 1]]) if len(found) >= k else None,
        "trials_to_k": int(found[k - 1]) + 1 if len(found) >= k else None,
        "distinct_gaits": int(len(found)),
        "falls": int(fell.sum()),
        "falls_before_k": int(np.cumsum(fell)[found[k - 1]]) if len(found) >= k else None,
        "target_eta": target_eta,
        "failures_before_target": int(failures[reached[0]]) if len(reached) else None,
        "trials_to_target": int(reached[0]) + 1 if len(reached) else None,
        "no_go_trials": int(no_go.sum()),
        "no_go_failures": int((no_go & ~success).sum()),
        "best_eta": float(np.nanmax(eta)) if success.any() else None,
        "decisions_per_trial": (last_decision + 1) / n if n and last_decision is not None else None,
        "cumulative_failures": failures.tolist(),
        "best_eta_so_far": [None if np.isnan(x) else float(x) for x in best],
    }
