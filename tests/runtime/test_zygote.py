"""The run's fork server (sfl_brain.runtime.zygote): module processes forked from one process that imported what
they share. Real runs over processes: the forked run gives the records of a run that starts its processes anew,
and a fork server killed mid-run leaves the run going (a module that dies after it restarts on its own)."""

from __future__ import annotations

import json
import os
import signal

import psutil

from sfl_brain.protocols.local import run_local
from sfl_brain.recording.records import read_records
from sfl_brain.runtime import zygote
from sfl_brain.scenario import load

from ..conftest import SCENARIOS, argv_of, poll_until, sfl_run, start_sfl_run, trials_recorded, wait_for_trials
from .test_faults import module_process, stable

WALKER = SCENARIOS / "quickstart.yaml"
SETS = ("protocol.trials=8", "modules.body.params.duration=3", "record.body_every=0")


def test_a_forked_run_gives_the_records_of_a_run_whose_processes_start_anew(tmp_path):
    forked = sfl_run(WALKER, tmp_path / "forked", *SETS)
    assert forked.returncode == 0, forked.stderr
    fresh = sfl_run(WALKER, tmp_path / "fresh", *SETS, env={**os.environ, "SFL_FORK_SERVER": "0"})
    assert fresh.returncode == 0, fresh.stderr
    assert (tmp_path / "forked" / "logs" / "zygote.log").exists()
    assert not (tmp_path / "fresh" / "logs" / "zygote.log").exists()  # turned off: no fork server at all
    rows = read_records(tmp_path / "forked")
    assert sum(r["kind"] == "trial" for r in rows) == 8
    assert stable(rows) == stable(read_records(tmp_path / "fresh"))
    assert stable(rows) == stable(run_local(load(WALKER, list(SETS))))


def test_a_fork_server_killed_mid_run_leaves_the_run_going_and_a_module_dead_after_it_restarts(tmp_path):
    out = tmp_path / "run"
    sets = ("protocol.trials=100000", "modules.body.params.duration=3", "record.body_every=0")
    proc = start_sfl_run(WALKER, out, *sets)
    wait_for_trials(out, 2, proc)
    body = module_process(proc, "body")  # found now: once its server is gone, it is nobody's descendant here
    server = next(p for p in psutil.Process(proc.pid).children() if "sfl_brain.runtime.zygote" in p.cmdline())
    server.kill()  # a zombie until the supervisor reaps it at the run's end
    poll_until(lambda: not server.is_running() or server.status() == psutil.STATUS_ZOMBIE, "the server's end", 10)
    wait_for_trials(out, trials_recorded(out) + 2, proc)  # the modules it forked go on
    body.kill()  # its end is seen without the server; it starts anew, as without a fork server
    wait_for_trials(out, trials_recorded(out) + 3, proc)  # and the run goes on with it
    proc.send_signal(signal.SIGINT)
    stdout, stderr = proc.communicate(timeout=60)
    stderr = " ".join(stderr.split())
    assert proc.returncode == 130, stderr
    assert "module `body` died" in stderr and "restarting" in stderr, stderr
    rows = read_records(out)
    trials = sum(r["kind"] == "trial" for r in rows)
    assert json.loads((out / "summary.json").read_text())["trials"] == trials
    retried = [r for r in rows if r["kind"] == "retry"]
    assert len(retried) <= 1, retried  # the trial in flight when the body died, if one was
    clean = stable(run_local(load(WALKER, [f"protocol.trials={trials}", *sets[1:]])))
    kept = stable([r for r in rows if r["kind"] != "retry"])
    assert kept[: len(clean)] == clean  # then at most the decisions of the trial Ctrl-C came before
    assert all(r["kind"] == "decision" for r in kept[len(clean) :]), kept[len(clean) :]


def test_only_the_projects_own_modules_are_imported_ahead():
    refs = [
        "sfl_brain.bodies.planar_biped:PlanarBiped",
        "modules.acc:ACC",
        "my_module.py:Thing",  # a user's file: may do anything at import, must fail in its own process
        "somepackage.mod:Other",  # an installed third party's
        "modules.acc:ACC",
    ]
    assert zygote.preloads(refs) == ["sfl_brain.bodies.planar_biped", "modules.acc"]


def test_a_forked_host_given_no_spec_exits_1_saying_why_and_a_signal_after_its_end_goes_nowhere(tmp_path):
    server = zygote.ForkServer.start([], tmp_path / "zygote.log")
    assert server is not None, (tmp_path / "zygote.log").read_text()
    try:
        with open(tmp_path / "x.log", "ab") as logf:
            child = server.spawn("x", logf)
        assert psutil.Process(child.pid).ppid() == server.proc.pid
        shown = psutil.Process(child.pid)
        poll_until(lambda: argv_of(shown)[-2:] == ["--name", "x"], "ps to show the host's name", 10)
        child.stdin.close()  # no spec: the host says so and exits 1, as python -m sfl_brain.runtime.host would
        assert child.wait(timeout=30) == 1
        assert "expected the JSON spec on the first line of stdin" in (tmp_path / "x.log").read_text()
        assert child.pidfd is None  # closed at its end: nothing can signal a later process with its pid
        child.kill()
        child.send_signal(signal.SIGTERM)
    finally:
        server.close()
    assert server.proc.returncode == 0
