"""Run folders and their append-only records.

A run folder holds:

* ``scenario.yaml``: the resolved scenario (after ``--set`` and ``--seed``);
* ``records.jsonl``: one JSON object per line, ``kind`` = ``decision`` or ``trial``,
  appended and flushed as they happen (read with ``pandas.read_json(path, lines=True)``
  or ``pyarrow.json.read_json``); a kill loses at most the line being written;
* ``recording.rrd``: the Rerun recording (per-process parts under ``rerun/`` until merged);
* ``acc.npz``: the learnt maps (learn protocol);
* ``summary.json``: written at the end; ``sfl inspect`` rebuilds it from the records
  when the run was interrupted;
* ``logs/``: one log file per module process.
"""

from __future__ import annotations

import json
import math
from pathlib import Path
from typing import Any

import numpy as np

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


def _plain(value: Any) -> Any:
    if isinstance(value, np.ndarray):
        return value.tolist()
    if isinstance(value, np.generic):
        return value.item()
    if isinstance(value, float) and not math.isfinite(value):
        return None
    if isinstance(value, dict):
        return {k: _plain(v) for k, v in value.items()}
    if isinstance(value, list | tuple):
        return [_plain(v) for v in value]
    return value


class RecordWriter:
    """Append rows to ``records.jsonl``, one line each, flushed per row."""

    def __init__(self, path: Path) -> None:
        self.path = path
        self._file = open(path, "a", encoding="utf-8")  # noqa: SIM115 - kept open for the run

    def write(self, row: dict) -> None:
        self._file.write(json.dumps(_plain(row), separators=(",", ":")) + "\n")
        self._file.flush()

    def write_many(self, rows: list[dict]) -> None:
        if rows:
            self._file.write("".join(json.dumps(_plain(r), separators=(",", ":")) + "\n" for r in rows))
            self._file.flush()

    def close(self) -> None:
        self._file.close()


def read_records(run_dir: Path) -> list[dict]:
    """All complete rows of a run's records (a truncated last line is skipped)."""
    path = Path(run_dir) / "records.jsonl"
    rows = []
    if not path.exists():
        return rows
    with open(path, encoding="utf-8") as f:
        for line in f:
            try:
                rows.append(json.loads(line))
            except json.JSONDecodeError:
                continue  # the line in flight when the run was killed
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
    """Summary of a finished or interrupted run."""
    run_dir = Path(run_dir)
    if not (run_dir / "records.jsonl").exists():
        raise FileNotFoundError(f"{run_dir}: no records.jsonl (is this a run folder?)")
    summary_path = run_dir / "summary.json"
    stored = {}
    if summary_path.exists():
        try:
            stored = json.loads(summary_path.read_text())
        except json.JSONDecodeError:
            stored = {}
    wall = stored.get("wall_time_s")
    if wall is None:
        started = run_dir / "started"
        if started.exists():
            wall = max(0.0, (run_dir / "records.jsonl").stat().st_mtime - started.stat().st_mtime)
    return summarise(read_records(run_dir), wall)
