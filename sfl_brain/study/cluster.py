"""``sfl study --cluster``: the runs of a study as tasks on a Dask cluster (``pip install 'sfl-brain[cluster]'``).

Each run is one task (:func:`run_on_worker`): the study sends the run's self-contained scenario (``scenario.yaml``
and the files it names, as ``sfl run`` copies them into ``inputs/``) as a tar archive; the task runs ``sfl run`` on
its worker in a temporary folder, says ``started`` and its trials so far as Dask events on the study's topic, and
returns the run folder's files as a tar archive, which :class:`DaskRunner` unpacks into the study folder. Nothing
needs a shared file system. The study stops its running tasks by setting a Dask event they watch.

Importing this module does not import Dask; :func:`connect` says in one line when it is missing.
"""

from __future__ import annotations

import contextlib
import io
import os
import queue
import shutil
import signal
import socket
import subprocess
import sys
import tarfile
import tempfile
import time
import uuid
from collections.abc import Iterator
from pathlib import Path

import yaml

from ..scenario.plan import Plan
from ..status import BadInput, RunStatus
from .study import (
    STOP_GRACE,
    Outcome,
    RunFinished,
    RunProgress,
    RunStarted,
    StudyEvent,
    StudyRun,
    TrialCounter,
    finished,
    interrupt,
    sfl_run_command,
    start_sfl_run,
)

#: s a Dask scheduler is given to answer ``--cluster``
CONNECT_TIMEOUT = 5.0


def tar_folder(folder: Path) -> bytes:
    """The files under ``folder`` as an uncompressed tar archive (its parquet, npz and rrd are compressed)."""
    buffer = io.BytesIO()
    with tarfile.open(fileobj=buffer, mode="w") as tar:
        for path in sorted(folder.rglob("*")):
            tar.add(path, arcname=str(path.relative_to(folder)), recursive=False)
    return buffer.getvalue()


def untar(data: bytes, folder: Path) -> None:
    """Unpack :func:`tar_folder`'s archive into ``folder`` (only plain files and folders inside it)."""
    folder.mkdir(parents=True, exist_ok=True)
    with tarfile.open(fileobj=io.BytesIO(data), mode="r") as tar:
        tar.extractall(folder, filter="data")


def scenario_bundle(plan: Plan) -> bytes:
    """A run's self-contained scenario (``scenario.yaml`` and its ``inputs/``) as a tar archive for a worker."""
    from ..runtime.run import self_contained

    with tempfile.TemporaryDirectory(prefix="sfl-study-") as tmp:
        folder = Path(tmp)
        resolved = self_contained(plan, folder)
        (folder / "scenario.yaml").write_text(yaml.safe_dump(resolved, sort_keys=False))
        return tar_folder(folder)


def run_on_worker(name: str, bundle: bytes, topic: str, stop_event: str) -> dict:
    """A Dask task: run one study run with ``sfl run`` on this worker, in a temporary folder, and return its
    files. Says ``started`` and its trials so far as events on ``topic``; stops the run (as Ctrl-C does) when
    the study sets the Dask event ``stop_event``."""
    from distributed import Event, get_worker

    worker = get_worker()
    stop = Event(stop_event)
    where = f"{socket.gethostname()} {worker.address}"
    if stop.is_set():
        return {"exit_code": None, "files": None, "where": where, "trials": 0, "wall_s": 0.0}
    with tempfile.TemporaryDirectory(prefix="sfl-study-") as tmp:
        untar(bundle, Path(tmp) / "in")
        run_dir = Path(tmp) / "run"
        proc = start_sfl_run(sfl_run_command(Path(tmp) / "in" / "scenario.yaml", run_dir), run_dir)
        started = time.monotonic()
        worker.log_event(topic, {"run": name, "started": where})
        counter = TrialCounter(run_dir / "records.jsonl")
        while proc.poll() is None:
            with contextlib.suppress(subprocess.TimeoutExpired):
                proc.wait(timeout=1.0)
            if counter.poll():
                worker.log_event(topic, {"run": name, "trials": counter.trials, "successes": counter.successes})
            if proc.poll() is None and stop.is_set():
                interrupt([proc])
        counter.poll()
        return {
            "exit_code": proc.returncode,
            "files": tar_folder(run_dir),
            "where": where,
            "trials": counter.trials,
            "wall_s": time.monotonic() - started,
        }


def connect(address: str, timeout: float = CONNECT_TIMEOUT):
    """A Dask client of the scheduler at ``address`` (or named by a scheduler file); :class:`BadInput` in one line
    when Dask is not installed or no scheduler answers within ``timeout`` s."""
    try:
        import distributed
    except ImportError:
        raise BadInput("--cluster needs Dask: pip install 'sfl-brain[cluster]'") from None
    scheduler_file = Path(address).is_file()
    what = f"--cluster {address}"
    try:
        if scheduler_file:
            return distributed.Client(scheduler_file=address, timeout=timeout, set_as_default=False)
        return distributed.Client(address, timeout=timeout, set_as_default=False)
    except (OSError, TimeoutError) as exc:
        said = str(exc).splitlines()[0][:160] if str(exc) else type(exc).__name__
        raise BadInput(f"{what}: no Dask scheduler answered within {timeout:g} s ({said})") from None
    except (ValueError, TypeError) as exc:
        raise BadInput(f"{what}: not a Dask scheduler address or scheduler file ({exc})") from None


class DaskRunner:
    """Runs of a study as tasks on a Dask cluster (every run submitted at once; the scheduler queues them)."""

    def __init__(self, client, out: Path, plans: dict[str, Plan]) -> None:
        self.client, self.out, self.plans = client, out, plans
        token = uuid.uuid4().hex[:8]
        self.topic = f"sfl-study-{token}"
        self.stop_name = f"sfl-study-stop-{token}"
        self.inbox: queue.Queue = queue.Queue()  # filled on the client's thread, read by the study's loop
        self.futures: dict[str, object] = {}
        self.started: dict[str, tuple[float, str]] = {}
        self.trials: dict[str, int] = {}
        self.cancelled: set[str] = set()
        client.subscribe_topic(self.topic, lambda event: self.inbox.put(("event", event[1])))

    def describe(self) -> str:
        workers = self.client.scheduler_info().get("workers", {})
        threads = sum(w.get("nthreads", 0) for w in workers.values())
        text = f"Dask scheduler {self.client.scheduler.address}: {len(workers)} workers, {threads} threads"
        return text + ("" if workers else " (no worker yet: runs wait for one)")

    def has_room(self) -> bool:
        return True

    def busy(self) -> bool:
        return bool(self.futures)

    def start(self, run: StudyRun) -> Iterator[StudyEvent]:
        bundle = scenario_bundle(self.plans[run.name])
        future = self.client.submit(
            run_on_worker,
            run.name,
            bundle,
            self.topic,
            self.stop_name,
            key=f"sfl-run-{run.name}-{uuid.uuid4().hex[:8]}",
            pure=False,
        )
        future.add_done_callback(lambda f, name=run.name: self.inbox.put(("done", name)))
        self.futures[run.name] = future
        return iter(())

    def poll(self, timeout: float) -> Iterator[StudyEvent]:
        deadline = time.monotonic() + timeout
        while True:
            try:
                kind, item = self.inbox.get(timeout=max(0.0, deadline - time.monotonic()))
            except queue.Empty:
                return
            if kind == "event" and item.get("run") in self.futures:
                name = item["run"]
                if "started" in item:
                    self.started[name] = (time.monotonic(), item["started"])
                    yield RunStarted(name, item["started"])
                else:
                    self.trials[name] = item["trials"]
                    yield RunProgress(name, item["trials"], item["successes"])
            elif kind == "done" and item in self.futures:
                yield RunFinished(item, self._collect(item))

    def _collect(self, name: str) -> Outcome:
        future = self.futures.pop(name)
        began, where = self.started.get(name, (time.monotonic(), "a Dask worker"))
        if name in self.cancelled:
            future.release()
            return Outcome(str(RunStatus.INTERRUPTED), "stopped before it started", None, 0, None, where)
        try:
            result = future.result()
        except BaseException as exc:  # noqa: BLE001 - the task failed or its workers died
            if isinstance(exc, KeyboardInterrupt):
                raise
            reason = f"the Dask task failed on {where}: {type(exc).__name__}: {exc}"
            return Outcome(str(RunStatus.FAILED), reason, None, self.trials.get(name, 0), None, where)
        finally:
            future.release()
        if result["files"] is None:
            return Outcome(str(RunStatus.INTERRUPTED), "stopped before it started", None, 0, None, result["where"])
        incoming = self.out / f".incoming-{name}"
        shutil.rmtree(incoming, ignore_errors=True)
        untar(result["files"], incoming)
        incoming.rename(self.out / name)
        return finished(self.out / name, result["exit_code"], result["trials"], result["wall_s"], result["where"])

    def stop(self) -> Iterator[StudyEvent]:
        """Ask every task to stop its run (a Dask event the tasks watch); cancel the ones not started."""
        from distributed import Event

        Event(self.stop_name, client=self.client).set()
        self.cancelled = {n for n in self.futures if n not in self.started}
        self.client.cancel([self.futures[n] for n in self.cancelled])
        deadline = time.monotonic() + STOP_GRACE + 10.0
        while self.futures and time.monotonic() < deadline:
            try:
                yield from self.poll(min(1.0, deadline - time.monotonic()))
            except KeyboardInterrupt:  # asked again: do not wait for them
                break
        for name, future in list(self.futures.items()):
            self.client.cancel([future])
            del self.futures[name]
            where = self.started.get(name, (0, "a Dask worker"))[1]
            stopped = Outcome("interrupted", "stopped by the study", None, self.trials.get(name, 0), None, where)
            yield RunFinished(name, stopped)

    def close(self) -> None:
        with contextlib.suppress(Exception):
            self.client.unsubscribe_topic(self.topic)
        with contextlib.suppress(Exception):
            self.client.close(timeout=5)


@contextlib.contextmanager
def loopback_cluster(folder: Path, workers: int = 2, cores: list[list[int]] | None = None) -> Iterator[Path]:
    """A Dask cluster on 127.0.0.1, started as on machines: ``dask scheduler`` and ``workers`` ``dask worker``
    processes of one thread each (worker i on ``cores[i]`` if given), every server and dashboard on loopback, each
    in a process group of its own, stopped (SIGTERM, then SIGKILL) on leaving. Yields the scheduler file. For tests
    and benchmarks; their output goes to ``folder/dask.log``."""
    import distributed

    scheduler_file = Path(folder) / "scheduler.json"
    loopback = ["--host", "127.0.0.1", "--dashboard-address", "127.0.0.1:0"]
    procs: list[subprocess.Popen] = []
    log = open(Path(folder) / "dask.log", "ab")  # noqa: SIM115 - closed below

    def dask(*args: str, cpus: list[int] | None = None) -> subprocess.Popen:
        proc = subprocess.Popen(
            [sys.executable, "-m", "dask", *args, *loopback],
            stdout=log,
            stderr=subprocess.STDOUT,
            start_new_session=True,
        )
        if cpus is not None:  # before it starts its worker process, which inherits them
            os.sched_setaffinity(proc.pid, cpus)
        procs.append(proc)
        return proc

    try:
        scheduler = dask("scheduler", "--port", "0", "--scheduler-file", str(scheduler_file))
        deadline = time.monotonic() + 60
        while not scheduler_file.exists():
            if scheduler.poll() is not None or time.monotonic() > deadline:
                raise RuntimeError(f"the Dask scheduler did not start (see {Path(folder) / 'dask.log'})")
            time.sleep(0.05)
        for i in range(workers):
            cpus = cores[i % len(cores)] if cores else None
            dask("worker", "--scheduler-file", str(scheduler_file), "--nthreads", "1", "--nworkers", "1", cpus=cpus)
        with distributed.Client(scheduler_file=str(scheduler_file), timeout=30) as client:
            client.wait_for_workers(workers, timeout=60)
        yield scheduler_file
    finally:
        for proc in reversed(procs):
            with contextlib.suppress(ProcessLookupError):
                os.killpg(proc.pid, signal.SIGTERM)
        deadline = time.monotonic() + 10
        for proc in procs:
            try:
                proc.wait(timeout=max(0.1, deadline - time.monotonic()))
            except subprocess.TimeoutExpired:
                with contextlib.suppress(ProcessLookupError):
                    os.killpg(proc.pid, signal.SIGKILL)
                proc.wait()
        log.close()
