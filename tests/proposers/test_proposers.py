"""The proposer seam (issue 22, part 1): every proposer through ask/tell, seeded, resumable, and in a real run."""

from __future__ import annotations

import functools

import numpy as np
import pytest

from sfl_brain import messages as m
from sfl_brain.proposers import PROPOSERS, Outcome, Proposer
from sfl_brain.protocols.local import run_local
from sfl_brain.recording.records import read_records
from sfl_brain.scenario import ScenarioError, load

from ..conftest import SCENARIOS, sfl

LEARN = SCENARIOS / "analytic_learn.yaml"
UNGATED = ["random", "cma", "tpe", "safe_bo"]


class OpenGate:
    """A gate that says go to everything and keeps what it was asked to record."""

    threshold = m.Threshold(s_vig=0.0, low=0.0, high=0.0)

    def __init__(self) -> None:
        self.recorded: list[tuple[np.ndarray, int | None, int]] = []

    def evaluate(self, candidates):
        n = len(candidates)
        return m.Evaluation(go=np.ones(n, dtype=bool), d_success=np.zeros(n), d_failure=np.zeros(n))

    def record(self, candidates, evaluation, tried, count):
        self.recorded.append((candidates.copy(), tried, count))

    def rejected(self, consecutive):
        raise AssertionError("only success-failure learning tells vigilance of its no-go decisions")


def disc(v: np.ndarray) -> Outcome:
    """The analytic body's landscape: success inside a disc, eta peaking at (0.6, 0.6)."""
    ok = bool(np.linalg.norm(v - 0.5) < 0.3)
    return Outcome(ok, float(1.0 - np.linalg.norm(v - 0.6)) if ok else None)


def make(kind: str, seed: int = 3, dim: int = 2, **params) -> Proposer:
    cls = PROPOSERS[kind]
    return cls(cls.Params(kind=kind, **params), dim, seed)


def drive(proposer: Proposer, n: int, gate=None) -> list[np.ndarray]:
    gate = gate or OpenGate()
    asked = []
    for _ in range(n):
        v = proposer.ask(gate)
        asked.append(v)
        proposer.tell(v, disc(v))
    return asked


@pytest.mark.parametrize("kind", UNGATED)
def test_a_proposer_is_seeded_stays_in_the_cube_and_records_each_point_it_tries(kind):
    gate = OpenGate()
    first = drive(make(kind), 25, gate)
    again = drive(make(kind), 25)
    other = drive(make(kind, seed=4), 25)
    assert all(np.array_equal(a, b) for a, b in zip(first, again, strict=True))
    assert not all(np.array_equal(a, b) for a, b in zip(first, other, strict=True))
    assert all(v.shape == (2,) and np.all((v >= 0) & (v <= 1)) for v in first)
    assert [(go, count) for _, go, count in gate.recorded] == [(0, 1)] * 25
    assert all(np.array_equal(c[0], v) for (c, _, _), v in zip(gate.recorded, first, strict=True))


@pytest.mark.parametrize("kind", UNGATED)
def test_a_restored_proposer_asks_what_the_uninterrupted_one_asks(kind, tmp_path):
    whole = make(kind)
    straight = drive(whole, 30)
    stopped = make(kind)
    drive(stopped, 17)  # mid-population for CMA-ES (population 6 in 2-D)
    stopped.checkpoint(tmp_path / "proposer.pkl")
    resumed = Proposer.restore(tmp_path / "proposer.pkl")
    rest = drive(resumed, 13)
    assert all(np.array_equal(a, b) for a, b in zip(straight[17:], rest, strict=True))


@pytest.mark.parametrize("kind", ["cma", "tpe", "safe_bo"])
def test_a_model_based_proposer_learns_the_landscape(kind):
    """After 60 trials the model-based proposers try the successful disc more often than its share of the
    square (28 %): the tell reached them."""
    asked = drive(make(kind, seed=1), 80)
    late = [disc(v).success for v in asked[40:]]
    assert np.mean(late) > 0.5, np.mean(late)


def test_safe_bo_with_failures_only_asks_away_from_them():
    """Every trial failed (a gated run told its vetoes as failures; baselines' gated safe_bo, planar seed 2, stopped
    with scikit-learn's "requires 2 or more distinct classes"): the next point is the draw least like a failure."""
    proposer = make("safe_bo", n_startup_trials=3)
    failed = [np.array([0.1, 0.1]), np.array([0.2, 0.15]), np.array([0.15, 0.3]), np.array([0.3, 0.2])]
    for v in failed:
        proposer.tell(v, Outcome(False, None))
    v = proposer.ask(OpenGate())
    assert min(np.linalg.norm(v - f) for f in failed) > 0.9, v  # the far corner of the unit square
    proposer.tell(v, Outcome(True, 0.5))  # then the classifier has both outcomes and the models take over
    assert proposer.ask(OpenGate()).shape == (2,)


def test_cma_es_starts_again_when_it_stops():
    proposer = make("cma", popsize=4, sigma0=0.05)
    for _ in range(400):
        v = proposer.ask(OpenGate())
        proposer.tell(v, Outcome(True, 1.0))  # a flat landscape: the strategy stops on no change in f
    assert proposer.restarts >= 1


def stable(rows):
    return [{k: v for k, v in r.items() if k not in ("wall_ms", "cpu_body_s", "cpu_controller_s")} for r in rows]


@functools.cache
def rows_of(kind: str, trials: int = 40) -> list[dict]:
    plan = load(LEARN, [f"protocol.trials={trials}", f"protocol.proposer.kind={kind}"])
    return run_local(plan)


@pytest.mark.parametrize("kind", ["sfl", *UNGATED])
def test_every_proposer_gives_the_same_records_in_a_real_run(kind):
    """The analytic body's learn run, every module real, in one process: the same columns whichever proposer
    chose, and one decision per trial without the gate (the same seed gives the same records: the tests above, and
    over processes below)."""
    rows = rows_of(kind)
    trials = [r for r in rows if r["kind"] == "trial"]
    decisions = [r for r in rows if r["kind"] == "decision"]
    assert len(trials) == 40
    reference = rows_of("sfl") if kind != "sfl" else rows
    assert set(trials[0]) == {k for k in [r for r in reference if r["kind"] == "trial"][0]}
    assert {r["kind"] for r in rows} == {"trial", "decision"}
    if kind != "sfl":  # one decision per trial, the gate's real one (3.3), whatever it said the point was tried
        assert len(decisions) == 40 and [d["trial"] for d in decisions] == list(range(40))
        assert [d["go"] for d in decisions] == [d["d_failure"] - d["d_success"] > d["s_vig"] for d in decisions]


def test_the_thesis_proposer_is_the_default_and_unchanged():
    plan = load(LEARN, ["protocol.trials=20"])
    assert plan.scenario.protocol.proposer.kind == "sfl"
    explicit = run_local(load(LEARN, ["protocol.trials=20", "protocol.proposer.kind=sfl"]))
    assert stable(run_local(plan)) == stable(explicit)


@pytest.mark.parametrize(
    ("setting", "path", "says"),
    [
        ("protocol.proposer.kind=cmaes", "protocol.proposer.kind", "did you mean `cma`"),
        ("protocol.proposer={kind: cma, sigma0: 2}", "protocol.proposer.sigma0", "less than or equal to 1"),
        ("protocol.proposer={kind: tpe, n_startup_trials: 0}", "protocol.proposer.n_startup_trials", ">= 1"),
        ("protocol.proposer={kind: safe_bo, seed: 1}", "protocol.proposer.seed", "unknown key"),
        (
            "protocol.proposer={kind: safe_bo, min_success_probability: 1.5}",
            "protocol.proposer.min_success_probability",
            "less than or equal to 1",
        ),
    ],
)
def test_bad_proposer_settings_are_one_clear_line(setting, path, says):
    with pytest.raises(ScenarioError) as err:
        load(LEARN, [setting])
    text = str(err.value)
    assert path in text
    assert says.replace(">= 1", "greater than or equal to 1") in text
    if setting.endswith("cmaes"):  # and the command says it in one line, exit 2
        done = sfl("check", str(LEARN), "--set", setting)
        assert done.returncode == 2 and "Traceback" not in done.stderr and path in done.stderr


def test_a_run_over_processes_checkpoints_its_proposer_and_matches_one_process(tmp_path):
    """``sfl run`` with CMA-ES over processes: completed, the same records as in one process from the same seed,
    and the checkpoint in the run folder is the proposer after the last trial (it continues from there)."""
    out = tmp_path / "run"
    sets = ["protocol.trials=12", "protocol.proposer.kind=cma"]
    done = sfl("run", str(LEARN), *(x for s in sets for x in ("--set", s)), "--out", str(out), "--quiet")
    assert done.returncode == 0, done.stderr
    assert stable(read_records(out)) == stable(run_local(load(LEARN, sets)))
    proposer = Proposer.restore(out / "proposer.pkl")
    assert proposer.params.kind == "cma" and proposer.es.countevals == 12
