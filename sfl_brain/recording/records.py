"""Run folders and their append-only records.

A run folder holds:

* ``scenario.yaml``: the resolved scenario (after ``--set`` and ``--seed``);
* ``records.jsonl``: one JSON object per line, ``kind`` = ``decision``, ``trial`` or ``retry``,
  appended and flushed as they happen (read with ``pandas.read_json(path, lines=True)``
  or ``pyarrow.json.read_json``); a kill loses at most the line being written;
* ``recording.rrd``: the Rerun recording (per-process parts under ``rerun/`` until merged);
* ``acc.npz``: the learnt maps (learn protocol);
* ``summary.json``: written at the end, status first (``completed``, ``stalled``, ``failed``,
  ``interrupted``) with its ``stop_reason``; ``sfl inspect`` rebuilds the counts from the records
  when the run was killed before writing it;
* ``logs/``: one log file per module process.
"""

from __future__ import annotations

import json
import math
from pathlib import Path
from typing import Any

import numpy as np

from ..events import DecisionsMade, Events, TrialInterrupted, TrialRecorded
from ..messages import TrialResult
from ..status import EnvironmentProblem
from .metrics import safe_learning

SUMMARY_FIELDS = (
    "trials",
    "successes",
    "failures",
    "decisions",
    "no_go",
    "success_rate",
    "final_vigilance",
    "best_quality",
    "wall_time_s",
)


#: the fields of a trial row that are not reproducible: the wall clock, the CPU clocks, which worker ran the trial
NOT_REPRODUCIBLE = ("wall_ms", "worker", "cpu_body_s", "cpu_controller_s")


def plain(value: Any) -> Any:
    """``value`` as JSON holds it in the records: numpy values as Python's, a non-finite float as None."""
    if isinstance(value, np.ndarray):
        return plain(value.tolist())  # a NaN inside an array too
    if isinstance(value, np.generic):
        return value.item()
    if isinstance(value, float) and not math.isfinite(value):
        return None
    if isinstance(value, dict):
        return {k: plain(v) for k, v in value.items()}
    if isinstance(value, list | tuple):
        return [plain(v) for v in value]
    return value


#: one row in one call of the C encoder, numpy values turned by :func:`plain`; a non-finite float the encoder sees
#: raises, and that row takes :func:`plain`'s whole path
_FAST = json.JSONEncoder(separators=(",", ":"), allow_nan=False, default=plain)


def row_json(row: dict) -> str:
    """One row as its records line holds it (without the newline): ``json.dumps(plain(row))``, the same text, in one
    pass of the C encoder when every float is finite (a decision-heavy run writes thousands of rows a second)."""
    try:
        return _FAST.encode(row)
    except ValueError:  # a NaN or an infinity: None in the records, as plain() writes it
        return json.dumps(plain(row), separators=(",", ":"))


class RecordWriter:
    """Append rows to ``records.jsonl``, one line each, flushed per row.

    A write the machine refuses (a full disk, a folder gone read-only) raises
    :class:`EnvironmentProblem` with one line; the rows written before it stay whole.
    """

    def __init__(self, path: Path) -> None:
        self.path = path
        try:
            self._file = open(path, "a", encoding="utf-8")  # noqa: SIM115 - kept open for the run
        except OSError as exc:
            raise EnvironmentProblem(f"cannot write {path}: {exc.strerror or exc}") from None

    def _append(self, text: str) -> None:
        try:
            self._file.write(text)
            self._file.flush()
        except OSError as exc:
            raise EnvironmentProblem(f"cannot write {self.path}: {exc.strerror or exc}") from None

    def write(self, row: dict) -> None:
        self._append(row_json(row) + "\n")

    def write_many(self, rows: list[dict]) -> None:
        if rows:
            self._append("".join(row_json(r) + "\n" for r in rows))

    def close(self) -> None:
        try:
            self._file.close()
        except OSError:  # the last flush failed (full disk): what was written before stays
            pass


def point_fields(axes, unit: np.ndarray) -> dict:
    """Where a point of the parameter space is: ``v_unit`` (unit coordinates) and each axis's physical value."""
    return {"v_unit": unit.tolist(), **{a.name: a.to_physical(u) for a, u in zip(axes, unit, strict=True)}}


def decision_row(decision: int, trial: int | None, go: bool, s_vig: float, d_success, d_failure, point: dict) -> dict:
    """One ``kind: decision`` row: the go/no-go of candidate ``point`` (:func:`point_fields`) against
    ``s_vig``, with its distances to the success and failure maps; ``trial`` is the trial a go starts."""
    return {
        "kind": "decision",
        "decision": decision,
        "trial": trial,
        "go": go,
        "s_vig": s_vig,
        "d_success": float(d_success),
        "d_failure": float(d_failure),
        **point,
    }


def trial_row(
    trial: int,
    result: TrialResult,
    wall_s: float,
    success_rate: float,
    point: dict | None = None,
    learning: dict | None = None,
) -> dict:
    """One ``kind: trial`` row: the outcome, the worker, its wall, simulated and CPU seconds, the success rate so far,
    where it was tried (``point``, :func:`point_fields`; none for the exploit walk), the learning
    state after it (``learning``: learn protocol) and the body's metrics as ``m_<name>``."""
    return {
        "kind": "trial",
        "trial": trial,
        "success": result.success,
        "quality": result.quality,
        "worker": result.worker,
        "wall_ms": wall_s * 1e3,
        "sim_s": result.sim_s,
        "cpu_body_s": result.cpu_body_s,
        "cpu_controller_s": result.cpu_controller_s,
        "success_rate": success_rate,
        **(learning or {}),
        **(point or {}),
        **{f"m_{k}": v for k, v in result.metrics.items()},
    }


def retry_row(event: TrialInterrupted) -> dict:
    """One ``kind: retry`` row: trial ``trial`` was cut short (its body worker or controller died, hung, or lost its
    link) and is run again from its start; ``attempt`` 1 for the first retry. Its trial row, when it comes, is the
    retried trial's, as an uninterrupted run would have it."""
    return {"kind": "retry", "trial": event.trial, "attempt": event.attempt, "reason": event.reason}


def record_to(events: Events, writer: RecordWriter, decisions: bool = True) -> None:
    """Write the rows a protocol publishes: every trial, every retry of a trial, and the decisions if ``decisions``
    (``record.decisions``)."""
    events.subscribe(TrialRecorded, lambda event: writer.write(event.row))
    events.subscribe(TrialInterrupted, lambda event: writer.write(retry_row(event)))
    if decisions:
        events.subscribe(DecisionsMade, lambda event: writer.write_many(event.rows))


def read_records(run_dir: Path, damage: list[str] | None = None) -> list[dict]:
    """The rows of a run's records up to the last whole row.

    A torn last line (the row in flight when the run was killed) is left out. A damaged line
    before the end (bytes that are not UTF-8 or not a JSON object) ends the reading there: the
    rows after it cannot be trusted to follow it. What was left out is described in ``damage``.
    """
    path = Path(run_dir) / "records.jsonl"
    rows: list[dict] = []
    if not path.exists():
        return rows
    with open(path, "rb") as f:  # line by line: a long run's records need not fit in memory twice
        for number, line in enumerate(f, 1):
            try:
                row = json.loads(line.decode("utf-8"))
                if not isinstance(row, dict):
                    raise ValueError("not a JSON object")
            except (UnicodeDecodeError, ValueError) as exc:
                if damage is not None:
                    torn = not line.endswith(b"\n")  # the last line, cut while it was written
                    what = "a torn last row (the run was killed while writing it)" if torn else f"a damaged row ({exc})"
                    damage.append(f"records.jsonl line {number}: {what}; read the {len(rows)} rows before it")
                break
            rows.append(row)
    return rows


def summarise(rows: list[dict], wall_time_s: float | None = None) -> dict:
    """The run summary computed from its records."""
    trials = [r for r in rows if r.get("kind") == "trial"]
    decisions = [r for r in rows if r.get("kind") == "decision"]
    successes = sum(1 for r in trials if r.get("success"))
    qualities = [r["quality"] for r in trials if r.get("success") and r.get("quality") is not None]
    vig = [r["s_vig"] for r in trials if r.get("s_vig") is not None] or [
        r["s_vig"] for r in decisions if r.get("s_vig") is not None
    ]
    return {
        "trials": len(trials),
        "successes": successes,
        "failures": len(trials) - successes,
        "decisions": len(decisions),
        "no_go": sum(1 for r in decisions if not r.get("go")),
        "success_rate": successes / len(trials) if trials else None,
        "final_vigilance": vig[-1] if vig else None,
        "best_quality": max(qualities) if qualities else None,
        "wall_time_s": wall_time_s,
    }


def inspect_run(run_dir: Path) -> dict:
    """Summary of a finished, stopped or killed run: status and stop reason first, then the counts
    rebuilt from the records, and last the ``time_budget`` of a run that wrote its summary."""
    run_dir = Path(run_dir)
    if not (run_dir / "records.jsonl").exists():
        raise FileNotFoundError(f"{run_dir}: no records.jsonl (is this a run folder?)")
    stored: dict = {}
    try:
        loaded = json.loads((run_dir / "summary.json").read_text())
        stored = loaded if isinstance(loaded, dict) else {}
    except (OSError, ValueError):
        stored = {}
    wall = stored.get("wall_time_s")
    if wall is None:
        started = run_dir / "started"
        if started.exists():
            wall = max(0.0, (run_dir / "records.jsonl").stat().st_mtime - started.stat().st_mtime)
    damage: list[str] = []
    rows = read_records(run_dir, damage)
    counts = summarise(rows, wall)
    if any(r.get("kind") == "decision" for r in rows):  # a learn run: whichever proposer chose, and how safely
        wall_time = counts.pop("wall_time_s")  # stays last
        counts["proposer"] = stored.get("proposer", "sfl")
        metrics = safe_learning(rows)
        k = metrics["k"]
        counts["failures_before_first_success"] = metrics["failures_before_first_success"]
        counts[f"failures_before_{k}_gaits"] = metrics["failures_before_k"]
        counts["distinct_gaits"] = metrics["distinct_gaits"]  # successes metrics.DISTINCT apart in the unit cube
        counts["wall_time_s"] = wall_time
    if stored.get("status"):
        head = {"status": stored["status"], "stop_reason": stored.get("stop_reason", stored.get("reason", ""))}
    else:
        head = {
            "status": "unfinished",
            "stop_reason": "no summary.json: the run was killed, or is still running",
        }
    head["planned_trials"] = stored.get("planned_trials")
    out = {**head, **counts}
    if damage:
        out["records_damage"] = "; ".join(damage)
    if isinstance(stored.get("time_budget"), dict):  # where the wall time went (sfl_brain.recording.budget)
        out["time_budget"] = stored["time_budget"]
    return out


def run_status(run_dir: Path) -> tuple[str, str]:
    """(status, stop_reason) of a run folder, from its summary (``unfinished`` when it has none)."""
    try:
        stored = json.loads((Path(run_dir) / "summary.json").read_text())
    except (OSError, ValueError):
        return "unfinished", "no summary.json: the run was killed, or is still running"
    if not isinstance(stored, dict) or "status" not in stored:
        return "unfinished", "summary.json has no status"
    return str(stored["status"]), str(stored.get("stop_reason", stored.get("reason", "")))
