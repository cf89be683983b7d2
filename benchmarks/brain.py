"""Brain-side speed: ACC evaluations per second, and the whole learning cycle per trial over processes.

    python benchmarks/brain.py [--trials 500] [--repeats 3] [--batches 2000]

(1) ACC on 5x5x5 maps in one process: candidates evaluated per second (batches of 64, eqs. 3.1-3.3);
(2) the learning cycle on the analytic body (no physics): per-trial wall time with every module in
    its own process over Zenoh, versus the same protocol in one process; the process figure is the
    brain-side overhead a real run adds on top of its physics (goal <= 2 ms per trial).
"""

from __future__ import annotations

import argparse
import tempfile
import time
from pathlib import Path

import numpy as np

from sfl_brain.messages import Evaluate
from sfl_brain.modules.acc import ACC
from sfl_brain.protocols.local import run_local
from sfl_brain.runtime.run import run
from sfl_brain.scenario import load

ROOT = Path(__file__).resolve().parents[1]


def main() -> None:
    parser = argparse.ArgumentParser()
    parser.add_argument("--trials", type=int, default=500, help="trials per learning run")
    parser.add_argument("--repeats", type=int, default=3, help="runs of each variant (the median is printed)")
    parser.add_argument("--batches", type=int, default=2000, help="ACC batches of 64 candidates")
    args = parser.parse_args()
    acc = ACC(ACC.Params(shape=(5, 5, 5), dim=3), seed=0)
    rng = np.random.default_rng(0)
    batches = [rng.random((64, 3)) for _ in range(args.batches)]
    t = time.perf_counter()
    for b in batches:
        acc.handle(Evaluate(candidates=b, s_vig=0.0))
    rate = 64 * len(batches) / (time.perf_counter() - t)
    print(f"ACC 5x5x5, one process: {rate:,.0f} evaluations/s (batches of 64)")
    trials = args.trials
    overrides = [f"protocol.trials={trials}", "modules.vigilance.params.value=-0.1"]
    per_trial_proc, teardown = [], []
    for _ in range(args.repeats):
        plan = load(ROOT / "scenarios" / "analytic_learn.yaml", overrides)
        with tempfile.TemporaryDirectory() as tmp:
            marks: dict[str, float] = {}

            def progress(p, marks=marks):
                marks.setdefault("first", time.perf_counter())
                marks["last"] = time.perf_counter()

            run(plan, Path(tmp) / "run", on_progress=progress)
            per_trial_proc.append((marks["last"] - marks["first"]) / (trials - 1))
            teardown.append(time.perf_counter() - marks["last"])
    per_trial_local = []
    for _ in range(args.repeats):
        t0 = time.perf_counter()
        run_local(load(ROOT / "scenarios" / "analytic_learn.yaml", overrides))
        per_trial_local.append((time.perf_counter() - t0) / trials)
    p, l = np.median(per_trial_proc), np.median(per_trial_local)
    print(f"learning cycle, analytic body, {trials} trials (s_vig -0.1), median of {args.repeats}:")
    print(
        f"  modules as processes over Zenoh: {p * 1e3:.2f} ms/trial ({1 / p:,.0f} trials/s; first to last trial,"
        " Rerun and records included; goal <= 2 ms)"
    )
    print(f"  after the last trial (finish, stop, merge the recording): {np.median(teardown):.2f} s once per run")
    print(f"  same protocol in one process:    {l * 1e3:.2f} ms/trial ({1 / l:,.0f} trials/s)")
    print(f"  ratio processes / one process:   {p / l:.2f}; the bus adds {(p - l) * 1e3:.2f} ms per trial")


if __name__ == "__main__":
    main()
