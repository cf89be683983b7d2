"""A run says how it ended: status, stop reason and exit code (issue 13, part 1), and the run folder's
faults (part 5): an --out that holds a run or cannot be written, a full disk, damaged records, a
second Ctrl-C, and --viewer with no display."""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
from pathlib import Path

import psutil
import pytest

from sfl_brain.events import Progress
from sfl_brain.recording.records import RecordWriter, inspect_run, read_records
from sfl_brain.status import EnvironmentProblem

from ..conftest import ROOT, SCENARIOS, sfl, sfl_run, wait_for_trials

ANALYTIC = SCENARIOS / "analytic_learn.yaml"
STALLING = ("modules.vigilance.params.value=1.5", "protocol.max_decisions=2000")


def summary_of(run_dir) -> dict:
    return json.loads((run_dir / "summary.json").read_text())


def test_a_run_that_spends_its_budget_is_completed(tmp_path):
    out = tmp_path / "run"
    done = sfl_run(ANALYTIC, out, "protocol.trials=30")
    assert done.returncode == 0, done.stderr
    summary = summary_of(out)
    assert summary["status"] == "completed"
    assert summary["exit_code"] == 0
    assert summary["trials"] == summary["planned_trials"] == 30
    assert summary["stop_reason"] == "trial budget spent (30 trials)"
    assert "completed (exit code 0)" in done.stderr


def test_a_run_stopped_by_the_decision_cap_is_stalled_not_completed(tmp_path):
    out = tmp_path / "run"
    done = sfl_run(ANALYTIC, out, *STALLING)
    assert done.returncode == 3, done.stderr
    summary = summary_of(out)
    assert summary["status"] == "stalled"
    assert summary["exit_code"] == 3
    assert summary["trials"] < summary["planned_trials"]
    assert summary["stop_reason"].startswith("decision cap reached: 2000 decisions (protocol.max_decisions) gave 0")
    # the live warning came before the end, once (no progress bar with --quiet)
    assert done.stderr.count("stall likely") == 1
    # sfl inspect shows the status first
    shown = sfl("inspect", str(out))
    assert shown.returncode == 0
    first, second = shown.stdout.splitlines()[:2]
    assert first.split() == ["status:", "stalled"]
    assert second.strip().startswith("stop_reason: decision cap reached")


def test_a_long_run_of_no_go_decisions_is_stalled(tmp_path):
    out = tmp_path / "run"
    done = sfl_run(
        ANALYTIC, out, "modules.vigilance.params.value=1.5", "protocol.stall_decisions=500", "protocol.batch=16"
    )
    assert done.returncode == 3, done.stderr
    summary = summary_of(out)
    assert summary["status"] == "stalled"
    assert summary["stop_reason"].startswith("no progress: 500 decisions in a row without a trial")
    assert summary["decisions"] == 500


def test_stall_warning_is_computed_from_the_recent_no_go_ratio():
    p = Progress(planned=100, trials=10, decisions=900, max_decisions=2000, stall_decisions=10_000)
    p.recent_decisions_per_trial = 90.0
    assert p.stall_warning() == (
        "stall likely: 90 or more decisions per trial, lately and on average; the cap of 2000 decisions stops the run "
        "near trial 22 of 100"
    )
    p.recent_decisions_per_trial = 5.0
    assert p.stall_warning() is None
    burst = Progress(planned=100, trials=50, decisions=1000, max_decisions=20_000, stall_decisions=10_000)
    burst.recent_decisions_per_trial = 500.0  # 20 x the run's average of 20: a burst, not a stall
    assert burst.stall_warning() is None
    burst.decisions = 15_000  # the average (300 per trial) now predicts the cap too
    assert burst.stall_warning().startswith("stall likely: 300 or more decisions per trial")
    first = Progress(planned=200, trials=1, decisions=13_751, max_decisions=2_000_000, stall_decisions=100_000)
    first.recent_decisions_per_trial = 13_751.0  # E4.2 seed 1's first trial: the run then took 45,421 in all
    assert first.stall_warning() is None
    p.consecutive_nogo = 2500
    assert p.stall_warning().startswith("stall likely: 2500 no-go decisions in a row")
    assert Progress(planned=10, trials=3).stall_warning() is None  # protocols that cannot stall


def test_study_marks_a_stalled_run_and_leaves_it_out_of_the_means(tmp_path):
    out = tmp_path / "study"
    done = sfl(
        "study",
        str(ANALYTIC),
        "--vary",
        "modules.vigilance.params.value=0,1.5",
        "--set",
        "protocol.trials=20",
        "--set",
        "protocol.max_decisions=1500",
        "--out",
        str(out),
        "--quiet",
        "--jobs",
        "2",
    )
    assert done.returncode == 3, done.stderr
    assert "1 of 2 runs stalled, marked in the report and left out of its means: value1.5" in done.stderr
    report = (out / "report" / "README.md").read_text()
    assert "| value1.5 | **stalled** |" in report
    assert "| value0 | completed |" in report
    assert "Left out of the means above: 1 runs that did not complete:" in report
    assert "- value1.5 (s_vig 1.5): stalled, decision cap reached" in report
    stored = json.loads((out / "report" / "summary.json").read_text())
    assert {v["status"] for v in stored.values()} == {"completed", "stalled"}


def test_out_that_holds_a_run_is_bad_input_and_keeps_its_records(tmp_path):
    out = tmp_path / "run"
    assert sfl_run(ANALYTIC, out, "protocol.trials=5").returncode == 0
    before = (out / "records.jsonl").read_bytes()
    again = sfl_run(ANALYTIC, out, "protocol.trials=5")
    assert again.returncode == 2
    assert again.stderr.strip() == f"sfl: --out {out} already holds a run (records.jsonl); choose another folder"
    assert (out / "records.jsonl").read_bytes() == before


def test_out_that_cannot_be_written_is_an_environment_problem(tmp_path):
    blocker = tmp_path / "file"
    blocker.write_text("not a folder")
    done = sfl_run(ANALYTIC, blocker / "run", "protocol.trials=5")
    assert done.returncode == 4
    assert done.stderr.strip() == f"sfl: cannot write the run folder {blocker / 'run'}: Not a directory"
    assert "Traceback" not in done.stderr


def test_a_full_device_stops_the_writer_with_one_line():
    if not os.path.exists("/dev/full"):
        pytest.skip("no /dev/full here")
    writer = RecordWriter(Path("/dev/full"))
    with pytest.raises(EnvironmentProblem, match=r"cannot write /dev/full: No space left on device"):
        writer.write({"kind": "trial"})
    writer.close()


@pytest.fixture
def small_disk(tmp_path):
    """A 1 MiB tmpfs (needs root and mount rights; skipped elsewhere)."""
    mount = tmp_path / "disk"
    mount.mkdir()
    made = subprocess.run(["mount", "-t", "tmpfs", "-o", "size=1m", "tmpfs", str(mount)], capture_output=True)
    if made.returncode != 0:
        pytest.skip(f"cannot mount a small tmpfs here: {made.stderr.decode().strip()}")
    try:
        yield mount
    finally:
        subprocess.run(["umount", "-l", str(mount)], capture_output=True)


def test_a_full_disk_ends_the_run_failed_with_exit_code_4_and_whole_rows(small_disk):
    out = small_disk / "run"
    done = sfl_run(ANALYTIC, out, "protocol.trials=200", timeout=120)
    assert done.returncode == 4, done.stderr
    assert "Traceback" not in done.stderr
    assert "No space left on device" in done.stderr
    rows = read_records(out)
    assert rows and all(isinstance(r, dict) and "kind" in r for r in rows)


def test_inspect_reads_up_to_the_last_whole_row_of_damaged_records(tmp_path):
    out = tmp_path / "run"
    assert sfl_run(ANALYTIC, out, "protocol.trials=10").returncode == 0
    path = out / "records.jsonl"
    whole = read_records(out)
    with open(path, "ab") as f:
        f.write(b'{"kind":"trial","trial":99,"succ')  # torn by a kill
    shown = sfl("inspect", str(out), "--json")
    assert shown.returncode == 0, shown.stderr
    info = json.loads(shown.stdout)
    assert info["trials"] == 10 and info["status"] == "completed"
    assert info["records_damage"].startswith("records.jsonl line")
    assert "torn last row" in info["records_damage"]
    # bytes that are not UTF-8 in the middle: the rows before them are read, the rest not trusted
    lines = path.read_bytes().split(b"\n")
    lines[3] = b"\xff\xfe garbage"
    path.write_bytes(b"\n".join(lines))
    damage: list[str] = []
    assert read_records(out, damage) == whole[:3]
    assert damage[0].startswith("records.jsonl line 4: a damaged row")
    shown = sfl("inspect", str(out))
    assert shown.returncode == 0 and "Traceback" not in shown.stderr
    assert "records_damage: records.jsonl line 4" in shown.stdout
    assert inspect_run(out)["decisions"] + inspect_run(out)["trials"] == 3


def test_a_second_ctrl_c_still_leaves_a_summary_whole_records_and_a_merged_recording(tmp_path):
    out = tmp_path / "run"
    proc = subprocess.Popen(
        [sys.executable, "-m", "sfl_brain.cli", "run", str(SCENARIOS / "quickstart.yaml"), "--out", str(out)]
        + ["--quiet", "--set", "protocol.trials=1000"],
        cwd=ROOT,
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
    )
    try:
        wait_for_trials(out, 1, proc)
        children = psutil.Process(proc.pid).children(recursive=True)
        proc.send_signal(signal.SIGINT)
        # the first Ctrl-C is being handled once the module processes are stopped; the records,
        # the recording and the summary are written after that, and the second Ctrl-C lands there
        _, alive = psutil.wait_procs(children, timeout=30)
        assert not alive, f"the first Ctrl-C did not stop {alive}"
        proc.send_signal(signal.SIGINT)
        _, stderr = proc.communicate(timeout=60)
    finally:
        proc.kill()
    assert proc.returncode == 130, stderr
    assert "Traceback" not in stderr and "Aborted" not in stderr
    summary = summary_of(out)
    assert summary["status"] == "interrupted"
    assert summary["stop_reason"].endswith("; stopped at once by a second signal")  # it was handled as such
    assert summary["exit_code"] == 130
    assert summary["trials"] >= 1
    assert (out / "recording.rrd").exists()
    damage: list[str] = []
    rows = read_records(out, damage)
    assert rows and not damage


def test_viewer_without_a_display_fails_fast_with_a_hint(tmp_path):
    env = {k: v for k, v in os.environ.items() if k not in ("DISPLAY", "WAYLAND_DISPLAY")}
    done = sfl_run(ANALYTIC, tmp_path / "run", "protocol.trials=5", extra=("--viewer",), env=env, timeout=60)
    assert done.returncode == 4
    assert done.stderr.startswith("sfl: --viewer needs a display (DISPLAY / WAYLAND_DISPLAY is not set)")
    assert "--viewer-url" in done.stderr
    assert not (tmp_path / "run").exists()  # nothing started


def test_exit_codes_are_documented():
    text = sfl("--help").stdout
    assert "Exit codes: 0 completed, 1 failed, 2 bad input, 3 stalled, 4 environment" in " ".join(text.split())


def test_listen_on_a_port_in_use_is_an_environment_problem(tmp_path):
    import socket

    with socket.socket() as taken:
        taken.bind(("127.0.0.1", 0))
        taken.listen()
        port = taken.getsockname()[1]
        done = sfl_run(ANALYTIC, tmp_path / "run", "protocol.trials=5", extra=("--listen", f"tcp/127.0.0.1:{port}"))
    assert done.returncode == 4, done.stderr
    assert f"cannot listen on tcp/127.0.0.1:{port}: port in use" in done.stderr
    assert "Traceback" not in done.stderr


def test_a_relative_run_folder_keeps_its_maps(tmp_path):
    """The README's main job writes to runs/... relative to where it is started."""
    done = sfl("run", str(ANALYTIC), "--set", "protocol.trials=5", "--out", "runs/rel", "--quiet", cwd=tmp_path)
    assert done.returncode == 0, done.stderr
    assert (tmp_path / "runs" / "rel" / "acc.npz").exists()


def test_version_and_installed_names(tmp_path):
    """`sfl --version` names the installed version; the brain modules and bodies install under
    sfl_brain (no top-level `modules` / `bodies` of ours in site-packages)."""
    import sfl_brain

    done = subprocess.run(["sfl", "--version"], capture_output=True, text=True, timeout=60)
    assert done.returncode == 0 and done.stdout.strip() == f"sfl-brain {sfl_brain.__version__}"
    probe = (
        "import importlib.util as u, sfl_brain.modules.acc, sfl_brain.bodies.planar_biped;"
        "print(u.find_spec('modules'), u.find_spec('bodies'))"
    )
    done = subprocess.run([sys.executable, "-c", probe], cwd=tmp_path, capture_output=True, text=True, timeout=60)
    assert done.returncode == 0, done.stderr
    assert done.stdout.split() == ["None", "None"]
