"""The benchmarks stay runnable: each script runs on a tiny budget and prints its figures.

Nothing here asserts a time (machines are noisy); only that each figure is printed and is a
finite positive number."""

import math
import re
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]


def bench(script: str, *args: str) -> str:
    done = subprocess.run(
        [sys.executable, str(ROOT / "benchmarks" / script), *args],
        capture_output=True,
        text=True,
        timeout=600,
        cwd=ROOT,
    )
    assert done.returncode == 0, done.stderr[-3000:]
    return done.stdout


def figures(text: str, pattern: str, count: int = 1) -> list[float]:
    values = [float(v) for v in re.findall(pattern, text)]
    assert len(values) == count, f"{pattern!r} in:\n{text}"
    assert all(math.isfinite(v) and v > 0 for v in values), values
    return values


def test_bus_benchmark_prints_the_framework_against_raw_zenoh():
    out = bench("bus.py", "--ticks", "400", "--blocks", "4", "--pin", "always")
    assert "pin always" in out
    figures(out, r"framework / raw(?: polling)? \(medians, the faster raw pattern\): ([\d.]+)")
    figures(out, r"median +([\d.]+) us", count=6)  # raw, polling, z_ping/z_pong, by hand, framework, one process
    figures(out, r"first trial done ([\d.]+) s")


def test_planar_benchmark_prints_the_trial_ratios_and_the_sweep_speed_ups():
    out = bench("planar.py", "--repeats", "1", "--grid", "2")
    figures(out, r"\(c\)/\(b\) = ([\d.]+)")
    figures(out, r"\(b0\)/\(b\) = ([\d.]+)")  # the body before batching, measured beside it
    figures(out, r"speed-up ([\d.]+)x", count=2)


def test_brain_benchmark_prints_the_cycle_per_trial():
    out = bench("brain.py")
    figures(out, r"([\d.]+) ms/trial", count=2)


def test_cpg_benchmark_prints_the_cost_per_tick_beside_the_physics():
    out = bench("cpg.py", "--ticks", "200")
    # planar and humanoid circuits (network and controller tick each), the stand-in and the 8-link walker physics
    figures(out, r"median +([\d.]+) us", count=6)
