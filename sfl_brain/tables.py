"""Typed tables of a run: ``trials.parquet`` and ``decisions.parquet`` beside ``records.jsonl``.

``records.jsonl`` is the append-only log a killed run keeps; it mixes decision and trial rows, so a
data user who loads it in pandas gets one sparse table with booleans as floats. At the end of a run
the same rows are written as two Parquet tables with a fixed schema: booleans as booleans, integers
as integers, "no value" as null, and each column's unit and meaning in the schema's field metadata
(``pyarrow.parquet.read_schema(path).field(name).metadata``). ``docs/records.md`` documents every
column from :data:`DECISION_COLUMNS` and :data:`TRIAL_COLUMNS` (a test keeps the two in step).

Columns that depend on the scenario: one per axis of Omega (``<axis name>``, the physical value,
with the axis's ``unit``) and one per body metric (``m_<metric>``: bool, int64 or float64 by its values).
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import pyarrow as pa
import pyarrow.parquet as pq

from .records import read_records


@dataclass(frozen=True)
class Column:
    name: str
    type: pa.DataType
    unit: str
    meaning: str


_f8, _i8, _b = pa.float64(), pa.int64(), pa.bool_()

DECISION_COLUMNS: tuple[Column, ...] = (
    Column("decision", _i8, "", "index of the decision in the run, from 0"),
    Column("trial", _i8, "", "the trial this go decision started (null for a no-go)"),
    Column("go", _b, "", "the early warning let the candidate through (3.3)"),
    Column("s_vig", _f8, "", "vigilance threshold the decision used"),
    Column("d_success", _f8, "unit space", "distance to the success map's winner (3.1)"),
    Column("d_failure", _f8, "unit space", "distance to the failure map's winner (3.2)"),
    Column("v_unit", pa.list_(_f8), "unit space", "the candidate, one coordinate in [0, 1] per axis"),
)

TRIAL_COLUMNS: tuple[Column, ...] = (
    Column("trial", _i8, "", "index of the trial in the run, from 0"),
    Column("decision", _i8, "", "the go decision that started it (learn protocol)"),
    Column("success", _b, "", "the body's verdict on the trial"),
    Column("quality", _f8, "", "the body's quality eta of the trial (efficiency); null if none"),
    Column("rho", _f8, "", "OFC's graded reward of a success (QARL); null for failures or without OFC"),
    Column("n_success", _i8, "", "successes so far, this trial included"),
    Column("n_failure", _i8, "", "failures so far, this trial included"),
    Column("ns_nf", _f8, "", "n_success / n_failure; null while there is no failure"),
    Column("success_rate", _f8, "", "successes / trials so far"),
    Column("s_vig", _f8, "", "vigilance threshold the trial's decision used"),
    Column("band_low", _f8, "", "lower edge of the vigilance band after the trial"),
    Column("band_high", _f8, "", "upper edge of the vigilance band after the trial"),
    Column("map_change", _f8, "unit space", "how far the learnt map moved on this trial"),
    Column("worker", pa.string(), "", "the body worker that ran the trial"),
    Column("wall_ms", _f8, "ms", "wall time of the trial, request to result (not reproducible)"),
    Column("v_unit", pa.list_(_f8), "unit space", "the tried point, one coordinate in [0, 1] per axis"),
)


def _field(col: Column) -> pa.Field:
    return pa.field(col.name, col.type, nullable=True, metadata={"unit": col.unit, "meaning": col.meaning})


def _schema(base: tuple[Column, ...], rows: list[dict], axes: list[dict]) -> pa.Schema:
    present = set().union(*(r.keys() for r in rows)) if rows else set()
    fields = [_field(c) for c in base if c.name in present]
    for axis in axes:
        if axis["name"] in present:
            fields.append(_field(Column(axis["name"], _f8, axis.get("unit", ""), f"{axis['target']}: physical value")))
    for name in sorted(k for k in present if k.startswith("m_")):
        fields.append(_field(Column(name, _metric_type(r.get(name) for r in rows), "", f"body metric `{name[2:]}`")))
    return pa.schema(fields)


def _metric_type(values) -> pa.DataType:
    """bool if every value is a bool, int64 if every value is an int, else float64 (nulls aside)."""
    seen = [v for v in values if v is not None]
    if seen and all(isinstance(v, bool) for v in seen):
        return _b
    if seen and all(isinstance(v, int) and not isinstance(v, bool) for v in seen):
        return _i8
    return _f8


def _table(rows: list[dict], schema: pa.Schema) -> pa.Table:
    columns = {}
    for f in schema:
        values = [r.get(f.name) for r in rows]
        if pa.types.is_floating(f.type):
            values = [None if v is None else float(v) for v in values]
        columns[f.name] = pa.array(values, type=f.type)
    return pa.table(columns, schema=schema)


def write_tables(run_dir: Path, axes: list[dict]) -> list[Path]:
    """Write ``decisions.parquet`` and ``trials.parquet`` from the run's records; returns the paths.

    ``axes``: the scenario's ``space`` entries (name, target, unit). A kind with no row gets no file.
    """
    run_dir = Path(run_dir)
    rows = read_records(run_dir)
    written = []
    for kind, base in (("decision", DECISION_COLUMNS), ("trial", TRIAL_COLUMNS)):
        of_kind = [r for r in rows if r.get("kind") == kind]
        if not of_kind:
            continue
        schema = _schema(base, of_kind, axes)
        path = run_dir / f"{kind}s.parquet"
        pq.write_table(_table(of_kind, schema), path)
        written.append(path)
    return written


def columns_markdown() -> str:
    """The fixed columns of both tables as Markdown (the body of ``docs/records.md``'s tables)."""
    out = []
    for title, cols in (("decisions.parquet", DECISION_COLUMNS), ("trials.parquet", TRIAL_COLUMNS)):
        out += [f"### `{title}`", "", "| column | type | unit | meaning |", "|---|---|---|---|"]
        out += [f"| `{c.name}` | {c.type} | {c.unit} | {c.meaning} |" for c in cols]
        out.append("")
    return "\n".join(out)
