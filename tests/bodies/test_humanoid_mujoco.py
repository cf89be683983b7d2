"""The humanoid on MuJoCo (issue 31): the MJCF is the table, the body is the PyBullet body's contract (the same signals,
start, conformance), stands, walks on the CPG unchanged, gives the same trial for the same request, and runs under
``sfl run`` with ``physics: mujoco`` with the same records over processes as in one process."""

from __future__ import annotations

import json
import subprocess
import sys

import numpy as np
import pytest
from rerun.chunk import RrdReader

mujoco = pytest.importorskip("mujoco", reason="the mujoco extra (in the test extra: pip install -e '.[test]')")

from sfl_brain.bodies.humanoid import COMMANDS, SENSORS, Humanoid, link_inertial  # noqa: E402
from sfl_brain.bodies.humanoid_mjcf import TREE_ORDER, world_mjcf  # noqa: E402
from sfl_brain.bodies.humanoid_mujoco import HumanoidMujoco, import_mujoco  # noqa: E402
from sfl_brain.bodies.humanoid_table import JOINTS, LEG_LENGTH, LINKS, PARTS, TOTAL_MASS  # noqa: E402
from sfl_brain.body import InProcessLink  # noqa: E402
from sfl_brain.conformance import check_module  # noqa: E402
from sfl_brain.messages import TrialRequest  # noqa: E402
from sfl_brain.modules.controllers.cpg import CPGController, CPGParams  # noqa: E402
from sfl_brain.protocols.local import run_local  # noqa: E402
from sfl_brain.recording.records import read_records  # noqa: E402
from sfl_brain.scenario import load  # noqa: E402

from ..conftest import ROOT, SCENARIOS, sfl_run  # noqa: E402
from .test_humanoid import INDEX, WEIGHT, Hold, run  # noqa: E402

WALL = ("wall_ms", "cpu_body_s", "cpu_controller_s")  # the trial rows' clocks

MUJOCO = "modules.body.params.physics=mujoco"


def test_the_mjcf_is_the_table():
    """Every link's mass, centre of mass and inertia tensor, every joint's axis and limits, the clutches' effort, the
    total mass and the leg's length, read back from the compiled model."""
    model = mujoco.MjModel.from_xml_string(world_mjcf([((0, 0, -0.1), (1, 1, 0.1), (0, 0, 0, 1))], 0.0025))
    data = mujoco.MjData(model)
    mujoco.mj_kinematics(model, data)  # all joints at 0: legs straight
    robot = [model.body(link).id for link in LINKS]
    assert model.body_mass[robot].sum() == pytest.approx(TOTAL_MASS, abs=1e-12)
    for link, body in zip(LINKS, robot, strict=True):
        mass, com, inertia = link_inertial(link)
        assert model.body_mass[body] == pytest.approx(mass, abs=1e-12), link
        np.testing.assert_allclose(model.body_ipos[body], com, atol=1e-12, err_msg=link)
        turn = np.zeros(9)
        mujoco.mju_quat2Mat(turn, model.body_iquat[body])  # MuJoCo keeps the principal axes and moments
        turn = turn.reshape(3, 3)
        np.testing.assert_allclose(turn @ np.diag(model.body_inertia[body]) @ turn.T, inertia, atol=1e-9, err_msg=link)
    for j in JOINTS:
        joint = model.joint(j.name)
        assert tuple(joint.range) == (j.lower, j.upper) and model.jnt_limited[joint.id], j.name
        assert tuple(joint.axis) == j.axis and model.body(model.jnt_bodyid[joint.id]).name == j.child, j.name
        # the clutch at its effort until the first step
        assert model.tendon_frictionloss[model.tendon(j.name).id] == j.effort
    assert sorted(TREE_ORDER) == sorted(j.name for j in JOINTS)
    assert sum(model.geom_bodyid[g] in robot for g in range(model.ngeom)) == sum(p.collides for p in PARTS)
    for side in "lr":
        hip = data.xpos[model.body(f"hip_{side}").id]
        sole = model.geom(f"{side.upper()}sole")
        bottom = data.geom_xpos[sole.id][2] - sole.size[2]
        assert hip[2] - bottom == pytest.approx(LEG_LENGTH, abs=1e-9)


def test_the_same_signals_and_start_as_the_pybullet_body():
    """The same sensor and command signals (so the CPG circuit wires unchanged) and, at t = 0, the same sensor values
    from the same standing start (measured: within 1e-8)."""
    assert HumanoidMujoco.SENSORS == SENSORS and HumanoidMujoco.COMMANDS == COMMANDS
    assert HumanoidMujoco.TRIAL_PARAMS == Humanoid.TRIAL_PARAMS
    CPGController.wire(SENSORS, COMMANDS, params=CPGParams(circuit="humanoid_nao"))
    request = TrialRequest(trial_id=0, seed=3, body_params={}, controller_params={}, log=False)
    values = []
    for physics in ("pybullet", "mujoco"):
        body = Humanoid(Humanoid.Params(physics=physics, start_noise=0.02))
        body.start_trial(request)
        values.append(body.sense())
        assert body.start_height == pytest.approx(0.403, abs=5e-4)
        body.close()
    assert isinstance(Humanoid(Humanoid.Params(physics="mujoco")), HumanoidMujoco)
    np.testing.assert_allclose(values[1], values[0], atol=1e-6)


def test_it_conforms():
    check_module(HumanoidMujoco)


def test_standing_holds_and_the_feet_carry_the_weight():
    body = Humanoid(Humanoid.Params(physics="mujoco", duration=3.0))
    body.link = InProcessLink(Hold())
    result = run(body)
    values = body.sense()
    body.close()
    assert not result.metrics["fell"] and abs(result.metrics["distance"]) < 0.01
    feet = sum(values[INDEX[name]] for name in ("heel_l", "toe_l", "heel_r", "toe_r"))
    assert feet == pytest.approx(WEIGHT, rel=0.02)  # measured 50.97 N of 50.97
    assert abs(values[INDEX["torso_pitch"]]) < 0.1
    assert result.metrics["energy"] < 3.0  # holding the crouch (measured 2.0 J over 3 s; PyBullet 2.2 J)


def test_the_cpg_gait_walks():
    """The default CPG gait (humanoid_nao.yaml, unchanged) walks 1.5 m from two perturbed starts (over 10 starts per
    alpha_MLR over processes: docs/bodies/humanoid.md, "Two engines")."""
    body = Humanoid(Humanoid.Params(physics="mujoco", duration=20.0, start_noise=0.02))
    body.link = InProcessLink(CPGController(CPGParams(circuit="humanoid_nao")))
    results = [run(body, seed=seed, trial_id=seed) for seed in (0, 1)]
    body.close()
    for result in results:
        m = result.metrics
        assert result.success and not m["fell"] and 10.0 < m["time"] < 16.0 and abs(m["lateral"]) < 0.3, m
        assert result.quality == pytest.approx(0.5 * TOTAL_MASS * (1.5 / m["time"]) ** 2 / m["energy"])
    assert results[0].metrics != results[1].metrics  # the seeds perturbed the starts


def test_the_same_request_gives_the_same_trial_whatever_ran_before():
    """A trial run after others, after a world with a ball, and in a fresh body, and a ball trial after one with
    another ball: the same metrics bit for bit."""
    params = Humanoid.Params(physics="mujoco", duration=2.0, start_noise=0.02)
    body = Humanoid(params)
    body.link = InProcessLink(CPGController(CPGParams(circuit="humanoid_nao")))
    first = run(body, seed=0, trial_id=0)
    run(body, seed=1, trial_id=1)
    throw = {"ball_mass": 0.5, "ball_speed": 3.0, "ball_time": 0.5}
    ball = run(body, body_params=throw, seed=7, trial_id=2)
    assert ball.metrics["ball_impulse"] > 0  # the ball hit the robot
    run(body, body_params={**throw, "ball_mass": 2.0}, seed=7, trial_id=3)  # a heavier ball in the same world
    assert run(body, body_params=throw, seed=7, trial_id=4).metrics == ball.metrics
    again = run(body, seed=0, trial_id=5)
    body.close()
    fresh = Humanoid(params)
    fresh.link = InProcessLink(CPGController(CPGParams(circuit="humanoid_nao")))
    assert again.metrics == run(fresh, seed=0, trial_id=0).metrics == first.metrics
    fresh.close()


def test_a_missing_mujoco_is_a_clear_error_naming_the_extra_and_the_core_never_imports_it():
    check = ["check", str(SCENARIOS / "humanoid_walk.yaml"), "--set", MUJOCO]
    absent = "import sys; sys.modules['mujoco'] = None; "  # as if mujoco were not installed
    code = absent + f"sys.argv = ['sfl', *{check!r}]; from sfl_brain.cli import main; main()"
    done = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, cwd=ROOT, timeout=120)
    assert done.returncode == 2  # sfl check refuses the scenario, as if mujoco were not installed
    assert (
        "humanoid_walk.yaml: modules.body.params.physics: physics: mujoco needs MuJoCo, an optional extra of "
        "sfl-brain: pip install -e '.[mujoco]'"
    ) in done.stderr
    code = (
        "import sys, sfl_brain.cli, sfl_brain.bodies.humanoid, sfl_brain.bodies.humanoid_mujoco; "
        "print('mujoco' in sys.modules)"
    )
    done = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, cwd=ROOT, timeout=120)
    assert done.stdout.strip() == "False", done.stderr
    with pytest.raises(ImportError, match=r"pip install -e '\.\[mujoco\]'"):
        sys.modules["mujoco"], saved = None, sys.modules["mujoco"]
        try:
            import_mujoco()
        finally:
            sys.modules["mujoco"] = saved


def test_sfl_run_with_physics_mujoco_records_and_matches_one_process(tmp_path):
    """scenarios/humanoid_walk.yaml with ``physics: mujoco`` and 3-s trials, over processes: completed, the recording
    holds the robot's boxes, and the records are the ones the same scenario gives in one process."""
    sets = [MUJOCO, "modules.body.params.duration=3.0"]
    out = tmp_path / "run"
    done = sfl_run(SCENARIOS / "humanoid_walk.yaml", out, *sets)
    assert done.returncode == 0, done.stderr
    summary = json.loads((out / "summary.json").read_text())
    assert summary["status"] == "completed" and summary["trials"] == 3
    rows = read_records(out)
    trials = [r for r in rows if r["kind"] == "trial"]
    assert all(r["m_timed_out"] and r["m_distance"] > 0.1 for r in trials), trials  # walking when the time ran out
    boxes = 0
    for chunk in RrdReader(out / "recording.rrd").stream().to_chunks():
        if str(chunk.entity_path) == "/body/robot" and not chunk.is_static:
            boxes += chunk.num_rows
    assert boxes >= 3 * 25 * 3  # 25 pictures per simulated second, 3 s per trial
    local = run_local(load(SCENARIOS / "humanoid_walk.yaml", sets))
    stable = [{k: v for k, v in r.items() if k not in WALL} for r in rows]
    assert [{k: v for k, v in r.items() if k not in WALL} for r in local] == stable
