"""QARL's outputs (thesis §5.4.2): the reward each success neuron learns, each trial's winners, and the best
parameters (L1584) in the run's summary."""

from __future__ import annotations

import json

import numpy as np
import pyarrow.parquet as pq

from sfl_brain import messages as m
from sfl_brain.modules.acc import ACC

from ..conftest import SCENARIOS, sfl_run


def test_each_success_neuron_learns_the_eta_it_was_pulled_by():
    acc = ACC(ACC.Params(shape=(3, 3), dim=2))
    assert np.isnan(acc.success_map.learnt_reward()).all()
    low, high = np.array([0.1, 0.1]), np.array([0.9, 0.9])
    first = acc.handle(m.Learn(v=low, success=True, rho=2.5, eta=1.0))
    acc.handle(m.Learn(v=high, success=True, rho=0.1, eta=3.0))
    reward = acc.success_map.learnt_reward()
    assert np.all((reward >= 1.0) & (reward <= 3.0))  # a weighted mean of the two etas
    # the neuron that won the low trial learnt it with the most weight, and the low trial had the larger rho
    assert reward[first.success_winner] < 2.0
    failure = acc.handle(m.Learn(v=low, success=False, rho=1.0))
    assert failure.failure_winner >= 0 and np.array_equal(acc.success_map.learnt_reward(), reward)


def test_a_learn_run_reports_each_trials_winners_and_the_best_parameters(tmp_path):
    out = tmp_path / "run"
    done = sfl_run(SCENARIOS / "analytic_learn.yaml", out, "protocol.trials=30")
    assert done.returncode == 0, done.stderr
    trials = pq.read_table(out / "trials.parquet").to_pylist()
    assert all(0 <= t["success_winner"] <= 99 and 0 <= t["failure_winner"] <= 99 for t in trials)
    best = json.loads((out / "summary.json").read_text())["best"]
    top = max((t for t in trials if t["success"]), key=lambda t: t["quality"])  # the first of equals, as idxmax
    assert best["trial"] == top["trial"] and best["trial_eta"] == top["quality"]
    maps = np.load(out / "acc.npz")
    weights, active = maps["success_weights"], maps["success_active"]
    distances = np.where(active, np.linalg.norm(weights - np.array(best["trial_point"]["v_unit"]), axis=1), np.inf)
    assert best["neuron"] == int(np.argmin(distances))
    assert np.allclose(best["neuron_point"]["v_unit"], weights[best["neuron"]])
    assert np.isfinite(maps["success_reward"]).any()
