"""The humanoid walking on its CPG (issue 16): the default gait of the humanoid circuit (modules/cpg/circuits/
humanoid_nao.yaml) walks the NAO-sized body 1.5 m on the flat from its standing start, in one process and as
``sfl run`` runs scenarios/humanoid_walk.yaml over real processes. Numbers: docs/results/chapter4/humanoid.md."""

from __future__ import annotations

import json

import numpy as np
import pytest
import yaml
from rerun.chunk import RrdReader

from sfl_brain.bodies.humanoid import JOINT_NAMES, Humanoid
from sfl_brain.bodies.humanoid_table import PARTS, STANDING, TOTAL_MASS
from sfl_brain.body import InProcessLink
from sfl_brain.messages import TrialRequest
from sfl_brain.modules.controllers.cpg import CPGController, CPGParams
from sfl_brain.recording.records import read_records

from ..conftest import SCENARIOS, sfl_run

SCENARIO = SCENARIOS / "humanoid_walk.yaml"


def scenario_modules() -> dict:
    return yaml.safe_load(SCENARIO.read_text())["modules"]


def test_the_default_gait_walks_the_15_m_from_perturbed_starts():
    """Three seeds, each its own joint offsets at the start (start_noise 0.02 rad): each reaches the line without a
    fall, near the middle of the lane (measured: 13.1-13.3 s, |y| <= 0.22 m over 12 seeds), with eta of (5.8) > 0."""
    modules = scenario_modules()
    body = Humanoid(Humanoid.Params(**modules["body"]["params"]))
    controller = CPGController(CPGParams(**modules["controller"]["params"]))
    body.link = InProcessLink(controller)
    times = []
    for seed in range(3):
        request = TrialRequest(trial_id=seed, seed=seed, body_params={}, controller_params={}, log=False)
        result = body.handle(request)
        m = result.metrics
        assert result.success and not m["fell"] and m["distance"] >= 1.5, (seed, m)
        assert 10.0 < m["time"] < 15.0 and abs(m["lateral"]) < 0.3, (seed, m)
        assert result.quality > 0
        assert result.quality == pytest.approx(0.5 * TOTAL_MASS * (1.5 / m["time"]) ** 2 / m["energy"])
        times.append(m["time"])
    body.close()
    assert len(set(times)) == 3  # the seeds perturbed the starts


def test_at_t0_the_cpg_commands_the_standing_pose():
    """theta0 makes up for what the reflexes command at rest (they are not symmetric about the standing angles): the
    first command is the body's standing pose, but for the ankle pitches, whose kick starts at t = 0 (10 ms of it
    moves them by 0.012 rad: the PF's slope at V = 0 is 8 / (5 x 5) = 0.32 per unit of V with the bounded input and PF
    alpha 8, times the gain 1.14; it was 0.009 rad on V, 1 / 5 = 0.2 per unit, times 1.29)."""
    body = Humanoid(Humanoid.Params(duration=0.01))
    body.link = InProcessLink(CPGController(CPGParams(**scenario_modules()["controller"]["params"])))
    commands = []
    original = body.actuate
    body.actuate = lambda command: (commands.append(np.array(command)), original(command))
    body.handle(TrialRequest(trial_id=0, seed=0, body_params={}, controller_params={}, log=False))
    body.close()
    standing = np.array([STANDING[name] for name in JOINT_NAMES])
    at_rest = [k for k, name in enumerate(JOINT_NAMES) if not name.startswith("ankle_pitch")]
    np.testing.assert_allclose(commands[0][at_rest], standing[at_rest], atol=1e-4)
    np.testing.assert_allclose(commands[0], standing, atol=0.015)


def test_sfl_run_walks_over_processes_and_records_success_eta_and_the_bodys_boxes(tmp_path):
    out = tmp_path / "run"
    done = sfl_run(SCENARIO, out)
    assert done.returncode == 0, done.stderr
    summary = json.loads((out / "summary.json").read_text())
    assert summary["status"] == "completed" and summary["trials"] == 3
    trials = [r for r in read_records(out) if r["kind"] == "trial"]
    assert [r["alpha_mlr"] for r in trials] == pytest.approx([0.9, 1.0, 1.1])
    for r in trials:
        assert r["success"] and r["quality"] > 0 and not r["m_fell"], r
        assert r["m_distance"] >= 1.5 and r["m_time"] < 20.0
    # a larger alpha_MLR, a larger amplitude: faster (measured 14.5, 13.2, 12.3 s)
    assert trials[0]["m_time"] > trials[1]["m_time"] > trials[2]["m_time"]
    # the recording: each trial's success and quality, and the humanoid's links as boxes, every picture all of them
    rows: dict[str, int] = {}
    boxes_per_picture = set()
    for chunk in RrdReader(out / "recording.rrd").stream().to_chunks():
        path = str(chunk.entity_path)
        if not chunk.is_static:
            rows[path] = rows.get(path, 0) + chunk.num_rows
        if path == "/body/robot":
            batch = chunk.to_record_batch()
            if "Boxes3D:centers" in batch.schema.names:
                boxes_per_picture |= {len(row) for row in batch.column("Boxes3D:centers").to_pylist()}
    assert rows["/trials/success"] == rows["/trials/quality"] == 3
    assert boxes_per_picture == {len(PARTS)}
    assert rows["/body/robot"] >= 3 * 25 * 11  # 25 pictures per simulated second, more than 11 s per trial
    assert rows["/body/trial/events"] == 2 * 3  # every trial's body was recorded: start and end
