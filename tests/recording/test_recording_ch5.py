"""Chapter 5 in the recording by itself (issue 21 item 6), read back from real runs' ``recording.rrd``.

A short learn run of the humanoid (``e5_learn.yaml``) records each trial's winning neuron of both maps as series and
as a labelled point over the map it won in, and opens with the humanoid's layout; a short conditions run with a
terrain switch (``e5_switch.yaml``'s up conditions, the learnt values given as numbers) records the switch's
threshold over the torso pitch and the switch itself on ``sim_time``.
"""

from __future__ import annotations

import json

import numpy as np
import pyarrow.parquet as pq
import pytest
import yaml
from rerun.chunk import RrdReader

from sfl_brain.modules.controllers.cpg import CPGParams
from sfl_brain.recording.recorded import read_events, read_series
from sfl_brain.recording.rrlog import blueprint, layout_of
from sfl_brain.scenario import load

from ..conftest import SCENARIOS, sfl_run

TRIALS = 4


def trial_rows(run) -> list[dict]:
    rows = [json.loads(line) for line in (run / "records.jsonl").read_text().splitlines()]
    return sorted((r for r in rows if r.get("kind") == "trial"), key=lambda r: r["trial"])


def contents(container) -> set[str]:
    """Every entity pattern the layout's views show."""
    out = set()
    for part in container.contents:
        out |= set(getattr(part, "contents", None) or []) if hasattr(part, "origin") else contents(part)
    return out


@pytest.fixture(scope="module")
def learn_run(tmp_path_factory):
    out = tmp_path_factory.mktemp("ch5") / "learn"
    done = sfl_run(SCENARIOS / "e5_learn.yaml", out, f"protocol.trials={TRIALS}", "modules.body.params.duration=2.0")
    assert done.returncode == 0, done.stderr
    return out


def test_each_trials_winning_neurons_are_series_and_labelled_points_over_the_map(learn_run):
    rows = trial_rows(learn_run)
    assert len(rows) == TRIALS
    rrd = learn_run / "recording.rrd"
    series = read_series(rrd, ["trials/success_winner", "trials/failure_winner"])
    for name in ("success", "failure"):
        logged = {trial: int(s.values[0]) for trial, s in series[f"trials/{name}_winner"].items()}
        assert logged == {r["trial"]: r[f"{name}_winner"] for r in rows}, name
    # the highlight: at trial k, the neuron that won k's point, where it stood in the map that judged it (the
    # snapshot at index k: the maps after learning trial k - 1)
    maps = pq.read_table(learn_run / "maps.parquet").to_pylist()
    for name in ("success", "failure"):
        points = {}
        for chunk in RrdReader(rrd).stream().to_chunks():
            if str(chunk.entity_path) == f"/acc/{name}_map/winner" and not chunk.is_static:
                batch = chunk.to_record_batch()
                for trial, position, label in zip(
                    batch.column("trial").to_pylist(),
                    batch.column("Points3D:positions").to_pylist(),
                    batch.column("Points3D:labels").to_pylist(),
                    strict=True,
                ):
                    points[trial] = (np.array(position[0]), label[0])
        assert sorted(points) == list(range(TRIALS)), name
        for r in rows:
            position, label = points[r["trial"]]
            assert label == f"{name} winner {r[f'{name}_winner']}"
            if r["trial"] > 0:  # no snapshot before the first trial
                (weights,) = [
                    m["weights"]
                    for m in maps
                    if m["trial"] == r["trial"] and m["map"] == name and not m["final"]
                    if m["neuron"] == r[f"{name}_winner"]
                ]
                np.testing.assert_allclose(position, weights, atol=1e-6)


def test_a_chapter_5_learn_run_opens_with_the_humanoid_layout_and_its_panels(learn_run):
    layout = layout_of(load(learn_run / "scenario.yaml"))
    assert layout == {"body": "humanoid", "learning": True}
    shown = contents(blueprint(**layout).root_container)
    for entity in (
        "/trials/success_winner",
        "/trials/failure_winner",
        "/trials/quality",
        "/trials/rho",
        "/vigilance/s_vig",
        "/trials/ns_nf",
        "/acc/**",
        "/body/robot",
        "/body/torso/pitch",
        "/controller/terrain_switch/band_low",
        "/controller/terrain_switch/at",
    ):
        assert entity in shown, entity
    # the walk's camera follows the robot: its frame moves along x on both timelines
    follow = [
        c for c in RrdReader(learn_run / "recording.rrd").stream().to_chunks() if str(c.entity_path) == "/body/follow"
    ]
    assert follow and {"trial", "sim_time"} <= {t for c in follow if not c.is_static for t in c.timeline_names}


@pytest.fixture(scope="module")
def switch_run(tmp_path_factory):
    """E5.3's up conditions, without and with the switch (its band narrowed to 0.5 x the half range, so that the gait
    itself leaves it soon after it is measured), the learnt values as numbers, one walk each of 8 s."""
    raw = yaml.safe_load((SCENARIOS / "e5_switch.yaml").read_text())
    protocol = raw["protocol"]
    del protocol["best_of"]
    learnt = {"gain_pitch": 1.0, "gain_roll": 1.0, "sigma_s": 4.0}
    conditions = {}
    for name in ("up_without", "up_switching"):
        condition = protocol["conditions"][name]
        for key, value in list(condition.items()):
            if isinstance(value, str) and value.startswith("@"):
                condition[key] = learnt[value.partition(".")[2]] * (1.1 if key.startswith("controller.next_") else 1)
        conditions[name] = condition
    conditions["up_switching"]["controller.switch_band"] = 0.5
    conditions["up_switching"]["controller.switch_detector"] = "torso"  # the thesis's detector, drawn over the pitch
    protocol.update(conditions=conditions, repeats=1, compare=[["up_without", "up_switching"]], analyses=[])
    raw["modules"]["body"]["params"]["duration"] = 8.0
    raw["modules"]["body"]["workers"] = 1
    raw["record"]["body_every"] = 1
    folder = tmp_path_factory.mktemp("ch5_switch")
    scenario = folder / "switch.yaml"
    scenario.write_text(yaml.safe_dump(raw, sort_keys=False))
    out = folder / "run"
    done = sfl_run(scenario, out)
    assert done.returncode == 0, done.stderr
    return out


def test_the_terrain_switch_threshold_and_the_switch_are_drawn_over_the_torso_pitch(switch_run):
    rows = {r["condition"]: r for r in trial_rows(switch_run)}
    rrd = switch_run / "recording.rrd"
    band = "controller/terrain_switch/"
    series = read_series(rrd, [band + "band_low", band + "band_high", band + "at", "body/torso/pitch"])
    events = read_events(rrd, ["controller/events/terrain_switch"])["controller/events/terrain_switch"]
    without, switching = rows["up_without"]["trial"], rows["up_switching"]["trial"]
    assert without not in series[band + "band_low"] and without not in series[band + "at"] and without not in events
    low, high = series[band + "band_low"][switching], series[band + "band_high"][switching]
    t0 = switching * 8.0
    known = CPGParams.model_fields["terrain_switch_after"].default + CPGParams.model_fields["switch_measure"].default
    assert low.times[0] == pytest.approx(t0 + known) and high.times[0] == pytest.approx(t0 + known)
    assert low.values[0] < high.values[0]  # deg: the measured band of the gait's torso pitch (switch_when outside)
    assert np.ptp(low.values) == np.ptp(high.values) == 0 and low.times[-1] == pytest.approx(
        t0 + rows["up_switching"]["m_time"], abs=0.11
    )
    # the switch: one marker at the event's time, outside the band, at the torso pitch the body logged then
    at = series[band + "at"][switching]
    assert len(at.times) == 1 and len(events[switching].times) == 1
    assert at.times[0] == pytest.approx(events[switching].times[0])
    assert not low.values[0] < at.values[0] < high.values[0]
    pitch = series["body/torso/pitch"][switching]
    assert at.values[0] == pytest.approx(np.interp(at.times[0], pitch.times, pitch.values), abs=2.0)
    layout = layout_of(load(switch_run / "scenario.yaml"))
    assert layout == {"body": "humanoid", "learning": False}
    assert {"/body/torso/pitch", f"/{band}band_low", "/controller/events/**"} <= contents(
        blueprint(**layout).root_container
    )


def test_the_sensed_slope_and_each_ankles_centre_are_drawn_beside_the_torso_pitch(switch_run):
    """Issue 29: with the ankle adaptation on (chapter 5's setting), every logged walk has each foot's sensed slope and
    each ankle's centre shift on sim_time (deg), from its start to its end, in the humanoid layout's terrain panel."""
    names = [f"controller/terrain/{kind}_{foot}" for kind in ("slope", "ankle_centre") for foot in "lr"]
    series = read_series(switch_run / "recording.rrd", names + ["body/torso/pitch"])
    for row in trial_rows(switch_run):
        pitch = series["body/torso/pitch"][row["trial"]]
        for name in names:
            trace = series[name][row["trial"]]
            assert trace.times[0] == pytest.approx(pitch.times[0], abs=0.05)
            assert trace.times[-1] == pytest.approx(pitch.times[-1], abs=0.05)
            assert np.all(np.abs(trace.values) < 5.0)  # deg: 1 m of flat ground, then the ramp's first steps
    shown = contents(blueprint(**layout_of(load(switch_run / "scenario.yaml"))).root_container)
    assert {f"/{name}" for name in names} | {"/controller/terrain/switch"} <= shown
