"""``sfl run``: launch a validated plan, run its protocol, and leave a complete run folder."""

from __future__ import annotations

import json
import shutil
import signal
import socket
import subprocess
import sys
import time
import uuid
from collections.abc import Callable
from datetime import datetime
from pathlib import Path

import yaml

from .protocols import PROTOCOLS, Conductor, Progress
from .records import RecordWriter, read_records, summarise
from .rrlog import RerunLog
from .runtime import RunError, Supervisor
from .scenario import Plan


def default_run_dir(plan: Plan) -> Path:
    stamp = datetime.now().strftime("%Y%m%d-%H%M%S")
    return Path("runs") / plan.scenario.name / f"{stamp}-s{plan.scenario.seed}-{uuid.uuid4().hex[:4]}"


def merge_recordings(run_dir: Path) -> Path | None:
    """Merge the per-process .rrd parts (one recording id) into ``recording.rrd``."""
    parts = sorted((run_dir / "rerun").glob("*.rrd"))
    if not parts:
        return None
    target = run_dir / "recording.rrd"
    rerun_cli = shutil.which("rerun")
    command = [rerun_cli] if rerun_cli else [sys.executable, "-m", "rerun"]
    done = subprocess.run(
        [*command, "rrd", "merge", "--continue-on-error", "-o", str(target), *map(str, parts)],
        capture_output=True,
        text=True,
    )
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


def start_viewer() -> tuple[subprocess.Popen, str]:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        port = s.getsockname()[1]
    rerun_cli = shutil.which("rerun") or "rerun"
    proc = subprocess.Popen([rerun_cli, "--bind", "127.0.0.1", "--port", str(port)])
    return proc, f"rerun+http://127.0.0.1:{port}/proxy"


class _Terminate(Exception):
    pass


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
) -> tuple[Path, dict]:
    """Run a scenario plan to the end; returns (run folder, summary). Raises nothing for module deaths:
    the summary's ``status`` says ``completed``, ``failed`` or ``interrupted``."""
    run_dir = Path(out) if out else default_run_dir(plan)
    run_dir.mkdir(parents=True, exist_ok=True)
    if (run_dir / "records.jsonl").exists():
        raise RunError(f"{run_dir} already holds a run; choose another --out")
    run_id = uuid.uuid4().hex[:12]
    resolved = dict(plan.raw, seed=plan.scenario.seed)
    (run_dir / "scenario.yaml").write_text(yaml.safe_dump(resolved, sort_keys=False))
    (run_dir / "started").write_text(datetime.now().isoformat() + "\n")
    viewer_proc, viewer_url = None, None
    if viewer:
        viewer_proc, viewer_url = start_viewer() if viewer is True else (None, viewer)
    writer = RecordWriter(run_dir / "records.jsonl")
    sup = Supervisor(plan, run_dir, run_id, listen=listen, connect=connect, viewer=viewer_url, realtime=realtime)
    (run_dir / "rerun").mkdir(exist_ok=True)
    rr_log = RerunLog(
        run_id,
        str(run_dir / "rerun" / "_supervisor.rrd"),  # also saved when streaming to a viewer
        viewer_url,
        [a.name for a in plan.scenario.space],
    )
    started = time.perf_counter()
    status, reason, extra = "completed", "", {}
    previous = signal.signal(signal.SIGTERM, lambda *_: (_ for _ in ()).throw(_Terminate()))
    try:
        sup.start()
        if on_ready:
            on_ready(sup, time.perf_counter() - started)
        conductor = Conductor(plan, sup, writer, rr_log, run_dir, on_progress)
        extra = PROTOCOLS[plan.scenario.protocol.kind](conductor)
    except (KeyboardInterrupt, _Terminate):
        status, reason = "interrupted", "stopped by signal"
    except RunError as exc:
        status, reason = "failed", str(exc)
    finally:
        signal.signal(signal.SIGTERM, previous)
        sup.stop()
        writer.close()
        rr_log.close()
        merge_recordings(run_dir)
    summary = summarise(read_records(run_dir), time.perf_counter() - started)
    summary.update(
        status=status,
        reason=reason,
        run_id=run_id,
        scenario=plan.scenario.name,
        seed=plan.scenario.seed,
        protocol=plan.scenario.protocol.kind,
        **extra,
    )
    (run_dir / "summary.json").write_text(json.dumps(summary, indent=2) + "\n")
    return run_dir, summary
