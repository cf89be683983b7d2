"""Faults at run time: kill -9 of a module process, by kind."""

from __future__ import annotations

import json
import subprocess
import sys
import time

import psutil
import pytest

from sfl_brain.local import run_local
from sfl_brain.records import read_records
from sfl_brain.scenario import load

from .conftest import ROOT, SCENARIOS, wait_for

VOLATILE = {"wall_ms", "worker"}
WALKER = SCENARIOS / "quickstart.yaml"


def stable(rows):
    return [{k: v for k, v in r.items() if k not in VOLATILE} for r in rows]


def start(scenario, out, *sets):
    args = [arg for s in sets for arg in ("--set", s)]
    return subprocess.Popen(
        [sys.executable, "-m", "sfl_brain.cli", "run", str(scenario), *args, "--out", str(out), "--quiet"],
        cwd=ROOT,
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
    )


def module_process(proc: subprocess.Popen, name: str) -> psutil.Process:
    """The child hosting ``name`` (``python -m sfl_brain.host --name NAME``; the spec is on its stdin)."""
    found = {}

    def look():
        for child in psutil.Process(proc.pid).children(recursive=True):
            try:
                cmd = child.cmdline()
            except psutil.Error:
                continue
            if "--name" in cmd and cmd[cmd.index("--name") + 1] == name:
                found["p"] = child
                return True
        return False

    assert wait_for(look, 60), f"no process for {name}"
    return found["p"]


def trials_written(out) -> int:
    path = out / "records.jsonl"
    return path.read_text().count('"kind":"trial"') if path.exists() else 0


@pytest.mark.parametrize("name", ["acc", "vigilance", "ofc"])
def test_kill_9_of_a_brain_module_fails_the_run_naming_it(tmp_path, name):
    out = tmp_path / "run"
    proc = start(SCENARIOS / "analytic_learn.yaml", out, "protocol.trials=100000")
    victim = module_process(proc, name)
    assert wait_for(lambda: trials_written(out) >= 3, 60)
    victim.kill()
    _, stderr = proc.communicate(timeout=60)
    stderr = " ".join(stderr.split())  # the report may wrap lines
    assert proc.returncode == 1, stderr
    assert f"module `{name}`" in stderr and "died with exit code -9" in stderr, stderr
    assert f"{name} ready" in stderr  # its log tail
    summary = json.loads((out / "summary.json").read_text())
    assert summary["status"] == "failed"
    rows = read_records(out)
    trials = [r for r in rows if r["kind"] == "trial"]
    assert len(trials) >= 3 and [r["trial"] for r in trials] == list(range(len(trials)))


@pytest.mark.parametrize("name", ["controller", "body"])
def test_kill_9_of_a_body_or_controller_restarts_it_and_retries_the_trial_at_once(tmp_path, name):
    """With timeouts.tick = 60 s, a retry that waited for a tick time-out would make the run last
    over a minute; it starts as soon as the replacement is alive."""
    out = tmp_path / "run"
    sets = [
        "protocol.trials=60",
        "modules.body.params.duration=3",
        "record.body_every=0",
        "timeouts.tick=60",
        f"modules.{name}.restart=on-failure",
    ]
    started = time.monotonic()
    proc = start(WALKER, out, *sets)
    victim = module_process(proc, name)
    assert wait_for(lambda: trials_written(out) >= 2, 120)
    victim.kill()
    _, stderr = proc.communicate(timeout=120)
    stderr = " ".join(stderr.split())
    elapsed = time.monotonic() - started
    assert proc.returncode == 0, stderr
    assert f"module `{name}` died (exit code -9); restarting" in stderr, stderr
    assert elapsed < 60, f"the run took {elapsed:.0f} s: the retried trial waited for a tick time-out"
    clean = run_local(load(WALKER, sets))
    assert stable(read_records(out)) == stable(clean)
