"""The Gymnasium door (sfl_brain/gym.py, docs/gymnasium.md): both environments pass Gymnasium's own ``check_env`` on
the real planar reflex walker (pymunk) and the trial environment on the humanoid (PyBullet); the same seed gives the
same observations; an episode is the trial ``protocols.local`` runs for the same point and seed; bad input is refused
naming what is wrong; the page's Python runs and prints what the page shows."""

from __future__ import annotations

import contextlib
import io
import json
import re
import subprocess
import sys
import warnings

import gymnasium as gym
import numpy as np
import pytest
from gymnasium.utils.env_checker import check_env

import sfl_brain.gym as sfl_gym
from sfl_brain.events import Events
from sfl_brain.messages import NonFiniteError
from sfl_brain.protocols import Conductor
from sfl_brain.protocols.local import LocalModules
from sfl_brain.scenario import ScenarioError, load
from sfl_brain.signals import SENSOR_SLACK

from ..conftest import ROOT, SCENARIOS

WALKER = SCENARIOS / "e3_2_flat_s0.yaml"  # the planar reflex walker of chapter 3, learning (alpha_hip, theta_hip_max)
HUMANOID = SCENARIOS / "e5_learn.yaml"  # the humanoid of chapter 5 on its CPG, (gain_pitch, gain_roll, sigma_s)
PAGE = ROOT / "docs" / "gymnasium.md"
#: check_env's advice for an action space that is not [-1, 1] or [0, 1]: the Tick door's is the body's own units
NORMALISE = "we recommend using a symmetric and normalized space"


def checked(env_id: str, scenario) -> list[str]:
    """Run check_env on a fresh environment; return the warnings it gave."""
    env = gym.make(env_id, scenario=str(scenario)).unwrapped
    with warnings.catch_warnings(record=True) as seen:
        warnings.simplefilter("always")
        check_env(env)
    env.close()
    return [str(w.message) for w in seen]


@pytest.mark.parametrize("env_id", [sfl_gym.TRIAL_ID, sfl_gym.TICK_ID])
def test_both_doors_pass_check_env_on_the_planar_reflex_walker(env_id):
    said = checked(env_id, WALKER)
    if env_id == sfl_gym.TICK_ID:  # motor voltages in V, [-12, 12]: the advice to rescale, and nothing else
        assert len(said) == 1 and NORMALISE in said[0]
    else:
        assert said == []


def test_both_doors_pass_check_env_on_the_humanoid():
    """The trial door runs four humanoid trials (about 2.5 s on 2 cores); the tick door a few ticks."""
    assert checked(sfl_gym.TRIAL_ID, HUMANOID) == []
    said = checked(sfl_gym.TICK_ID, HUMANOID)  # joint position targets in rad: the advice to rescale, nothing else
    assert len(said) == 1 and NORMALISE in said[0]


@pytest.mark.parametrize("scenario", [WALKER, HUMANOID], ids=["walker", "humanoid"])
def test_normalized_doors_pass_check_env_without_a_word(scenario):
    """``normalize=True``: actions in [-1, 1], float32 everywhere, the observations within their box: Gymnasium's
    checker says nothing, and the spaces are what stable-baselines3's checker asks for (a symmetric [-1, 1] float32
    action box; docs/gymnasium.md shows its check_env passing too)."""
    for env_id in (sfl_gym.TRIAL_ID, sfl_gym.TICK_ID):
        env = gym.make(env_id, scenario=str(scenario), normalize=True).unwrapped
        with warnings.catch_warnings(record=True) as seen:
            warnings.simplefilter("always")
            check_env(env)
        assert [str(w.message) for w in seen] == [], env_id
        box = env.action_space
        assert box.dtype == np.float32 and np.all(box.low == -1.0) and np.all(box.high == 1.0), env_id
        assert env.observation_space.dtype == np.float32
        env.close()


def test_the_spaces_are_the_scenarios_and_the_bodys_signals():
    trial = sfl_gym.TrialEnv(WALKER)
    assert trial.action_space == gym.spaces.Box(0.0, 1.0, (2,), np.float32)
    assert trial.observation_space == gym.spaces.Box(0.0, 1.0, (3,), np.float32)
    tick = sfl_gym.TickEnv(WALKER)
    assert [s.name for s in tick.commands] == ["v_hip_l", "v_hip_r", "v_knee_l", "v_knee_r"]
    assert np.all(tick.action_space.low == -12.0) and np.all(tick.action_space.high == 12.0)
    knee_l = tick.sensors[2]
    assert knee_l.name == "knee_l" and knee_l.unit == "rad"
    slack = SENSOR_SLACK * (knee_l.high - knee_l.low)
    assert tick.observation_space.low[2] == np.float32(knee_l.low - slack)
    assert tick.observation_space.high[2] == np.float32(knee_l.high + slack)
    observation, info = tick.reset(seed=0)
    assert observation.dtype == np.float32 and np.array_equal(observation, tick.body.sense().astype(np.float32))
    assert info["params"]["body"] == {"slope_deg": 0.0}
    assert info["params"]["controller"] == {"alpha_hip": 10.0, "theta_hip_max_deg": 120.0}  # the space's centre
    trial.close()
    tick.close()


def local_trials(scenario, seed: int, points) -> list:
    """(request, result) of trials 0, 1, ... at ``points`` as a run with ``seed`` builds and runs them in one
    process: the request from ``Conductor.trial_request``, the result from ``LocalModules`` (through the codec)."""
    plan = load(scenario, seed=seed)
    modules = LocalModules(plan)
    conductor = Conductor(plan, modules, Events(), ROOT)
    out = []
    for trial_id, unit in enumerate(points):
        request = conductor.trial_request(trial_id, np.asarray(unit), log=False)
        ((_, result),) = modules.wait_any([modules.submit(plan.bodies[0], request, 30.0)])
        out.append((request, result))
    return out


def test_an_episode_is_the_trial_sfl_brain_local_runs_for_the_same_point_and_seed():
    points = [[0.5, 0.5], [0.9, 0.9], [0.2, 0.2]]  # a success, a shuffle that stays up, a fall
    expected = local_trials(WALKER, 11, points)
    assert [r.success for _, r in expected] == [True, False, False] and expected[2][1].metrics["fell"]
    env = gym.make(sfl_gym.TRIAL_ID, scenario=str(WALKER))
    env.reset(seed=11)
    for k, (unit, (request, result)) in enumerate(zip(points, expected, strict=True)):
        if k:
            env.reset()  # the next trial of the same run
        observation, reward, terminated, truncated, info = env.step(np.array(unit))
        assert reward == (result.quality if result.success else 0.0)
        assert (terminated, truncated) == (True, False)
        assert np.array_equal(observation, np.array([float(result.success), *unit], dtype=np.float32))
        assert info["trial_id"] == request.trial_id == k and info["trial_seed"] == request.seed
        assert info["success"] == result.success and info["eta"] == result.quality
        assert info["metrics"] == result.metrics
        assert info["params"] == {"controller": request.controller_params, "body": request.body_params}
    assert expected[0][1].quality > 0  # eta of the success: the reward
    env.close()


def test_the_same_seed_gives_the_same_observations():
    def tick_episode(seed: int) -> tuple[list[np.ndarray], list[float], dict]:
        env = gym.make(sfl_gym.TICK_ID, scenario=str(WALKER))
        observation, _ = env.reset(seed=seed)
        env.action_space.seed(seed)
        observations, rewards = [observation], []
        for _ in range(60):
            observation, reward, terminated, truncated, info = env.step(env.action_space.sample())
            observations.append(observation)
            rewards.append(reward)
            if terminated or truncated:
                break
        env.close()
        return observations, rewards, info

    first, again = tick_episode(4), tick_episode(4)
    assert len(first[0]) > 10 and all(np.array_equal(a, b) for a, b in zip(first[0], again[0], strict=True))
    assert first[1] == again[1] and first[2] == again[2]
    # the trial door: the same seed, the same trials in the same order, after any number of other episodes
    env = sfl_gym.TrialEnv(WALKER)
    rng = np.random.default_rng(0)
    points = rng.random((3, 2))

    def run(seed):
        runs = []
        for k, unit in enumerate(points):
            env.reset(seed=seed if k == 0 else None)
            observation, reward, _, _, info = env.step(unit)
            runs.append((observation, reward, info["trial_seed"]))
        return runs

    first = run(5)
    env.reset()
    env.step(rng.random(2))  # something else in between
    again = run(5)
    assert [(o.tolist(), r, s) for o, r, s in first] == [(o.tolist(), r, s) for o, r, s in again]
    assert [s for _, _, s in run(6)] != [s for _, _, s in first]  # another run: other trial seeds
    env.close()


@pytest.mark.parametrize("scenario", [WALKER, HUMANOID], ids=["walker", "humanoid"])
def test_an_episode_depends_on_its_seed_alone_not_on_the_episodes_before(scenario):
    """Whole first observations and trajectories of both doors: a fresh environment and one that ran other episodes
    first (to their end, and cut short) give the same episode for the same seed. The humanoid's first frame used to
    report the last episode's motor torques."""
    rng = np.random.default_rng(0)

    def tick_episode(env, seed, actions):
        first, _ = env.reset(seed=seed)
        return [first] + [env.step(a)[0] for a in actions]

    fresh = sfl_gym.TickEnv(scenario)
    actions = rng.uniform(fresh.action_space.low, fresh.action_space.high, (25, fresh.action_space.shape[0]))
    expected = tick_episode(fresh, 7, actions)
    used = sfl_gym.TickEnv(scenario)
    used.reset(seed=1)
    for a in rng.uniform(used.action_space.low, used.action_space.high, (60, used.action_space.shape[0])):
        if used.step(a)[2]:
            break
    used.reset(seed=2)
    used.step(actions[0])  # an episode cut short
    got = tick_episode(used, 7, actions)
    assert all(np.array_equal(a, b) for a, b in zip(expected, got, strict=True))
    fresh.close()
    used.close()
    points = rng.random((2, fresh.plan.dim))
    trials = sfl_gym.TrialEnv(scenario)
    trials.reset(seed=3)
    trials.step(points[0])
    trials.reset(seed=9)
    observation, reward, _, _, info = trials.step(points[1])
    again = sfl_gym.TrialEnv(scenario)
    again.reset(seed=9)
    same = again.step(points[1])
    assert np.array_equal(same[0], observation) and same[1] == reward and same[4]["metrics"] == info["metrics"]
    trials.close()
    again.close()


def test_the_humanoids_start_depends_on_the_seed_and_on_nothing_else():
    """The humanoid draws its start pose from the trial seed (``start_noise``): the same seed gives the same first
    observation, another seed another."""
    env = sfl_gym.TickEnv(HUMANOID)
    first, _ = env.reset(seed=1)
    other, _ = env.reset(seed=2)
    again, _ = env.reset(seed=1)
    assert np.array_equal(first, again) and not np.array_equal(first, other)
    env.close()


def test_a_tick_episodes_return_is_the_distance_walked_plus_the_success_bonus():
    env = sfl_gym.TickEnv(WALKER, success_bonus=2.0)
    env.reset(seed=0)
    env.action_space.seed(0)
    total, ended = 0.0, False
    while not ended:
        _, reward, terminated, truncated, info = env.step(env.action_space.sample())
        total += reward
        ended = terminated or truncated
    # seeded random voltages: the walker neither falls nor walks, and runs out of time
    assert truncated and not terminated and info["time"] == pytest.approx(env.body.params.duration)
    assert not info["metrics"]["fell"] and total == pytest.approx(info["metrics"]["distance"] + 2.0 * info["success"])
    with pytest.raises(RuntimeError, match=r"^TickEnv.step: the trial is over \(or not started\): call reset"):
        env.step(np.zeros(4))
    # a fall ends the trial before its time: terminated, not truncated
    env.reset()
    ticks = 0
    while True:
        _, _, terminated, truncated, info = env.step(np.array([12.0, -12.0, 12.0, -12.0]))
        ticks += 1
        if terminated or truncated:
            break
    assert terminated and not truncated and info["metrics"]["fell"] and ticks < 1000
    env.close()


def test_bad_input_is_refused_naming_what_is_wrong():
    with pytest.raises(ScenarioError, match=r"modules\.body\.params\.durration: unknown key.*did you mean `duration`"):
        sfl_gym.TrialEnv(WALKER, overrides=["modules.body.params.durration=5"])
    with pytest.raises(ScenarioError, match=r"protocl: unknown key.*did you mean `protocol`"):
        gym.make(sfl_gym.TICK_ID, scenario=str(WALKER), overrides=["protocl.trials=3"])
    with pytest.raises(TypeError, match=r"^TrialEnv: overrides: expected a list of 'KEY.PATH=VALUE' strings; got 's"):
        sfl_gym.TrialEnv(WALKER, overrides="seed=3")
    with pytest.raises(ValueError, match=r"^TrialEnv: seed: expected None or an integer in \[0, 2\*\*32\); got -1$"):
        sfl_gym.TrialEnv(WALKER, seed=-1)
    with pytest.raises(TypeError, match=r"^TrialEnv: scenario: expected the path of a scenario file; got None$"):
        sfl_gym.TrialEnv(None)
    env = sfl_gym.TrialEnv(WALKER)
    with pytest.raises(RuntimeError, match=r"^TrialEnv.step: no episode to step .*call reset\(\) first$"):
        env.step(np.full(2, 0.5))
    env.reset()
    for action, message in (
        ([0.5, np.nan], r"^TrialEnv.step: action\[1\] = nan: expected a finite number$"),
        ([np.inf, 0.5], r"^TrialEnv.step: action\[0\] = inf: expected a finite number$"),
        ([0.5, 0.5, 0.5], r"^TrialEnv.step: action: expected shape \(2,\); got shape \(3,\)$"),
        ([[0.5, 0.5]], r"^TrialEnv.step: action: expected shape \(2,\); got shape \(1, 2\)$"),
        (["fast", 0.5], r"^TrialEnv.step: action: expected 2 numbers; got \['fast', 0.5\]$"),
        ([0.5, 1.2], r"^TrialEnv.step: action\[1\] = 1.2: expected a number in \[0, 1\] \(clip it: np.clip"),
    ):
        with pytest.raises(ValueError, match=message):
            env.step(action)
    env.step([0.5, 0.5])  # the episode is still there after refused actions
    with pytest.raises(RuntimeError, match="no episode to step"):
        env.step([0.5, 0.5])  # one trial per episode
    with pytest.raises(ValueError, match=r"^TrialEnv.reset: options: expected none"):
        env.reset(options={"params": [0.5, 0.5]})
    with pytest.raises(ValueError, match=r"^TrialEnv.reset: seed: expected None or an integer in \[0, 2\*\*32\)"):
        env.reset(seed=2**32)
    env.close()
    tick = sfl_gym.TickEnv(WALKER)
    tick.reset()
    with pytest.raises(ValueError, match=r"^TickEnv.step: action\[2\] = nan: expected a finite number$"):
        tick.step([0.0, 0.0, np.nan, 0.0])
    with pytest.raises(ValueError, match=r"^TickEnv.step: action: expected shape \(4,\); got shape \(2,\)$"):
        tick.step([0.0, 0.0])
    with pytest.raises(ValueError, match=r"^TickEnv.reset: options\['params'\]\[0\] = -0.1: expected a number in"):
        tick.reset(options={"params": [-0.1, 0.5]})
    with pytest.raises(ValueError, match=r"^TickEnv.reset: options: expected only 'params'; got \['param'\]$"):
        tick.reset(options={"param": [0.1, 0.5]})
    tick.close()
    typo = sfl_gym.TickEnv(WALKER, progress_metric="distanse")
    with pytest.raises(ValueError, match=r"PlanarBiped reports no number 'distanse' \(did you mean `distance`\?\)"):
        typo.reset()
    with pytest.raises(ValueError, match=r"^TickEnv: body `body` \(AnalyticBody\) takes no commands.*sfl/Trial-v0"):
        sfl_gym.TickEnv(SCENARIOS / "analytic_learn.yaml")
    with pytest.raises(ValueError, match=r"^TrialEnv: .*analytic_conditions.yaml has no parameter space"):
        sfl_gym.TrialEnv(SCENARIOS / "analytic_conditions.yaml")
    with pytest.raises(ValueError, match=r"^TrialEnv: render_mode: expected None \(no render modes\); got 'human'$"):
        sfl_gym.TrialEnv(WALKER, render_mode="human")


@pytest.mark.parametrize("asynchronous", [False, True], ids=["sync", "async"])
def test_a_vector_of_trial_doors_runs_a_trial_in_every_env_on_every_step(asynchronous):
    """``gymnasium.make_vec`` takes Trial-v0's vector entry point (SAME_STEP autoreset): 3 steps of 2 envs are 6
    trials, each the trial a single env gives for its run seed (env i of reset(seed=s) runs the run seeded s + i),
    no step a reset that runs nothing. ``asynchronous=True``: each env in a process of its own, the same trials."""
    env = gym.make_vec(sfl_gym.TRIAL_ID, num_envs=2, scenario=str(WALKER), asynchronous=asynchronous)
    assert env.metadata["autoreset_mode"] == gym.vector.AutoresetMode.SAME_STEP
    points = np.array([[[0.5, 0.5], [0.9, 0.9]], [[0.2, 0.2], [0.5, 0.5]], [[0.6, 0.4], [0.3, 0.7]]])
    env.reset(seed=11)
    ran = []
    for step in points:
        _, reward, terminated, truncated, info = env.step(step.astype(np.float32))
        assert terminated.all() and not truncated.any()
        final = info["final_info"]
        ran.append((final["trial_id"].tolist(), final["success"].tolist(), reward.tolist()))
    env.close()
    assert [ids for ids, _, _ in ran] == [[0, 0], [1, 1], [2, 2]]  # a trial per env per step
    for i in range(2):
        alone = sfl_gym.TrialEnv(WALKER)
        for k, step in enumerate(points):
            alone.reset(seed=11 + i if k == 0 else None)
            _, reward, _, _, info = alone.step(step[i].astype(np.float32))
            assert (info["success"], reward) == (ran[k][1][i], ran[k][2][i])
        alone.close()
    assert any(r > 0 for _, _, rewards in ran for r in rewards)


def test_normalized_actions_and_observations_are_the_bodys_scaled():
    """normalize=True is a linear map of the same episode: -1 is each command's low, 1 its high; each observation is
    2 (x - low) / (high - low) - 1 of the sensor's declared range."""
    plain, scaled = sfl_gym.TickEnv(WALKER), sfl_gym.TickEnv(WALKER, normalize=True)
    low = np.array([c.low for c in plain.commands])
    high = np.array([c.high for c in plain.commands])
    sensor_low = np.array([c.low for c in plain.sensors])
    sensor_high = np.array([c.high for c in plain.sensors])
    first, _ = plain.reset(seed=0)
    unit_first, _ = scaled.reset(seed=0)
    rng = np.random.default_rng(1)
    for a in rng.uniform(-1.0, 1.0, (30, 4)):
        x, r, *_ = plain.step(low + (a + 1.0) / 2.0 * (high - low))
        y, q, *_ = scaled.step(a)
        sensed = plain.body.sense()
        expected = (
            2.0 * (np.clip(sensed, plain._sensor_low, plain._sensor_high) - sensor_low) / (sensor_high - sensor_low)
            - 1.0
        )
        assert np.allclose(y, expected.astype(np.float32), atol=1e-6) and r == pytest.approx(q, abs=1e-12)
    assert np.all(np.abs(y) <= 1.0 + 2.0 * SENSOR_SLACK)
    plain.close()
    scaled.close()


def test_a_closed_environment_says_so():
    for env in (gym.make(sfl_gym.TICK_ID, scenario=str(WALKER)), gym.make(sfl_gym.TRIAL_ID, scenario=str(WALKER))):
        env.reset(seed=0)
        env.close()
        name = type(env.unwrapped).__name__
        with pytest.raises(RuntimeError, match=rf"^{name}.step: the environment is closed; make a new one$"):
            env.step(env.action_space.sample())
        with pytest.raises(RuntimeError, match=rf"^{name}.reset: the environment is closed; make a new one$"):
            env.reset()
        env.close()  # again: nothing


def test_a_non_finite_sensor_value_stops_the_episode_naming_the_sensor(monkeypatch):
    env = sfl_gym.TickEnv(WALKER)
    env.reset()
    sense = env.body.sense
    monkeypatch.setattr(env.body, "sense", lambda: np.where(np.arange(8) == 3, np.nan, sense()))
    with pytest.raises(NonFiniteError, match=r"knee_r"):
        env.step(np.zeros(4))
    env.close()


def test_the_core_imports_no_gymnasium_and_the_door_says_how_to_get_it():
    def python(code: str) -> subprocess.CompletedProcess:
        return subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, cwd=ROOT, timeout=120)

    core = python(
        "import json, sys, sfl_brain, sfl_brain.protocols.local, sfl_brain.scenario, sfl_brain.body\n"
        "print(json.dumps(sorted(m for m in sys.modules if m.startswith('gymnasium'))))"
    )
    assert core.returncode == 0, core.stderr
    assert json.loads(core.stdout) == []
    missing = python("import sys; sys.modules['gymnasium'] = None\nimport sfl_brain.gym")
    assert missing.returncode == 1
    assert "ImportError: sfl_brain.gym needs Gymnasium: pip install 'sfl-brain[gym]' (gymnasium>=1.0)" in missing.stderr
    # `module:id` imports the door: no import of ours needed
    made = python(
        "import gymnasium as gym\n"
        f"env = gym.make('sfl_brain.gym:sfl/Trial-v0', scenario={str(WALKER)!r})\n"
        "print(type(env.unwrapped).__name__, env.spec.id)"
    )
    assert made.returncode == 0, made.stderr
    assert made.stdout.split() == ["TrialEnv", "sfl/Trial-v0"]


def test_registering_again_changes_nothing():
    spec = gym.spec(sfl_gym.TRIAL_ID)
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        sfl_gym.register_envs()
    assert gym.spec(sfl_gym.TRIAL_ID) is spec and gym.spec(sfl_gym.TICK_ID).entry_point == "sfl_brain.gym:TickEnv"


@pytest.mark.parametrize("index", [0, 1])
def test_the_pages_python_runs_and_prints_what_the_page_shows(index, monkeypatch):
    marked = r"<!-- run by tests/doors/test_gymnasium.py -->\n```python\n(.*?)```\n\n```text\n(.*?)```"
    runs = re.findall(marked, PAGE.read_text(), re.S)
    assert len(runs) == 2, "the page marks two blocks to run, each followed by what it prints"
    code, shown = runs[index]
    monkeypatch.chdir(ROOT)  # the page runs them from the checkout's root
    printed = io.StringIO()
    with contextlib.redirect_stdout(printed):
        exec(compile(code, str(PAGE), "exec"), {})
    assert printed.getvalue() == shown
