"""Wall time of one small study: its runs one at a time, two at a time, and as tasks on a Dask cluster.

    python benchmarks/study.py [--trials 60] [--runs 4] [--rounds 2] [--no-dask]

The study: ``--runs`` learning runs (seeds 0, 1, ...) of the planar reflexive walker on flat ground
(``scenarios/e3_2_flat_s0.yaml``, ``protocol.trials=--trials``), by ``sfl study ... --quiet``:

(jobs 1) one run at a time, each on every usable core (as ``sfl run`` alone);
(jobs 2) two at a time, each on its own share of the cores;
(dask)   as tasks on a Dask cluster on loopback, started as on machines (``dask scheduler`` and two one-thread
         ``dask worker`` processes, worker i on the cores (jobs 2) gives its i-th run), that this benchmark starts
         once, before the rounds (a user's cluster is running already); the study connects to it, each task runs
         ``sfl run`` in a temporary folder on its worker and returns the run folder as a tar archive.

Each variant runs once per round in a shuffled order, for ``--rounds`` rounds; a time is a median over the rounds,
a ratio the median of the ratios within each round. Two times per study: the whole command (the report included,
the same in every variant) and the runs' span (first run's start to last run's summary, from the run folders). The
speed-up (jobs 1 / jobs 2) is worth having when near 2 on 2 cores; the engine's cost (dask / jobs 2 - 1) should stay
within 10 % for runs of 30 s or more, so each run's own wall time is printed too. The load average is printed.
"""

from __future__ import annotations

import argparse
import json
import random
import subprocess
import sys
import tempfile
import time
from datetime import datetime
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
from _floor import machine_load  # noqa: E402

from sfl_brain.runtime.placement import usable_cpus  # noqa: E402
from sfl_brain.study.cluster import loopback_cluster  # noqa: E402
from sfl_brain.study.study import core_slots  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]
SCENARIO = ROOT / "scenarios" / "e3_2_flat_s0.yaml"


def study(out: Path, trials: int, runs: int, where: list[str]) -> dict:
    """Run the study into ``out``; its command's wall time, its runs' span and each run's wall time (s)."""
    seeds = ",".join(str(s) for s in range(runs))
    command = [sys.executable, "-m", "sfl_brain.cli", "study", str(SCENARIO), "--seeds", seeds]
    command += ["--set", f"protocol.trials={trials}", "--out", str(out), "--quiet", *where]
    t0 = time.perf_counter()
    done = subprocess.run(command, capture_output=True, text=True, cwd=ROOT)
    wall = time.perf_counter() - t0
    if done.returncode != 0:
        raise SystemExit(f"the study failed (exit {done.returncode}):\n{done.stderr[-3000:]}")
    starts, ends, walls = [], [], []
    for folder in sorted(out.glob("run_seed*")):
        starts.append(datetime.fromisoformat((folder / "started").read_text().strip()).timestamp())
        ends.append((folder / "summary.json").stat().st_mtime)
        walls.append(json.loads((folder / "summary.json").read_text())["wall_time_s"])
    assert len(walls) == runs, f"{len(walls)} run folders of {runs}"
    return {"command": wall, "span": max(ends) - min(starts), "runs": walls}


def main() -> None:
    parser = argparse.ArgumentParser()
    parser.add_argument("--trials", type=int, default=60, help="trials per run (sized for runs of 30 s or more)")
    parser.add_argument("--runs", type=int, default=4, help="runs in the study (seeds 0, 1, ...)")
    parser.add_argument("--rounds", type=int, default=2, help="rounds of every variant (medians over them)")
    parser.add_argument("--no-dask", action="store_true", help="leave out the Dask variant")
    args = parser.parse_args()
    cpus = usable_cpus()
    print(
        f"study: {args.runs} runs of {SCENARIO.name} with protocol.trials={args.trials}, {args.rounds} rounds; "
        f"usable cores {cpus}",
        flush=True,
    )
    print(f"before: {machine_load()}", flush=True)
    variants = {"jobs 1": ["--jobs", "1"], "jobs 2": ["--jobs", "2"]}
    results: dict[str, list[dict]] = {name: [] for name in [*variants, "dask"]}
    with tempfile.TemporaryDirectory(prefix="sfl-bench-study-") as tmp:
        cluster = None
        if not args.no_dask:
            cluster = loopback_cluster(Path(tmp), workers=2, cores=[c for c in core_slots(cpus, 2) if c] or None)
            variants["dask"] = ["--cluster", str(cluster.__enter__())]
        try:
            rng = random.Random(0)
            for round_ in range(args.rounds):
                order = list(variants)
                rng.shuffle(order)
                for name in order:
                    out = Path(tmp) / f"{name.replace(' ', '')}-{round_}"
                    results[name].append(got := study(out, args.trials, args.runs, variants[name]))
                    print(
                        f"  round {round_ + 1} {name:>6}: command {got['command']:6.1f} s, runs' span "
                        f"{got['span']:6.1f} s, each run {min(got['runs']):.1f}-{max(got['runs']):.1f} s "
                        f"({machine_load()})",
                        flush=True,
                    )
        finally:
            if cluster is not None:
                cluster.__exit__(None, None, None)
    print(f"after: {machine_load()}")
    print()
    print(f"{'variant':>8} {'command, s':>11} {'runs span, s':>13} {'one run, s':>11}")
    for name in variants:
        rows = results[name]
        run_wall = np.median([w for r in rows for w in r["runs"]])
        print(
            f"{name:>8} {np.median([r['command'] for r in rows]):11.1f} {np.median([r['span'] for r in rows]):13.1f} "
            f"{run_wall:11.1f}"
        )

    def ratio(a: str, b: str, key: str) -> float:
        return float(np.median([x[key] / y[key] for x, y in zip(results[a], results[b], strict=True)]))

    print()
    for key, what in (("span", "runs' span"), ("command", "whole command")):
        print(f"speed-up jobs 1 / jobs 2 ({what}): {ratio('jobs 1', 'jobs 2', key):.2f} (worth having near 2)")
        if "dask" in variants:
            cost = ratio("dask", "jobs 2", key) - 1
            print(f"Dask's cost over jobs 2 ({what}): {cost:+.1%} (goal within 10 % for runs of 30 s or more)")


if __name__ == "__main__":
    main()
