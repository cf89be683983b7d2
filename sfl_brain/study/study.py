"""``sfl study``: one run per combination of ``--vary`` values and ``--seeds``, several at once, resumable.

The cycle is visible in :func:`run_study`: start runs while there is room, read what the running ones say
(trials so far, an end), show it, until none is left. Where the runs go is a *runner*:

- :class:`LocalRunner` (``--jobs N``): each run a child ``sfl run ... --quiet`` process on this machine,
  ``N`` at once, each on its own share of the usable cores (so that two runs never pin their lockstep pairs
  to the same core); its trials so far read from the growth of its ``records.jsonl``.
- :class:`~sfl_brain.study.cluster.DaskRunner` (``--cluster ADDRESS``): each run a task on a running Dask cluster;
  the task runs ``sfl run`` on its worker in a temporary folder, says its trials so far as Dask events, and
  returns the run folder's files (a tar archive), which land in the study folder. No shared file system needed.

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
import itertools
import json
import math
import os
import signal
import subprocess
import sys
import tempfile
import time
from collections import deque
from collections.abc import Callable, Iterable, Iterator
from dataclasses import asdict, dataclass
from pathlib import Path

import yaml

from ..recording.records import run_status
from ..scenario.plan import Plan, load
from ..status import BadInput, RunStatus

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
#: trials in the moving window of the study report's success rate (``--window``)
WINDOW = 20


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
    from ..runtime.run import self_contained

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
    from ..recording.records import inspect_run

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
    after ``grace`` s, or at a second Ctrl-C, the second SIGINT (its modules killed at once; it still writes its
    summary, given ``grace`` s more), then SIGKILL."""
    procs = [p for p in procs if p.poll() is None]
    for step, wait in ((signal.SIGINT, grace), (signal.SIGINT, grace), (signal.SIGKILL, 5.0)):
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
        from ..runtime.placement import usable_cpus

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
            yield self._finished(child)

    def stop(self) -> Iterator[StudyEvent]:
        """Interrupt every running run; each ends ``interrupted`` (or as it was ending)."""
        interrupt([c.proc for c in self.children.values()])
        for child in list(self.children.values()):
            yield self._finished(child)

    def _finished(self, child) -> RunFinished:
        """A child that has ended, out of the running set, with its outcome as its folder says it."""
        del self.children[child.run.name]
        child.counter.poll()
        outcome = finished(
            self.out / child.run.name,
            child.proc.returncode,
            child.counter.trials,
            time.monotonic() - child.started,
            cores_text(self.slots[child.slot]),
        )
        return RunFinished(child.run.name, outcome)

    def close(self) -> None:
        pass


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
