"""The early warning as a safety layer for any optimiser (issue 33): ``protocol.proposer.gate: off | veto |
resample`` for CMA-ES, TPE and the safe optimiser, and the gate's real decision recorded for every proposer."""

from __future__ import annotations

import json
import math

import numpy as np
import pytest

from sfl_brain import messages as m
from sfl_brain.proposers import PROPOSERS, VETOED, Outcome, Proposer
from sfl_brain.protocols import trial_progress
from sfl_brain.protocols.local import run_local
from sfl_brain.recording.metrics import safe_learning
from sfl_brain.scenario import ScenarioError, load

from ..conftest import ROOT, SCENARIOS, sfl
from ..experiments.test_golden import differences
from ..golden import platform_now

LEARN = SCENARIOS / "analytic_learn.yaml"
GATED = ["cma", "tpe", "safe_bo"]
GATE_OFF = ROOT / "tests" / "proposers" / "gate_off"


class DiscGate:
    """A gate with a fixed go region, a disc of radius 0.25 around the centre of the square (d_s: the distance to
    the centre, d_f: the radius), that keeps what it was asked to record."""

    threshold = m.Threshold(s_vig=0.0, low=0.0, high=0.0)

    def __init__(self, radius: float = 0.25) -> None:
        self.radius = radius
        self.recorded: list[tuple[np.ndarray, np.ndarray, int | None]] = []  # (point, go, tried)

    def evaluate(self, candidates):
        d = np.linalg.norm(candidates - 0.5, axis=1)
        return m.Evaluation(d_success=d, d_failure=np.full(len(d), self.radius), go=self.radius - d > 0.0)

    def record(self, candidates, evaluation, tried, count):
        for i in range(count):
            self.recorded.append((candidates[i].copy(), bool(evaluation.go[i]), tried if tried == i else None))

    def rejected(self, consecutive):
        raise AssertionError("only success-failure learning tells vigilance of its no-go decisions")

    def tried(self) -> list[tuple[np.ndarray, bool]]:
        return [(v, go) for v, go, tried in self.recorded if tried is not None]


def landscape(v: np.ndarray) -> Outcome:
    """Success inside a disc of radius 0.35 (larger than the gate's), eta peaking at (0.6, 0.6); a failure got as
    far as it was near the disc."""
    d = float(np.linalg.norm(v - 0.5))
    if d < 0.35:
        return Outcome(True, float(1.0 - np.linalg.norm(v - 0.6)))
    return Outcome(False, None, progress=max(0.0, 1.0 - d))


def make(kind: str, seed: int = 3, **params) -> Proposer:
    cls = PROPOSERS[kind]
    return cls(cls.Params(kind=kind, **params), 2, seed)


def drive(proposer: Proposer, n: int, gate) -> list[np.ndarray]:
    asked = []
    for _ in range(n):
        v = proposer.ask(gate)
        asked.append(v)
        proposer.tell(v, landscape(v))
    return asked


#: (kind, mode) that keep to the go region: TPE's resample redraws from a model it has not told anything new, which
#: may keep its every draw in a no-go corner until the budget is spent (test_the_gate_gives_way_after_its_budget...)
KEEP_TO_GO = [("cma", "veto"), ("cma", "resample"), ("tpe", "veto"), ("safe_bo", "veto"), ("safe_bo", "resample")]


@pytest.mark.parametrize(("kind", "mode"), KEEP_TO_GO)
def test_a_gated_optimiser_never_tries_a_no_go_point(kind, mode):
    gate = DiscGate()
    asked = drive(make(kind, gate=mode, max_vetoes=100_000), 20, gate)
    tried = gate.tried()
    assert [v.tolist() for v, _ in tried] == [v.tolist() for v in asked]
    assert all(go for _, go in tried)
    assert any(not go for _, go, _ in gate.recorded), "the gate never said no-go: the test shows nothing"
    ungated = DiscGate()
    drive(make(kind), 20, ungated)
    assert not all(go for _, go in ungated.tried()), "without the gate the optimiser tries no-go points too"


@pytest.mark.parametrize("mode", ["veto", "resample"])
@pytest.mark.parametrize("kind", GATED)
def test_the_gate_gives_way_after_its_budget_of_vetoes(kind, mode):
    """A gate that says no-go to everything: max_vetoes no-go decisions per trial, then the next point is tried (a
    no-go that starts a trial), and the run goes on."""
    gate = DiscGate(radius=0.0)
    asked = drive(make(kind, gate=mode, max_vetoes=3), 5, gate)
    assert len(asked) == 5
    assert len(gate.recorded) == 5 * 4 and not any(go for _, go, _ in gate.recorded)
    assert [tried for _, _, tried in gate.recorded] == [None, None, None, 0] * 5


@pytest.mark.parametrize("failure_score", ["flat", "graded"])
@pytest.mark.parametrize("kind", GATED)
def test_a_vetoed_point_reaches_the_optimiser_as_the_worst_failure(kind, failure_score, monkeypatch):
    """The documented value: a vetoed point is a failure that was never tried, scored 0 (flat) or -1 (graded), as
    the library itself holds it."""
    worst = {"flat": 0.0, "graded": -1.0}[failure_score]
    assert VETOED.score(failure_score) == worst
    told: list[tuple[list[float], float]] = []
    if kind == "cma":
        import cma

        tell = cma.CMAEvolutionStrategy.tell

        def spy(es, solutions, values, *args, **kw):
            told.extend((list(x[:2]), -float(f)) for x, f in zip(solutions, values, strict=True))
            return tell(es, solutions, values, *args, **kw)

        monkeypatch.setattr(cma.CMAEvolutionStrategy, "tell", spy)
    gate = DiscGate()
    proposer = make(kind, gate="veto", failure_score=failure_score, max_vetoes=100_000)
    asked = drive(proposer, 24, gate)
    vetoed = [v.tolist() for v, go, _ in gate.recorded if not go]
    assert vetoed
    if kind == "tpe":
        told = [([t.params["u0"], t.params["u1"]], t.value) for t in proposer.study.trials]
    elif kind == "safe_bo":
        told = [(list(v), 0.0 if not ok else 1.0) for v, ok in zip(proposer.points, proposer.successes, strict=True)]
        worst = 0.0  # the classifier holds a vetoed point as a failure
    value = {tuple(x): f for x, f in told}
    assert all(value[tuple(v)] == worst for v in vetoed if tuple(v) in value)
    assert sum(tuple(v) in value for v in vetoed) >= len(vetoed) - 6  # CMA-ES: the last population may be untold
    tried = {tuple(v.tolist()) for v in asked}
    assert all(value[t] != worst or not landscape(np.array(t)).success for t in tried if t in value)


@pytest.mark.parametrize("kind", GATED)
def test_a_resampled_point_is_not_told(kind):
    gate = DiscGate()
    proposer = make(kind, gate="resample", max_vetoes=50)
    drive(proposer, 18, gate)
    assert sum(not go for _, go, _ in gate.recorded) > 0
    if kind == "cma":
        assert proposer.es.countevals == 18
    elif kind == "tpe":
        from optuna.trial import TrialState

        assert sum(t.state == TrialState.COMPLETE for t in proposer.study.trials) == 18
    else:
        assert len(proposer.points) == 18


@pytest.mark.parametrize("mode", ["veto", "resample"])
@pytest.mark.parametrize("kind", GATED)
def test_a_restored_gated_optimiser_asks_what_the_uninterrupted_one_asks(kind, mode, tmp_path):
    straight = drive(make(kind, gate=mode, max_vetoes=20), 20, DiscGate())
    stopped = make(kind, gate=mode, max_vetoes=20)
    drive(stopped, 13, DiscGate())  # mid-population for CMA-ES (6 in 2-D), past TPE's and safe_bo's 10 start-up trials
    stopped.checkpoint(tmp_path / "proposer.pkl")
    rest = drive(Proposer.restore(tmp_path / "proposer.pkl"), 7, DiscGate())
    assert [v.tolist() for v in straight[13:]] == [v.tolist() for v in rest]


def test_a_failure_is_graded_by_how_far_it_got():
    reach = (10.0, 1.5)  # duration s, finish line m

    def result(**metrics):
        return m.TrialResult(trial_id=0, success=False, quality=0.0, metrics=metrics, worker="w")

    assert trial_progress(result(time=2.5, distance=0.75), reach) == pytest.approx(0.375)
    assert trial_progress(result(time=10.0, distance=-0.2), reach) == pytest.approx(0.5)  # stayed up, went back
    assert trial_progress(result(time=12.0, distance=9.0), reach) == 1.0
    assert trial_progress(result(time=5.0), (10.0, None)) == 0.5
    assert trial_progress(result(steps=3), reach) is None
    fell_at_once, nearly = Outcome(False, None, progress=0.0), Outcome(False, None, progress=0.9)
    assert fell_at_once.score("graded") == -1.0 and nearly.score("graded") == pytest.approx(-0.1)
    assert fell_at_once.score() == nearly.score() == 0.0  # flat: today's score
    assert Outcome(True, 0.01).score("graded") == 0.01 > nearly.score("graded")


# --------------------------------------------------------------------------- real runs, one process
@pytest.mark.parametrize(("kind", "mode"), [("cma", "veto"), ("tpe", "veto"), ("safe_bo", "resample")])
def test_in_a_real_run_every_trial_of_a_gated_optimiser_is_a_go(kind, mode):
    """The analytic body with the real ACC and vigilance: each trial's decision row is a go, the no-go decisions
    are recorded without a trial, and the same proposer without the gate tries points the gate says no-go to."""
    sets = ["protocol.trials=30", f"protocol.proposer={{kind: {kind}, gate: {mode}, max_vetoes: 100000}}"]
    rows = run_local(load(LEARN, sets))
    decisions = [r for r in rows if r["kind"] == "decision"]
    tried = [d for d in decisions if d["trial"] is not None]
    assert [d["trial"] for d in tried] == list(range(30)) and all(d["go"] for d in tried)
    assert any(not d["go"] for d in decisions)
    assert all(d["go"] == (d["d_failure"] - d["d_success"] > d["s_vig"]) for d in decisions)
    assert safe_learning(rows)["no_go_trials"] == 0
    ungated = run_local(load(LEARN, ["protocol.trials=30", f"protocol.proposer.kind={kind}"]))
    assert safe_learning(ungated)["no_go_trials"] > 0


def snapshot(kind: str) -> list[dict]:
    return [json.loads(line) for line in (GATE_OFF / f"{kind}.jsonl").read_text().splitlines()]


def same_platform() -> bool:
    import importlib.metadata as md

    about = json.loads((GATE_OFF / "platform.json").read_text())
    here = {**platform_now(), "libraries": {d: md.version(d) for d in about["libraries"]}}
    return all(about[k] == here[k] for k in ("numeric_platform", "versions", "libraries"))


@pytest.mark.parametrize("kind", ["random", "cma", "tpe", "safe_bo"])
def test_gate_off_gives_the_records_of_the_optimisers_before_the_gate(kind):
    """``gate: off`` (the default; written out here) asks the very points the code before issue 33 asked and gives
    its records (``tests/proposers/gate_off``, written by that code), bit for bit on the platform that wrote them, but
    for one documented change: a decision row's ``go`` is now the gate's real decision (d_f - d_s > s_vig), where it was
    always true."""
    proposer = (
        f"protocol.proposer.kind={kind}" if kind == "random" else f"protocol.proposer={{kind: {kind}, gate: off}}"
    )
    rows = [
        # the clocks, and sim_s: the snapshots were written before trial rows had it
        {k: v for k, v in r.items() if k not in ("wall_ms", "worker", "cpu_body_s", "cpu_controller_s", "sim_s")}
        for r in run_local(load(LEARN, ["protocol.trials=30", proposer]))
    ]
    before = snapshot(kind)
    assert all(r["go"] for r in before if r["kind"] == "decision")
    said = [r["go"] for r in rows if r["kind"] == "decision"]
    assert said == [r["d_failure"] - r["d_success"] > r["s_vig"] for r in before if r["kind"] == "decision"]
    assert not all(said), "every point was a go: the test shows nothing"
    for row in rows:
        row.pop("go", None)
    for row in before:
        row.pop("go", None)
    if same_platform():
        assert [json.dumps(r, sort_keys=True) for r in rows] == [json.dumps(r, sort_keys=True) for r in before]
    else:
        assert len(rows) == len(before)
        assert [d for g, w in zip(rows, before, strict=True) for d in differences(g, w)] == []


# --------------------------------------------------------------------------- the scenario's checks
@pytest.mark.parametrize(
    ("setting", "path", "says"),
    [
        ("protocol.proposer={kind: cma, gate: vetto}", "protocol.proposer.gate", "did you mean `veto`"),
        ("protocol.proposer={kind: tpe, gate: true}", "protocol.proposer.gate", "'off', 'veto' or 'resample'"),
        ("protocol.proposer={kind: safe_bo, max_vetoes: -1}", "protocol.proposer.max_vetoes", "greater than or equal"),
        ("protocol.proposer={kind: cma, failure_score: gradd}", "protocol.proposer.failure_score", "`graded`"),
        ("protocol.proposer={kind: random, gate: veto}", "protocol.proposer.gate", "unknown key"),
        ("protocol.proposer={kind: sfl, gate: veto}", "protocol.proposer.gate", "unknown key"),
    ],
)
def test_bad_gate_settings_are_one_clear_line(setting, path, says):
    with pytest.raises(ScenarioError) as err:
        load(LEARN, [setting])
    assert path in str(err.value) and says in str(err.value), str(err.value)


def test_gate_off_is_the_word_or_yaml_s_false_and_a_bad_gate_exits_2():
    assert load(LEARN, ["protocol.proposer={kind: cma, gate: off}"]).scenario.protocol.proposer.gate == "off"
    assert load(LEARN, ["protocol.proposer={kind: cma, gate: 'off'}"]).scenario.protocol.proposer.gate == "off"
    done = sfl("check", str(LEARN), "--set", "protocol.proposer={kind: cma, gate: resampel}")
    assert done.returncode == 2 and "Traceback" not in done.stderr
    assert "protocol.proposer.gate" in done.stderr and "did you mean `resample`" in done.stderr
    assert str(LEARN.name) in done.stderr


def test_every_finite_score_is_below_a_success():
    for progress in (0.0, 0.3, 1.0, None):
        assert Outcome(False, None, progress=progress).score("graded") <= 0.0 < Outcome(True, 1e-9).score("graded")
    assert math.isclose(VETOED.score("graded"), -1.0)
