"""A proposer's cost beside the trials it chooses: ask + tell (with its checkpoint) against a trial's wall time.

    python benchmarks/proposers.py [--trials 200] [--repeats 3] [--scenario scenarios/e3_2_flat_s0.yaml]

For each proposer (``protocol.proposer.kind``), ``repeats`` learn runs of the planar reflex walker (the E3.2
setting) over processes, the controller in its body worker's process (``modules.controller.colocate``: the
fastest trials, so the strictest ratio). Each run's summary holds the seconds spent in the proposer
(``proposer_seconds``: ask, with the gate's requests, which are success-failure learning's decisions; tell, with
the pickled checkpoint); the records hold each trial's wall time. Printed per proposer, medians over the
repeats: ask + tell per trial, the trial's mean wall time, and their ratio (goal: under 5 %).
"""

from __future__ import annotations

import argparse
import json
import os
import tempfile
from pathlib import Path

import numpy as np

from sfl_brain.recording.records import read_records
from sfl_brain.runtime.run import run
from sfl_brain.scenario import load

ROOT = Path(__file__).resolve().parents[1]
KINDS = ("sfl", "random", "cma", "tpe", "safe_bo")


def one_run(scenario: Path, kind: str, trials: int, seed: int) -> tuple[float, float, float, float]:
    """(ask ms per trial without the gate's requests, the gate's ms per trial, tell ms per trial, trial wall ms
    mean) of one run."""
    plan = load(
        scenario,
        [f"protocol.trials={trials}", f"protocol.proposer.kind={kind}", "modules.controller.colocate=true"],
        seed=seed,
    )
    with tempfile.TemporaryDirectory() as tmp:
        run_dir, summary = run(plan, Path(tmp) / "run")
        if summary["status"] != "completed":
            raise SystemExit(f"{kind}: the run ended {summary['status']}: {summary.get('stop_reason')}")
        spent = json.loads((run_dir / "summary.json").read_text())["proposer_seconds"]
        walls = [r["wall_ms"] for r in read_records(run_dir) if r["kind"] == "trial"]
    n = len(walls)
    ms = {k: v * 1e3 / n for k, v in spent.items()}
    return ms["ask"] - ms["gate"], ms["gate"], ms["tell"], float(np.mean(walls))


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--trials", type=int, default=200, help="trials per run")
    parser.add_argument("--repeats", type=int, default=3, help="runs per proposer (medians printed)")
    parser.add_argument("--scenario", type=Path, default=ROOT / "scenarios" / "e3_2_flat_s0.yaml")
    parser.add_argument("--kinds", default=",".join(KINDS), help="proposers, comma-separated")
    args = parser.parse_args()
    print(f"load average before: {' '.join(f'{x:.2f}' for x in os.getloadavg())}")
    print(f"{args.scenario.name}, {args.trials} trials per run, {args.repeats} runs per proposer, medians:")
    print("  ask: the proposer's own time; gate: the ACC's evaluations it waits for (every proposer's decisions are")
    print("  evaluated and recorded; for sfl they are the decisions); tell: with the pickled checkpoint; per trial")
    head = f"{'proposer':<10} {'ask ms':>8} {'gate ms':>8} {'tell ms':>8} {'trial ms':>9}"
    print(f"  {head} {'(ask+tell)/trial':>17} {'with gate':>10}")
    for kind in args.kinds.split(","):
        got = np.array([one_run(args.scenario, kind, args.trials, seed) for seed in range(args.repeats)])
        ask, gate, tell, wall = np.median(got, axis=0)
        own = np.median((got[:, 0] + got[:, 2]) / got[:, 3])
        whole = np.median((got[:, 0] + got[:, 1] + got[:, 2]) / got[:, 3])
        print(f"  {kind:<10} {ask:8.2f} {gate:8.2f} {tell:8.2f} {wall:9.1f} {100 * own:16.2f} % {100 * whole:8.2f} %")
    print(f"load average after: {' '.join(f'{x:.2f}' for x in os.getloadavg())}")


if __name__ == "__main__":
    main()
