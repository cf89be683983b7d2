"""``sfl run --resume RUN_DIR``: an interrupted learn run goes on by replaying its recorded trials, and ends with
the records an uninterrupted run would have made."""

from __future__ import annotations

import json
import os
import signal
import subprocess
import tempfile
from pathlib import Path

from sfl_brain.protocols.local import run_local
from sfl_brain.scenario import load

from ..conftest import SCENARIOS, poll_until, sfl, sfl_run, start_sfl_run, trials_recorded

LEARN = SCENARIOS / "analytic_learn.yaml"
TRIALS = 40
STOP_AFTER = 15


def rows_without_wall(run_dir: Path) -> list[dict]:
    rows = [json.loads(line) for line in (run_dir / "records.jsonl").read_text().splitlines()]
    for row in rows:
        for clock in ("wall_ms", "cpu_body_s", "cpu_controller_s"):
            row.pop(clock, None)
    return rows


def stop_after(out: Path, trials: int, sets: tuple[str, ...], signum: int) -> subprocess.Popen:
    """Start a run and send ``signum`` to its process group once its records hold ``trials`` trials."""
    proc = start_sfl_run(LEARN, out, *sets, start_new_session=True)  # a Ctrl-C reaches its modules too
    poll_until(lambda: trials_recorded(out) >= trials, f"{trials} trials in {out}", 120, proc)
    os.killpg(proc.pid, signum)
    proc.communicate(timeout=60)
    return proc


def uninterrupted(sets: tuple[str, ...]) -> list[dict]:
    """The rows (without wall times) and summary of the same run uninterrupted, in one process (the records are
    the same as over processes: tests/runtime/test_e2e.py)."""
    with tempfile.TemporaryDirectory() as tmp:
        rows = run_local(load(LEARN, list(sets)), Path(tmp))
    for row in rows:
        for clock in ("wall_ms", "cpu_body_s", "cpu_controller_s"):
            row.pop(clock, None)
    return rows


def test_an_interrupted_learn_run_resumes_to_the_records_of_an_uninterrupted_one(tmp_path):
    """CMA-ES behind the gate (veto: the replay asks the gate again, and its vetoes are told again), Ctrl-C (the
    thesis's own proposer is resumed after a kill -9 below; CMA-ES without the gate asks as before the gate,
    tests/proposers/test_gate.py)."""
    sets = (f"protocol.trials={TRIALS}", "protocol.proposer={kind: cma, gate: veto}")
    whole = tmp_path / "whole"
    assert sfl_run(LEARN, whole, *sets).returncode == 0

    resumed = tmp_path / "resumed"
    proc = stop_after(resumed, STOP_AFTER, sets, signal.SIGINT)
    assert proc.returncode == 130
    stopped_at = json.loads((resumed / "summary.json").read_text())
    assert stopped_at["status"] == "interrupted"
    assert STOP_AFTER <= stopped_at["trials"] < TRIALS, "the run ended before it could be interrupted"

    done = sfl("run", "--resume", str(resumed), "--quiet")
    assert done.returncode == 0, done.stderr
    assert rows_without_wall(resumed) == rows_without_wall(whole)
    summary = json.loads((resumed / "summary.json").read_text())
    assert summary["status"] == "completed"
    assert summary["trials"] == TRIALS
    assert summary["resumed_from_trial"] == stopped_at["trials"]
    assert summary["run_id"] == stopped_at["run_id"]  # one recording id: the parts merge
    assert summary["previous_recordings"] == ["recording.part1.rrd"]
    assert (resumed / "recording.part1.rrd").exists() and (resumed / "recording.rrd").exists()
    first = json.loads((whole / "summary.json").read_text())
    for key in ("successes", "decisions", "no_go", "best", "safe_learning", "acc"):
        assert summary[key] == first[key], key


def test_a_run_killed_with_sigkill_resumes_from_its_whole_rows(tmp_path):
    """No summary, a torn last line, unmerged recording parts: the resumed run still ends as the whole run."""
    sets = (f"protocol.trials={TRIALS}",)
    killed = tmp_path / "killed"
    stop_after(killed, STOP_AFTER, sets, signal.SIGKILL)
    assert not (killed / "summary.json").exists()
    with open(killed / "records.jsonl", "a") as f:
        f.write('{"kind":"decision","decis')  # the row in flight when the run was killed

    done = sfl("run", "--resume", str(killed), "--quiet")
    assert done.returncode == 0, done.stderr
    assert rows_without_wall(killed) == uninterrupted(sets)
    summary = json.loads((killed / "summary.json").read_text())
    assert summary["status"] == "completed" and summary["trials"] == TRIALS
    assert not (killed / "rerun").exists(), "the killed run's parts were merged into recording.part1.rrd"
    assert summary["previous_recordings"] == ["recording.part1.rrd"]


def test_resuming_a_completed_run_or_a_sweep_is_bad_input_in_one_line(tmp_path):
    """What --resume refuses, on folders laid out as runs leave them (what is refused is read before anything
    starts: the folder's scenario.yaml, records.jsonl and summary.json)."""

    def folder(name: str, scenario: Path, status: str | None) -> Path:
        run_dir = tmp_path / name
        run_dir.mkdir()
        (run_dir / "scenario.yaml").write_text(scenario.read_text())
        (run_dir / "records.jsonl").write_text('{"kind":"trial","trial":0}\n')
        if status:
            (run_dir / "summary.json").write_text(json.dumps({"status": status}))
        return run_dir

    learnt = folder("learnt", LEARN, "completed")
    before = (learnt / "records.jsonl").read_bytes()
    done = sfl("run", "--resume", str(learnt), "--quiet")
    assert done.returncode == 2
    assert (
        done.stderr.strip()
        == f"sfl: --resume {learnt}: the run is completed, nothing to resume (only an unfinished learn run)"
    )
    assert (learnt / "records.jsonl").read_bytes() == before

    swept = folder("swept", SCENARIOS / "analytic_sweep.yaml", None)  # even unfinished: a sweep is run again
    done = sfl("run", "--resume", str(swept), "--quiet")
    assert done.returncode == 2
    assert "only a learn run can be resumed" in done.stderr and len(done.stderr.strip().splitlines()) == 1

    done = sfl("run", "--resume", str(tmp_path), "--quiet")
    assert done.returncode == 2
    assert done.stderr.strip() == f"sfl: --resume {tmp_path} is not a run folder (no scenario.yaml and records.jsonl)"

    done = sfl("run", str(LEARN), "--resume", str(learnt), "--quiet")
    assert done.returncode == 2
    assert done.stderr.strip() == "sfl: --resume runs the folder's own scenario.yaml; drop SCENARIO"


def test_a_replay_that_diverges_from_the_records_fails_naming_the_trial(tmp_path):
    run_dir = tmp_path / "run"
    assert sfl_run(LEARN, run_dir, "protocol.trials=10").returncode == 0
    (run_dir / "summary.json").unlink()  # as after a kill -9
    rows = [json.loads(line) for line in (run_dir / "records.jsonl").read_text().splitlines()]
    tampered = next(r for r in rows if r["kind"] == "trial" and r["trial"] == 3)
    tampered["v_unit"] = [0.5, 0.5]
    (run_dir / "records.jsonl").write_text("".join(json.dumps(r) + "\n" for r in rows))

    done = sfl("run", "--resume", str(run_dir), "--quiet")
    assert done.returncode == 1
    summary = json.loads((run_dir / "summary.json").read_text())
    assert summary["status"] == "failed"
    assert summary["stop_reason"].startswith("cannot resume: the replay diverged at trial 3: the proposer asked")
    assert summary["trials"] == 10, "the records are kept as they were"
