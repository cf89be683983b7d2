"""Chapter-3 records stay bit-identical through refactors (issue 14: "All chapter-3 records
bit-identical before and after (same seeds), shown by a test").

``tests/golden/*.jsonl`` were written by the code before issue 14's changes (commit 403dc6e), with
every module in one process (``sfl_brain.local.run_local``); each case runs again here and must give
the same rows, field for field, float for float (JSON keeps a float64's 17 significant digits).
Wall times and worker names are left out: they are not reproducible. Columns added since (``ADDED``: the winners
of both maps, issue 21) are the only keys a row may have beyond the golden one's.
"""

from __future__ import annotations

import json

import pytest

from sfl_brain.local import run_local
from sfl_brain.scenario import load

from .conftest import ROOT

GOLDEN = ROOT / "tests" / "golden"
CASES = {
    "quickstart": ("scenarios/quickstart.yaml", ["protocol.trials=25"]),
    "e3_2_flat_s02": ("scenarios/e3_2_flat_s02.yaml", ["protocol.trials=25"]),
    "e3_4_slopes": ("scenarios/e3_4_slopes.yaml", ["protocol.trials=20"]),
    "analytic_learn": ("scenarios/analytic_learn.yaml", ["protocol.trials=60", "modules.vigilance.params.value=-0.2"]),
    "e3_1_viability": ("scenarios/e3_1_viability.yaml", ["space.0.steps=4", "space.1.steps=3"]),
}


#: record fields added after the golden records were written (issue 21: each map's winner for the trial's point)
ADDED = {"success_winner", "failure_winner"}


@pytest.mark.parametrize("name", sorted(CASES))
def test_records_equal_the_golden_records(name):
    path, sets = CASES[name]
    rows = run_local(load(ROOT / path, sets))
    expected = [json.loads(line) for line in (GOLDEN / f"{name}.jsonl").read_text().splitlines()]
    assert len(rows) == len(expected)
    for i, (row, golden) in enumerate(zip(rows, expected, strict=True)):
        row = {k: v for k, v in row.items() if k not in ("wall_ms", "worker")}
        assert set(row) - set(golden) <= ADDED, f"{name} row {i} has new fields {set(row) - set(golden) - ADDED}"
        a = json.dumps({k: v for k, v in row.items() if k in golden}, sort_keys=True)
        b = json.dumps(golden, sort_keys=True)
        assert a == b, f"{name} row {i} differs:\n got      {a}\n expected {b}"
