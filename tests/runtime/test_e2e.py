"""End to end: real processes, a real Zenoh mesh on loopback, real Rerun files read back."""

import json
import os
import signal
import subprocess
import sys
import time

import psutil
import pytest
from rerun.chunk import RrdReader

from sfl_brain.protocols.local import run_local
from sfl_brain.recording.provenance import describe_platform
from sfl_brain.recording.records import read_records
from sfl_brain.runtime import bus
from sfl_brain.scenario import load

from ..conftest import ROOT, SCENARIOS, Lines, argv_of, joined_run, sfl, sfl_run, start_sfl_run, wait_for_trials

VOLATILE = {"wall_ms", "worker", "cpu_body_s", "cpu_controller_s"}


def stable(rows):
    return [{k: v for k, v in r.items() if k not in VOLATILE} for r in rows]


def rrd_rows(path):
    counts = {}
    for chunk in RrdReader(path).stream().to_chunks():
        counts[chunk.entity_path] = counts.get(chunk.entity_path, 0) + chunk.num_rows
    return counts


def test_learn_run_records_everything_and_matches_in_process(tmp_path):
    out = tmp_path / "run"
    done = sfl_run(SCENARIOS / "analytic_learn.yaml", out, "protocol.trials=60")
    assert done.returncode == 0, done.stderr
    summary = json.loads((out / "summary.json").read_text())
    assert summary["status"] == "completed" and summary["trials"] == 60
    rows = [json.loads(line) for line in (out / "records.jsonl").read_text().splitlines()]
    trials = [r for r in rows if r["kind"] == "trial"]
    decisions = [r for r in rows if r["kind"] == "decision"]
    assert len(trials) == 60 and sum(d["go"] for d in decisions) == 60 and len(decisions) == summary["decisions"]
    assert {"d_success", "d_failure", "s_vig", "v_unit", "x", "y"} <= set().union(*decisions)
    assert {"success", "quality", "rho", "n_success", "n_failure", "ns_nf"} <= set().union(*trials)
    # every decision and every trial is in the Rerun recording, logged by the processes
    counts = rrd_rows(out / "recording.rrd")
    assert counts["/decisions/margin"] == len(decisions)
    for series in ("d_success", "d_failure", "s_vig", "go", "v_unit/x", "v/y"):
        assert counts[f"/decisions/{series}"] == len(decisions), series
    assert counts["/trials/success"] == 60
    for series in ("n_success", "n_failure", "quality", "v/x"):
        assert counts[f"/trials/{series}"] == 60, series
    assert counts["/acc/success_map/neurons"] >= 60  # the ACC process logged its maps per trial
    # same scenario and seed in one process: identical records
    local = run_local(load(SCENARIOS / "analytic_learn.yaml", ["protocol.trials=60"]))
    assert stable(local) == stable(read_records(out))
    # sfl inspect --json prints the status first, then exactly the summary fields
    inspected = json.loads(sfl("inspect", str(out), "--json").stdout)
    assert list(inspected)[:3] == ["status", "stop_reason", "planned_trials"]
    assert inspected["status"] == "completed" and inspected["planned_trials"] == 60
    assert set(inspected) == {
        "status",
        "stop_reason",
        "planned_trials",
        "trials",
        "successes",
        "failures",
        "decisions",
        "no_go",
        "success_rate",
        "final_vigilance",
        "best_quality",
        "wall_time_s",
        "proposer",  # a learn run: which proposer chose, and its safe-learning metrics (sfl_brain.recording.metrics)
        "failures_before_first_success",
        "failures_before_10_gaits",
        "distinct_gaits",
        "time_budget",  # where the wall time went (tests/recording/test_budget.py)
    }
    assert inspected["time_budget"] == summary["time_budget"]
    assert inspected["trials"] == 60 and inspected["no_go"] == summary["no_go"]
    assert inspected["proposer"] == "sfl" and inspected["failures_before_first_success"] <= inspected["failures"]
    # sfl report draws the maps over the tried points and tabulates the run
    report = sfl("report", str(out), "--out", str(tmp_path / "report"))
    assert report.returncode == 0, report.stderr
    assert (tmp_path / "report" / "run.png").stat().st_size > 10_000
    table = (tmp_path / "report" / "README.md").read_text()
    assert "| run | completed | learn | sfl | 0.0 | 60 |" in table
    made = json.loads((out / "provenance.json").read_text())  # the report says what made the run, and when
    assert f"Runs made at `{(made['commit'] or 'no git commit')[:7]}`" in table
    platform = describe_platform(made["numeric_platform"])  # and on what its floats were computed
    assert f"started {made['started'][:10]}, on {platform}." in table and platform.startswith(
        made["numeric_platform"]["machine"]
    )


def test_sfl_list_names_every_registered_implementation():
    listing = sfl("list").stdout
    for name, kind in (
        ("acc", "brain"),
        ("vigilance", "brain"),
        ("ofc", "brain"),
        ("reflex", "controller"),
        ("planar_biped", "body"),
        ("analytic", "body"),
    ):
        assert any(line.split()[:2] == [name, kind] for line in listing.splitlines()), listing


def test_crashed_body_is_restarted_by_default_and_its_trial_retried(tmp_path):
    marker = tmp_path / "crashed"
    out = tmp_path / "run"
    done = sfl_run(
        SCENARIOS / "analytic_learn.yaml",
        out,
        "protocol.trials=20",
        "modules.body.params.crash_at_trial=5",
        f"modules.body.params.crash_marker={marker}",
    )
    assert done.returncode == 0, done.stderr
    assert marker.exists()
    assert "module `body` died (exit code 3); restarting" in done.stderr
    rows = read_records(out)
    trials = [r for r in rows if r["kind"] == "trial"]
    assert [r["trial"] for r in trials] == list(range(20))  # retried, not counted as a failure
    assert [(r["trial"], r["attempt"]) for r in rows if r["kind"] == "retry"] == [(5, 1)]  # recorded as retried
    expected = run_local(load(SCENARIOS / "analytic_learn.yaml", ["protocol.trials=20"]))
    assert stable([r for r in rows if r["kind"] != "retry"]) == stable(expected)


def test_dead_module_without_restart_is_reported_and_records_survive(tmp_path):
    out = tmp_path / "run"
    sets = ["protocol.trials=20", "modules.body.params.crash_at_trial=5", "modules.body.restart=never"]
    done = sfl_run(SCENARIOS / "analytic_learn.yaml", out, *sets)
    assert done.returncode == 1
    assert "module `body`" in done.stderr and "died with exit code 3" in done.stderr
    assert "Traceback" not in done.stderr.split("its log")[0]
    trials = [r for r in read_records(out) if r["kind"] == "trial"]
    assert [r["trial"] for r in trials] == list(range(5))
    assert json.loads(sfl("inspect", str(out), "--json").stdout)["trials"] == 5


def test_garbage_on_the_bus_is_logged_and_dropped(tmp_path):
    out = tmp_path / "run"
    with joined_run(SCENARIOS / "analytic_learn.yaml", out, "protocol.trials=150", modules=4) as (
        proc,
        session,
        run_id,
    ):
        errors = []
        for target in (
            "acc/acc.evaluate",
            "vigilance/vigilance.trial_done",
            "ofc/ofc.grade",
            "body/body.trial",
        ):
            for reply in session.get(f"sfl/{run_id}/{target}", payload=b"\x00garbage\xff", timeout=10):
                errors.append(reply.err.payload.to_string() if reply.err else "ok?")
        session.put(f"sfl/{run_id}/acc/acc.evaluate", b"not even a query")
    assert len(errors) == 4 and all(e.startswith("malformed request") for e in errors), errors
    assert proc.wait(timeout=240) == 0, proc.stderr.read()
    assert json.loads((out / "summary.json").read_text())["trials"] == 150
    assert "dropped malformed request" in (out / "logs" / "acc.log").read_text()


def _long_walker_run(tmp_path, trials_seen):
    """``sfl run`` of the walker with an endless budget, once ``trials_seen`` trials are recorded."""
    out = tmp_path / "run"
    proc = start_sfl_run(SCENARIOS / "quickstart.yaml", out, "protocol.trials=100000")
    wait_for_trials(out, trials_seen, proc)
    return proc, out, out / "records.jsonl", psutil.Process(proc.pid).children(recursive=True)


def test_ctrl_c_stops_every_child_and_keeps_records(tmp_path):
    """Ctrl-C stops the children with SIGTERM: each one shuts down on its own (a host that ends
    its serve loop writes its drop counters last; one killed after the 3 s grace period would not,
    nor one still running a trial that ignored the stop), and the records stay whole."""
    proc, out, _, children = _long_walker_run(tmp_path, 2)
    hosts = [child for child in children if "--name" in argv_of(child)]
    names = sorted(argv_of(child)[argv_of(child).index("--name") + 1] for child in hosts)
    assert names == ["acc", "body", "controller", "ofc", "vigilance"]
    # besides them only the run's fork server (sfl_brain.runtime.zygote), which they were forked from
    others = [child for child in children if child not in hosts]
    assert len(others) == 1 and "sfl_brain.runtime.zygote" in others[0].cmdline(), [c.cmdline() for c in others]
    assert {child.ppid() for child in hosts} == {others[0].pid}
    proc.send_signal(signal.SIGINT)
    assert proc.wait(timeout=30) == 130
    gone, alive = psutil.wait_procs(children, timeout=1)
    assert not alive, f"orphans: {alive}"
    for name in names:  # a clean exit on SIGTERM, not a SIGKILL after the grace period
        assert (out / "logs" / f"{name}.counters.json").exists(), name
    summary = json.loads(sfl("inspect", str(out), "--json").stdout)
    assert summary["trials"] >= 2
    assert json.loads((out / "summary.json").read_text())["status"] == "interrupted"


def test_kill_9_of_the_supervisor_loses_at_most_the_trial_in_flight(tmp_path):
    proc, out, records, children = _long_walker_run(tmp_path, 3)
    proc.send_signal(signal.SIGKILL)
    proc.wait(timeout=10)
    written = records.read_text().count('"kind":"trial"')
    # the module processes notice their parent is gone (stdin closes) and exit on their own
    gone, alive = psutil.wait_procs(children, timeout=10)
    assert not alive, f"orphans after kill -9: {alive}"
    summary = json.loads(sfl("inspect", str(out), "--json").stdout)
    assert summary["trials"] >= 3 and summary["trials"] in (written, written - 1)  # a torn last line is skipped
    assert not (out / "summary.json").exists()  # nothing claimed the run finished


@pytest.mark.filterwarnings("ignore:RRD file has no footer")  # the server's --save writes no footer
def test_viewer_url_streams_live_and_the_run_folder_keeps_the_recording(tmp_path):
    """A headless Rerun server on loopback stands in for the viewer; it saves what it receives."""
    import shutil

    port = int(bus.free_endpoint().rsplit(":", 1)[1])
    live = tmp_path / "live.rrd"
    server = subprocess.Popen(
        [shutil.which("rerun") or "rerun", "--bind", "127.0.0.1", "--port", str(port), "--save", str(live)],
        stdout=subprocess.DEVNULL,
        stderr=subprocess.PIPE,
        text=True,
        start_new_session=True,  # `rerun` is a Python wrapper around the viewer binary: Ctrl-C reaches both
    )
    try:
        Lines(server.stderr).expect(f"Listening for gRPC connections on 127.0.0.1:{port}", 30)
        out = tmp_path / "run"
        done = sfl_run(
            SCENARIOS / "analytic_learn.yaml",
            out,
            "protocol.trials=25",
            extra=(
                "--viewer-url",
                f"rerun+http://127.0.0.1:{port}/proxy",
            ),
        )
        assert done.returncode == 0, done.stderr
    finally:
        os.killpg(server.pid, signal.SIGINT)  # as Ctrl-C in a terminal: the wrapper alone may not pass it on
        try:
            server.wait(timeout=5)
        except subprocess.TimeoutExpired:  # the server may outlive Ctrl-C (rerun 0.41, seen loaded and quiet); what
            os.killpg(server.pid, signal.SIGKILL)  # it received is on disk already (--save streams, no footer)
            server.wait(timeout=10)
    saved, streamed = rrd_rows(out / "recording.rrd"), rrd_rows(live)
    for counts in (saved, streamed):
        assert counts["/trials/success"] == 25 and counts["/acc/success_map/neurons"] >= 25


def test_user_module_from_a_file_is_swapped_in(tmp_path):
    """The README's example: a brain module in one short file, named by path in a scenario."""
    out = tmp_path / "run"
    done = sfl_run(ROOT / "docs" / "examples" / "cautious.yaml", out, "protocol.trials=30")
    assert done.returncode == 0, done.stderr
    trials = [r for r in read_records(out) if r["kind"] == "trial"]
    assert len(trials) == 30
    # the user's module raised the threshold after each failure: s_vig never decreased
    s_vig = [r["s_vig"] for r in trials]
    assert all(b >= a for a, b in zip(s_vig, s_vig[1:], strict=False)) and s_vig[-1] > s_vig[0]


@pytest.mark.skipif(os.cpu_count() < 2, reason="needs two cores")
def test_sweep_fans_out_over_workers(tmp_path):
    out = tmp_path / "run"
    done = sfl_run(SCENARIOS / "analytic_sweep.yaml", out, "modules.body.workers=2")
    assert done.returncode == 0, done.stderr
    trials = [r for r in read_records(out) if r["kind"] == "trial"]
    assert sorted(r["trial"] for r in trials) == list(range(121))
    assert {r["worker"] for r in trials} == {"body.0", "body.1"}


def test_buslink_times_out_when_no_controller_answers():
    """A body blocked in recv() on a silent controller is woken by the watchdog: the trial is interrupted."""
    import numpy as np

    from sfl_brain.messages import SensorFrame
    from sfl_brain.runtime.ticklink import BusLink, LinkError

    session = bus.open_session([bus.free_endpoint()], [])
    link = BusLink(session, "lonely", "body", "controller", timeout=0.3)
    try:
        with pytest.raises(LinkError, match="no answer to tick 0 within 0.3 s"):
            link.step(SensorFrame(trial_id=0, tick=0, values=np.zeros(3)))
    finally:
        link.close()
        session.close()


def test_a_request_nobody_answers_says_the_query_ended_not_that_it_waited_out_its_time():
    """A module gone (killed between two requests) ends the query at once: the error must not read as a time-out."""
    from sfl_brain.messages import Rejected
    from sfl_brain.runtime.host import NoReply, request

    session = bus.open_session([bus.free_endpoint()], [])
    try:
        started = time.monotonic()
        with pytest.raises(NoReply, match=r"no reply from sfl/gone/vigilance/x: the query ended after 0\.\d\d s"):
            request(session, "sfl/gone/vigilance/x", Rejected(consecutive=0), 30.0)
        assert time.monotonic() - started < 5
    finally:
        session.close()


def test_sessions_run_zenoh_on_one_runtime_thread_unless_the_user_says_otherwise():
    """bus.RUNTIME: Zenoh's runtimes handed over to one worker (a lockstep tick wakes fewer threads);
    a ZENOH_RUNTIME of the user's is kept."""
    script = (
        "import glob, os, time, zenoh\n"
        "from sfl_brain import bus\n"
        "ep = bus.free_endpoint()\n"
        "a = bus.open_session([ep], [])\n"
        "b = bus.open_session(['tcp/127.0.0.1:0'], [ep])\n"
        "pub, sub = a.declare_publisher('t/x'), b.declare_subscriber('t/x', zenoh.handlers.RingChannel(4))\n"
        "deadline = time.monotonic() + 10\n"
        "while sub.try_recv() is None and time.monotonic() < deadline:\n"
        "    pub.put(b'x'); time.sleep(0.05)\n"
        "names = [open(f).read().strip().rsplit('-', 1)[0] for f in glob.glob('/proc/self/task/*/comm')]\n"
        "print(os.environ['ZENOH_RUNTIME']); print(sorted(set(names) - {'python'}))\n"
        "a.close(); b.close()\n"
    )
    env = {k: v for k, v in os.environ.items() if k != "ZENOH_RUNTIME"}
    done = subprocess.run([sys.executable, "-c", script], env=env, capture_output=True, text=True, timeout=60)
    assert done.returncode == 0, done.stderr
    runtime, threads = done.stdout.splitlines()
    assert runtime == bus.RUNTIME and threads == "['tx']"  # no rx, acc, net or app threads
    mine = "(rx: (worker_threads: 2))"
    done = subprocess.run(
        [sys.executable, "-c", script], env=env | {"ZENOH_RUNTIME": mine}, capture_output=True, text=True, timeout=60
    )
    assert done.returncode == 0, done.stderr
    runtime, threads = done.stdout.splitlines()
    assert runtime == mine and "rx" in threads


def test_the_body_polls_for_commands_only_while_polling_makes_ticks_shorter():
    from sfl_brain.runtime.ticklink import SpinThenSleep

    def run(spin_tick, sleep_tick, ticks=1024):
        now = 0.0
        waiter = SpinThenSleep(200e-6)
        ways = []
        for _ in range(ticks):
            ways.append(waiter.next_tick(now))
            now += spin_tick if ways[-1] else sleep_tick  # the tick's time, by the way it waited
        return ways

    fast_spin = run(100e-6, 150e-6)
    assert sum(fast_spin[128:]) == (1024 - 128) * 120 // 128  # polls, but waits the other way 8 ticks a cycle
    slow_spin = run(150e-6, 100e-6)  # a busy machine: polling takes the partner's core
    assert sum(slow_spin[256:]) == (1024 - 256) * 8 // 128  # sleeps after the first cycle; tries polling 8 a cycle
    never = SpinThenSleep(0.0)  # lockstep.spin_us: 0
    assert not any(never.next_tick(t * 1e-4) for t in range(300))
