"""``sfl study``: one run per combination of ``--vary`` values and ``--seeds``, several at once, resumable.

The cycle is visible in :func:`run_study`: start runs while there is room, read what the running ones say
(trials so far, an end), show it, until none is left. Where the runs go is a *runner*:

- :class:`LocalRunner` (``--jobs N``): each run a child ``sfl run ... --quiet`` process on this machine,
  ``N`` at once, each on its own share of the usable cores (so that two runs never pin their lockstep pairs
  to the same core); its trials so far read from the growth of its ``records.jsonl``.
- :class:`DaskRunner` (``--cluster ADDRESS``): each run a task on a running Dask cluster; the task runs
  ``sfl run`` on its worker in a temporary folder, says its trials so far as Dask events, and returns the
  run folder's files (a tar archive), which land in the study folder. Nothing needs a shared file system.

A study folder holds a folder per run (``<varied values>_seed<S>``), ``study.json`` (the command and each
run's last outcome) and, after the report, ``report/``. Run again with the same command, a study skips every
run whose folder ended ``completed`` or ``stalled`` (a stalled run is the protocol's own end and the same
seed stalls again) and runs again, from scratch, every run that is missing, unfinished (killed), interrupted
or failed; the folder of such a run is first moved aside to ``attempts/<name>.<n>/`` (kept for its logs, never
reported). Runs that did not complete are named at the end and in the report, and never enter a mean.
"""

from __future__ import annotations

import contextlib
import ctypes
import io
import itertools
import json
import math
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
from collections import deque
from collections.abc import Callable, Iterable, Iterator
from dataclasses import asdict, dataclass, field
from pathlib import Path

import yaml

from .records import run_status
from .scenario import Plan, load
from .status import BadInput, RunStatus

#: the study's record of itself, in the study folder
MANIFEST = "study.json"
#: where the folders of unfinished, interrupted or failed runs are moved before they run again
ATTEMPTS = "attempts"
#: a child ``sfl run``'s own output (its stdout and stderr), in its run folder
RUN_LOG = "sfl-run.log"
#: run endings that are kept when the study runs again (a stalled run stalls again with the same seed)
FINAL = (RunStatus.COMPLETED, RunStatus.STALLED)
#: s a run is given to stop after an interrupt before it is asked again (its records, summary and recording)
STOP_GRACE = 30.0
#: s a Dask scheduler is given to answer ``--cluster``
CONNECT_TIMEOUT = 5.0


# --------------------------------------------------------------------------- what the study runs
@dataclass(frozen=True)
class StudyRun:
    """One run of a study: its folder name, its ``--set`` overrides (the study's, then its varied values) and seed."""

    name: str
    sets: tuple[str, ...]
    seed: int | None
    #: trials its protocol plans (None: not known before it runs)
    planned: int | None


def parse_vary(items: Iterable[str]) -> list[list[tuple[str, str]]]:
    """``KEY.PATH=V1,V2,...`` options as axes of (key, value) pairs; :class:`BadInput` names a bad one."""
    axes = []
    for item in items:
        key, sep, values = item.partition("=")
        split = [v.strip() for v in values.split(",")]
        if not sep or not key or not all(split):
            raise BadInput(f"--vary {item!r}: expected KEY.PATH=V1,V2,...")
        twice = sorted({v for v in split if split.count(v) > 1})
        if twice:
            raise BadInput(f"--vary {key}: {', '.join(twice)} given twice")
        axes.append([(key, v) for v in split])
    return axes


def parse_seeds(text: str) -> list[int | None]:
    """``S1,S2,...`` as seeds ([None]: the scenario's own); :class:`BadInput` when they are not whole numbers."""
    try:
        seeds = [int(x) for x in text.split(",") if x.strip()]
    except ValueError:
        raise BadInput(f"--seeds {text!r}: expected integers separated by commas") from None
    if len(set(seeds)) != len(seeds):
        raise BadInput(f"--seeds {text!r}: a seed given twice")
    return seeds or [None]


def run_name(combo: Iterable[tuple[str, str]], seed: int | None) -> str:
    """A run's folder name: each varied key's last part and value, then the seed (``value-0.3_seed1``)."""
    name = "_".join(f"{k.rsplit('.', 1)[-1]}{v}" for k, v in combo).replace(os.sep, "-") or "run"
    return name + ("" if seed is None else f"_seed{seed}")


def planned_trials(plan: Plan) -> int | None:
    """The trials a plan's protocol runs when it completes (None where that is not known before it runs)."""
    proto = plan.scenario.protocol
    if proto.kind == "sweep":
        steps = [a.steps for a in plan.scenario.space]
        return math.prod(steps) if all(steps) else None
    trials = getattr(proto, "trials", None)
    return int(trials) if isinstance(trials, int) else None


def plan_study(scenario: str, vary: Iterable[str], seeds: str, overrides: Iterable[str]) -> list[tuple[StudyRun, Plan]]:
    """Every run of the study with its checked plan, in order (values, then seeds). Raises
    :class:`BadInput` for a bad option and :class:`~sfl_brain.scenario.ScenarioError` for a bad combination,
    before anything runs."""
    axes = parse_vary(vary)
    runs = []
    for combo in itertools.product(*axes):
        for seed in parse_seeds(seeds):
            sets = (*overrides, *(f"{k}={v}" for k, v in combo))
            plan = load(scenario, list(sets), seed)
            runs.append((StudyRun(run_name(combo, seed), sets, seed, planned_trials(plan)), plan))
    return runs


# --------------------------------------------------------------------------- the study folder
def self_contained_scenario(plan: Plan) -> dict:
    """The scenario a run of ``plan`` writes as its ``scenario.yaml`` (module files and maps under ``inputs/``)."""
    from .run import self_contained

    with tempfile.TemporaryDirectory(prefix="sfl-study-") as tmp:
        return _plain(self_contained(plan, Path(tmp)))


def _plain(value):
    """``value`` as a YAML round trip gives it back (tuples as lists): what a stored scenario compares with."""
    return yaml.safe_load(yaml.safe_dump(value, sort_keys=False))


def first_difference(a, b, path: str = "") -> str | None:
    """The first key path where two scenarios differ (None when they are the same)."""
    if isinstance(a, dict) and isinstance(b, dict):
        for key in list(a) + [k for k in b if k not in a]:
            where = f"{path}.{key}" if path else str(key)
            if key not in a or key not in b:
                return where
            found = first_difference(a[key], b[key], where)
            if found:
                return found
        return None
    return None if a == b else (path or "(the whole scenario)")


@dataclass(frozen=True)
class Triage:
    """What a study folder holds for this study's runs: runs kept as they are, runs to run, folders moved aside."""

    kept: list[tuple[StudyRun, str]]  # (run, status)
    todo: list[StudyRun]
    moved: list[tuple[str, str, Path]]  # (name, status it had, where it went)


def triage(out: Path, runs: list[tuple[StudyRun, Plan]]) -> Triage:
    """Sort the runs by what ``out`` holds of them. A kept folder made from other settings is :class:`BadInput`
    (a study folder is never mixed); a folder to run again is moved to ``attempts/<name>.<n>/``."""
    kept, todo, moved = [], [], []
    for run, plan in runs:
        folder = out / run.name
        if not folder.exists():
            todo.append(run)
            continue
        status, _ = run_status(folder)
        if status in FINAL:
            try:
                stored = yaml.safe_load((folder / "scenario.yaml").read_text())
            except (OSError, yaml.YAMLError):
                stored = None
            differs = first_difference(stored, self_contained_scenario(plan))
            if differs:
                raise BadInput(
                    f"{folder} holds a {status} run made with another `{differs}` than this study's; "
                    "run this study into another --out (or move that folder away)"
                )
            kept.append((run, status))
            continue
        target = out / ATTEMPTS / f"{run.name}.1"
        n = 1
        while target.exists():
            n += 1
            target = out / ATTEMPTS / f"{run.name}.{n}"
        target.parent.mkdir(parents=True, exist_ok=True)
        folder.rename(target)
        moved.append((run.name, status, target))
        todo.append(run)
    return Triage(kept, todo, moved)


def write_manifest(out: Path, study: dict, runs: list[StudyRun], outcomes: dict[str, Outcome]) -> None:
    """``study.json``: the command, every run (name, overrides, seed) and the last outcome of each."""
    previous = read_manifest(out).get("outcomes", {})
    record = {
        **study,
        "runs": [asdict(r) for r in runs],
        "outcomes": {**previous, **{name: asdict(o) for name, o in outcomes.items()}},
    }
    tmp = out / f".{MANIFEST}.tmp"
    tmp.write_text(json.dumps(record, indent=1) + "\n")
    tmp.replace(out / MANIFEST)


def read_manifest(out: Path) -> dict:
    """The study's ``study.json`` ({} when there is none or it cannot be read)."""
    try:
        loaded = json.loads((Path(out) / MANIFEST).read_text())
    except (OSError, ValueError):
        return {}
    return loaded if isinstance(loaded, dict) else {}


# --------------------------------------------------------------------------- how runs report
@dataclass(frozen=True)
class Outcome:
    """How a run of the study ended (``status`` as :mod:`sfl_brain.status`, or ``unfinished``)."""

    status: str
    reason: str
    exit_code: int | None
    trials: int
    wall_s: float | None
    where: str
    kept: bool = False


@dataclass(frozen=True)
class RunStarted:
    name: str
    where: str


@dataclass(frozen=True)
class RunProgress:
    name: str
    trials: int
    successes: int


@dataclass(frozen=True)
class RunFinished:
    name: str
    outcome: Outcome


StudyEvent = RunStarted | RunProgress | RunFinished


class TrialCounter:
    """The trials (and successes) of a run so far, read from its growing ``records.jsonl`` (whole lines only)."""

    def __init__(self, path: Path) -> None:
        self.path = path
        self.offset = 0
        self.partial = b""
        self.trials = 0
        self.successes = 0

    def poll(self) -> bool:
        """Read what was appended since the last call; True when the trial count changed."""
        try:
            with open(self.path, "rb") as f:
                f.seek(self.offset)
                data = f.read()
        except OSError:
            return False
        self.offset += len(data)
        *lines, self.partial = (self.partial + data).split(b"\n")
        before = self.trials
        for line in lines:
            if b'"kind":"trial"' not in line:
                continue
            try:
                row = json.loads(line)
            except ValueError:
                continue
            self.trials += 1
            self.successes += bool(row.get("success"))
        return self.trials != before


def finished(run_dir: Path, exit_code: int | None, trials: int, wall_s: float, where: str) -> Outcome:
    """A run's outcome from its folder's summary; a process that ended without one is ``failed``, saying how."""
    status, reason = run_status(run_dir)
    stored_wall = None
    with contextlib.suppress(OSError, ValueError, AttributeError):
        stored_wall = json.loads((run_dir / "summary.json").read_text()).get("wall_time_s")
    if status == "unfinished":
        how = f"was killed by signal {-exit_code}" if exit_code is not None and exit_code < 0 else None
        how = how or f"exited with code {exit_code}"
        status = RunStatus.FAILED
        reason = f"`sfl run` {how} and wrote no summary.json (its output: {run_dir / RUN_LOG})"
    return Outcome(str(status), reason, exit_code, trials, stored_wall if stored_wall is not None else wall_s, where)


def kept_outcomes(out: Path, kept: list[tuple[StudyRun, str]]) -> dict[str, Outcome]:
    """The outcomes of the runs a study keeps from before, from their folders."""
    from .records import inspect_run

    outcomes = {}
    for run, status in kept:
        counts = inspect_run(out / run.name)
        reason, trials, wall = counts["stop_reason"], counts["trials"], counts["wall_time_s"]
        outcomes[run.name] = Outcome(status, reason, None, trials, wall, "kept from before", kept=True)
    return outcomes


# --------------------------------------------------------------------------- child processes
_PR_SET_PDEATHSIG = 1


def _libc_prctl():
    try:
        return ctypes.CDLL(None, use_errno=True).prctl
    except (OSError, AttributeError):  # not Linux: a child outlives a killed study there
        return None


_PRCTL = _libc_prctl() if sys.platform.startswith("linux") else None


def _stop_with_parent() -> None:
    """In the child, before exec: SIGTERM when the process that started it dies (even by kill -9), so that a
    killed study leaves no run behind (it stops as after Ctrl-C and writes its summary)."""
    if _PRCTL is not None:
        _PRCTL(_PR_SET_PDEATHSIG, signal.SIGTERM, 0, 0, 0)


def sfl_run_command(scenario: str | Path, run_dir: Path, sets: Iterable[str] = (), seed: int | None = None) -> list:
    """The ``sfl run ... --quiet`` command line of one run."""
    command = [sys.executable, "-m", "sfl_brain.cli", "run", str(scenario)]
    command += [arg for s in sets for arg in ("--set", s)]
    command += ["--seed", str(seed)] if seed is not None else []
    return [*command, "--out", str(run_dir), "--quiet"]


def start_sfl_run(command: list, run_dir: Path) -> subprocess.Popen:
    """Start a child ``sfl run`` in a session of its own (a terminal's Ctrl-C reaches the study, which stops it),
    its output to ``run_dir/sfl-run.log``; it stops when the process that started it dies."""
    run_dir.mkdir(parents=True, exist_ok=True)
    with open(run_dir / RUN_LOG, "ab") as log:
        return subprocess.Popen(
            command,
            stdin=subprocess.DEVNULL,
            stdout=log,
            stderr=subprocess.STDOUT,
            start_new_session=True,
            preexec_fn=_stop_with_parent if _PRCTL is not None else None,  # noqa: PLW1509 - one prctl call
        )


def interrupt(procs: Iterable[subprocess.Popen], grace: float = STOP_GRACE) -> None:
    """Stop child ``sfl run`` processes as Ctrl-C stops one (SIGINT: it stops its modules and writes its summary);
    after ``grace`` s, or at a second Ctrl-C, the second SIGINT (its modules killed at once), then SIGKILL."""
    procs = [p for p in procs if p.poll() is None]
    for step, wait in ((signal.SIGINT, grace), (signal.SIGINT, 5.0), (signal.SIGKILL, 5.0)):
        for proc in procs:
            with contextlib.suppress(ProcessLookupError):
                proc.send_signal(step)
        deadline = time.monotonic() + wait
        try:
            for proc in procs:
                with contextlib.suppress(subprocess.TimeoutExpired):
                    proc.wait(timeout=max(0.0, deadline - time.monotonic()))
        except KeyboardInterrupt:  # asked again: the next step now
            pass
        procs = [p for p in procs if p.poll() is None]
        if not procs:
            return


def core_slots(cpus: list[int], jobs: int) -> list[list[int] | None]:
    """The cores each of ``jobs`` runs at once may use: the usable cores shared out in contiguous blocks (with more
    jobs than cores, a core each in turn); None where the OS has no CPU affinity, or for a single job (all)."""
    if not cpus or jobs == 1:
        return [None] * jobs
    if jobs <= len(cpus):
        return [cpus[i * len(cpus) // jobs : (i + 1) * len(cpus) // jobs] for i in range(jobs)]
    return [[cpus[i % len(cpus)]] for i in range(jobs)]


def cores_text(cores: list[int] | None) -> str:
    if cores is None:
        return "all cores"
    if len(cores) > 1 and cores == list(range(cores[0], cores[-1] + 1)):
        return f"cores {cores[0]}-{cores[-1]}"
    return f"core{'s' if len(cores) > 1 else ''} {','.join(map(str, cores))}"


@dataclass
class _Child:
    run: StudyRun
    proc: subprocess.Popen
    slot: int
    counter: TrialCounter
    started: float


class LocalRunner:
    """Runs of a study as child ``sfl run`` processes on this machine, ``jobs`` at once."""

    def __init__(self, scenario: str, out: Path, jobs: int, cpus: list[int] | None = None) -> None:
        from .placement import usable_cpus

        self.scenario, self.out, self.jobs = scenario, out, jobs
        self.slots = core_slots(usable_cpus() if cpus is None else cpus, jobs)
        self.children: dict[str, _Child] = {}

    def describe(self) -> str:
        if all(s is None for s in self.slots):
            return f"{self.jobs} run{'s' if self.jobs > 1 else ''} at once"
        return f"{self.jobs} runs at once, on {'; '.join(cores_text(s) for s in self.slots)}"

    def has_room(self) -> bool:
        return len(self.children) < self.jobs

    def busy(self) -> bool:
        return bool(self.children)

    def start(self, run: StudyRun) -> Iterator[StudyEvent]:
        slot = min(set(range(self.jobs)) - {c.slot for c in self.children.values()})
        run_dir = self.out / run.name
        proc = start_sfl_run(sfl_run_command(self.scenario, run_dir, run.sets, run.seed), run_dir)
        cores = self.slots[slot]
        if cores is not None:
            with contextlib.suppress(OSError):  # before it reads its cores (its modules start seconds later)
                os.sched_setaffinity(proc.pid, cores)
        self.children[run.name] = _Child(run, proc, slot, TrialCounter(run_dir / "records.jsonl"), time.monotonic())
        yield RunStarted(run.name, cores_text(cores))

    def poll(self, timeout: float) -> Iterator[StudyEvent]:
        deadline = time.monotonic() + timeout
        while True:
            ended = [c for c in self.children.values() if c.proc.poll() is not None]
            if ended or time.monotonic() >= deadline:
                break
            time.sleep(min(0.05, max(0.0, deadline - time.monotonic())))
        for child in list(self.children.values()):
            if child.counter.poll():
                yield RunProgress(child.run.name, child.counter.trials, child.counter.successes)
        for child in ended:
            del self.children[child.run.name]
            child.counter.poll()
            outcome = finished(
                self.out / child.run.name,
                child.proc.returncode,
                child.counter.trials,
                time.monotonic() - child.started,
                cores_text(self.slots[child.slot]),
            )
            yield RunFinished(child.run.name, outcome)

    def stop(self) -> Iterator[StudyEvent]:
        """Interrupt every running run; each ends ``interrupted`` (or as it was ending)."""
        interrupt([c.proc for c in self.children.values()])
        for child in list(self.children.values()):
            del self.children[child.run.name]
            child.counter.poll()
            outcome = finished(
                self.out / child.run.name,
                child.proc.returncode,
                child.counter.trials,
                time.monotonic() - child.started,
                cores_text(self.slots[child.slot]),
            )
            yield RunFinished(child.run.name, outcome)

    def close(self) -> None:
        pass


# --------------------------------------------------------------------------- Dask
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
    from .run import self_contained

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


# --------------------------------------------------------------------------- the study's loop
class StudyInterrupted(Exception):
    """Ctrl-C or SIGTERM stopped the study; ``outcomes`` holds every run that ended, the stopped ones too."""

    def __init__(self, outcomes: dict[str, Outcome]) -> None:
        super().__init__("interrupted")
        self.outcomes = outcomes


@contextlib.contextmanager
def stop_on_signals() -> Iterator[None]:
    """While in the block, Ctrl-C and SIGTERM stop the study (KeyboardInterrupt in the main thread), also where
    SIGINT came ignored (a study started in the background by a shell)."""

    def on_signal(signum, frame):
        raise KeyboardInterrupt

    try:
        previous = {sig: signal.signal(sig, on_signal) for sig in (signal.SIGINT, signal.SIGTERM)}
    except ValueError:  # not the main thread
        yield
        return
    try:
        yield
    finally:
        for sig, handler in previous.items():
            signal.signal(sig, handler)


def run_study(todo: list[StudyRun], runner, show: Callable[[StudyEvent], None]) -> dict[str, Outcome]:
    """Run ``todo`` on ``runner``: start runs while there is room, pass on what they say, until none is left.
    Returns each run's outcome; raises :class:`StudyInterrupted` (after stopping every run) on Ctrl-C / SIGTERM."""
    waiting = deque(todo)
    outcomes: dict[str, Outcome] = {}

    def handle(events: Iterable[StudyEvent]) -> None:
        for event in events:
            if isinstance(event, RunFinished):
                outcomes[event.name] = event.outcome
            show(event)

    with stop_on_signals():
        try:
            while waiting or runner.busy():
                while waiting and runner.has_room():
                    handle(runner.start(waiting.popleft()))
                handle(runner.poll(0.5))
        except KeyboardInterrupt:
            try:
                handle(runner.stop())
            except KeyboardInterrupt:
                pass
            raise StudyInterrupted(outcomes) from None
    return outcomes


# --------------------------------------------------------------------------- what the terminal shows
def _duration(seconds: float) -> str:
    seconds = max(0, int(round(seconds)))
    if seconds < 120:
        return f"{seconds} s"
    if seconds < 7200:
        return f"{seconds // 60} min {seconds % 60:02d} s"
    return f"{seconds // 3600} h {seconds % 3600 // 60:02d} min"


@dataclass
class _Running:
    planned: int | None
    where: str
    since: float
    trials: int = 0
    successes: int = 0
    last_trial: float = field(default_factory=time.monotonic)
    task: object = None


class StudyView:
    """The whole study on the terminal: runs done / running / queued / failed / stalled, each running run's trials
    so far and the study's ETA (a rich view; ``quiet``: plain lines, and a status line every ``every`` s).

    Every update comes from the study's own loop (no refresh thread): :meth:`tick` redraws."""

    QUIET_AFTER = 60.0  # s without a new trial before a running run is said to be quiet

    def __init__(self, runs: list[StudyRun], kept: dict[str, Outcome], quiet: bool, every: float = 60.0) -> None:
        from rich.console import Console
        from rich.progress import BarColumn, MofNCompleteColumn, Progress, TextColumn

        self.runs = {r.name: r for r in runs}
        self.order = {r.name: i for i, r in enumerate(runs, 1)}
        self.kept = kept
        self.outcomes: dict[str, Outcome] = dict(kept)
        self.running: dict[str, _Running] = {}
        self.quiet, self.every = quiet, every
        self.console = Console(stderr=True, soft_wrap=True, highlight=False)
        self.started = time.monotonic()
        self.last_line = self.started
        self.trials_here = 0  # trials run by this invocation (the ETA's rate)
        self.bar = Progress(
            TextColumn("{task.description}"),
            BarColumn(bar_width=24),
            MofNCompleteColumn(),
            TextColumn("{task.fields[status]}"),
            console=self.console,
            auto_refresh=False,
            disable=quiet,
        )
        self.study_task = None

    def __enter__(self):
        self.bar.start()
        self.study_task = self.bar.add_task("study", total=self._planned_total(), status="")
        self.tick()
        return self

    def __exit__(self, *exc):
        self.tick()
        self.bar.stop()
        return False

    def say(self, text: str, style: str = "") -> None:
        """One whole line above the bars (or on its own when quiet)."""
        if self.quiet:
            print(text, file=sys.stderr, flush=True)
        else:
            self.bar.console.print(text, style=style or None, markup=False)

    def _planned_total(self) -> int | None:
        planned = [r.planned for r in self.runs.values()]
        return None if any(p is None for p in planned) else sum(planned)

    def _counts(self) -> dict[str, int]:
        statuses = [o.status for o in self.outcomes.values()]
        return {
            "done": len(self.outcomes),
            "running": len(self.running),
            "failed": statuses.count(RunStatus.FAILED),
            "stalled": statuses.count(RunStatus.STALLED),
            "interrupted": statuses.count(RunStatus.INTERRUPTED),
        }

    def trials_done(self) -> int:
        """Trials done or no longer to do: a run that ended (even early) counts its whole plan."""
        ended = sum(
            self.runs[n].planned if self.runs[n].planned is not None else o.trials for n, o in self.outcomes.items()
        )
        return ended + sum(r.trials for r in self.running.values())

    def eta(self) -> float | None:
        """s until every run is done, at this invocation's rate of trials so far (None: not known yet)."""
        total = self._planned_total()
        elapsed = time.monotonic() - self.started
        if total is None or self.trials_here == 0 or elapsed <= 0:
            return None
        return max(0.0, total - self.trials_done()) / (self.trials_here / elapsed)

    def status_text(self) -> str:
        c = self._counts()
        queued = len(self.runs) - c["done"] - c["running"]
        text = f"{c['done']}/{len(self.runs)} done"
        if self.kept:
            text += f" ({len(self.kept)} kept)"
        text += f", {c['running']} running, {queued} queued, {c['failed']} failed, {c['stalled']} stalled"
        if c["interrupted"]:
            text += f", {c['interrupted']} interrupted"
        eta = self.eta()
        return text + (f", ETA {_duration(eta)}" if eta is not None else "")

    def show(self, event: StudyEvent) -> None:
        now = time.monotonic()
        if isinstance(event, RunStarted):
            run = self.runs[event.name]
            state = self.running[event.name] = _Running(run.planned, event.where, now)
            if self.quiet:
                self.say(f"sfl: [{self.order[event.name]}/{len(self.runs)}] {event.name} started on {event.where}")
            else:
                state.task = self.bar.add_task(f"  {event.name}", total=run.planned, status=event.where)
        elif isinstance(event, RunProgress):
            state = self.running.get(event.name)
            if state is None:  # a Dask task whose start event came late
                state = self.running[event.name] = _Running(self.runs[event.name].planned, "a Dask worker", now)
                if not self.quiet:
                    state.task = self.bar.add_task(f"  {event.name}", total=state.planned, status="")
            self.trials_here += max(0, event.trials - state.trials)
            state.trials, state.successes, state.last_trial = event.trials, event.successes, now
        elif isinstance(event, RunFinished):
            state = self.running.pop(event.name, None)
            if state is not None:
                self.trials_here += max(0, event.outcome.trials - state.trials)
                if state.task is not None:
                    self.bar.remove_task(state.task)
            else:
                self.trials_here += event.outcome.trials
            self.outcomes[event.name] = event.outcome
            self.say(self.finished_line(event.name, event.outcome), style=_STYLE.get(event.outcome.status, "red"))
        self.tick()

    def finished_line(self, name: str, o: Outcome) -> str:
        wall = f", {_duration(o.wall_s)}" if o.wall_s is not None else ""
        line = f"sfl: [{self.order[name]}/{len(self.runs)}] {name} {o.status}: {o.trials} trials{wall}, on {o.where}"
        return line + (f" ({o.reason})" if o.status != RunStatus.COMPLETED and o.reason else "")

    def tick(self) -> None:
        now = time.monotonic()
        if self.quiet:
            if self.running and now - self.last_line >= self.every:
                self.last_line = now
                each = ", ".join(
                    f"{n} {r.trials}/{r.planned if r.planned is not None else '?'}" for n, r in self.running.items()
                )
                self.say(f"sfl: study: {self.status_text()}; running: {each}")
            return
        if self.study_task is None:
            return
        self.bar.update(self.study_task, completed=self.trials_done(), status=self.status_text())
        for state in self.running.values():
            rate = f"success {state.successes / state.trials:.0%}" if state.trials else "starting"
            status = f"{rate}, {_duration(now - state.since)}, on {state.where}"
            if now - state.last_trial > self.QUIET_AFTER:
                status += f", no new trial for {_duration(now - state.last_trial)}"
            self.bar.update(state.task, completed=state.trials, status=status)
        self.bar.refresh()


_STYLE = {"completed": "green", "stalled": "yellow", "interrupted": "yellow"}
