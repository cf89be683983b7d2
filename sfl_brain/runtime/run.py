"""``sfl run``: launch a validated plan, run its protocol, and leave a complete run folder.

The run wires the parts together: the :class:`~sfl_brain.runtime.supervisor.Supervisor` hosts the modules
and publishes their lifecycle; the protocol publishes its decisions, trials and progress; the run
subscribes the records, the Rerun log, the progress callback and the terminal lines to those
:mod:`~sfl_brain.events`.

The run's status is decided here (see :mod:`sfl_brain.status`): ``completed`` only when the
protocol ran its whole budget, ``stalled`` when it stopped early on its own, ``failed`` when a
module or the machine let it down, ``interrupted`` on Ctrl-C / SIGTERM. Whatever happens, the
children are stopped, the records closed, the recording merged and ``summary.json`` written.
"""

from __future__ import annotations

import copy
import errno
import json
import logging
import os
import shutil
import signal
import socket
import subprocess
import sys
import time
import traceback
import uuid
from collections.abc import Callable
from dataclasses import dataclass, field
from datetime import datetime
from pathlib import Path

import yaml

from ..events import (
    DecisionsMade,
    Events,
    ModuleAlive,
    ModuleDied,
    ModuleHung,
    ModuleSilent,
    ModuleStopped,
    PlacementYielded,
    Progress,
    ProgressUpdated,
    Restarted,
    TrialInterrupted,
    TrialRecorded,
    WorkerJoined,
    WorkerLeft,
)
from ..protocols import PROTOCOLS
from ..protocols.conductor import Conductor
from ..protocols.service import RunError
from ..recording.budget import TimeBudget
from ..recording.provenance import provenance
from ..recording.records import RecordWriter, read_records, record_to, run_status, summarise
from ..recording.rrlog import RERUN_FLUSH_TIMEOUT, RerunLog, layout_of
from ..recording.tables import write_tables
from ..scenario.errors import ScenarioError
from ..scenario.plan import Plan, load
from ..status import EXIT_CODES, EXIT_ENVIRONMENT, BadInput, EnvironmentProblem, RunStatus
from .processes import kill_quietly
from .supervisor import Supervisor

log = logging.getLogger("sfl.run")


def default_run_dir(plan: Plan) -> Path:
    stamp = datetime.now().strftime("%Y%m%d-%H%M%S")
    return Path("runs") / plan.scenario.name / f"{stamp}-s{plan.scenario.seed}-{uuid.uuid4().hex[:4]}"


MERGE_TIMEOUT = 600.0  # s: far above a merge of the largest run measured (a 1000-trial run's parts, seconds)


def merge_recordings(run_dir: Path) -> Path | None:
    """Merge the per-process .rrd parts (one recording id) into ``recording.rrd``."""
    parts = sorted((run_dir / "rerun").glob("*.rrd"))
    if not parts:
        return None
    target = run_dir / "recording.rrd"
    rerun_cli = shutil.which("rerun")
    command = [rerun_cli] if rerun_cli else [sys.executable, "-m", "rerun"]
    try:
        done = subprocess.run(
            [*command, "rrd", "merge", "--continue-on-error", "-o", str(target), *map(str, parts)],
            capture_output=True,
            text=True,
            timeout=MERGE_TIMEOUT,
        )
    except subprocess.TimeoutExpired:
        kept = run_dir / "rerun"
        print(f"sfl: merging the Rerun parts took over {MERGE_TIMEOUT:.0f} s; kept in {kept}", file=sys.stderr)
        return None
    if done.returncode != 0 or not target.exists():
        print(
            f"sfl: could not merge Rerun parts (kept in {run_dir / 'rerun'}): {done.stderr.strip()[-400:]}",
            file=sys.stderr,
        )
        return None
    for p in parts:
        p.unlink()
    (run_dir / "rerun").rmdir()
    return target


def has_display() -> bool:
    """Whether a native viewer window can open here (X11 or Wayland on Linux/BSD; always elsewhere)."""
    if not sys.platform.startswith(("linux", "freebsd", "openbsd", "netbsd")):
        return True
    return bool(os.environ.get("DISPLAY") or os.environ.get("WAYLAND_DISPLAY"))


def check_viewer() -> str:
    """The ``rerun`` command a native viewer starts with; :class:`EnvironmentProblem` (exit code 4) at
    once where no window can open, instead of a viewer that hangs."""
    if not has_display():
        raise EnvironmentProblem(
            "--viewer needs a display (DISPLAY / WAYLAND_DISPLAY is not set). The run folder keeps the "
            "recording anyway: open recording.rrd on a machine with a screen, or stream to a viewer "
            "that is already running with --viewer-url (for a browser: `rerun --serve-web --bind 127.0.0.1`)"
        )
    rerun_cli = shutil.which("rerun")
    if rerun_cli is None:
        raise EnvironmentProblem("--viewer needs the `rerun` command (pip install rerun-sdk); none is on PATH")
    return rerun_cli


def start_viewer() -> tuple[subprocess.Popen, str]:
    """Spawn a native Rerun viewer on 127.0.0.1."""
    rerun_cli = check_viewer()
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        port = s.getsockname()[1]
    proc = subprocess.Popen([rerun_cli, "--bind", "127.0.0.1", "--port", str(port)])
    try:
        code = proc.wait(timeout=1.0)  # a viewer that cannot start says so at once
    except subprocess.TimeoutExpired:
        return proc, f"rerun+http://127.0.0.1:{port}/proxy"
    raise EnvironmentProblem(f"the Rerun viewer exited at start with code {code}; run without --viewer")


def prepare_run_dir(run_dir: Path) -> None:
    """Make the run folder, or say in one line why it cannot be used (before any process starts).

    A folder that already holds a run is bad input (exit code 2): records are never overwritten.
    A folder that cannot be made or written is the environment's problem (exit code 4).
    """
    if run_dir.exists() and not run_dir.is_dir():
        raise BadInput(f"--out {run_dir} is a file, not a folder")
    for held in ("records.jsonl", "summary.json"):
        if (run_dir / held).exists():
            raise BadInput(f"--out {run_dir} already holds a run ({held}); choose another folder")
    try:
        run_dir.mkdir(parents=True, exist_ok=True)
        probe = run_dir / ".sfl-write-probe"
        probe.write_bytes(b"ok")
        probe.unlink()
    except OSError as exc:
        raise EnvironmentProblem(f"cannot write the run folder {run_dir}: {exc.strerror or exc}") from None


@dataclass(frozen=True, kw_only=True)
class Resume:
    """Where an interrupted learn run goes on from (``sfl run --resume RUN_DIR``).

    The run replays ``trials`` (its trial rows, in order: the proposer asks again, the brain modules learn again from
    the recorded outcomes, nothing is re-run or re-recorded) and then runs the rest of its budget, appending to its
    records: the records and recording are those an uninterrupted run would have made.
    """

    #: the trial rows recorded, replayed in order
    trials: list[dict]
    #: records.jsonl up to its last trial row; what follows (the decisions of the trial in flight, a torn line) goes
    keep_bytes: int
    #: the run id (and Rerun recording id) the run had, when the folder says it
    run_id: str | None
    #: wall seconds the run had taken before (summary.json; else the records' last write after ``started``)
    wall_time_s: float | None


def prepare_resume(run_dir: Path) -> tuple[Plan, Resume]:
    """The scenario of an interrupted learn run and where it goes on from, or :class:`BadInput` in one line: a
    folder that holds no run, a run that is not a learn run, or one that ended on its own (``completed``, ``stalled``).
    Reads only: the folder changes when the resumed run starts (:func:`continue_run_dir`)."""
    run_dir = Path(run_dir)
    scenario = run_dir / "scenario.yaml"
    if not run_dir.is_dir() or not scenario.is_file() or not (run_dir / "records.jsonl").is_file():
        raise BadInput(f"--resume {run_dir} is not a run folder (no scenario.yaml and records.jsonl)")
    status, _ = run_status(run_dir)
    if status in (RunStatus.COMPLETED, RunStatus.STALLED):
        raise BadInput(f"--resume {run_dir}: the run is {status}, nothing to resume (only an unfinished learn run)")
    try:
        plan = load(scenario)
    except ScenarioError as exc:
        raise BadInput(f"--resume {run_dir}: its scenario.yaml is not valid: {str(exc).splitlines()[-1]}") from None
    kind = plan.scenario.protocol.kind
    if kind != "learn":
        raise BadInput(f"--resume {run_dir}: a {kind} run; only a learn run can be resumed (run it again instead)")
    rows = read_records(run_dir)  # up to the last whole row
    last = max((i for i, r in enumerate(rows) if r.get("kind") == "trial"), default=-1)
    keep_bytes = 0
    with open(run_dir / "records.jsonl", "rb") as f:  # rows are read line by line: row i is line i
        for _, line in zip(range(last + 1), f, strict=False):
            keep_bytes += len(line)
    stored = {}
    for name in ("summary.json", "provenance.json"):
        try:
            loaded = json.loads((run_dir / name).read_text())
        except (OSError, ValueError):
            continue
        if isinstance(loaded, dict):
            stored = {**loaded, **stored}
    wall = stored.get("wall_time_s")
    if wall is None and (run_dir / "started").exists():
        wall = max(0.0, (run_dir / "records.jsonl").stat().st_mtime - (run_dir / "started").stat().st_mtime)
    run_id = stored.get("run_id")
    return plan, Resume(
        trials=[r for r in rows if r.get("kind") == "trial"],
        keep_bytes=keep_bytes,
        run_id=run_id if isinstance(run_id, str) and run_id else None,
        wall_time_s=wall,
    )


def continue_run_dir(run_dir: Path, resume: Resume) -> list[str]:
    """Make an interrupted run's folder ready to go on; returns the previous recordings' names.

    ``records.jsonl`` is cut after its last trial row (the resumed run appends what follows); the recording made so
    far (``recording.rrd``, merged first from ``rerun/`` after a kill -9) becomes ``recording.part<N>.rrd`` (same
    recording id: ``rerun rrd merge`` joins them); the old ``summary.json`` goes (a resumed run that is killed is
    unfinished again)."""
    try:
        with open(run_dir / "records.jsonl", "r+b") as f:
            f.truncate(resume.keep_bytes)
            if resume.keep_bytes:
                f.seek(resume.keep_bytes - 1)
                if f.read(1) != b"\n":  # a last row whole but for its end of line
                    f.write(b"\n")
        parts = run_dir / "rerun"
        if parts.is_dir() and any(parts.glob("*.rrd")):
            merge_recordings(run_dir)
        previous = sorted(run_dir.glob("recording.part*.rrd"))
        number = len(previous) + 1
        if parts.is_dir() and any(parts.glob("*.rrd")):  # could not be merged: kept whole, beside
            parts.rename(run_dir / f"rerun.part{number}")
        if (run_dir / "recording.rrd").exists():
            (run_dir / "recording.rrd").rename(run_dir / f"recording.part{number}.rrd")
        (run_dir / "summary.json").unlink(missing_ok=True)
        probe = run_dir / ".sfl-write-probe"
        probe.write_bytes(b"ok")
        probe.unlink()
    except OSError as exc:
        raise EnvironmentProblem(f"cannot write the run folder {run_dir}: {exc.strerror or exc}") from None
    return sorted(p.name for p in run_dir.glob("recording.part*.rrd"))


def self_contained(plan: Plan, run_dir: Path) -> dict:
    """The resolved scenario, made re-runnable from the run folder alone: a module given by file
    (``impl: my_vig.py:Cls``) and an exploit protocol's maps are copied into ``inputs/`` and the
    scenario points at the copies (``sfl run RUN_DIR/scenario.yaml`` runs the same run again)."""
    resolved = copy.deepcopy(dict(plan.raw, seed=plan.scenario.seed))
    inputs = run_dir / "inputs"
    references = {}
    for inst in plan.instances:
        references[inst.spec_name] = inst.reference
        if inst.colocated is not None:
            references[inst.colocated.spec_name] = inst.colocated.reference
    for name, spec in resolved.get("modules", {}).items():
        target, _, class_name = references.get(name, "").rpartition(":")
        if target.endswith(".py") and Path(target).is_file():
            inputs.mkdir(exist_ok=True)
            copied = inputs / Path(target).name
            shutil.copyfile(target, copied)
            spec["impl"] = f"inputs/{copied.name}:{class_name}"
    protocol = resolved.get("protocol", {})
    maps = getattr(plan.scenario.protocol, "maps", None)
    if maps:
        source = Path(maps) if Path(maps).is_absolute() or Path(maps).exists() else Path(plan.file).parent / maps
        if source.is_file():
            inputs.mkdir(exist_ok=True)
            shutil.copyfile(source, inputs / source.name)
            protocol["maps"] = f"inputs/{source.name}"
    return resolved


def _counters(run_dir: Path, sup: Supervisor) -> dict:
    """Messages dropped during the run, by process and reason (malformed, unauthenticated, stale...)."""
    dropped: dict[str, dict] = {}
    own = getattr(sup, "dropped", None)
    if own:
        dropped["supervisor"] = dict(own)
    for path in sorted((run_dir / "logs").glob("*.counters.json")):
        try:
            counts = json.loads(path.read_text()).get("dropped", {})
        except (OSError, ValueError, AttributeError):
            continue
        if counts:
            dropped[path.name.removesuffix(".counters.json")] = counts
    return dropped


class _Terminate(Exception):
    pass


def tell(events: Events) -> None:
    """Say what happens to the modules and trials: on the terminal what the user must see, the rest to the log."""

    def restarted(e: Restarted) -> None:
        log.warning("module %s exited with code %s: restart %d/%d", e.name, e.exit_code, e.restart, e.max_restarts)
        how = f"was {e.cause}: killed" if e.cause else f"died (exit code {e.exit_code})"
        print(f"sfl: module `{e.name}` {how}; restarting ({e.restart}/{e.max_restarts})", file=sys.stderr)

    events.subscribe(Restarted, restarted)
    events.subscribe(ModuleHung, lambda e: print(f"sfl: {e.describe()}", file=sys.stderr, flush=True))

    def stopped(e: ModuleStopped) -> None:
        if e.stopped:
            print(f"sfl: module `{e.name}` is stopped (SIGSTOP? a suspended machine?): waiting for it", file=sys.stderr)
        else:
            print(f"sfl: module `{e.name}` runs again", file=sys.stderr)

    events.subscribe(ModuleStopped, stopped)
    events.subscribe(
        PlacementYielded,
        lambda e: print(f"sfl: other work keeps {e.busy} busy: the placement yields; {e.placement}", flush=True),
    )
    events.subscribe(
        TrialInterrupted, lambda e: print(f"sfl: trial {e.trial} interrupted ({e.reason}); retrying", flush=True)
    )
    events.subscribe(ModuleAlive, lambda e: log.info("%s is alive", e.name))
    events.subscribe(WorkerJoined, lambda e: log.info("external worker %s joined", e.name))
    events.subscribe(WorkerLeft, lambda e: log.warning("external worker %s left", e.name))
    events.subscribe(ModuleSilent, lambda e: log.warning("%s lost its link but runs: waited for", e.name))
    events.subscribe(ModuleDied, lambda e: log.error("module %s died with exit code %s", e.name, e.exit_code))


def run(
    plan: Plan,
    out: Path | None = None,
    *,
    viewer: bool | str = False,
    realtime: bool = False,
    listen: list[str] | None = None,
    connect: list[str] | None = None,
    on_progress: Callable[[Progress], None] | None = None,
    on_ready: Callable[[Supervisor, float], None] | None = None,
    zenoh_config: str | Path | None = None,
    resume: Resume | None = None,
    budget: TimeBudget | None = None,
) -> tuple[Path, dict]:
    """Run a scenario plan to its end; returns (run folder, summary). ``resume``: go on with the interrupted learn
    run in ``out`` (:func:`prepare_resume`) instead of starting a new folder. ``budget``: where the run's wall time
    is counted (``sfl run`` passes one that counts its process's launch as start-up); a new one by default.

    Raises :class:`BadInput` or :class:`EnvironmentProblem` only before anything started (a run
    folder that holds a run or cannot be written, no display for ``--viewer``). After that it
    raises nothing: the summary's ``status`` is ``completed``, ``stalled``, ``failed`` or
    ``interrupted``, with ``stop_reason`` and the ``exit_code`` the CLI ends with.
    """
    budget = budget or TimeBudget()  # where this invocation's wall time goes, up to the summary
    run_dir = Path(out) if out else default_run_dir(plan)
    with budget.part("startup"):
        run_id, viewer_url, earlier = _open_run_dir(plan, run_dir, viewer, resume)
        writer = RecordWriter(run_dir / "records.jsonl")
        events = Events()
        sup = Supervisor(
            plan,
            run_dir,
            run_id,
            listen=listen,
            connect=connect,
            viewer=viewer_url,
            realtime=realtime,
            zenoh_config=zenoh_config,
            events=events,
        )
        rr_log = _rerun_log(plan, run_dir, run_id, viewer_url, resume)
        _subscribe(events, plan, writer, rr_log, on_progress)
    started = time.perf_counter()
    with _Stopping(sup) as stopping:
        ended = _Ended()
        try:
            ended = _conduct(plan, sup, events, run_dir, resume, on_ready, started, budget)
        finally:
            stopping.cleaning = True
            cleanup, rows = _close(plan, run_dir, sup, writer, rr_log, ended, stopping, budget)
    if rows is None:  # the tables' step failed before it read them
        with budget.part("records"):
            rows = read_records(run_dir)
    _judge_run(ended, rows, cleanup, stopping)
    wall = time.perf_counter() - started
    if resume is not None:  # the time it had taken before, and where it went on from
        wall += resume.wall_time_s or 0.0
        ended.extra = ended.extra | {"resumed_from_trial": len(resume.trials), "previous_recordings": earlier}
    ended.extra = ended.extra | {"time_budget": budget.summary()}
    return run_dir, _write_summary(plan, run_dir, sup, run_id, ended, rows, wall)


def _open_run_dir(
    plan: Plan, run_dir: Path, viewer: bool | str, resume: Resume | None
) -> tuple[str, str | None, list[str]]:
    """Check for a viewer, make the run folder (or make an interrupted run's ready to go on), start a viewer, and
    write what the run starts from; returns (run id, the viewer's URL, the previous recordings' names)."""
    if viewer is True:
        check_viewer()
    if resume is None:
        prepare_run_dir(run_dir)
    viewer_url = None
    if viewer:
        _, viewer_url = start_viewer() if viewer is True else (None, viewer)
    run_id = (resume and resume.run_id) or uuid.uuid4().hex[:12]  # resumed: the same recording id
    if resume is not None:  # the scenario, provenance and start stay the run's; the records and recording go on
        return run_id, viewer_url, continue_run_dir(run_dir, resume)
    (run_dir / "scenario.yaml").write_text(yaml.safe_dump(self_contained(plan, run_dir), sort_keys=False))
    (run_dir / "provenance.json").write_text(json.dumps({**provenance(), "run_id": run_id}, indent=2) + "\n")
    (run_dir / "started").write_text(datetime.now().isoformat() + "\n")
    return run_id, viewer_url, []


def _rerun_log(plan: Plan, run_dir: Path, run_id: str, viewer_url: str | None, resume: Resume | None) -> RerunLog:
    """The supervisor's own recording stream, saved beside the modules' parts (also when streaming to a viewer)."""
    (run_dir / "rerun").mkdir(exist_ok=True)
    return RerunLog(
        run_id,
        str(run_dir / "rerun" / "_supervisor.rrd"),
        viewer_url,
        [a.name for a in plan.scenario.space],
        plan.trial_seconds,
        layout_of(plan),
        first_trial=len(resume.trials) if resume is not None else 0,
    )


def _subscribe(
    events: Events,
    plan: Plan,
    writer: RecordWriter,
    rr_log: RerunLog,
    on_progress: Callable[[Progress], None] | None,
) -> None:
    """The records, the Rerun log, the progress callback and the terminal lines, each told what it shows."""
    record_to(events, writer, decisions=plan.scenario.record.decisions)
    events.subscribe(DecisionsMade, lambda e: rr_log.decisions(e.rows))
    events.subscribe(TrialRecorded, lambda e: rr_log.trial(e.row))
    if on_progress is not None:
        events.subscribe(ProgressUpdated, lambda e: on_progress(e.progress))
    tell(events)


class _Stopping:
    """The run's Ctrl-C / SIGTERM handler, installed while the run goes on (``with``) and the ones before it back
    after: how many signals came, and whether the run is already cleaning up."""

    def __init__(self, sup: Supervisor) -> None:
        self.sup = sup
        self.signals = 0
        self.cleaning = False
        self._previous: dict = {}

    def __enter__(self) -> _Stopping:
        self._previous = {sig: signal.signal(sig, self._on_signal) for sig in (signal.SIGINT, signal.SIGTERM)}
        return self

    def __exit__(self, *_exc) -> None:
        for sig, handler in self._previous.items():
            signal.signal(sig, handler)

    def _on_signal(self, signum, _frame) -> None:
        # This handler never raises. Python runs it in the main thread at whatever Python code that thread runs
        # next, and that can be a Zenoh callback: with indirect=False, Zenoh calls the reply and query-end
        # callbacks of Supervisor.submit in the thread that happens to finish the query, sometimes the main
        # thread inside session.get. Zenoh logs what a callback raises ("callback error") and drops it: the
        # Ctrl-C was lost. So the first signal only asks the supervisor to raise it where the run waits for
        # an event (it wakes the wait), in the run's own code, and the interrupted path of _conduct runs.
        self.signals += 1
        if not self.cleaning and self.signals == 1:
            self.sup.raise_at_wait(KeyboardInterrupt if signum == signal.SIGINT else _Terminate)
            return
        # a second signal (or one while the run is already stopping): the fast path. Kill the
        # children now instead of waiting for them (a wait still to come raises the first signal); the
        # records, summary and recording are still written.
        print("sfl: stopping now: module processes killed; writing the summary", file=sys.stderr, flush=True)
        for pid in self.sup.pids():
            kill_quietly(pid)


@dataclass(kw_only=True)
class _Ended:
    """How the run ended: its status and why, the exit code when it is not its status's, what the protocol returned."""

    status: RunStatus = RunStatus.COMPLETED
    reason: str = ""
    exit_code: int | None = None
    extra: dict = field(default_factory=dict)


def _conduct(
    plan: Plan,
    sup: Supervisor,
    events: Events,
    run_dir: Path,
    resume: Resume | None,
    on_ready: Callable[[Supervisor, float], None] | None,
    started: float,
    budget: TimeBudget,
) -> _Ended:
    """Start the module processes and run the protocol; how that ended (a fault or a signal is a status, not raised)."""
    try:
        with budget.part("startup"):
            sup.start()
        if on_ready:
            on_ready(sup, time.perf_counter() - started)
        conductor = Conductor(plan, sup, events, run_dir, replay=resume.trials if resume else None, budget=budget)
        return _Ended(extra=PROTOCOLS[plan.scenario.protocol.kind](conductor))
    except (KeyboardInterrupt, _Terminate):
        return _Ended(status=RunStatus.INTERRUPTED, reason="stopped by signal (Ctrl-C or SIGTERM)")
    except RunError as exc:
        return _Ended(status=RunStatus.FAILED, reason=str(exc))
    except EnvironmentProblem as exc:
        return _Ended(status=RunStatus.FAILED, reason=str(exc), exit_code=EXIT_ENVIRONMENT)
    except OSError as exc:
        reason = f"{exc.strerror or exc}" + (f": {exc.filename}" if exc.filename else "")
        refused = exc.errno in (errno.ENOSPC, errno.EDQUOT, errno.EROFS, errno.EACCES, errno.EPERM)
        return _Ended(status=RunStatus.FAILED, reason=reason, exit_code=EXIT_ENVIRONMENT if refused else None)
    except Exception as exc:  # a bug of ours or of a protocol: say so, keep the traceback in logs/
        _log_internal(run_dir)
        return _Ended(
            status=RunStatus.FAILED, reason=f"internal error: {type(exc).__name__}: {exc} (see logs/_run.log)"
        )


def _close(
    plan: Plan,
    run_dir: Path,
    sup: Supervisor,
    writer: RecordWriter,
    rr_log: RerunLog,
    ended: _Ended,
    stopping: _Stopping,
    budget: TimeBudget,
) -> tuple[list[str], list[dict] | None]:
    """Stop the modules, close the records and the Rerun log, merge the recording and write the tables; what went
    wrong doing so, one line each, and the records as the tables read them (None if that step failed before).
    Every step runs whatever the others did: a full disk must not cost the summary."""
    cleanup = []
    rows: list[dict] | None = None  # the records read once, for the tables and the summary (a long run's are large)

    def tables() -> None:
        nonlocal rows
        rows = read_records(run_dir)
        write_tables(run_dir, plan.raw.get("space", []), plan.body_class.METRICS, rows=rows)

    for part, step in (
        ("shutdown", lambda: sup.stop(grace=0.0 if stopping.signals > 1 else 3.0)),
        ("records", writer.close),
        # a full disk: rerun's writer has stopped, do not wait the healthy disk's time for it
        ("records", lambda: rr_log.close(timeout=2.0 if ended.exit_code == EXIT_ENVIRONMENT else RERUN_FLUSH_TIMEOUT)),
        ("records", lambda: merge_recordings(run_dir)),
        ("records", tables),
    ):
        try:
            with budget.part(part):
                step()
        except Exception as exc:  # noqa: BLE001 - reported in the summary, never raised
            cleanup.append(f"{type(exc).__name__}: {exc}")
            _log_internal(run_dir)
    return cleanup, rows


def _judge_run(ended: _Ended, rows: list[dict], cleanup: list[str], stopping: _Stopping) -> None:
    """The run's status and stop reason, from how it ended, its records, its clean-up and the signals it got."""
    if cleanup:
        ended.reason += ("; " if ended.reason else "") + "while stopping: " + "; ".join(cleanup)
    if ended.status == RunStatus.COMPLETED:
        ended.status, ended.reason = _judge(ended.extra, sum(1 for r in rows if r.get("kind") == "trial"))
    if ended.status == RunStatus.INTERRUPTED and stopping.signals > 1:
        ended.reason += "; stopped at once by a second signal"


def _write_summary(
    plan: Plan, run_dir: Path, sup: Supervisor, run_id: str, ended: _Ended, rows: list[dict], wall: float
) -> dict:
    """``summary.json``: the run's status, its records summed up, what it dropped; written last."""
    extra = ended.extra
    summary = {
        "status": str(ended.status),
        "stop_reason": ended.reason,
        "exit_code": ended.exit_code if ended.exit_code is not None else EXIT_CODES[ended.status],
        **summarise(rows, wall),
        "planned_trials": extra.get("planned_trials"),
        "run_id": run_id,
        "scenario": plan.scenario.name,
        "seed": plan.scenario.seed,
        "protocol": plan.scenario.protocol.kind,
        "dropped": _counters(run_dir, sup),
        **{k: v for k, v in extra.items() if k not in ("planned_trials", "stop_reason", "stalled")},
    }
    try:
        (run_dir / "summary.json").write_text(json.dumps(summary, indent=2) + "\n")
    except OSError as exc:
        summary["exit_code"] = EXIT_ENVIRONMENT
        summary["stop_reason"] += f"; summary.json not written: {exc.strerror or exc}"
    return summary


def _judge(extra: dict, trials: int) -> tuple[RunStatus, str]:
    """The status of a protocol that returned: completed only if its records hold its whole budget."""
    reason = extra.get("stop_reason", "")
    if extra.get("stalled"):
        return RunStatus.STALLED, reason
    planned = extra.get("planned_trials")
    if planned is not None and trials < planned:
        return RunStatus.STALLED, f"the protocol ended after {trials} of {planned} trials ({reason})"
    return RunStatus.COMPLETED, reason


def _log_internal(run_dir: Path) -> None:
    try:
        with open(run_dir / "logs" / "_run.log", "a", encoding="utf-8") as f:
            f.write(traceback.format_exc())
    except OSError:
        pass
