"""Typed tables of a run: ``trials.parquet``, ``decisions.parquet`` and ``maps.parquet`` beside ``records.jsonl``.

``records.jsonl`` is the append-only log a killed run keeps; it mixes decision and trial rows, so a
data user who loads it in pandas gets one sparse table with booleans as floats. At the end of a run
the same rows are written as two Parquet tables with a fixed schema: booleans as booleans, integers
as integers, "no value" as null, and each column's unit and meaning in the schema's field metadata
(``pyarrow.parquet.read_schema(path).field(name).metadata``). ``docs/records.md`` documents every
column from :data:`DECISION_COLUMNS` and :data:`TRIAL_COLUMNS` (a test keeps the two in step).

Columns that depend on the scenario: one per axis of Omega (``<axis name>``, the physical value,
with the axis's ``unit``) and one per body metric (``m_<metric>``: bool, int64 or float64 by its values).

``maps.parquet`` holds the ACC's success and failure maps after every trial (:data:`MAP_COLUMNS`, one
row per neuron per map per snapshot). The ACC emits them as telemetry
(:class:`~sfl_brain.telemetry.MapSnapshots`); in each module process a :class:`MapTable` writes them to
``maps/<process>.parquet`` as they come, and :func:`write_tables` joins the parts at the end of the run.
"""

from __future__ import annotations

import logging
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pyarrow as pa
import pyarrow.parquet as pq

from ..telemetry import MapSnapshots
from .records import read_records

log = logging.getLogger("sfl.tables")


@dataclass(frozen=True)
class Column:
    name: str
    type: pa.DataType
    unit: str
    meaning: str


_f8, _i8, _b = pa.float64(), pa.int64(), pa.bool_()
#: a list of float64 as a Parquet file holds it (its item is named `element`, as ``pq.read_schema`` shows it)
_list_f8 = pa.list_(pa.field("element", _f8))

DECISION_COLUMNS: tuple[Column, ...] = (
    Column("decision", _i8, "", "index of the decision in the run, from 0"),
    Column("trial", _i8, "", "the trial its candidate was tried in (null when not tried: a no-go of a gated proposer)"),
    Column("go", _b, "", "the early warning's decision, d_f - d_s > s_vig (3.3), for every proposer"),
    Column("s_vig", _f8, "", "vigilance threshold the decision used"),
    Column("d_success", _f8, "unit space", "distance to the success map's winner (3.1)"),
    Column("d_failure", _f8, "unit space", "distance to the failure map's winner (3.2)"),
    Column("v_unit", _list_f8, "unit space", "the candidate, one coordinate in [0, 1] per axis"),
)

TRIAL_COLUMNS: tuple[Column, ...] = (
    Column("trial", _i8, "", "index of the trial in the run, from 0"),
    Column("decision", _i8, "", "the decision whose candidate it tried (learn protocol)"),
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
    Column("success_winner", _i8, "", "the success map's winning neuron for the trial's point, before it learnt"),
    Column("failure_winner", _i8, "", "the failure map's winning neuron for the trial's point, before it learnt"),
    Column("worker", pa.string(), "", "the body worker that ran the trial"),
    Column("wall_ms", _f8, "ms", "wall time of the trial, request to result (not reproducible)"),
    Column("sim_s", _f8, "s", "simulated time the body ran: control ticks x control_dt (0: a body without a clock)"),
    Column(
        "cpu_body_s",
        _f8,
        "s",
        "CPU time of the body worker's process on the trial, with a controller hosted in it (not reproducible)",
    ),
    Column(
        "cpu_controller_s",
        _f8,
        "s",
        "CPU time of the controller's own process on the trial; null when hosted in the body's (not reproducible)",
    ),
    Column("v_unit", _list_f8, "unit space", "the tried point, one coordinate in [0, 1] per axis"),
    Column("condition", pa.string(), "", "the named condition the trial ran under (conditions protocol)"),
    Column("repeat", _i8, "", "which start (trial seed) of its condition and grid point, from 0 (conditions protocol)"),
    Column("survived", _b, "", "the trial's verdict by protocol.judge: success, or upright (no fall)"),
)


MAP_COLUMNS: tuple[Column, ...] = (
    Column("module", pa.string(), "", "the module that holds the maps (its name in the scenario, e.g. `acc`)"),
    Column("trial", _i8, "", "trials learnt when the snapshot was taken: the maps that chose trial `trial`"),
    Column("map", pa.string(), "", "`success` (S_m) or `failure` (F_m)"),
    Column(
        "final", _b, "", "the maps as the run leaves them, after pruning (thesis §4.4.3), at the last trial's index"
    ),
    Column("neuron", _i8, "", "index of the neuron, row-major over the map's grid (`shape`)"),
    Column("weights", _list_f8, "unit space", "the neuron's weight vector, one coordinate in [0, 1] per axis"),
    Column("active", _b, "", "False for a failure neuron switched off by pruning"),
)


def _field(col: Column) -> pa.Field:
    return pa.field(col.name, col.type, nullable=True, metadata={"unit": col.unit, "meaning": col.meaning})


def _schema(
    base: tuple[Column, ...], rows: list[dict], axes: list[dict], metric_units: dict[str, str] | None = None
) -> pa.Schema:
    present = set().union(*(r.keys() for r in rows)) if rows else set()
    fields = [_field(c) for c in base if c.name in present]
    for axis in axes:
        if axis["name"] in present:
            fields.append(_field(Column(axis["name"], _f8, axis.get("unit", ""), f"{axis['target']}: physical value")))
    for name in sorted(k for k in present if k.startswith(("body.", "controller."))):
        kind = _metric_type(r.get(name) for r in rows)
        fields.append(_field(Column(name, kind, "", f"trial parameter `{name}` set by the conditions protocol")))
    for name in sorted(k for k in present if k.startswith("m_")):
        unit = (metric_units or {}).get(name[2:], "")  # as the body declares it (Body.METRICS)
        fields.append(_field(Column(name, _metric_type(r.get(name) for r in rows), unit, f"body metric `{name[2:]}`")))
    return pa.schema(fields)


def _metric_type(values) -> pa.DataType:
    """bool if every value is a bool, int64 if every value is an int, text if any value is text, a list of float64
    if every value is a list, else float64 (nulls aside)."""
    seen = [v for v in values if v is not None]
    if seen and all(isinstance(v, bool) for v in seen):
        return _b
    if seen and all(isinstance(v, int) and not isinstance(v, bool) for v in seen):
        return _i8
    if any(isinstance(v, str) for v in seen):  # text, or a grid of text and numbers: kept as text
        return pa.string()
    if seen and all(isinstance(v, list) for v in seen):
        return _list_f8
    return _f8


def _table(rows: list[dict], schema: pa.Schema) -> pa.Table:
    columns = {}
    for f in schema:
        values = [r.get(f.name) for r in rows]
        if pa.types.is_floating(f.type):
            values = [None if v is None else float(v) for v in values]
        elif pa.types.is_string(f.type):
            values = [None if v is None else str(v) for v in values]
        elif pa.types.is_list(f.type):
            values = [None if v is None else [float(x) for x in v] for v in values]
        columns[f.name] = pa.array(values, type=f.type)
    return pa.table(columns, schema=schema)


def write_tables(
    run_dir: Path, axes: list[dict], metric_units: dict[str, str] | None = None, rows: list[dict] | None = None
) -> list[Path]:
    """Write ``decisions.parquet`` and ``trials.parquet`` from the run's records, and ``maps.parquet``
    from the module processes' parts; returns the paths.

    ``axes``: the scenario's ``space`` entries (name, target, unit); ``metric_units``: the body's metric units
    (``Body.METRICS``) for the ``m_<metric>`` columns; ``rows``: the records already read (read here if None). A kind
    with no row gets no file.
    """
    run_dir = Path(run_dir)
    if rows is None:
        rows = read_records(run_dir)
    written = []
    for kind, base in (("decision", DECISION_COLUMNS), ("trial", TRIAL_COLUMNS)):
        of_kind = [r for r in rows if r.get("kind") == kind]
        if not of_kind:
            continue
        if kind == "trial":  # in trial order (workers finish them in any order)
            of_kind.sort(key=lambda r: r.get("trial", 0))
        schema = _schema(base, of_kind, axes, metric_units)
        path = run_dir / f"{kind}s.parquet"
        pq.write_table(_table(of_kind, schema), path)
        written.append(path)
    maps = join_map_parts(run_dir)
    if maps is not None:
        written.append(maps)
    return written


MAP_SCHEMA = pa.schema([_field(c) for c in MAP_COLUMNS])


def map_rows(item: MapSnapshots, module: str) -> pa.Table:
    """The rows of one :class:`~sfl_brain.telemetry.MapSnapshots` item: one per neuron per snapshot."""
    k, size, _ = item.weights.shape
    name = item.path.removesuffix("_map")
    columns = {
        "module": pa.array([module] * (k * size), pa.string()),
        "trial": pa.array(np.repeat(np.asarray(item.trials, dtype=np.int64), size)),
        "map": pa.array([name] * (k * size), pa.string()),
        "final": pa.array(np.full(k * size, bool(item.final))),
        "neuron": pa.array(np.tile(np.arange(size, dtype=np.int64), k)),
        "weights": pa.FixedSizeListArray.from_arrays(
            pa.array(np.asarray(item.weights, dtype=np.float64).reshape(-1)), item.weights.shape[2]
        ).cast(_list_f8),
        "active": pa.array(np.asarray(item.active, dtype=bool).reshape(-1)),
    }
    return pa.table(columns, schema=MAP_SCHEMA)


class MapTable:
    """A telemetry sink that writes the map snapshots it is given to a Parquet file, as they come
    (one row group per batch); other telemetry is not its business. The file is created with the
    first snapshot; :meth:`close` finishes it."""

    def __init__(self, path: Path, module: str) -> None:
        self.path = Path(path)
        self.module = module
        self._writer: pq.ParquetWriter | None = None

    def emit(self, item) -> None:
        if not isinstance(item, MapSnapshots):
            return
        if self._writer is None:
            self.path.parent.mkdir(parents=True, exist_ok=True)
            self._writer = pq.ParquetWriter(self.path, MAP_SCHEMA)
        self._writer.write_table(map_rows(item, self.module))

    def close(self) -> None:
        if self._writer is not None:
            self._writer.close()
            self._writer = None


def join_map_parts(run_dir: Path) -> Path | None:
    """Join ``maps/*.parquet`` (one per module process that kept maps) into ``maps.parquet``; the
    parts are removed once joined. A part that cannot be read (its process was killed before it
    closed the file) is left where it is and named in the log. None when there is no part."""
    parts_dir = Path(run_dir) / "maps"
    parts = sorted(parts_dir.glob("*.parquet")) if parts_dir.is_dir() else []
    tables, joined = [], []
    for part in parts:
        try:
            tables.append(pq.read_table(part, schema=MAP_SCHEMA))
            joined.append(part)
        except (OSError, pa.ArrowException) as exc:
            log.warning("map snapshots in %s could not be read (%s); left there", part, exc)
    if not tables:
        return None
    path = Path(run_dir) / "maps.parquet"
    pq.write_table(pa.concat_tables(tables), path)
    for part in joined:
        part.unlink()
    if not any(parts_dir.iterdir()):
        parts_dir.rmdir()
    return path


def columns_markdown() -> str:
    """The fixed columns of the tables as Markdown (the body of ``docs/records.md``'s tables)."""
    out = []
    for title, cols in (
        ("decisions.parquet", DECISION_COLUMNS),
        ("trials.parquet", TRIAL_COLUMNS),
        ("maps.parquet", MAP_COLUMNS),
    ):
        out += [f"### `{title}`", "", "| column | type | unit | meaning |", "|---|---|---|---|"]
        out += [f"| `{c.name}` | {c.type} | {c.unit} | {c.meaning} |" for c in cols]
        out.append("")
    return "\n".join(out)
