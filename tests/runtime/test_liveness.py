"""A busy machine never kills a healthy run (issue 34): module processes are judged by their progress and the CPU
they could have used (``sfl_brain.runtime.liveness``), not by the wall clock or a lease; a hung one is still found.

The runs here start real processes under real faults: a controller stopped mid-trial (SIGSTOP, SIGCONT) for longer
than its tick time-out and the lease that used to kill it; a run at ``nice -n 10`` beside more busy processes than
cores, with time-outs shorter than its starved trials; a brain module, a body worker and (``test_planar.py``) a
controller that loop forever in a handler. Each run's records are compared with a quiet run's.
"""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

from sfl_brain.protocols.local import run_local
from sfl_brain.recording.records import read_records
from sfl_brain.events import Events, ModuleStopped
from sfl_brain.messages import Ack
from sfl_brain.runtime.inbox import Pending
from sfl_brain.runtime.liveness import CpuSample, NoProgressClock, ProgressBoard, cpu_sample, had_the_cpu
from sfl_brain.runtime.processes import Child
from sfl_brain.runtime.watch import WATCH_PERIOD, HangWatch
from sfl_brain.runtime.placement import usable_cpus
from sfl_brain.scenario import load

from ..conftest import SCENARIOS, Lines, poll_until, start_sfl_run, trials_recorded, wait_for_trials
from .test_faults import module_process

WALKER = SCENARIOS / "quickstart.yaml"
LEARN = SCENARIOS / "analytic_learn.yaml"
VOLATILE = {"wall_ms", "worker", "cpu_body_s", "cpu_controller_s"}


def stable(rows):
    return [{k: v for k, v in r.items() if k not in VOLATILE} for r in rows]


# ---------------------------------------------------------------- the clock
def sample(at, state="S", cpu=0.0, waited=0.0):
    return CpuSample(at, state, cpu, waited)


def test_the_clock_counts_the_time_a_group_could_run_not_a_stop_nor_a_wait_for_a_core():
    # 1 s apart: a process that used the core all along, one that waited for a core 0.9 s of it, one stopped
    assert had_the_cpu([sample(0, "R")], [sample(1, "R", cpu=1.0)]) == pytest.approx(1.0)
    assert had_the_cpu([sample(0, "R")], [sample(1, "R", cpu=0.1, waited=0.9)]) == pytest.approx(0.1)
    assert had_the_cpu([sample(0, "R")], [sample(1, "T")]) == 0.0
    assert had_the_cpu([sample(0, "D")], [sample(1, "R")]) == 0.0  # an uninterruptible wait on the machine
    # a pair taking turns: the body asleep waiting, its controller starved: nothing counts
    assert had_the_cpu([sample(0), sample(0, "R")], [sample(1), sample(1, "R", waited=1.0)]) == 0.0
    # asleep with the CPU to take (a deadlock, a lost message) counts; a long gap (the watcher stopped) counts 2 s
    assert had_the_cpu([sample(0)], [sample(1)]) == pytest.approx(1.0)
    assert had_the_cpu([sample(0)], [sample(600)]) == pytest.approx(2.0)
    # without run delays (no schedstat): the CPU time used
    assert had_the_cpu([CpuSample(0, "R", 0, None)], [CpuSample(1, "R", 0.25, None)]) == pytest.approx(0.25)
    clock = NoProgressClock()
    assert clock.update([sample(0)], marks=1) == 0.0
    assert clock.update([sample(1)], marks=1) == pytest.approx(1.0)
    assert clock.update([sample(2)], marks=2) == 0.0  # progress: from zero again


def test_a_stopped_process_reads_stopped_and_a_spinning_one_uses_the_cpu():
    spinning = subprocess.Popen([sys.executable, "-c", "while True: pass"])
    try:
        first = cpu_sample(spinning.pid)
        poll_until(lambda: cpu_sample(spinning.pid).cpu > first.cpu + 0.05, "the loop to use some CPU", 30)
        os.kill(spinning.pid, signal.SIGSTOP)
        poll_until(lambda: cpu_sample(spinning.pid).state == "T", "the loop to read stopped", 30)
        stopped = cpu_sample(spinning.pid)
        os.kill(spinning.pid, signal.SIGCONT)
        poll_until(lambda: cpu_sample(spinning.pid).state != "T", "the loop to run again", 30)
        assert had_the_cpu([first], [stopped]) == 0.0
    finally:
        spinning.kill()
        spinning.wait()
    assert cpu_sample(spinning.pid) is None


# ---------------------------------------------------------------- stopped and continued, starved
def test_a_controller_stopped_mid_trial_longer_than_its_tick_time_out_resumes_the_run(tmp_path):
    """SIGSTOP of the controller while its body waits on it, for longer than timeouts.tick (1 s) and the 3-s lease
    that used to kill it (issue 34): the run says it waits, goes on after SIGCONT, and its records are a quiet run's,
    with no trial retried."""
    out = tmp_path / "run"
    sets = ["protocol.trials=8", "modules.body.params.duration=3", "record.body_every=0", "timeouts.tick=1"]
    proc = start_sfl_run(WALKER, out, *sets)
    stderr = Lines(proc.stderr)
    try:
        wait_for_trials(out, 2, proc)
        controller = module_process(proc, "controller")
        controller.suspend()
        stderr.expect("module `controller` is stopped", 60)  # the run waits on it: a trial is in flight
        with pytest.raises(subprocess.TimeoutExpired):
            proc.wait(timeout=5)  # stopped 5 s more: the run neither fails nor gives up on it
        controller.resume()
        stderr.expect("module `controller` runs again", 60)
        assert proc.wait(timeout=180) == 0, "".join(stderr.lines)
    finally:
        proc.kill()
    rows = read_records(out)
    assert not [r for r in rows if r["kind"] == "retry"]
    assert stable(rows) == stable(run_local(load(WALKER, sets)))


def test_a_process_seen_stopped_is_said_to_run_again_when_the_run_no_longer_waits_on_it(tmp_path):
    """A CI run at c37a163: the controller was continued and the run's last trial ended before the watch's next look,
    so the run said it waited on it and never that it ran again. A real stopped process: told stopped while a
    request waits on it; continued and its request answered, told running at the next look (or when the run stops,
    :meth:`HangWatch.settle`); gone, never told running."""
    plan = load(WALKER)
    events, told = Events(), []
    events.subscribe(ModuleStopped, lambda e: told.append((e.name, e.stopped)))
    watch = HangWatch(plan, events)
    board = ProgressBoard(tmp_path, [i.name for i in plan.instances])
    instances = {i.name: i for i in plan.instances}
    procs = [subprocess.Popen([sys.executable, "-c", "import time; time.sleep(600)"]) for _ in range(2)]
    try:
        names = ["acc", "ofc"]
        children = {name: Child(instances[name], tmp_path / name, proc, alive=True) for name, proc in zip(names, procs)}
        pending = {1: Pending("acc", Ack()), 2: Pending("ofc", Ack())}
        for proc in procs:
            proc.send_signal(signal.SIGSTOP)
        poll_until(lambda: all(cpu_sample(p.pid).state in "Tt" for p in procs), "both to stop", 30)
        list(watch.hung(board, children, pending))
        assert sorted(told) == [("acc", True), ("ofc", True)]
        for proc in procs:
            proc.send_signal(signal.SIGCONT)
        poll_until(lambda: all(cpu_sample(p.pid).state not in "Tt" for p in procs), "both to run again", 30)
        pending[1].done = pending[2].done = True  # answered: the run no longer waits on them
        time.sleep(WATCH_PERIOD)  # the watch looks again
        list(watch.hung(board, children, {1: pending[1]}))
        assert sorted(told[2:]) == [("acc", False), ("ofc", False)]
        # stopped again, then continued, and the run stops before its next look: said when it stops
        procs[0].send_signal(signal.SIGSTOP)
        poll_until(lambda: cpu_sample(procs[0].pid).state in "Tt", "it to stop", 30)
        time.sleep(WATCH_PERIOD)
        list(watch.hung(board, children, {3: Pending("acc", Ack())}))
        procs[0].send_signal(signal.SIGCONT)
        poll_until(lambda: cpu_sample(procs[0].pid).state not in "Tt", "it to run again", 30)
        watch.settle(children)
        assert told[4:] == [("acc", True), ("acc", False)]
        # stopped, then gone: not said to run again
        procs[1].send_signal(signal.SIGSTOP)
        poll_until(lambda: cpu_sample(procs[1].pid).state in "Tt", "it to stop", 30)
        time.sleep(WATCH_PERIOD)
        list(watch.hung(board, children, {4: Pending("ofc", Ack())}))
        procs[1].kill()
        procs[1].wait()
        watch.settle(children)
        assert told[6:] == [("ofc", True)]
    finally:
        board.close()
        for proc in procs:
            proc.kill()
            proc.wait()


#: a busy loop ends by itself after this many seconds, should the test that started it be killed before it kills them
LOOP_DEADLINE = 600


def spun(loop: subprocess.Popen) -> bool:
    """Whether a busy loop has used some CPU; a loop that died fails the test, naming its exit."""
    sample = cpu_sample(loop.pid)
    assert sample is not None and loop.poll() is None, f"a busy loop ended: exit {loop.poll()}"
    return sample.cpu > 0.05


def busy_loops(count: int, cpu: int | None = None) -> list[subprocess.Popen]:
    """``count`` processes that spin, at nice 0, on the cores this test may use (on core ``cpu`` only, if given),
    each for LOOP_DEADLINE s at most. Each is a session of its own: where the kernel groups the scheduler's shares by
    session (autogroup, on by default in many distributions), a session's processes share one slice, and each module
    of a run is a session of its own (``setsid``), so loops in the test's own session would take one slice between
    them and starve nothing."""
    pin = None if cpu is None else (lambda: os.sched_setaffinity(0, {cpu}))
    spin = f"import time\nend = time.monotonic() + {LOOP_DEADLINE}\nwhile time.monotonic() < end: pass"
    return [
        subprocess.Popen([sys.executable, "-c", spin], start_new_session=True, preexec_fn=pin) for _ in range(count)
    ]


def test_a_run_at_nice_10_beside_more_busy_processes_than_cores_gives_a_quiet_runs_records(tmp_path):
    """Starved far past its time-outs (a trial's 0.15 s, a tick's 0.15 s, a request's 0.4 s, all counted only while a
    process could run), the run completes with a quiet run's records; its trials took longer than ``timeouts.trial``
    in wall time, which the run before issue 34 capped. The run and two busy loops share one core, each loop a
    session of its own. With the kernel's autogroup on, a session competes at its group's nice: the run's modules
    carry their nice 10 to their sessions' groups (checked here), so the run gets about a twentieth of the core (nice
    10 against two at 0, as without autogroup). Before that, every session got an equal slice whatever its nice, and
    three loops on two cores slowed a 3-s trial only from 31 ms quiet to 34-87 ms. Only the trials that start after the
    loops spin are counted (a quiet trial takes about 30 ms, so several may end while the loops start), at least 3."""
    out = tmp_path / "run"
    sets = [
        "protocol.trials=16",
        "modules.body.params.duration=3",
        "record.body_every=0",
        "timeouts.trial=0.15",
        "timeouts.tick=0.15",
        "timeouts.request=0.4",
    ]
    cpu = next(reversed(usable_cpus()), None)

    def nice_on_one_core():
        os.nice(10)
        if cpu is not None:
            os.sched_setaffinity(0, {cpu})

    proc = start_sfl_run(WALKER, out, *sets, preexec_fn=nice_on_one_core, start_new_session=True)
    loops = []
    try:
        wait_for_trials(out, 1, proc)
        body = module_process(proc, "body")
        niced = min(os.nice(0) + 10, 19)  # nice -n 10 from wherever the tests run
        assert body.nice() == niced
        if os.path.exists(f"/proc/{body.pid}/autogroup"):  # its session keeps the nice too (keep_nice_in_own_session)
            assert Path(f"/proc/{body.pid}/autogroup").read_text().split()[-1] == str(niced)
        loops = busy_loops(2, cpu)
        poll_until(lambda: all(spun(loop) for loop in loops), "the loops to spin", 30)
        spinning_at = trials_recorded(out)  # trials up to this one (in flight, or next) may have started before
        wait_for_trials(out, 16, proc, timeout=300)
    except BaseException:  # a failed check: the run's whole process group goes too, not only the loops
        os.killpg(proc.pid, signal.SIGKILL)
        raise
    finally:
        for loop in loops:  # the run's own end (merging its recording) needs no load
            loop.kill()
            loop.wait()
    _, stderr = proc.communicate(timeout=300)
    assert proc.returncode == 0, stderr
    rows = read_records(out)
    assert stable(rows) == stable(run_local(load(WALKER, sets)))
    loaded = [r["wall_ms"] for r in rows if r["kind"] == "trial"][spinning_at + 1 :]
    assert len(loaded) >= 3, f"only {len(loaded)} trials started after the loops spun ({spinning_at} before)"
    assert min(loaded) > 150, f"the loops did not slow every trial past timeouts.trial: {loaded}"


# ---------------------------------------------------------------- a hung module is still found
HUNG_VIGILANCE = """
from sfl_brain.messages import TrialDone
from sfl_brain.module import on
from sfl_brain.modules.vigilance import Vigilance


class HungVigilance(Vigilance):
    @on(TrialDone)
    def on_trial_done(self, msg):
        while msg.trial_index == 4:  # an infinite loop in a handler
            pass
        return super().on_trial_done(msg)
"""

HUNG_BODY = """
from pathlib import Path

from sfl_brain.bodies.analytic import AnalyticBody


class HungOnce(AnalyticBody):
    def start_trial(self, request):
        marker = Path(__file__).with_suffix(".hung")
        if request.trial_id == 3 and not marker.exists():
            marker.write_text("hung")
            while True:  # spins in its trial: once in the run
                pass
        super().start_trial(request)
"""


def test_a_brain_module_that_loops_forever_in_a_handler_fails_the_run_naming_it(tmp_path):
    (tmp_path / "hung.py").write_text(HUNG_VIGILANCE)
    out = tmp_path / "run"
    sets = ["protocol.trials=10", f"modules.vigilance.impl={tmp_path / 'hung.py'}:HungVigilance", "timeouts.request=2"]
    proc = start_sfl_run(LEARN, out, *sets)
    _, stderr = proc.communicate(timeout=180)
    assert proc.returncode == 1, stderr
    reason = json.loads((out / "summary.json").read_text())["stop_reason"]
    assert reason.startswith("module `vigilance` is hung: for ") and "did not finish answering" in reason, reason
    assert "(timeouts.request is 2 s)" in reason and "vigilance ready" in reason  # its log tail
    assert f"resume: sfl run --resume {out}" in stderr
    trials = [r["trial"] for r in read_records(out) if r["kind"] == "trial"]
    assert trials == [0, 1, 2]  # trial 3 waits for its vigilance for good


def test_a_body_worker_that_spins_in_a_trial_is_killed_restarted_and_its_trial_retried(tmp_path):
    (tmp_path / "hung_body.py").write_text(HUNG_BODY)
    out = tmp_path / "run"
    sets = ["protocol.trials=8", "timeouts.trial=2"]
    proc = start_sfl_run(LEARN, out, *sets, f"modules.body.impl={tmp_path / 'hung_body.py'}:HungOnce")
    _, stderr = proc.communicate(timeout=180)
    assert proc.returncode == 0, stderr
    assert "module `body` is hung: for " in stderr and "did not finish answering `body.trial`" in stderr, stderr
    assert "module `body` was hung: it could run for" in stderr and "killed; restarting (1/3)" in stderr, stderr
    rows = read_records(out)
    (retry,) = [r for r in rows if r["kind"] == "retry"]
    assert retry["trial"] == 3 and retry["attempt"] == 1 and "hung" in retry["reason"], retry
    clean = run_local(load(LEARN, sets))
    assert stable([r for r in rows if r["kind"] != "retry"]) == stable(clean)


SPINS_AT_START = """
from sfl_brain.modules.vigilance import Vigilance


class SpinsAtStart(Vigilance):
    def reset(self, seed):
        while True:  # never comes alive
            pass
"""


def test_a_module_that_spins_before_it_comes_alive_fails_the_start_naming_it(tmp_path):
    (tmp_path / "spins.py").write_text(SPINS_AT_START)
    out = tmp_path / "run"
    sets = [f"modules.vigilance.impl={tmp_path / 'spins.py'}:SpinsAtStart", "timeouts.ready=3"]
    proc = start_sfl_run(LEARN, out, *sets)
    _, stderr = proc.communicate(timeout=180)
    assert proc.returncode == 1, stderr
    reason = json.loads((out / "summary.json").read_text())["stop_reason"]
    assert reason.startswith("modules not ready: module `vigilance` is hung: for ") and "coming alive" in reason, reason
    assert "(timeouts.ready is 3 s)" in reason


def test_the_supervisor_stopped_and_continued_goes_on_with_its_run(tmp_path):
    """Ctrl-Z on ``sfl run`` (SIGSTOP of the supervisor alone: its modules run in sessions of their own) for longer
    than the 3-s lease its modules used to hold it to, then ``fg``: the run goes on with a quiet run's records."""
    out = tmp_path / "run"
    sets = ["protocol.trials=60"]
    proc = start_sfl_run(LEARN, out, *sets)
    try:
        wait_for_trials(out, 10, proc)
        proc.send_signal(signal.SIGSTOP)
        with pytest.raises(subprocess.TimeoutExpired):
            proc.wait(timeout=5)  # stopped: it cannot end
        proc.send_signal(signal.SIGCONT)
        _, stderr = proc.communicate(timeout=180)
        assert proc.returncode == 0, stderr
    finally:
        proc.kill()
    assert stable(read_records(out)) == stable(run_local(load(LEARN, sets)))
