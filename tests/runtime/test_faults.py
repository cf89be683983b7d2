"""Faults at run time: kill -9 of a module process, by kind."""

from __future__ import annotations

import json
import subprocess
import time

import psutil
import pytest

from sfl_brain.protocols.local import run_local
from sfl_brain.recording.records import read_records
from sfl_brain.scenario import load

from ..conftest import SCENARIOS, argv_of, start_sfl_run, wait_for_trials

VOLATILE = {"wall_ms", "worker", "cpu_body_s", "cpu_controller_s"}
WALKER = SCENARIOS / "quickstart.yaml"


def stable(rows):
    return [{k: v for k, v in r.items() if k not in VOLATILE} for r in rows]


def module_process(proc: subprocess.Popen, name: str) -> psutil.Process:
    """The child hosting ``name`` (``python -m sfl_brain.runtime.host --name NAME``; the spec is on its stdin).

    Asked once trials are recorded: the protocol starts only when every module is alive."""
    for child in psutil.Process(proc.pid).children(recursive=True):
        try:
            cmd = argv_of(child)
        except psutil.Error:
            continue
        if "--name" in cmd and cmd[cmd.index("--name") + 1] == name:
            return child
    raise AssertionError(f"no process for {name}")


def in_a_trial(process: psutil.Process, timeout: float = 60.0) -> None:
    """Return once ``process`` (a body or its controller) is seen ticking a trial: it spent over half of the last
    20 ms on a CPU (between trials both wait for the next request)."""
    deadline = time.monotonic() + timeout
    before = sum(process.cpu_times()[:2])
    while time.monotonic() < deadline:
        time.sleep(0.02)
        now = sum(process.cpu_times()[:2])
        if now - before > 0.01:
            return
        before = now
    raise AssertionError(f"{process} was not seen in a trial within {timeout} s")


@pytest.mark.parametrize("name", ["acc", "vigilance", "ofc"])
def test_kill_9_of_a_brain_module_fails_the_run_naming_it(tmp_path, name):
    out = tmp_path / "run"
    proc = start_sfl_run(SCENARIOS / "analytic_learn.yaml", out, "protocol.trials=100000")
    wait_for_trials(out, 3, proc, timeout=60)
    module_process(proc, name).kill()
    _, stderr = proc.communicate(timeout=60)
    stderr = " ".join(stderr.split())  # the report may wrap lines
    assert proc.returncode == 1, stderr
    assert f"module `{name}`" in stderr and "died with exit code -9" in stderr, stderr
    assert f"{name} ready" in stderr  # its log tail
    assert f"resume: sfl run --resume {out}" in stderr  # the run says how to go on
    summary = json.loads((out / "summary.json").read_text())
    assert summary["status"] == "failed"
    rows = read_records(out)
    trials = [r for r in rows if r["kind"] == "trial"]
    assert len(trials) >= 3 and [r["trial"] for r in trials] == list(range(len(trials)))


@pytest.mark.parametrize("name", ["controller", "body"])
def test_kill_9_of_a_body_or_controller_restarts_it_and_retries_the_trial_at_once(tmp_path, name):
    """Bodies and controllers restart by default. The trial in flight is interrupted by the death itself (the
    supervisor sees the exit, the body sees its controller's link close), not by a time-out: with timeouts.tick =
    60 s, nothing waits for a tick or a request to time out; the trial is recorded as retried, and the retried trial
    gives the records of a run without the kill."""
    out = tmp_path / "run"
    sets = [
        "protocol.trials=20",
        "modules.body.params.duration=3",
        "record.body_every=0",
        "timeouts.tick=60",
    ]
    proc = start_sfl_run(WALKER, out, *sets)
    wait_for_trials(out, 2, proc)
    victim = module_process(proc, name)
    in_a_trial(victim)  # a kill between two trials, while the gate decides, would leave no trial to retry
    victim.kill()
    stdout, stderr = proc.communicate(timeout=180)
    stderr = " ".join(stderr.split())
    assert proc.returncode == 0, stderr
    assert f"module `{name}` died (exit code -9); restarting" in stderr, stderr
    retries = [line for line in stdout.splitlines() if "interrupted (" in line]
    for line in retries:  # interrupted by the death, not by a time-out
        assert "no command for tick" not in line and "no reply" not in line, line
    assert "within 60 s" not in (out / "logs" / "body.log").read_text()  # no tick waited out its time-out
    rows = read_records(out)
    retried = [r for r in rows if r["kind"] == "retry"]
    assert len(retried) == 1 and retried[0]["attempt"] == 1 and f"`{name}`" in retried[0]["reason"], retried
    clean = run_local(load(WALKER, sets))
    assert stable([r for r in rows if r["kind"] != "retry"]) == stable(clean)
