"""Chapter-3 records stay bit-identical through refactors (issue 14: "All chapter-3 records
bit-identical before and after (same seeds), shown by a test").

``tests/golden/*.jsonl`` were written by the code before issue 14's changes (commit 403dc6e), with
every module in one process (``sfl_brain.local.run_local``); each case runs again here and must give
the same rows, field for field, float for float (JSON keeps a float64's 17 significant digits).
Wall times and worker names are left out: they are not reproducible.
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


@pytest.mark.parametrize("name", sorted(CASES))
def test_records_equal_the_golden_records(name):
    path, sets = CASES[name]
    rows = run_local(load(ROOT / path, sets))
    got = [json.dumps({k: v for k, v in r.items() if k not in ("wall_ms", "worker")}, sort_keys=True) for r in rows]
    expected = (GOLDEN / f"{name}.jsonl").read_text().splitlines()
    assert len(got) == len(expected)
    for i, (a, b) in enumerate(zip(got, expected, strict=True)):
        assert a == b, f"{name} row {i} differs:\n got      {a}\n expected {b}"
