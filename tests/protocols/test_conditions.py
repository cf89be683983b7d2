"""The conditions protocol: a set of trials under named conditions, over a grid and repeats (issue 23 item 6), its
checks, its records and tables, and ``sfl report``'s survival tables with Wilson intervals and exact tests."""

from __future__ import annotations

import json
import math

import numpy as np
import pyarrow as pa
import pyarrow.parquet as pq
import pytest
import yaml
from rerun.chunk import RrdReader

from sfl_brain import scenario as sc
from sfl_brain.protocols import condition_cases, repeat_seed
from sfl_brain.report.conditions import Trials, fisher_exact, mcnemar_exact, pattern_space_paths, value_at, wilson
from sfl_brain.scenario import PatternSpaceAnalysis

from ..conftest import SCENARIOS, sfl, sfl_run

BASE = """
name: cond
seed: 5
protocol:
  kind: conditions
  conditions:
    near: {body.x: 0.5}
    far: {body.x: 0.9}
  grid:
    body.y: [0.4, 0.5]
  repeats: 2
  compare: [[near, far]]
modules:
  body: {impl: analytic}
"""


def test_cases_run_every_condition_point_and_repeat_and_pair_starts_by_repeat():
    plan = sc.build_plan(yaml.safe_load(BASE.replace("repeats: 2", "repeats: 3")), "cond.yaml", SCENARIOS)
    proto = plan.scenario.protocol
    cases = condition_cases(proto)
    assert proto.trials == len(cases) == 2 * 2 * 3
    assert [c.condition for c in cases[:6]] == ["near"] * 6 and cases[6].condition == "far"
    assert [c.point["body.y"] for c in cases[:6]] == [0.4, 0.4, 0.4, 0.5, 0.5, 0.5]
    assert [c.repeat for c in cases[:3]] == [0, 1, 2]
    # one start per repeat: the same in both conditions and at every point, different between repeats
    seeds = {repeat_seed(5, r) for r in range(3)}
    assert len(seeds) == 3 and repeat_seed(5, 1) != repeat_seed(6, 1)


@pytest.mark.parametrize(
    "change, message",
    [
        (
            ("compare: [[near, far]]", "compare: [[near, fra]]"),
            "protocol.compare.0.1: expected one of the conditions ['near', 'far']; got 'fra' (did you mean `far`?)",
        ),
        (("  repeats: 2", "  repeats: 2\n  pool: [body.yy]"), "protocol.pool.0: expected a key of the grid ['body.y']"),
        (
            ("near: {body.x: 0.5}", "near: {body.xx: 0.5}"),
            "protocol.conditions.near.body.xx: AnalyticBody takes trial parameters ['x', 'y', 'z']; got 'xx' "
            "(did you mean `body.x`?)",
        ),
        (("body.y: [0.4, 0.5]", "body.y: []"), "protocol.grid.body.y: expected at least one value; got []"),
        (("compare: [[near, far]]", "compare: [[near, near]]"), "protocol.compare.0: expected two different"),
        (("repeats: 2", "repeats: 0"), "protocol.repeats: input should be greater than or equal to 1; got 0"),
        (("  repeats: 2", "  repeats: 2\n  judge: alive"), "protocol.judge: expected one of 'success' or 'upright'"),
        (
            ("  repeats: 2", "  repeats: 2\n  analyses: [{kind: pattern_space, window: 0}]"),
            "protocol.analyses.0.window: input should be greater than 0; got 0",
        ),
        (
            ("  repeats: 2", "  repeats: 2\n  analyses: [{kind: pattern_space, windw: 0.5}]"),
            "protocol.analyses.0.windw: unknown key; expected one of ['after', 'events', 'joints', 'kind', 'module', "
            "'trials', 'where', 'window'] (did you mean `window`?)",
        ),
        (
            ("  repeats: 2", "  repeats: 2\n  analyses: [{kind: pattern_space, window: 0.5, where: {body.yy: 0.4}}]"),
            "protocol.analyses.0.where.body.yy: expected a key of the grid ['body.y']; got 'body.yy' "
            "(did you mean `body.y`?)",
        ),
        (
            (
                "compare: [[near, far]]",
                "compare: [[near, far]]\n  analyses: [{kind: pattern_space, window: 0.5}]\nrecord: {neurons: false}",
            ),
            "protocol.analyses.0: pattern_space reads the controller's RG potentials: expected record.neurons: true",
        ),
        (  # the conditions protocol's keys
            ("  repeats: 2", "  repeats: 2\n  repeatz: 3"),
            "protocol.repeatz: unknown key; expected one of ['analyses', 'best_by', 'best_of', ",
        ),
    ],
)
def test_a_bad_conditions_protocol_is_refused_before_anything_starts(write_scenario, change, message):
    path = write_scenario(BASE.replace(*change))
    done = sfl("check", str(path))
    assert done.returncode == 2, done.stdout
    assert message in done.stderr, done.stderr
    assert "Traceback" not in done.stderr


def test_grid_values_are_checked_by_the_body(write_scenario):
    text = """
name: pushes
protocol:
  kind: conditions
  conditions: {a: {}}
  grid: {body.push_force: [10, 5000], body.slope_deg: [0, 30]}
modules:
  controller: {impl: cpg}
  body: {impl: planar_8link}
"""
    done = sfl("check", str(write_scenario(text)))
    assert done.returncode == 2
    assert "protocol.grid.body.push_force: push_force: expected a number in [-1000, 1000]; got 5000" in done.stderr
    assert "protocol.grid.body.slope_deg: slope_deg: expected a number in [-15, 15]; got 30" in done.stderr


def test_other_protocols_still_need_a_space(write_scenario):
    text = "name: x\nprotocol: {kind: sweep}\nmodules:\n  body: {impl: analytic}\n"
    done = sfl("check", str(write_scenario(text)))
    assert done.returncode == 2
    assert "space: expected at least one axis for protocol 'sweep'; got none" in done.stderr


def test_statistics_match_known_values():
    low, high = wilson(0, 4)
    assert low == pytest.approx(0.0, abs=1e-12) and high == pytest.approx(0.4899, abs=1e-3)
    low, high = wilson(14, 15)
    assert (low, high) == pytest.approx((0.7018, 0.9881), abs=1e-3)
    assert all(math.isnan(x) for x in wilson(0, 0))
    # McNemar exact: 6 pairs where only the first survived, 0 the other way: p = 2 / 2^6
    p, only_a, only_b = mcnemar_exact([(True, False)] * 6 + [(True, True)] * 5 + [(False, False)] * 3)
    assert (only_a, only_b) == (6, 0) and p == pytest.approx(2 / 64)
    assert mcnemar_exact([(True, True), (False, False)])[0] == 1.0
    # Fisher exact, 14/15 against 10/15 (the old E4.3 counts): not significant
    assert fisher_exact(14, 15, 10, 15) == pytest.approx(0.1686, abs=1e-3)


def test_a_conditions_run_over_processes_records_tables_recording_and_report(tmp_path):
    out = tmp_path / "run"
    done = sfl_run(SCENARIOS / "analytic_conditions.yaml", out)
    assert done.returncode == 0, done.stderr
    summary = json.loads((out / "summary.json").read_text())
    assert summary["status"] == "completed" and summary["trials"] == summary["planned_trials"] == 18
    read = pq.read_table(out / "trials.parquet")
    table = read.to_pylist()
    assert [t["trial"] for t in table] == list(range(18))  # in trial order, whichever worker ran them
    assert {t["condition"] for t in table} == {"inside", "edge"} and sorted({t["repeat"] for t in table}) == [0, 1, 2]
    assert read.schema.field("body.x").type == pa.float64() and {t["body.y"] for t in table} == {0.3, 0.5, 0.7}
    # the analytic body's disc: x = 0.5 is inside at every y; x = 0.75 only at y = 0.5
    inside = [t for t in table if t["condition"] == "inside"]
    edge = [t for t in table if t["condition"] == "edge"]
    assert all(t["survived"] for t in inside)
    assert [sum(t["survived"] for t in edge if t["body.y"] == y) for y in (0.3, 0.5, 0.7)] == [0, 3, 0]
    assert all(t["survived"] == t["success"] for t in table)  # judge: success
    assert {t["worker"] for t in table} == {"body.0", "body.1"}
    rows = {}
    for chunk in RrdReader(out / "recording.rrd").stream().to_chunks():
        if not chunk.is_static:
            rows[str(chunk.entity_path)] = rows.get(str(chunk.entity_path), 0) + chunk.num_rows
    assert rows["/trials/success"] == 18
    # the same scenario and seed give the same records
    again = tmp_path / "again"
    assert sfl_run(SCENARIOS / "analytic_conditions.yaml", again).returncode == 0
    keep = ["trial", "condition", "repeat", "body.x", "body.y", "success", "quality", "survived"]
    second = pq.read_table(again / "trials.parquet").to_pylist()
    assert len(second) == len(table)
    for first, other in zip(table, second, strict=True):
        for key in keep:  # equal, NaN as NaN
            assert first[key] == other[key] or (first[key] != first[key] and other[key] != other[key]), key

    report = sfl("report", str(out), str(again), "--out", str(tmp_path / "report"))
    assert report.returncode == 0, report.stderr
    page = (tmp_path / "report" / "analytic_conditions.md").read_text()
    assert "| y | inside | edge | inside vs edge: McNemar p (only inside / only edge) | Fisher p |" in page
    # pooled over both runs: 6 starts per cell; at y = 0.3 inside 6/6, edge 0/6, McNemar p = 2 / 2^6
    assert "| 0.3 | 6/6 = 100% [61%, 100%] | 0/6 = 0% [0%, 39%] | 0.031 (6 / 0) | 0.0022 |" in page
    assert "distance_to_centre: mean (sd)" in page
    assert (tmp_path / "report" / "analytic_conditions_y.png").stat().st_size > 10_000


def test_judge_upright_needs_a_body_that_reports_falls(tmp_path, write_scenario):
    path = write_scenario(BASE.replace("  repeats: 2", "  repeats: 1\n  judge: upright"))
    done = sfl_run(path, tmp_path / "run")
    assert done.returncode == 1, done.stdout
    assert "protocol.judge is 'upright' but the body reports no metric `fell`" in done.stdout + done.stderr
    summary = json.loads((tmp_path / "run" / "summary.json").read_text())
    assert summary["status"] == "failed"


def test_follow_gives_a_parameter_another_ones_value_and_is_checked(write_scenario):
    text = """
name: push_switch
protocol:
  kind: conditions
  conditions: {walk: {controller.switch: none}, switch: {controller.switch: brace}}
  grid: {body.push_time: [4.0, 4.5]}
  follow: {controller.switch_at: body.push_time}
modules:
  controller:
    impl: cpg
    params:
      switches:
        brace: {trigger: time, at: 5.0, joints: {hip_l: plateau, hip_r: plateau}}
  body: {impl: planar_8link}
"""
    plan = sc.build_plan(yaml.safe_load(text), "push.yaml", SCENARIOS)
    assert plan.scenario.protocol.follow == {"controller.switch_at": "body.push_time"}
    bad = text.replace(
        "follow: {controller.switch_at: body.push_time}", "follow: {controller.switch_at: body.push_tim}"
    )
    done = sfl("check", str(write_scenario(bad)))
    assert done.returncode == 2
    assert "protocol.follow.controller.switch_at: expected a key of the grid or of a condition" in done.stderr
    assert "(did you mean `body.push_time`?)" in done.stderr
    # a preset the controller does not have is refused by sfl check, naming the presets it has
    done = sfl("check", str(write_scenario(text.replace("controller.switch: brace}", "controller.switch: bracee}"))))
    assert done.returncode == 2
    assert """switch: expected "none" or one of the presets ['brace']; got 'bracee' (did you mean 'brace'?)""" in (
        done.stderr
    )


def test_e4_7_runs_its_conditions_and_the_report_marks_each_switch_when_the_push_comes(tmp_path):
    out = tmp_path / "run"
    sets = (
        "protocol.grid.body.push_time=[9.2]",
        "protocol.grid.body.push_force=[34.0]",
        "protocol.repeats=1",
        "record.body_every=1",
        "modules.body.params.duration=10",
    )
    done = sfl_run(SCENARIOS / "e4_7_push.yaml", out, *sets)
    assert done.returncode == 0, done.stderr
    table = pq.read_table(out / "trials.parquet").to_pylist()
    assert [t["condition"] for t in table] == ["walk", "switch", "switch_angle"]
    assert [t["controller.switch"] for t in table] == ["none", "reaction", "reaction_angle"]
    report = sfl("report", str(out), "--out", str(tmp_path / "report"))
    assert report.returncode == 0, report.stderr
    page = (tmp_path / "report" / "e4_7_push.md").read_text()
    switches = [line for line in page.splitlines() if "pattern switch" in line]
    # the touch sensor on the back fires the switch the tick after the push starts, in the switching conditions only
    assert [line.split(" | ")[1:3] for line in switches] == [["switch", "9.21"], ["switch_angle", "9.21"]]
    assert "couplings silenced between hip_pitch_l-hip_pitch_r" in switches[0]
    assert (tmp_path / "report" / "e4_7_push_trace.png").stat().st_size > 20_000


def test_e4_7_pattern_space_the_switched_joints_leave_the_oscillation_and_the_walks_do_not(tmp_path):
    """Fig. 4.23 from the recording of a short real run: the RG energy (4.15) of V_E - V_F over one gait cycle stays
    where the gait puts it in the walk condition and falls by decades once the switch fires (L1437: knees -> plateau,
    hips -> quiescent), and sfl report draws it."""
    out = tmp_path / "run"
    sets = (
        "protocol.grid.body.push_time=[3.0]",
        "protocol.grid.body.push_force=[10.0]",
        "protocol.repeats=1",
        "record.body_every=1",
        "modules.body.params.duration=5.5",
    )
    done = sfl_run(SCENARIOS / "e4_7_push.yaml", out, *sets)
    assert done.returncode == 0, done.stderr
    scenario = yaml.safe_load((out / "scenario.yaml").read_text())
    analysis = PatternSpaceAnalysis(kind="pattern_space", window=0.667, after=2.0, joints=["knee_l", "hip_pitch_l"])
    joints, paths = pattern_space_paths(Trials(scenario, [out]), [out], analysis.model_dump())
    assert joints == ["knee_l", "hip_pitch_l"]
    points = {}
    for row, path, push, _ in paths:
        assert push == pytest.approx(3.0, abs=0.02)  # the push, the first event of the trial
        points[row["condition"]] = {
            j: [math.log10(max(value_at(p.time, p.energy, when), 1e-12)) for when in (push, push + 2.0)]
            for j, p in path.items()
        }
    for joint in joints:
        before, later = points["walk"][joint]
        assert before > 3 and abs(later - before) < 0.3, (joint, before, later)  # it walks on: an oscillator
        before, later = points["switch"][joint]
        assert before > 3 and later < before - 4, (joint, before, later)  # plateau / quiescent: still
        assert points["switch"][joint][0] == pytest.approx(points["walk"][joint][0])  # the same start, no switch yet
    with pytest.raises(ValueError, match="no RG potentials of joint 'knee_x' .* the RGs of \\['ankle_pitch_l'"):
        pattern_space_paths(Trials(scenario, [out]), [out], {**analysis.model_dump(), "joints": ["knee_x"]})
    report = sfl("report", str(out), "--out", str(tmp_path / "report"))
    assert report.returncode == 0, report.stderr
    page = (tmp_path / "report" / "e4_7_push.md").read_text()
    # the shipped analyses: at 34 N (not in this run: said so) and at 10 N (drawn, with its table)
    assert "No logged trial with {'body.push_force': 34.0} holds the RG potentials" in page
    knee = next(line for line in page.splitlines() if line.startswith("| knee_l | plateau |"))
    assert knee.count(" -> ") == 3  # walk, switch, switch_angle
    assert (tmp_path / "report" / "e4_7_push_pattern_space2.png").stat().st_size > 50_000


def test_a_condition_takes_a_learn_runs_best_parameters_and_says_why_it_cannot(tmp_path, write_scenario):
    run = tmp_path / "flat"
    run.mkdir()
    best = {"neuron": 3, "neuron_point": {"v_unit": [0.5, 0.25], "x": 0.5, "y": 0.25}}
    (run / "summary.json").write_text(json.dumps({"status": "completed", "best": best}))
    text = f"""
name: learnt
protocol:
  kind: conditions
  best_of: {{flat: {run}}}
  conditions:
    best: {{body.x: "@flat.x", body.y: "@flat.y"}}
    other: {{body.x: 0.1}}
modules:
  body: {{impl: analytic}}
"""
    plan = sc.load(write_scenario(text))
    assert plan.scenario.protocol.conditions["best"] == {"body.x": 0.5, "body.y": 0.25}
    assert plan.raw["protocol"]["conditions"]["best"] == {"body.x": 0.5, "body.y": 0.25}  # what the run folder keeps
    for change, message in [
        (('"@flat.y"', '"@flta.y"'), "protocol.conditions.best.body.y: expected @RUN.AXIS with RUN in "
         "protocol.best_of ['flat']; got '@flta.y' (did you mean `flat`?)"),
        (('"@flat.y"', '"@flat.z"'), "protocol.conditions.best.body.y: expected an axis of flat's learn run "
         "['x', 'y']; got 'z'"),
        ((str(run), str(tmp_path / "none")), "protocol.best_of.flat: expected a completed learn run's folder (with "
         "summary.json)"),
    ]:  # fmt: skip
        done = sfl("check", str(write_scenario(text.replace(*change))))
        assert done.returncode == 2 and message in done.stderr, done.stderr
    (run / "summary.json").write_text(json.dumps({"status": "completed", "best": None}))
    done = sfl("check", str(write_scenario(text)))
    assert done.returncode == 2 and "expected best parameters in" in done.stderr


def test_best_by_wins_takes_the_success_neuron_that_won_most_and_says_why_it_cannot(tmp_path, write_scenario):
    run = tmp_path / "flat"
    run.mkdir()
    best = {"neuron": 0, "neuron_point": {"v_unit": [0.9, 0.9], "x": 0.9, "y": 1.8}}  # a lucky highest-reward trial
    (run / "summary.json").write_text(json.dumps({"status": "completed", "best": best}))
    (run / "scenario.yaml").write_text(
        "space: [{name: x, target: body.x, low: 0.0, high: 1.0}, {name: y, target: body.y, low: 0.0, high: 2.0}]\n"
    )
    np.savez(
        run / "acc.npz",
        success_weights=np.array([[0.9, 0.9], [0.2, 0.4], [0.3, 0.1], [0.6, 0.6]]),
        success_wins=np.array([1, 5, 5, 0]),  # two neurons won 5 successes each: the higher learnt reward wins
        success_reward=np.array([9.0, 2.0, 3.0, 0.0]),
    )
    text = f"""
name: learnt
protocol:
  kind: conditions
  best_of: {{flat: {run}}}
  best_by: wins
  conditions:
    best: {{body.x: "@flat.x", body.y: "@flat.y"}}
modules:
  body: {{impl: analytic}}
"""
    plan = sc.load(write_scenario(text))
    assert plan.scenario.protocol.conditions["best"] == {"body.x": pytest.approx(0.3), "body.y": pytest.approx(0.2)}
    thesis = sc.load(write_scenario(text.replace("  best_by: wins\n", "")))  # reward: L1584's neuron
    assert thesis.scenario.protocol.conditions["best"] == {"body.x": 0.9, "body.y": 1.8}
    done = sfl("check", str(write_scenario(text.replace("best_by: wins", "best_by: winz"))))
    assert done.returncode == 2 and "protocol.best_by" in done.stderr and "wins" in done.stderr, done.stderr
    np.savez(
        run / "acc.npz",
        success_weights=np.array([[np.nan, 0.9], [0.2, 0.4]]),  # hostile: a weight that is not a number
        success_wins=np.array([1, 5]),
        success_reward=np.array([9.0, 2.0]),
    )
    done = sfl("check", str(write_scenario(text)))
    assert done.returncode == 2 and "protocol.best_of.flat: expected finite weights and bounds" in done.stderr
    assert "Traceback" not in done.stderr
    (run / "acc.npz").unlink()
    done = sfl("check", str(write_scenario(text)))
    assert done.returncode == 2 and "protocol.best_of.flat: expected the success map (acc.npz)" in done.stderr
