"""Trials of whole runs placed as ``lockstep.pin_cpus: auto`` places them now, against the placement before issue 34.

    python benchmarks/placement.py [--rounds 3] [--trials 40] [--conditions quiet,pinned,later,crowded]

Two placements of the same run (the planar reflexive walker learning, ``scenarios/quickstart.yaml`` with
``protocol.trials=--trials``, 3-s trials, no body recording), by ``sfl run --quiet``:

(before) ``lockstep.pin_cpus: always``: the body and its controller on the last usable core, the brain modules on the
         others, whatever else runs there: the placement ``auto`` made before issue 34;
(yields) ``lockstep.pin_cpus: auto``: the pair on the least busy core, no module on a core other work keeps busy,
         nothing pinned when every core is; the supervisor looks again every 5 s and the placement yields when other
         work comes to keep the pair's core busy (``sfl_brain.runtime.placement``).

on four machines:

(quiet)   nothing else runs (but what runs on this machine anyway: the load average says);
(pinned)  a process spinning on the last usable core, started before the run (another run pinned there, a job
          under ``taskset``): the core ``before`` traps the pair on;
(later)   the same process started once the run's first trial is recorded, on the core its pair was placed on;
(crowded) one process spinning per usable core and one more, not pinned: more busy processes than cores.

The figure is a run's median trial time (``wall_ms`` of its trial rows; for ``later``, of the trials recorded after
the spinning process started), which leaves out the start and the end (the same in both). Each round runs, for each
machine in a shuffled order, both placements one after the other in a shuffled order (interleaved, so that both see
the same load); a time is a median over the rounds, a ratio (yields / before) the median of the ratios within each
round. The load average is printed.
"""

from __future__ import annotations

import argparse
import json
import os
import random
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
from _floor import machine_load  # noqa: E402

from sfl_brain.runtime.placement import usable_cpus  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]
SCENARIO = ROOT / "scenarios" / "quickstart.yaml"
PLACEMENTS = {"before": "always", "yields": "auto"}
CONDITIONS = ("quiet", "pinned", "later", "crowded")
SPIN = [sys.executable, "-c", "while True: pass"]


def spinning(cores: set[int] | None) -> subprocess.Popen:
    """A process that spins, on ``cores`` (None: wherever the scheduler puts it)."""
    return subprocess.Popen(SPIN, preexec_fn=(lambda: os.sched_setaffinity(0, cores)) if cores else None)


def stop(procs: list[subprocess.Popen]) -> None:
    for proc in procs:
        proc.kill()
        proc.wait()


def trial_rows(run_dir: Path) -> list[dict]:
    path = run_dir / "records.jsonl"
    if not path.exists():
        return []
    rows = []
    for line in path.read_bytes().splitlines():
        if line.startswith(b'{"kind":"trial"'):
            try:
                rows.append(json.loads(line))
            except ValueError:
                break
    return rows


def one_run(folder: Path, placement: str, condition: str, trials: int) -> tuple[float, str]:
    """(median trial ms, where the run placed its pair) of one ``sfl run`` under ``condition``."""
    cores = usable_cpus()
    out = folder / f"{condition}-{placement}-{time.monotonic_ns()}"
    sets = [
        f"protocol.trials={trials}",
        "modules.body.params.duration=3",
        "record.body_every=0",
        f"lockstep.pin_cpus={PLACEMENTS[placement]}",
    ]
    load = []
    if condition == "pinned":
        load = [spinning({cores[-1]})]
    elif condition == "crowded":
        load = [spinning(None) for _ in range(len(cores) + 1)]
    command = [sys.executable, "-m", "sfl_brain.cli", "run", str(SCENARIO), "--out", str(out), "--quiet"]
    proc = subprocess.Popen(
        command + [a for s in sets for a in ("--set", s)],
        cwd=ROOT,
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
    )
    first = 0
    try:
        if condition == "later":  # once the run has placed itself and tried once, spin on its pair's core
            while not trial_rows(out) and proc.poll() is None:
                time.sleep(0.05)
            placed = json.loads((out / "logs" / "placement.json").read_text())
            pair = placed["cores"].get("body") or [cores[-1]]
            first = len(trial_rows(out))
            load = [spinning(set(pair))]
        stdout, stderr = proc.communicate(timeout=3600)
    finally:
        stop(load)
    if proc.returncode != 0:
        raise SystemExit(f"sfl run failed ({placement}, {condition}): {stderr[-2000:]}")
    walls = [r["wall_ms"] for r in sorted(trial_rows(out), key=lambda r: r["trial"])[first:]]
    placed = json.loads((out / "logs" / "placement.json").read_text())
    where = placed["reason"] + ("; then it yielded" if placed.get("earlier") else "")
    return float(np.median(walls)), where


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--rounds", type=int, default=3)
    parser.add_argument("--trials", type=int, default=40, help="trials per run (3 s of simulated time each)")
    parser.add_argument("--conditions", default=",".join(CONDITIONS))
    args = parser.parse_args()
    conditions = [c for c in args.conditions.split(",") if c]
    if len(usable_cpus()) < 2:
        raise SystemExit("one usable core: no placement to compare")
    print(f"placement of whole runs, {args.trials} trials each, {args.rounds} rounds; {machine_load()}")
    times: dict[tuple[str, str], list[float]] = {}
    ratios: dict[str, list[float]] = {}
    where: dict[tuple[str, str], list[str]] = {}
    with tempfile.TemporaryDirectory(prefix="sfl-bench-placement-") as tmp:
        for _ in range(args.rounds):
            for condition in random.sample(conditions, len(conditions)):
                got = {}
                for placement in random.sample(list(PLACEMENTS), len(PLACEMENTS)):
                    got[placement], said = one_run(Path(tmp), placement, condition, args.trials)
                    times.setdefault((condition, placement), []).append(got[placement])
                    where.setdefault((condition, placement), []).append(said)
                ratios.setdefault(condition, []).append(got["yields"] / got["before"])
    print(f"after the runs: {machine_load()}")
    print("median trial time, ms (over the rounds), and yields / before (median of the ratios within each round):")
    for condition in conditions:
        before, yields = (float(np.median(times[(condition, p)])) for p in ("before", "yields"))
        print(
            f"  {condition:8s} before {before:8.1f}   yields {yields:8.1f}   "
            f"yields/before = {float(np.median(ratios[condition])):.2f}  (rounds: "
            + ", ".join(f"{r:.2f}" for r in ratios[condition])
            + ")"
        )
    print("where each placement put the pair (last round):")
    for condition in conditions:
        for placement in PLACEMENTS:
            print(f"  {condition:8s} {placement:7s} {where[(condition, placement)][-1]}")


if __name__ == "__main__":
    main()
