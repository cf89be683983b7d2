"""E4.2 (L1237-1260): the planar MLMP-CPG walks the 8-link walker for some patterns (sigma_s, sigma_f) and not for
others, so that learning them has both outcomes to learn from; and the learning scenario checks.

The two cells are from the grid of docs/results/chapter4/e4_2_grid.md, each inside a block of like cells: (2.5, 3.125)
walks and so do its four grid neighbours; (5, 2.5), a fast oscillator (period about 0.7 s), falls and so do its
neighbours (5, 1.88) and (5, 3.12). Since the PF reads tanh(V / A_f) (issue 23) it falls at 5.8 s, not at 1.2 s
as with the PF fed V, and its neighbour (4.38, 2.5) walks.
Controller and body run in one process with the scenario's own parameters.
"""

from __future__ import annotations

import yaml

from sfl_brain.bodies.planar_8link import PlanarWalker8
from sfl_brain.body import InProcessLink
from sfl_brain.messages import TrialRequest
from sfl_brain.modules.controllers.cpg import CPGController, CPGParams

from ..conftest import SCENARIOS, sfl

SCENARIO = SCENARIOS / "e4_2_learn.yaml"


def trial(sigma_s: float, sigma_f: float):
    """One 10-s trial with the controller and body parameters of scenarios/e4_2_learn.yaml."""
    modules = yaml.safe_load(SCENARIO.read_text())["modules"]
    body = PlanarWalker8(PlanarWalker8.Params(**modules["body"]["params"]))
    body.link = InProcessLink(CPGController(CPGParams(**modules["controller"]["params"])))
    request = TrialRequest(
        trial_id=0, seed=0, body_params={}, controller_params={"sigma_s": sigma_s, "sigma_f": sigma_f}, log=False
    )
    return body.handle(request)


def test_a_walking_pattern_walks_10_s_and_a_fast_one_falls():
    walked = trial(2.5, 3.125)
    assert walked.success  # no fall in the 10-s window and at least two steps (L1243)
    assert not walked.metrics["fell"] and walked.metrics["time"] >= 10.0 - 1e-9
    assert walked.metrics["steps"] >= 2
    assert walked.metrics["distance"] > 2.0  # forward, m: walking, not shuffling on the spot
    fell = trial(5.0, 2.5)
    assert not fell.success and fell.metrics["fell"] and fell.metrics["fell_at"] < 7.0  # 5.8 s (e4_2_grid.md)


def test_the_learning_scenario_checks():
    done = sfl("check", str(SCENARIO))
    assert done.returncode == 0, done.stdout + done.stderr
    assert "ok" in done.stdout
