"""Equation-level tests of the brain modules, hosted in-process."""

import math

import numpy as np
import pytest
from pydantic import ValidationError

from sfl_brain import messages as m
from sfl_brain.modules.acc import ACC
from sfl_brain.modules.ofc import OFC
from sfl_brain.modules.som import SelfOrganisingMap, SOMParams
from sfl_brain.modules.vigilance import Vigilance


def som(seed=0, **kw):
    return SelfOrganisingMap(SOMParams(**kw), 2, np.random.default_rng(seed))


def test_same_seed_same_weights_and_grid_shapes():
    np.testing.assert_array_equal(som(3).weights, som(3).weights)
    assert not np.array_equal(som(3).weights, som(4).weights)
    cube = SelfOrganisingMap(SOMParams(shape=(5, 5, 5)), 3, np.random.default_rng(0))
    assert cube.weights.shape == (125, 3) and cube.grid.max(axis=0).tolist() == [4, 4, 4]
    assert np.all((cube.weights >= 0) & (cube.weights <= 1))


def test_quantisation_error_falls_and_changes_converge():
    rng = np.random.default_rng(1)
    data = rng.random((400, 2)) * 0.1 + 0.45  # a small patch of the unit square
    s = som(0)
    before = s.nearest(data).mean()
    changes = [s.update(v) for v in data]
    assert s.nearest(data).mean() < before / 2
    assert np.mean(changes[-50:]) < np.mean(changes[:50]) / 10  # convergence (§3.3.3)


@pytest.mark.parametrize("neighbourhood, power", [("gaussian", 2), ("thesis", 1)])
def test_update_follows_equations_2_10_2_11_and_5_1(neighbourhood, power):
    s = som(0, shape=(3, 3), learning_rate=0.4, radius=1.5, decay=1e9, neighbourhood=neighbourhood)
    w0 = s.weights.copy()
    v = np.array([0.5, 0.5])
    winner = s.winner(v)
    s.update(v, rho=2.0)
    grid_distance = np.linalg.norm(s.grid - s.grid[winner], axis=1)
    h = np.exp(-(grid_distance**power) / (2 * 1.5**2))  # (2.11): Gaussian, or as printed (no square)
    np.testing.assert_allclose(s.weights, w0 + 0.4 * 2.0 * h[:, None] * (v - w0))
    assert s.wins[winner] == 1 and s.samples == 1
    assert s.learning_rate() == pytest.approx(0.4)


def test_learning_rate_and_radius_decay_with_samples_of_this_map():
    s = som(0, learning_rate=0.4, learning_rate_min=0.02, decay=10)
    for _ in range(10):
        s.update(np.array([0.1, 0.1]))
    assert s.learning_rate() == pytest.approx(0.4 * math.exp(-1))
    assert s.radius() == pytest.approx(5.0 * math.exp(-1))


def test_acc_distances_and_early_warning_3_1_to_3_3():
    acc = ACC(ACC.Params(shape=(2, 2), dim=2), seed=0)
    acc.success_map.weights[:] = [[0.1, 0.1]] * 4
    acc.failure_map.weights[:] = [[0.9, 0.9]] * 4
    v = np.array([[0.1, 0.2], [0.9, 0.8]])
    reply = acc.handle(m.Evaluate(candidates=v, s_vig=0.0))
    np.testing.assert_allclose(reply.d_success, np.linalg.norm(v - 0.1, axis=1))
    np.testing.assert_allclose(reply.d_failure, np.linalg.norm(v - 0.9, axis=1))
    assert reply.go.tolist() == [True, False]
    # the thesis's own example: s_vig 0.1, d_s 0.3, d_f 0.35 -> no-go
    assert ACC.early_warning(np.array([0.3]), np.array([0.35]), 0.1).tolist() == [True]
    assert ACC.early_warning(np.array([0.3]), np.array([0.35]), 0.04).tolist() == [False]


def test_acc_learns_into_the_right_map_and_checkpoints(tmp_path):
    acc = ACC(ACC.Params(shape=(3, 3), dim=2), seed=1)
    before_f = acc.failure_map.weights.copy()
    acc.handle(m.Learn(v=np.array([0.2, 0.2]), success=True, rho=2.5))
    np.testing.assert_array_equal(acc.failure_map.weights, before_f)
    assert acc.success_map.samples == 1
    acc.handle(m.Finish(path=str(tmp_path / "maps.npz"), prune=False))
    restored = ACC(ACC.Params(shape=(3, 3), dim=2, restore=str(tmp_path / "maps.npz")), seed=99)
    np.testing.assert_array_equal(restored.success_map.weights, acc.success_map.weights)


def test_failure_neurons_that_never_won_in_the_success_zone_are_pruned():
    acc = ACC(ACC.Params(shape=(1, 3), dim=2), seed=0)
    acc.success_map.weights[:] = [[0.2, 0.2], [0.25, 0.2], [0.3, 0.2]]
    acc.failure_map.weights[:] = [[0.9, 0.9], [0.22, 0.21], [0.85, 0.9]]
    acc.failure_map.wins[:] = [5, 0, 0]
    removed = acc.prune_failure_map()
    assert removed.tolist() == [1]  # neuron 2 never won but sits in the failure zone: kept
    d_f = acc.failure_map.nearest(np.array([[0.22, 0.21]]))
    assert d_f[0] > 0.5  # the pruned neuron no longer takes part in evaluation


def test_exploit_picks_success_neuron_closest_on_the_condition_axis():
    acc = ACC(ACC.Params(shape=(1, 3), dim=3), seed=0)
    acc.success_map.weights[:] = [[0.1, 0.2, 0.0], [0.4, 0.5, 0.5], [0.7, 0.8, 1.0]]
    table = acc.handle(m.Exploit(axis=2, conditions=np.array([0.1, 0.6, 0.9])))
    np.testing.assert_array_equal(table.weights[:, 0], [0.1, 0.4, 0.7])


def test_vigilance_fixed_stays_fixed():
    v = Vigilance(Vigilance.Params(mode="fixed", value=0.05), seed=0)
    assert v.handle(m.VigilanceStart()).s_vig == 0.05
    assert v.handle(m.TrialDone(trial_index=1, success=True, n_success=1, n_failure=0)).s_vig == 0.05
    assert v.handle(m.Rejected(consecutive=1000)).s_vig == 0.05


def test_vigilance_band_4_14():
    v = Vigilance(Vigilance.Params(mode="scheduled", dim=2), seed=0)
    low, high = v.band(0)
    assert low == pytest.approx(0.9 - 0.15 * math.log(400))
    assert high == pytest.approx(1.47 - 0.15 * math.log(400))
    for x in (1, 50, 200):
        t = v.handle(m.TrialDone(trial_index=x, success=True, n_success=x, n_failure=0))
        y1, y2 = v.band(x)
        assert t.low == pytest.approx(y1) and t.high == pytest.approx(y2) and y1 <= t.s_vig <= y2
    assert v.band(200)[1] < v.band(0)[0]  # cautious at first, adventurous later


def test_adaptive_vigilance_steps_and_clamps_at_diameter():
    v = Vigilance(Vigilance.Params(mode="adaptive", value=0.0, step=0.01, dim=2), seed=0)
    assert v.handle(m.TrialDone(trial_index=1, success=True, n_success=1, n_failure=0)).s_vig == pytest.approx(-0.01)
    assert v.handle(m.TrialDone(trial_index=2, success=False, n_success=1, n_failure=1)).s_vig == pytest.approx(-0.01)
    assert v.handle(m.TrialDone(trial_index=3, success=False, n_success=1, n_failure=2)).s_vig == pytest.approx(0.0)
    for k in range(400):
        last = v.handle(m.TrialDone(trial_index=4 + k, success=False, n_success=1, n_failure=3 + k))
    assert last.s_vig == pytest.approx(math.sqrt(2))  # clamped at +D
    for k in range(600):
        last = v.handle(m.TrialDone(trial_index=500 + k, success=True, n_success=1000 + k, n_failure=3))
    assert last.s_vig == pytest.approx(-math.sqrt(2))  # clamped at -D


def test_thousand_rejections_lower_adaptive_threshold_one_step():
    v = Vigilance(Vigilance.Params(mode="adaptive", value=0.3, dim=3), seed=0)
    assert v.handle(m.Rejected(consecutive=999)).s_vig == pytest.approx(0.3)
    assert v.handle(m.Rejected(consecutive=1000)).s_vig == pytest.approx(0.29)
    assert v.handle(m.Rejected(consecutive=2000)).s_vig == pytest.approx(0.28)


def test_qarl_5_2_first_success_gets_rho_max_then_linear_rescaling():
    ofc = OFC(seed=0)
    assert ofc.handle(m.Grade(eta=0.4)).rho == 2.5  # k = 0
    assert ofc.handle(m.Grade(eta=0.4)).rho == 2.5  # eta_max == eta_min: equally the best
    assert ofc.handle(m.Grade(eta=0.2)).rho == pytest.approx(0.1)  # the new worst
    reply = ofc.handle(m.Grade(eta=0.3))
    assert reply.rho == pytest.approx((2.5 - 0.1) / (0.4 - 0.2) * (0.3 - 0.2) + 0.1)
    assert (reply.eta_min, reply.eta_max) == (0.2, 0.4)
    assert ofc.handle(m.Grade(eta=0.8)).rho == pytest.approx(2.5)  # a new best


def test_qarl_switched_off_gives_rho_one():
    ofc = OFC(OFC.Params(enabled=False), seed=0)
    assert [ofc.handle(m.Grade(eta=e)).rho for e in (0.1, 0.9, 0.5)] == [1.0, 1.0, 1.0]


def test_ofc_params_are_validated():
    with pytest.raises(ValidationError, match="rho_min"):
        OFC.Params(rho_min=3.0, rho_max=2.5)
    with pytest.raises(ValueError, match="finite"):
        OFC(seed=0).reward(float("nan"))


@pytest.mark.parametrize("shape, dim", [((10, 10), 2), ((5, 5, 5), 3), ((4, 6), 2), ((7,), 1)])
def test_segments_join_exactly_the_grid_neighbours(shape, dim):
    s = SelfOrganisingMap(SOMParams(shape=shape), dim, np.random.default_rng(0))
    index = np.arange(s.size).reshape(shape)
    expected = []
    for axis, n in enumerate(shape):
        lo = np.take(index, range(n - 1), axis=axis).ravel()
        hi = np.take(index, range(1, n), axis=axis).ravel()
        expected += [np.stack([s.weights[i], s.weights[j]]) for i, j in zip(lo, hi, strict=True)]
    segments = s.segments()
    assert sorted(e.tobytes() for e in expected) == sorted(g.tobytes() for g in segments)
    stacked = s.segments(np.stack([s.weights, s.weights + 1.0]))  # snapshots, as ACC logs them
    np.testing.assert_array_equal(stacked[1], segments + 1.0)


def test_a_large_reward_never_carries_a_neuron_past_the_sample():
    """(5.1) with rho up to 2.5: gamma h rho is capped at 1 (CPG-HUMANOID.md §7.15): the winner lands on v at most."""
    som = SelfOrganisingMap(SOMParams(shape=(3, 3), learning_rate=1.0), dim=2, rng=np.random.default_rng(0))
    v = np.array([0.5, 0.5])
    winner = som.winner(v)
    before = som.weights.copy()
    som.update(v, rho=2.5)
    assert np.allclose(som.weights[winner], v)
    moved = np.linalg.norm(som.weights - before, axis=1)
    assert np.all(moved <= np.linalg.norm(v - before, axis=1) + 1e-12)  # no neuron overshoots
