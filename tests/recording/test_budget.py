"""The honest time budget (issue 31, item 3): every trial row's simulated and CPU seconds, and where a run's wall
time went (``time_budget`` in ``summary.json``, ``sfl inspect``)."""

from __future__ import annotations

import json

import pytest

from sfl_brain.protocols.local import run_local
from sfl_brain.recording import budget as budget_module
from sfl_brain.recording.budget import PARTS, TimeBudget, budget_lines, process_age
from sfl_brain.recording.records import read_records
from sfl_brain.scenario import load

from ..conftest import SCENARIOS, sfl, sfl_run


class Clock:
    """A perf_counter the test moves by hand."""

    def __init__(self) -> None:
        self.now = 100.0

    def __call__(self) -> float:
        return self.now


def test_a_part_opened_inside_another_counts_for_itself_only(monkeypatch):
    clock = Clock()
    monkeypatch.setattr(budget_module.time, "perf_counter", clock)
    budget = TimeBudget(launched=2.0)
    with budget.part("decisions"):
        clock.now += 1.0
        with budget.part("records"):  # the decision rows written while the proposer asks
            clock.now += 0.25
        clock.now += 0.5
    with budget.part("trials"):
        clock.now += 3.0
    clock.now += 0.125  # between the parts: counted in the wall time only
    summary = budget.summary()
    assert summary["startup_s"] == 2.0  # the process's launch
    assert summary["decisions_s"] == 1.5 and summary["records_s"] == 0.25 and summary["trials_s"] == 3.0
    assert summary["sum_s"] == 6.75 and summary["wall_s"] == 6.875
    with pytest.raises(ValueError, match=r"'part' must be in \('startup', .*\) \(got 'thinking'\)"):
        with budget.part("thinking"):
            pass


def test_the_process_age_is_known_here():
    age = process_age()
    assert age is None or age >= 0.0


def test_trial_rows_carry_their_simulated_and_cpu_seconds_in_one_process():
    """The planar biped's clock: ticks x control_dt, at most its trial's duration; the analytic body has none (0).
    In one process the body's CPU seconds hold the controller's, which has no process of its own (null)."""
    rows = run_local(load(SCENARIOS / "quickstart.yaml", ["protocol.trials=2"]))
    trials = [r for r in rows if r["kind"] == "trial"]
    assert len(trials) == 2
    for row in trials:
        assert 0.0 < row["sim_s"] <= 10.0 + 1e-9
        assert row["cpu_body_s"] > 0.0 and row["cpu_controller_s"] is None
    rows = run_local(load(SCENARIOS / "analytic_learn.yaml", ["protocol.trials=2"]))
    assert [r["sim_s"] for r in rows if r["kind"] == "trial"] == [0.0, 0.0]


def test_a_real_run_says_where_its_wall_time_went(tmp_path):
    """A learn run over processes: the parts of its time budget are each >= 0 and add up to its wall time within
    5%; ``sfl inspect`` prints one line per part and ``--json`` holds the budget."""
    out = tmp_path / "run"
    done = sfl_run(SCENARIOS / "analytic_learn.yaml", out, "protocol.trials=4")
    assert done.returncode == 0, done.stderr
    budget = json.loads((out / "summary.json").read_text())["time_budget"]
    assert set(budget) == {f"{p}_s" for p in PARTS} | {"sum_s", "wall_s"}
    assert all(budget[f"{p}_s"] >= 0.0 for p in PARTS)
    assert budget["startup_s"] > 0 and budget["trials_s"] > 0 and budget["decisions_s"] > 0
    assert budget["sum_s"] == pytest.approx(sum(budget[f"{p}_s"] for p in PARTS))
    assert abs(budget["wall_s"] - budget["sum_s"]) <= 0.05 * budget["wall_s"]
    trials = [r for r in read_records(out) if r["kind"] == "trial"]
    assert [r["sim_s"] for r in trials] == [0.0] * 4  # the analytic body has no clock
    assert all(r["cpu_body_s"] >= 0.0 and r["cpu_controller_s"] is None for r in trials)  # nor a controller

    shown = sfl("inspect", "--json", str(out))
    assert json.loads(shown.stdout)["time_budget"] == budget
    text = sfl("inspect", str(out)).stdout
    for line in budget_lines(budget):
        assert line in text
    assert "startup" in text and "%" in text


def test_a_controller_in_its_own_process_has_its_cpu_seconds_counted(tmp_path):
    """The planar biped and its reflex controller in two processes: the controller's CPU seconds are its own
    process's, read by the body worker around the trial."""
    out = tmp_path / "run"
    done = sfl_run(SCENARIOS / "quickstart.yaml", out, "protocol.trials=1", "record.body_every=0")
    assert done.returncode == 0, done.stderr
    (trial,) = [r for r in read_records(out) if r["kind"] == "trial"]
    assert 0.0 < trial["sim_s"] <= 10.0 + 1e-9
    assert trial["cpu_body_s"] > 0.0 and trial["cpu_controller_s"] > 0.0
    budget = json.loads((out / "summary.json").read_text())["time_budget"]
    assert abs(budget["wall_s"] - budget["sum_s"]) <= 0.05 * budget["wall_s"]
