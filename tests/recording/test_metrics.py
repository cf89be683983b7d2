"""Safe-learning metrics (issue 22, part 2) on hand-made trial rows."""

from __future__ import annotations

from sfl_brain.recording.metrics import safe_learning


def row(i, ok, eta, v, decision=None):
    return {"kind": "trial", "trial": i, "success": ok, "quality": eta, "v_unit": v, "decision": decision}


def test_failures_before_first_and_before_k_distinct_gaits():
    rows = [
        row(0, False, 0.0, [0.0, 0.0], 4),
        row(1, True, 0.2, [0.5, 0.5], 9),
        row(2, False, 0.0, [0.9, 0.9], 12),
        row(3, True, 0.5, [0.55, 0.5], 13),  # 0.05 from the gait of trial 1: not a new gait
        row(4, True, 0.1, [0.1, 0.9], 15),  # a second distinct gait
        {"kind": "decision", "decision": 0},
    ]
    got = safe_learning(rows, k=2, distinct=0.1)
    assert got["failures_before_first_success"] == 1
    assert got["distinct_gaits"] == 2
    assert got["failures_before_k"] == 2 and got["trials_to_k"] == 5
    assert got["cumulative_failures"] == [1, 1, 2, 2, 2]
    assert got["best_eta_so_far"] == [None, 0.2, 0.2, 0.5, 0.5]
    assert got["success_rate"] == 0.6 and got["best_eta"] == 0.5
    assert got["decisions_per_trial"] == 16 / 5


def test_a_run_that_never_gets_there_is_censored_not_zero():
    got = safe_learning([row(0, False, 0.0, [0.1]), row(1, False, 0.0, [0.2])], k=1)
    assert got["failures_before_first_success"] is None and got["failures_before_k"] is None
    assert got["best_eta"] is None and got["failures"] == 2


def test_a_run_without_trials_has_metrics_too():
    got = safe_learning([{"kind": "decision", "decision": 0}])
    assert got["trials"] == 0 and got["failures"] == 0 and got["failures_before_first_success"] is None
