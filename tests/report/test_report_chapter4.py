"""``sfl report`` on chapter-4 runs (the CPG on the 8-link walker, E4.2): the figures, a table whose numbers are the
run's records, and the energy order of Fig. 4.16 (L1298) on known patterns."""

from __future__ import annotations

import json
import re

import numpy as np
import pytest

from sfl_brain.modules.cpg.patterns import PATTERN_POINTS
from sfl_brain.report.cpg import Neuron, energy_order, joint_patterns

from ..conftest import SCENARIOS, sfl, sfl_run

# (sigma_s, sigma_f) of each class (the digest's reference map, §1.7), and a faster oscillator
KNOWN = {**PATTERN_POINTS, "faster oscillator": (5.0, 2.0)}


def neuron(kind: str, log_e: float, frequency: float = float("nan")) -> Neuron:
    return Neuron("failure", 0, True, 1, 0.0, 0.0, kind, frequency, log_e, kind)


def test_energy_order_on_known_patterns_puts_plateau_below_oscillators():
    ss, sf = zip(*KNOWN.values(), strict=True)
    kinds, frequency, log_e = joint_patterns(list(ss), list(sf))
    assert kinds == ["plateau", "quiescent", "almost_oscillator", "oscillator", "oscillator"]
    assert frequency[4] > frequency[3]  # 0.69-s period against 1.25 s
    order = energy_order([neuron(k, e, f) for k, e, f in zip(kinds, log_e, frequency, strict=True)])
    assert order["class_order_holds"], order["overlaps"]
    assert order["ranges"]["plateau"][1] < order["ranges"]["oscillator"][0]
    assert order["oscillator_discordant"] == 0 and order["oscillator_pairs"] == 1


def test_energy_order_says_where_it_breaks():
    order = energy_order(
        [
            neuron("plateau", 1.0),
            neuron("quiescent", 0.5),
            neuron("oscillator", 3.0, 0.5),
            neuron("oscillator", 2.5, 1.0),  # faster but lower: one discordant pair
        ]
    )
    assert not order["class_order_holds"]
    assert order["overlaps"] == ["P up to 1.00 > Q from 0.50"]
    assert (order["oscillator_discordant"], order["oscillator_pairs"]) == (1, 1)


@pytest.fixture(scope="module")
def short_run(tmp_path_factory):
    """E4.2's scenario, 10 trials of 4 s: a real run over processes."""
    out = tmp_path_factory.mktemp("e4_2") / "e4_2_short"
    done = sfl_run(
        SCENARIOS / "e4_2_learn.yaml",
        out,
        "protocol.trials=10",
        "modules.body.params.duration=4.0",
        "seed=3",
        timeout=120,
    )
    assert done.returncode == 0, done.stdout + done.stderr
    return out


def test_the_chapter_4_report_draws_its_figures_and_tabulates_the_records(short_run, tmp_path):
    report = tmp_path / "report"
    done = sfl("report", str(short_run), "--out", str(report), timeout=120)
    assert done.returncode == 0, done.stderr
    page = (report / "e4_2_learn.md").read_text()
    assert not (report / "README.md").exists()  # a chapter-4 page is named after its scenario
    for suffix in ("maps", "energy", "learning", "gait"):
        assert (report / f"e4_2_short_{suffix}.png").stat().st_size > 10_000, suffix
        assert f"![](e4_2_short_{suffix}.png)" in page
    trials = [json.loads(line) for line in (short_run / "records.jsonl").open() if '"kind":"trial"' in line]
    n = len(trials)
    wins = sum(r["success"] for r in trials)
    assert n == 10
    row = next(line for line in page.splitlines() if line.startswith("| e4_2_short | 3 |"))
    cells = [c.strip() for c in row.split("|")[1:-1]]
    assert cells[2:6] == ["completed", str(n), f"{wins / n:.1%}", f"{(n - wins) / n:.1%}"]
    assert cells[6] == ("yes" if min(wins, n - wins) >= 0.2 * n else "**no**")
    with np.load(short_run / "acc.npz") as maps:
        pruned = int((~maps["failure_active"]).sum())
        kept = int(maps["failure_active"].sum() + maps["success_active"].sum())
    assert cells[7].startswith(f"{pruned}:")
    counts = [sum(int(x) for x in re.findall(r"(\d+)[PQAO]", cells[k])) for k in (8, 9)]
    assert sum(counts) == kept  # every surviving neuron classified once
