"""``sfl worker``: joins with the run secret, exits when its run ends, gives up when no run answers."""

from __future__ import annotations

import os
import signal
import subprocess
import sys

from sfl_brain.runtime import bus

from ..conftest import ROOT, SCENARIOS, Lines, listening_run, sfl

SWEEP = SCENARIOS / "analytic_sweep.yaml"
LEARN = SCENARIOS / "analytic_learn.yaml"


def worker(*args: str, env: dict | None = None) -> subprocess.Popen:
    return subprocess.Popen(
        [sys.executable, "-m", "sfl_brain.cli", "worker", *args],
        cwd=ROOT,
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
        env={**os.environ, **(env or {})},
    )


def test_worker_gives_up_when_no_run_answers():
    done = sfl(
        "worker", str(SWEEP), "--connect", bus.free_endpoint(), "--run-id", "nosuchrun", "--wait", "1",
        env={**os.environ, "SFL_RUN_SECRET": "x" * 32}, timeout=60,
    )  # fmt: skip
    assert done.returncode == 1, done.stderr
    assert "sfl worker: no run nosuchrun answered" in done.stderr
    assert "Traceback" not in done.stderr


def test_worker_needs_the_secret():
    env = {k: v for k, v in os.environ.items() if k != "SFL_RUN_SECRET"}
    done = sfl("worker", str(SWEEP), "--connect", bus.free_endpoint(), "--run-id", "r", env=env, timeout=60)
    assert done.returncode == 2
    assert "no run secret" in done.stderr


def test_join_command_reproduces_overrides_and_seed_and_the_worker_exits_when_the_run_ends(tmp_path):
    out = tmp_path / "run"
    with listening_run(LEARN, out, "protocol.trials=300", modules=4) as run:
        assert "--set protocol.trials=300" in run.join and "--seed 1" in run.join
        assert f"--secret-file {out / 'secret'}" in run.join
        joined = worker(
            str(LEARN), "--connect", run.endpoint, "--run-id", run.run_id,
            "--set", "protocol.trials=300", "--secret-file", str(out / "secret"),
        )  # fmt: skip
        assert run.proc.wait(timeout=240) == 0, run.proc.stderr.read()
        assert joined.wait(timeout=30) == 0  # its run ended
        stdout = joined.stdout.read()
        assert "joined run" in stdout and "ended" in stdout, stdout + joined.stderr.read()


def test_worker_wrong_run_id_gives_up_and_ctrl_c_stops_a_waiting_worker(tmp_path):
    out = tmp_path / "run"
    with listening_run(SCENARIOS / "analytic_learn.yaml", out, "protocol.trials=100000", modules=4) as run:
        env = {"SFL_RUN_SECRET": run.secret}
        wrong = worker(str(SWEEP), "--connect", run.endpoint, "--run-id", "wrongid", "--wait", "2", env=env)
        assert wrong.wait(timeout=60) == 1
        assert "no run wrongid answered" in wrong.stderr.read()
        joined = worker(str(SWEEP), "--connect", run.endpoint, "--run-id", run.run_id, "--name", "x1", env=env)
        Lines(joined.stdout).expect("joined run", 60)
        joined.send_signal(signal.SIGINT)
        assert joined.wait(timeout=30) == 130
        run.proc.kill()
        run.proc.wait(timeout=30)


def test_a_workers_lease_is_timeouts_lease_and_the_runs_own_processes_hold_a_day():
    """A worker on another machine cannot be seen, only heard: the run gives it up after its lease
    (``timeouts.lease``); the run's own processes declare a lease of a day, and are judged by their progress."""
    from sfl_brain.runtime.supervisor import Supervisor
    from sfl_brain.runtime.worker import worker_spec
    from sfl_brain.scenario import load

    plan = load(LEARN, ["timeouts.lease=1.5"])
    assert worker_spec(plan, "run", "ext0", ["tcp/127.0.0.1:7447"], "secret")["lease_ms"] == 1500
    assert bus.config(lease_ms=1500).get_json("transport/link/tx/lease") == "1500"
    own = Supervisor(plan, ROOT / "runs", "run").spec_for(plan.instances[0])
    assert own["lease_ms"] == bus.LOCAL_LEASE_MS == 24 * 3600 * 1000
