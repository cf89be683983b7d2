"""The side-by-side tables of docs/experiments/engines.sh: the humanoid on PyBullet and on MuJoCo.

    python docs/experiments/engines_table.py RUNS_DIR

RUNS_DIR (default runs/engines) holds gait_<engine>, e4_5_<engine> and e5_1_<engine>_s<seed>.

Prints, from each run's records and summary: the gait's successes per condition with their Wilson 95% intervals and
the time to the 1.5-m line; E4.5's walks that stayed up for 250 s; E5.1's successes in 100 trials per seed (Wilson
95%), N_s / N_f, the best and the mean efficiency eta of the successes, how the failures ended, and the run's status
and wall time. E4.5's return maps are on the ``sfl report`` pages (docs/results/engines/e4_5_<engine>/).
"""

from __future__ import annotations

import json
import sys
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[2]
sys.path.insert(0, str(ROOT))
from sfl_brain.recording.records import read_records  # noqa: E402
from sfl_brain.report.conditions import wilson  # noqa: E402

ENGINES = ("pybullet", "mujoco")


def trials(run: Path) -> list[dict]:
    return [r for r in read_records(run) if r["kind"] == "trial"]


def summary(run: Path) -> dict:
    path = run / "summary.json"
    return json.loads(path.read_text()) if path.exists() else {"status": "missing"}


def rate(k: int, n: int) -> str:
    low, high = wilson(k, n)
    return f"{k}/{n} [{low:.0%}, {high:.0%}]"


def gait(runs: Path) -> None:
    print("### The gait over 10 starts (humanoid_gait.yaml)\n")
    print("| engine | status | condition | walks 1.5 m (Wilson 95%) | time s, mean (sd) | energy J, mean | eta, mean |")
    print("|---|---|---|---|---|---|---|")
    for engine in ENGINES:
        run = runs / f"gait_{engine}"
        if not run.exists():
            continue
        rows, status = trials(run), summary(run)["status"]
        for condition in dict.fromkeys(r["condition"] for r in rows):
            mine = [r for r in rows if r["condition"] == condition]
            ok = [r for r in mine if r["success"]]
            time = np.array([r["m_time"] for r in ok])
            energy = np.mean([r["m_energy"] for r in ok]) if ok else float("nan")
            eta = np.mean([r["quality"] for r in ok]) if ok else float("nan")
            print(
                f"| {engine} | {status} | {condition} | {rate(len(ok), len(mine))} | "
                f"{time.mean():.2f} ({time.std():.2f}) | {energy:.1f} | {eta:.2e} |"
            )
    print()


def poincare(runs: Path) -> None:
    print("### E4.5: 250-s walks (e4_5_poincare.yaml)\n")
    print("| engine | status | start_noise | upright for 250 s (Wilson 95%) |")
    print("|---|---|---|---|")
    for engine in ENGINES:
        run = runs / f"e4_5_{engine}"
        if not run.exists():
            continue
        rows, status = trials(run), summary(run)["status"]
        for noise in sorted({r["body.start_noise"] for r in rows}):
            mine = [r for r in rows if r["body.start_noise"] == noise]
            up = sum(1 for r in mine if not r["m_fell"] and not r["m_left_lane"] and r["m_time"] >= 250.0 - 1e-6)
            print(f"| {engine} | {status} | {noise:g} | {rate(up, len(mine))} |")
    print()


def learning(runs: Path) -> None:
    print("### E5.1, 100 trials with QARL (e5_learn.yaml, protocol.trials=100)\n")
    print(
        "| engine | seed | status | successes (Wilson 95%) | N_s / N_f | best eta | mean eta of successes | failures: "
        "fell / lane / timed out | wall s |"
    )
    print("|---|---|---|---|---|---|---|---|---|")
    for engine in ENGINES:
        for seed in (0, 1, 2):
            run = runs / f"e5_1_{engine}_s{seed}"
            if not run.exists():
                continue
            rows, info = trials(run), summary(run)
            ok = [r for r in rows if r["success"]]
            bad = [r for r in rows if not r["success"]]
            fell = sum(1 for r in bad if r["m_fell"])
            lane = sum(1 for r in bad if r["m_left_lane"] and not r["m_fell"])
            wall = info.get("wall_time_s")
            wall = "-" if wall is None else f"{wall:.0f}"
            mean = np.mean([r["quality"] for r in ok]) if ok else 0.0
            print(
                f"| {engine} | {seed} | {info['status']} | {rate(len(ok), len(rows))} | "
                f"{len(ok) / max(len(bad), 1):.2f} | {max((r['quality'] for r in ok), default=0):.2e} | "
                f"{mean:.2e} | {fell} / {lane} / {len(bad) - fell - lane} | "
                f"{wall} |"
            )
    print()


def main() -> None:
    runs = Path(sys.argv[1] if len(sys.argv) > 1 else "runs/engines")
    gait(runs)
    poincare(runs)
    learning(runs)


if __name__ == "__main__":
    main()
