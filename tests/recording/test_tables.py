"""Records a data user opens: typed Parquet tables, a documented schema, a run folder that runs again
and says what produced it (issue 14, part 6)."""

from __future__ import annotations

import json
import shutil

import numpy as np
import pyarrow as pa
import pyarrow.parquet as pq

from sfl_brain.messages import Learn
from sfl_brain.modules.acc import ACC
from sfl_brain.recording.records import NOT_REPRODUCIBLE, read_records
from sfl_brain.recording.tables import (
    DECISION_COLUMNS,
    MAP_COLUMNS,
    TRIAL_COLUMNS,
    MapTable,
    _list_f8,
    columns_markdown,
    join_map_parts,
)
from sfl_brain.telemetry import CaptureTelemetry, TelemetryTee

from ..conftest import ROOT, sfl

CAUTIOUS = ROOT / "docs" / "examples" / "cautious.yaml"


def stable(rows):
    return [{k: v for k, v in r.items() if k not in NOT_REPRODUCIBLE} for r in rows]


def test_tables_are_typed_and_hold_every_row(tmp_path):
    out = tmp_path / "run"
    done = sfl("run", str(CAUTIOUS), "--set", "protocol.trials=20", "--out", str(out), "--quiet")
    assert done.returncode == 0, done.stderr
    rows = read_records(out)
    trials = pq.read_table(out / "trials.parquet")
    decisions = pq.read_table(out / "decisions.parquet")
    assert trials.num_rows == sum(r["kind"] == "trial" for r in rows) == 20
    assert decisions.num_rows == sum(r["kind"] == "decision" for r in rows)
    assert trials.schema.field("success").type == pa.bool_() and decisions.schema.field("go").type == pa.bool_()
    assert trials.schema.field("trial").type == pa.int64() and trials.schema.field("n_success").type == pa.int64()
    assert trials.column("trial").to_pylist() == list(range(20))
    # a no-go decision has no trial: null, not NaN-as-float in an int column
    no_go = [d for d in decisions.to_pylist() if not d["go"]]
    assert len(no_go) > 0 and all(d["trial"] is None for d in no_go)
    assert decisions.schema.field("trial").type == pa.int64()
    # a failure has no reward
    assert all(t["rho"] is None for t in trials.to_pylist() if not t["success"])
    schema = pq.read_schema(out / "trials.parquet")
    assert schema.field("wall_ms").metadata[b"unit"] == b"ms"
    assert schema.field("x").metadata[b"meaning"] == b"body.x: physical value"
    # a body metric carries the unit its body declares (Body.METRICS); the list column is typed as the file holds it
    assert schema.field("m_distance_to_centre").metadata[b"unit"] == b"unit space"
    assert str(schema.field("v_unit").type) == "list<element: double>"
    first = next(r for r in rows if r["kind"] == "trial")
    written = trials.slice(0, 1).to_pylist()[0]
    assert written["quality"] == first["quality"] and written["v_unit"] == first["v_unit"]
    # the ACC's maps after every trial, and as the run left them (== acc.npz, which it checkpointed)
    maps = pq.read_table(out / "maps.parquet")
    assert maps.schema.field("active").type == pa.bool_() and maps.schema.field("final").type == pa.bool_()
    assert maps.schema.field("trial").type == pa.int64()
    snapshots = maps.to_pylist()
    assert sorted({m["trial"] for m in snapshots if not m["final"]}) == list(range(1, 21))
    assert len(snapshots) == (20 + 1) * 2 * 100  # 20 snapshots and the final one, two 10 x 10 maps
    saved = np.load(out / "acc.npz")
    for name in ("success", "failure"):
        final = sorted((m for m in snapshots if m["final"] and m["map"] == name), key=lambda m: m["neuron"])
        assert np.array_equal(np.array([m["weights"] for m in final]), saved[f"{name}_weights"])
        assert [m["active"] for m in final] == saved[f"{name}_active"].tolist()
    assert pq.read_schema(out / "maps.parquet").field("weights").metadata[b"unit"] == b"unit space"


def test_map_table_writes_snapshots_as_they_come_and_joins_the_parts(tmp_path):
    acc = ACC(ACC.Params(shape=(2, 3), dim=2), seed=0)
    acc.entity = "acc"
    table = MapTable(tmp_path / "maps" / "acc.parquet", module="acc")
    acc.telemetry = TelemetryTee(CaptureTelemetry(), table)
    rng = np.random.default_rng(1)
    for _ in range(3):
        acc.handle(Learn(v=rng.random(2), success=True, rho=1.0))
        acc.run_deferred()  # the host snapshots the maps after it has replied
        acc.flush_maps()  # one row group per flush
    acc.telemetry.close()
    assert pq.ParquetFile(tmp_path / "maps" / "acc.parquet").num_row_groups == 6  # 3 flushes x 2 maps
    (tmp_path / "maps" / "killed.parquet").write_bytes(b"PAR1 not finished")  # a process killed mid-write
    assert join_map_parts(tmp_path) == tmp_path / "maps.parquet"
    assert [p.name for p in (tmp_path / "maps").iterdir()] == ["killed.parquet"]  # left for a person to look at
    maps = pq.read_table(tmp_path / "maps.parquet").to_pylist()
    assert [m["trial"] for m in maps][:6] == [1] * 6 and {m["map"] for m in maps} == {"success", "failure"}
    last = sorted((m for m in maps if m["trial"] == 3 and m["map"] == "success"), key=lambda m: m["neuron"])
    assert np.array_equal(np.array([m["weights"] for m in last]), acc.success_map.weights)
    assert all(m["active"] for m in last)


def test_records_doc_lists_every_fixed_column():
    text = (ROOT / "docs" / "records.md").read_text()
    assert columns_markdown() in text
    for col in (*DECISION_COLUMNS, *TRIAL_COLUMNS, *MAP_COLUMNS):
        assert f"| `{col.name}` |" in text


def test_records_doc_gives_the_types_and_units_the_files_carry():
    """Issue 32: records.md said `list<item: double>` where the files hold `list<element: double>`, and gave m, m/s, J
    for `m_*` columns that carried no unit. The list type is the writer's own; each planar-biped unit the page
    gives is the one its body declares (Body.METRICS), which the writer puts in the column's metadata (tested on a
    real run above, and on the planar biped's files in test_planar.py's test_learning_run_end_to_end_with_processes)."""
    from sfl_brain.bodies.planar_biped import PlanarBiped

    text = (ROOT / "docs" / "records.md").read_text()
    assert "list<item" not in text and f"| {_list_f8} |" in text and str(_list_f8) == "list<element: double>"
    units = {name: unit for name, unit in PlanarBiped.METRICS.items() if unit}
    assert {"distance": "m", "velocity": "m/s", "energy": "J"}.items() <= units.items()
    for name, unit in units.items():
        assert f"`m_{name}` {unit}," in text, name


def test_run_folder_runs_again_on_its_own_and_says_what_made_it(tmp_path):
    first = tmp_path / "first"
    assert sfl("run", str(CAUTIOUS), "--set", "protocol.trials=15", "--out", str(first), "--quiet").returncode == 0
    moved = tmp_path / "elsewhere" / "copy"
    shutil.copytree(first, moved)  # the original scenario folder plays no part any more
    again = tmp_path / "again"
    done = sfl("run", str(moved / "scenario.yaml"), "--out", str(again), "--quiet", cwd=tmp_path)
    assert done.returncode == 0, done.stderr
    assert (moved / "inputs" / "cautious_vigilance.py").exists()
    assert stable(read_records(again)) == stable(read_records(first))
    made = json.loads((first / "provenance.json").read_text())
    assert made["versions"]["sfl-brain"] and made["versions"]["eclipse-zenoh"]
    assert made["python"].count(".") == 2
    assert made["commit"] is None or len(made["commit"]) == 40
