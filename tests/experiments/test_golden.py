"""Chapter-3 records stay the same through refactors, and hold across machines (issues 14 and 35).

The golden records (``tests/golden/<snapshot>/``) were first written by the code before issue 14's changes (commit
403dc6e), with every module in one process, on a CPU with AVX-512. On another CPU numpy takes other SIMD kernels
(``recording.provenance``), so the same code gives the same outcomes and decisions but floats that differ in their
last bits, and a 10-s walk amplifies those bits. Two promises, two tests:

- **on the platform that wrote a snapshot, bit for bit** (the refactor guard): every row, field for field, float for
  float (JSON keeps a float64's 17 significant digits). The snapshot whose ``platform.json`` equals this machine's
  (numeric platform and the versions that compute) is the reference; a machine that has none skips this test and
  says how to write one.
- **on any machine, against every snapshot**: every outcome, decision, go/no-go, count, step and winner identical,
  and every float within :data:`REL_TOL` of the snapshot's (``docs/records.md``, "Reproducibility", gives what was
  measured between an AVX-512 and an AVX2 machine).

Columns added since a snapshot was written (``ADDED``: the winners of both maps, issue 21) are the only keys a row may
have beyond the golden one's.
"""

from __future__ import annotations

import json
import math
from pathlib import Path

import pytest

from ..golden import CASES, platform_now, read_platform, read_snapshot, run_case, snapshots

#: record fields added after the first snapshot was written (issue 21: each map's winner for the trial's point)
ADDED = {"success_winner", "failure_winner"}

#: how far a float may be from another machine's, relative to the larger: a 10-s planar walk turns a last-bit
#: difference of one ``exp`` into up to 8.1e-4 of its energy (measured: AVX-512 snapshot against an AVX2 machine)
REL_TOL = 1e-2
#: and absolute, for values that are 0 on one machine
ABS_TOL = 1e-12

SNAPSHOTS = snapshots()


def differences(got, want, path: str = "") -> list[str]:
    """Where ``got`` is not ``want`` within the cross-machine tolerance: exact for everything but floats."""
    if isinstance(want, float) or isinstance(got, float):
        if isinstance(want, float) and isinstance(got, float):
            if math.isnan(want) and math.isnan(got):
                return []
            if math.isclose(got, want, rel_tol=REL_TOL, abs_tol=ABS_TOL):
                return []
        return [f"{path}: got {got!r}, golden {want!r}"]
    if isinstance(want, dict) and isinstance(got, dict) and set(got) == set(want):
        return [d for key in sorted(want) for d in differences(got[key], want[key], f"{path}.{key}".lstrip("."))]
    if isinstance(want, list) and isinstance(got, list) and len(got) == len(want):
        return [d for i, (g, w) in enumerate(zip(got, want, strict=True)) for d in differences(g, w, f"{path}[{i}]")]
    if type(got) is not type(want) or got != want:
        return [f"{path}: got {got!r}, golden {want!r}"]
    return []


def test_there_are_snapshots_of_every_case():
    assert len(SNAPSHOTS) >= 2, SNAPSHOTS
    for folder in SNAPSHOTS:
        assert sorted(p.stem for p in folder.glob("*.jsonl")) == sorted(CASES), folder


def exact_snapshot() -> Path | None:
    """The snapshot written on this machine's numeric platform, if there is one."""
    here = platform_now()
    for folder in SNAPSHOTS:
        about = read_platform(folder)
        if about.get("exact") and about.get("numeric_platform") == here["numeric_platform"]:
            if about.get("versions") == here["versions"]:
                return folder
    return None


def test_this_platform_has_a_bit_for_bit_snapshot():
    """Says (as a skip) when the bit-for-bit guard below cannot run here; the cross-machine comparison still does."""
    if exact_snapshot() is None:
        pytest.skip(
            f"no golden snapshot was written on this numeric platform ({json.dumps(platform_now(), sort_keys=True)}): "
            "records are compared with every snapshot within the cross-machine tolerance only; "
            "`python -m tests.golden.write NAME` writes one (tests/golden/README.md)"
        )


@pytest.mark.parametrize("name", sorted(CASES))
def test_records_equal_the_golden_records(name):
    """Bit for bit against the snapshot of this platform (the refactor guard), then against every snapshot within the
    cross-machine tolerance: every discrete field identical, floats within REL_TOL (one run of the case for both)."""
    rows = run_case(name)
    exact = exact_snapshot()
    if exact is not None:
        expected = read_snapshot(exact, name)
        assert len(rows) == len(expected)
        for i, (row, golden) in enumerate(zip(rows, expected, strict=True)):
            assert set(row) - set(golden) <= ADDED, f"{name} row {i} has new fields {set(row) - set(golden) - ADDED}"
            a = json.dumps({k: v for k, v in row.items() if k in golden}, sort_keys=True)
            b = json.dumps(golden, sort_keys=True)
            assert a == b, f"{name} row {i} differs from {exact.name} (this platform's):\n got      {a}\n expected {b}"
    for snapshot in SNAPSHOTS:
        expected = read_snapshot(snapshot, name)
        assert len(rows) == len(expected), f"{name}: {len(rows)} rows, {snapshot.name} has {len(expected)}"
        for i, (row, golden) in enumerate(zip(rows, expected, strict=True)):
            assert set(row) - set(golden) <= ADDED, f"{name} row {i} has new fields {set(row) - set(golden) - ADDED}"
            found = differences({k: v for k, v in row.items() if k in golden}, golden)
            assert not found, f"{name} row {i} ({golden.get('kind')}) differs from {snapshot.name}: " + "; ".join(found)


def test_the_tolerance_catches_what_it_must():
    """The cross-machine comparison is not a blank cheque: a flipped outcome, another winner, a float off by more than
    REL_TOL all fail it; last-bit and 1e-4 differences of a float pass."""
    golden = {"success": True, "success_winner": 3, "m_energy": 39.09199487091651, "v_unit": [0.77, 0.11]}
    assert differences({**golden, "m_energy": 39.091994870916494}, golden) == []
    assert differences({**golden, "m_energy": 39.09199487091651 * (1 + 1e-4)}, golden) == []
    assert differences({**golden, "success": False}, golden)
    assert differences({**golden, "success_winner": 4}, golden)
    assert differences({**golden, "m_energy": 39.09199487091651 * (1 + 2 * REL_TOL)}, golden)
    assert differences({**golden, "v_unit": [0.77]}, golden)
    assert differences({**golden, "m_energy": None}, golden)
