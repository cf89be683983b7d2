"""What a whole short ``sfl run`` costs with its module processes forked from the run's fork server, against each
started anew (``SFL_FORK_SERVER=0``): wall time and the CPU seconds of the run and every process it started.

    python benchmarks/startup.py [--repeats 7] [--trials 3] [--only planar|analytic]

Each round runs both, in a shuffled order (interleaved, so that both see the same machine load), for ``--repeats``
rounds: the planar walker (``planar``: ``scenarios/e3_2_flat_s0.yaml``: five module processes, three of them
import Rerun) and the analytic learner (``analytic``: ``scenarios/analytic_learn.yaml``), ``--trials`` trials each.
CPU is the run's own and its children's (``RUSAGE_CHILDREN``, the fork server's children included: it waits for
them, and the run for it). A time is a median over the rounds; a ratio the median of the ratios within each round.
The load average is printed before and after.
"""

from __future__ import annotations

import argparse
import os
import resource
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
import _floor  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]
SCENARIOS = {"planar": "e3_2_flat_s0.yaml", "analytic": "analytic_learn.yaml"}


def one_run(scenario: str, trials: int, fork: bool, folder: Path) -> tuple[float, float]:
    """(wall s, CPU s of the run and all it started) of ``sfl run SCENARIO`` with ``trials`` trials."""
    env = {**os.environ, "SFL_FORK_SERVER": "1" if fork else "0"}
    out = folder / f"run-{time.monotonic_ns()}"
    before = resource.getrusage(resource.RUSAGE_CHILDREN)
    t = time.perf_counter()
    done = subprocess.run(
        [sys.executable, "-m", "sfl_brain.cli", "run", str(ROOT / "scenarios" / scenario)]
        + ["--set", f"protocol.trials={trials}", "--out", str(out), "--quiet"],
        env=env,
        cwd=ROOT,
        capture_output=True,
        text=True,
    )
    wall = time.perf_counter() - t
    after = resource.getrusage(resource.RUSAGE_CHILDREN)
    assert done.returncode == 0, done.stderr[-2000:]
    assert (out / "logs" / "zygote.log").exists() == fork, "the fork server was not used as asked"
    cpu = (after.ru_utime - before.ru_utime) + (after.ru_stime - before.ru_stime)
    return wall, cpu


def main() -> None:
    parser = argparse.ArgumentParser()
    parser.add_argument("--repeats", type=int, default=7, help="rounds")
    parser.add_argument("--trials", type=int, default=3, help="trials per run")
    parser.add_argument("--only", choices=list(SCENARIOS), help="one scenario only")
    args = parser.parse_args()
    scenarios = {args.only: SCENARIOS[args.only]} if args.only else SCENARIOS
    print(f"before: {_floor.machine_load()}", flush=True)
    shuffle = np.random.default_rng(0).shuffle
    samples: dict[tuple[str, bool], list[tuple[float, float]]] = {}
    with tempfile.TemporaryDirectory(prefix="sfl-startup-") as tmp:
        for _ in range(args.repeats):
            order = [(name, fork) for name in scenarios for fork in (True, False)]
            shuffle(order)
            for name, fork in order:
                samples.setdefault((name, fork), []).append(one_run(scenarios[name], args.trials, fork, Path(tmp)))
    print(
        f"a whole sfl run of {args.trials} trials, {args.repeats} rounds, interleaved; times: medians; "
        "ratios: medians of the ratios within a round"
    )
    for name in scenarios:
        forked, fresh = np.array(samples[(name, True)]), np.array(samples[(name, False)])
        print(
            f"  {name:8s} forked   wall {np.median(forked[:, 0]):6.2f} s   CPU {np.median(forked[:, 1]):6.2f} s\n"
            f"  {name:8s} anew     wall {np.median(fresh[:, 0]):6.2f} s   CPU {np.median(fresh[:, 1]):6.2f} s\n"
            f"  {name:8s} forked/anew: wall {np.median(forked[:, 0] / fresh[:, 0]):.2f}, "
            f"CPU {np.median(forked[:, 1] / fresh[:, 1]):.2f}"
        )
    print(f"after: {_floor.machine_load()}")


if __name__ == "__main__":
    main()
