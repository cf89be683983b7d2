"""Telemetry out of the physics, and a recording that explains itself (issue 14, parts 2 and 3).

Bodies, controllers and the ACC emit typed telemetry that a test captures without Rerun; the
runtime turns it into a recording whose default layout has something to show in every panel on
both the ``trial`` and the ``sim_time`` timeline.
"""

from __future__ import annotations

import fnmatch
import json
import math
import subprocess
import sys
import textwrap

import numpy as np
import pyarrow.parquet as pq
import pytest
import rerun.blueprint as rrb
from rerun.chunk import RrdReader

from sfl_brain.bodies.planar_biped import COMMANDS, SENSORS, SHANK, THIGH, PlanarBiped
from sfl_brain.body import InProcessLink
from sfl_brain.messages import Finish, Learn, TrialRequest
from sfl_brain.modules.acc import ACC
from sfl_brain.modules.controllers.reflex import ReflexController
from sfl_brain.recording.rrlog import RerunLog, blueprint
from sfl_brain.telemetry import FAILURE, SUCCESS, CaptureTelemetry, Event, MapSnapshots, Rates, Scalars, Strips2D

from ..conftest import SCENARIOS, sfl_run

DURATION = 2.0  # s of simulated time per trial: 200 control ticks of 10 ms


def logged_trial(rates: Rates | None = None, trial_id: int = 3, log: bool = True):
    """One walking trial of the planar walker and the reflex controller in this process, captured."""
    rates = rates or Rates()
    body = PlanarBiped(PlanarBiped.Params(duration=DURATION))
    controller = ReflexController()
    sink = CaptureTelemetry(rates=rates)
    body.telemetry = controller.telemetry = sink
    body.link = InProcessLink(controller)
    result = body.handle(
        TrialRequest(
            trial_id=trial_id,
            seed=0,
            body_params={"slope_deg": 0.0},
            controller_params={"alpha_hip": 10.0, "theta_hip_max_deg": 110.0},
            log=log,
        )
    )
    controller.flush_neurons()  # the controller sends a logged trial's neurons at the next reset or at close
    return sink, result


def test_a_logged_trial_is_typed_telemetry_in_physical_units_on_sim_time():
    sink, result = logged_trial()
    t0 = 3 * DURATION
    assert not result.metrics["fell"] and math.isclose(result.metrics["time"], DURATION)
    joints = {s.name: sink.at(f"joints/{s.name}") for s in SENSORS[:4]}
    for name, (item,) in joints.items():
        assert isinstance(item, Scalars) and item.unit == "deg" and item.trial == 3
        # 25 samples per simulated second: ticks 0, 4, 8, ..., the state after tick i at t0 + (i + 1) dt
        assert np.allclose(item.times, t0 + 0.01 + 0.04 * np.arange(50))
        low, high = next(np.degrees([s.low, s.high]) for s in SENSORS if s.name == name)
        # degrees, not radians: within the joint's stops (which pymunk's soft limits pass by a fraction of a degree)
        assert low - 1.0 <= item.values.min() and item.values.max() <= high + 1.0
    assert np.ptp(joints["hip_l"][0].values) > 10  # the hip swings: tens of degrees
    for s in COMMANDS:
        (motor,) = sink.at(f"motors/{s.name}")
        assert motor.unit == "V" and np.abs(motor.values).max() <= 12.0
    (contact,) = sink.at("contacts/left")
    assert set(np.unique(contact.values)) <= {0.0, 1.0}
    # the controller's neurons, on the same samples as the body's state
    for name in ReflexController.NEURONS:
        (neuron,) = sink.at(f"neurons/{name}")
        assert np.array_equal(neuron.times, joints["hip_l"][0].times) and neuron.trial == 3
        assert 0.0 <= neuron.values.min() and neuron.values.max() <= 1.0
    # the walker: 25 pictures per simulated second, three strips of three points (m, y up)
    (walker,) = sink.of(Strips2D)[:1]
    assert walker.path == "walker" and walker.per_frame == 3 and len(walker.times) == 50 and walker.follow
    strips = np.asarray(walker.strips)
    assert strips.shape == (150, 3, 2)
    trunk, left, right = strips[0::3], strips[1::3], strips[2::3]
    for leg in (left, right):  # hip -> knee -> foot: the links' real lengths (pymunk's pivots give by mm)
        assert np.allclose(np.linalg.norm(leg[:, 1] - leg[:, 0], axis=1), THIGH, atol=3e-3)
        assert np.allclose(np.linalg.norm(leg[:, 2] - leg[:, 1], axis=1), SHANK, atol=3e-3)
        assert (leg[:, 0, 1] > leg[:, 2, 1] + 0.15).all()  # the hip above the foot: y is up
    assert (trunk[:, 0, 1] > trunk[:, 1, 1]).all()  # the trunk's centre above the hip
    (ground,) = sink.at("ground")
    assert ground.times.tolist() == [t0] and len(ground.strips) == 1 and ground.strips[0].shape == (60, 2)
    assert np.allclose(ground.strips[0][:, 1], 0.0)  # flat ground
    # the trial's start and end, coloured by its outcome
    start, end = sink.at("trial/events")
    assert isinstance(start, Event) and (start.time, start.text, start.color) == (t0, "trial 3 starts", SUCCESS)
    assert math.isclose(end.time, t0 + DURATION) and end.text.startswith("trial 3: success after 2.00 s (distance")
    (marker,) = sink.at("trial/success")
    assert marker.points and marker.color == SUCCESS and np.allclose(marker.times, [t0, t0 + DURATION])
    assert marker.values.tolist() == [1.0, 1.0] and not sink.at("trial/failure")


def test_the_sink_sets_the_rates_and_an_unlogged_trial_shows_nothing():
    sink, _ = logged_trial(Rates(signals_hz=0, pictures_hz=10, neurons=False))
    assert len(sink.at("joints/hip_l")[0].times) == 200  # every control tick
    assert len(sink.at("walker")[0].times) == 20  # 10 pictures per simulated second
    assert not [p for p in sink.paths() if p.startswith("neurons/")]
    quiet, result = logged_trial(log=False)
    assert quiet.items == [] and result.success
    body = PlanarBiped(PlanarBiped.Params(duration=DURATION))
    body.link = InProcessLink(ReflexController())
    body.handle(TrialRequest(trial_id=0, seed=0, body_params={}, controller_params={}, log=True))
    assert body.telemetry is None and not body.logging and body._log is None  # no sink: nothing is kept


def test_a_failed_trial_is_marked_red_where_it_ended():
    body = PlanarBiped(PlanarBiped.Params(duration=DURATION))
    body.telemetry = sink = CaptureTelemetry()
    body.link = InProcessLink(ReflexController())
    result = body.handle(  # a hip extensor that hardly fires: it falls after half a second
        TrialRequest(
            trial_id=0,
            seed=0,
            body_params={"slope_deg": 0.0},
            controller_params={"alpha_hip": 0.5, "theta_hip_max_deg": 100.0},
            log=True,
        )
    )
    assert not result.success and result.metrics["fell"] and result.metrics["time"] < 1.0
    (marker,) = sink.at("trial/failure")
    assert marker.color == FAILURE and marker.values.tolist() == [0.0, 0.0]
    assert math.isclose(marker.times[1], result.metrics["time"]) and sink.at("trial/events")[1].level == "WARN"


def test_the_acc_emits_both_maps_after_every_trial_and_the_final_ones():
    acc = ACC(ACC.Params(shape=(3, 3), dim=2), seed=1)
    acc.telemetry = sink = CaptureTelemetry()
    rng = np.random.default_rng(0)
    for i in range(5):
        acc.handle(Learn(v=rng.random(2), success=i % 2 == 0, rho=1.0))
    acc.run_deferred()
    acc.handle(Finish(path="", prune=True))
    maps = sink.of(MapSnapshots)
    learning = [m for m in maps if not m.final]
    final = [m for m in maps if m.final]
    assert sorted(m.path for m in learning) == ["failure_map", "success_map"]
    for item in learning:
        assert item.trials.tolist() == [1, 2, 3, 4, 5]
        assert item.weights.shape == (5, 9, 2) and item.active.shape == (5, 9) and item.active.dtype == bool
        assert item.edges.shape == (5, 12, 2, 2)  # a 3 x 3 grid has 12 edges
    assert {m.path: m.trials.tolist() for m in final} == {"success_map": [5], "failure_map": [5]}
    success = next(m for m in final if m.path == "success_map")
    assert np.array_equal(success.weights[0], acc.success_map.weights) and success.color == SUCCESS
    failure = next(m for m in final if m.path == "failure_map")
    assert np.array_equal(failure.active[0], acc.failure_map.active)


def test_bodies_controllers_and_the_acc_need_no_viewer_library():
    script = textwrap.dedent(
        """
        import sys
        sys.modules["rerun"] = None  # any `import rerun` fails
        import numpy as np
        from sfl_brain.bodies.planar_biped import PlanarBiped
        from sfl_brain.body import InProcessLink
        from sfl_brain.messages import Finish, Learn, TrialRequest
        from sfl_brain.modules.acc import ACC
        from sfl_brain.modules.controllers.reflex import ReflexController
        from sfl_brain.telemetry import CaptureTelemetry

        sink = CaptureTelemetry()
        body = PlanarBiped(PlanarBiped.Params(duration=1.0))
        controller = ReflexController()
        body.telemetry = controller.telemetry = sink
        body.link = InProcessLink(controller)
        body.handle(TrialRequest(trial_id=0, seed=0, body_params={}, controller_params={}, log=True))
        controller.close()
        acc = ACC(ACC.Params(shape=(2, 2), dim=2))
        acc.telemetry = sink
        acc.handle(Learn(v=np.array([0.5, 0.5]), success=True, rho=1.0))
        acc.handle(Finish(path="", prune=False))
        print(len(sink.items), len(sink.paths()))
        """
    )
    done = subprocess.run([sys.executable, "-c", script], capture_output=True, text=True)
    assert done.returncode == 0, done.stderr
    items, paths = map(int, done.stdout.split())
    assert paths == 4 + 4 + 2 + 2 + 2 + len(ReflexController.NEURONS) + 2 and items > paths


def entity_timelines(path) -> dict[str, set[str]]:
    """Each entity's timelines with temporal data, and the archetypes it holds."""
    found: dict[str, set[str]] = {}
    for chunk in RrdReader(path).stream().to_chunks():
        kinds = {f.name.split(":")[0] for f in chunk.to_record_batch().schema if ":" in f.name}
        entry = found.setdefault(str(chunk.entity_path), set())
        entry |= {f"archetype:{k}" for k in kinds}
        if not chunk.is_static:
            entry |= set(chunk.timeline_names)
    return found


#: what a view needs to show something: an archetype it draws
DRAWS = {
    rrb.Spatial3DView: {"LineStrips3D", "Points3D", "Boxes3D", "Arrows3D"},
    rrb.TimeSeriesView: {"Scalars"},
    rrb.TextLogView: {"TextLog"},
}


def views(container):
    for part in container.contents:
        if isinstance(part, rrb.View):
            yield part
        else:
            yield from views(part)


@pytest.fixture(scope="module")
def quickstart_run(tmp_path_factory):
    out = tmp_path_factory.mktemp("recording") / "run"
    done = sfl_run(SCENARIOS / "quickstart.yaml", out, "protocol.trials=6")
    assert done.returncode == 0, done.stderr
    return out


def test_every_panel_of_the_default_layout_has_data_on_both_timelines(quickstart_run):
    entities = entity_timelines(quickstart_run / "recording.rrd")
    for view in views(blueprint().root_container):
        patterns = [p.removeprefix("/") for p in view.contents]
        shown = {
            path: kinds
            for path, kinds in entities.items()
            if any(fnmatch.fnmatch(path.removeprefix("/"), p.replace("/**", "*")) for p in patterns)
            and {f"archetype:{a}" for a in DRAWS[type(view)]} & kinds
        }
        for timeline in ("trial", "sim_time"):
            assert any(timeline in kinds for kinds in shown.values()), (view.name, timeline, sorted(shown))
    # the walker is drawn upright: its entity is in a y-up space, and so are the maps
    assert "archetype:ViewCoordinates" in entities["/body"] and "archetype:ViewCoordinates" in entities["/acc"]
    # the walker's view is seen from a frame that walks with it, on both timelines
    assert {"archetype:Transform3D", "trial", "sim_time"} <= entities["/body/follow"]


def test_the_recording_keeps_every_decision_and_trial_and_the_map_table(quickstart_run):
    summary = json.loads((quickstart_run / "summary.json").read_text())
    rows: dict[str, int] = {}
    for chunk in RrdReader(quickstart_run / "recording.rrd").stream().to_chunks():
        if not chunk.is_static:
            rows[str(chunk.entity_path)] = rows.get(str(chunk.entity_path), 0) + chunk.num_rows
    for series in ("d_success", "d_failure", "margin", "s_vig", "go"):
        assert rows[f"/decisions/{series}"] == summary["decisions"], series
    assert rows["/trials/success"] == rows["/trials/log"] == summary["trials"] == 6
    assert rows["/body/trial/events"] == 2 * 6  # every trial's body was recorded: start and end
    assert rows["/body/joints/hip_l"] == rows["/controller/neurons/motor/hip_EM_l"] <= 6 * 250
    maps = pq.read_table(quickstart_run / "maps.parquet").to_pylist()
    assert not (quickstart_run / "maps").exists()  # the parts were joined
    learning = [m for m in maps if not m["final"]]
    assert sorted({m["trial"] for m in learning}) == list(range(1, 7))
    assert len(learning) == 6 * 2 * 100 and len(maps) - len(learning) == 2 * 100  # 10 x 10 maps


def test_the_supervisor_places_a_no_go_decision_on_the_trial_it_was_drawn_for(tmp_path):
    log = RerunLog("r", str(tmp_path / "s.rrd"), None, ["x", "y"], trial_seconds=10.0)
    decision = {"s_vig": 0.0, "d_success": 0.1, "d_failure": 0.2, "v_unit": [0.5, 0.5]}
    log.decisions(
        [
            {**decision, "decision": 0, "trial": 0, "go": True},
            {**decision, "decision": 1, "trial": None, "go": False},  # drawn for trial 1
            {**decision, "decision": 2, "trial": 1, "go": True},
        ]
    )
    log.close()
    for chunk in RrdReader(tmp_path / "s.rrd").stream().to_chunks():
        if str(chunk.entity_path) == "/decisions/go":
            batch = chunk.to_record_batch()
            assert batch.column("trial").to_pylist() == [0, 1, 1]
            assert [t.total_seconds() for t in batch.column("sim_time").to_pylist()] == [0.0, 10.0, 10.0]
            break
    else:
        raise AssertionError("no /decisions/go in the recording")
