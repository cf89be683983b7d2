"""What recording every trial's body costs: the quickstart with ``record.body_every=1`` and ``=0``.

    python benchmarks/recording.py [--trials 40] [--repeats 3] [--scenario scenarios/quickstart.yaml]
                                   [--set KEY=VALUE ...]

Runs ``sfl run`` as a user does (every module in its own process, the recording merged at the end),
alternating the two settings ``--repeats`` times, and prints side by side the medians of the whole
command's wall time, of the run's own ``wall_time_s`` (protocol start to end) and of the CPU time of
all its processes, the ratio of the two medians (goal for the wall time: at most 1.25, issue 14),
the size of ``recording.rrd``, and a check that the recording holds every decision and every trial
(rows of ``/decisions/go`` and ``/trials/success``).
"""

from __future__ import annotations

import argparse
import json
import resource
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

from rerun.chunk import RrdReader

ROOT = Path(__file__).resolve().parents[1]


def rows(path: Path) -> dict[str, int]:
    counts: dict[str, int] = {}
    for chunk in RrdReader(path).stream().to_chunks():
        counts[str(chunk.entity_path)] = counts.get(str(chunk.entity_path), 0) + chunk.num_rows
    return counts


def one_run(scenario: str, trials: int, body_every: int, extra: list[str], out: Path) -> dict:
    sets = [f"protocol.trials={trials}", f"record.body_every={body_every}", *extra]
    command = [sys.executable, "-m", "sfl_brain.cli", "run", scenario, "--out", str(out), "--quiet"]
    for s in sets:
        command += ["--set", s]
    before = resource.getrusage(resource.RUSAGE_CHILDREN)
    t = time.perf_counter()
    done = subprocess.run(command, capture_output=True, text=True, cwd=ROOT)
    wall = time.perf_counter() - t
    after = resource.getrusage(resource.RUSAGE_CHILDREN)  # sfl run and every process it waited for
    cpu = (after.ru_utime - before.ru_utime) + (after.ru_stime - before.ru_stime)
    if done.returncode != 0:
        raise SystemExit(f"sfl run failed ({done.returncode}): {done.stderr[-2000:]}")
    summary = json.loads((out / "summary.json").read_text())
    recording = out / "recording.rrd"
    counts = rows(recording)
    complete = (
        counts.get("/decisions/go") == summary["decisions"] and counts.get("/trials/success") == summary["trials"]
    )
    return {
        "command_s": wall,
        "cpu_s": cpu,
        "run_s": summary["wall_time_s"],
        "mb": recording.stat().st_size / 1e6,
        "complete": complete,
        "body_rows": counts.get("/body/walker", 0),
    }


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--scenario", default="scenarios/quickstart.yaml")
    parser.add_argument("--trials", type=int, default=40)
    parser.add_argument("--repeats", type=int, default=3)
    parser.add_argument("--set", action="append", default=[], help="further scenario overrides")
    args = parser.parse_args()
    results: dict[int, list[dict]] = {1: [], 0: []}
    with tempfile.TemporaryDirectory() as tmp:
        for repeat in range(args.repeats):
            for every in (1, 0):  # alternated, so that a busy spell of the machine hits both
                out = Path(tmp) / f"r{repeat}-b{every}"
                results[every].append(one_run(args.scenario, args.trials, every, args.set, out))
    print(f"{args.scenario}, {args.trials} trials, {args.repeats} runs each (medians)")
    print(f"{'':24}{'body_every=1':>14}{'body_every=0':>14}{'ratio':>8}")
    for key, label in (
        ("command_s", "sfl run, wall s"),
        ("run_s", "run wall_time_s"),
        ("cpu_s", "CPU s, all processes"),
    ):
        on = statistics.median(r[key] for r in results[1])
        off = statistics.median(r[key] for r in results[0])
        print(f"{label:24}{on:14.2f}{off:14.2f}{on / off:8.2f}")
    for every in (1, 0):
        sizes = ", ".join(f"{r['mb']:.1f}" for r in results[every])
        complete = all(r["complete"] for r in results[every])
        print(
            f"body_every={every}: recording.rrd {sizes} MB; every decision and trial in it: {complete}; "
            f"walker pictures {results[every][0]['body_rows']}"
        )


if __name__ == "__main__":
    main()
