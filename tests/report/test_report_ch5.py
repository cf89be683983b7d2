"""Chapter 5's report: the success region of E5.3 (sfl_brain/report/ch5.py)."""

import numpy as np
import pytest

from sfl_brain.report.ch5 import success_region


def maps(success_at, failure_at, success_wins=1, failure_wins=1, spread=0.0):
    """Two 2-neuron maps: neuron 0 at the given corner (with those wins), neuron 1 untrained in the cube's middle."""

    def one(at, wins):
        return np.array([at, [0.5 + spread] * 3], float), np.array([wins, 0]), np.array([True, True])

    sw, swins, sact = one(success_at, success_wins)
    fw, fwins, fact = one(failure_at, failure_wins)
    return {"success_weights": sw, "success_wins": swins, "success_active": sact,
            "failure_weights": fw, "failure_wins": fwins, "failure_active": fact}  # fmt: skip


def test_the_success_region_is_the_share_nearer_the_learnt_success_neurons():
    # a winning success neuron at the origin, a winning failure neuron at (1, 1, 1): half the cube each (the grid's
    # middle plane, equidistant, counts as failure)
    assert success_region(maps([0, 0, 0], [1, 1, 1])) == pytest.approx(0.5, abs=0.05)
    # the untrained neurons in the middle do not count, wherever they sit
    assert success_region(maps([0, 0, 0], [1, 1, 1], spread=0.4)) == pytest.approx(0.5, abs=0.05)


def test_no_success_is_no_region_and_no_failure_is_the_whole_cube():
    assert success_region(maps([0, 0, 0], [1, 1, 1], success_wins=0)) == 0.0
    assert success_region(maps([0, 0, 0], [1, 1, 1], failure_wins=0)) == 1.0
