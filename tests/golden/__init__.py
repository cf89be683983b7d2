"""Golden chapter-3 records, one snapshot per numeric platform (``tests/golden/README.md``).

Each snapshot is a folder of ``<case>.jsonl`` files (one record row per line, as
:func:`~sfl_brain.protocols.local.run_local` returns them, without their wall times and worker names) and a
``platform.json`` saying what wrote them and on what.
"""

from __future__ import annotations

import json
from pathlib import Path

HERE = Path(__file__).resolve().parent
ROOT = HERE.parents[1]

#: the cases: a scenario of the repository and its ``--set`` overrides, short enough for the test suite
CASES = {
    "quickstart": ("scenarios/quickstart.yaml", ["protocol.trials=25"]),
    "e3_2_flat_s02": ("scenarios/e3_2_flat_s02.yaml", ["protocol.trials=25"]),
    "e3_4_slopes": ("scenarios/e3_4_slopes.yaml", ["protocol.trials=20"]),
    "analytic_learn": ("scenarios/analytic_learn.yaml", ["protocol.trials=60", "modules.vigilance.params.value=-0.2"]),
    "e3_1_viability": ("scenarios/e3_1_viability.yaml", ["space.0.steps=4", "space.1.steps=3"]),
}

#: the fields of a row that are not reproducible at all (the wall and CPU clocks, which worker ran the trial)
UNSTABLE = ("wall_ms", "worker", "cpu_body_s", "cpu_controller_s")

#: the fields of a row that the snapshots were written before (reproducible, but not in them)
NEWER = ("sim_s",)

#: the distributions that compute a golden case's numbers besides numpy (its version is in the numeric platform)
COMPUTING = ("pymunk",)


def run_case(name: str) -> list[dict]:
    """The case's record rows, computed now with every module in one process."""
    from sfl_brain.protocols.local import run_local
    from sfl_brain.scenario import load

    path, sets = CASES[name]
    rows = run_local(load(ROOT / path, sets))
    return [{k: v for k, v in row.items() if k not in UNSTABLE + NEWER} for row in rows]


def platform_now() -> dict:
    """What decides the last bits of a golden case's floats on this machine (compared whole with a snapshot's)."""
    from sfl_brain.recording.provenance import numeric_platform, versions

    return {"numeric_platform": numeric_platform(), "versions": versions(COMPUTING)}


def snapshots() -> list[Path]:
    """The snapshot folders, by name."""
    return sorted(p.parent for p in HERE.glob("*/platform.json"))


def read_snapshot(folder: Path, name: str) -> list[dict]:
    return [json.loads(line) for line in (folder / f"{name}.jsonl").read_text().splitlines()]


def read_platform(folder: Path) -> dict:
    return json.loads((folder / "platform.json").read_text())
