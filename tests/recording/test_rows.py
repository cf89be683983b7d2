"""A records line is ``json.dumps(plain(row))``, whichever path writes it (Hypothesis): the C encoder's one pass for
finite rows, :func:`plain` for a row with a NaN or an infinity anywhere, numpy scalars and arrays as Python's."""

from __future__ import annotations

import json
import math

import numpy as np
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from sfl_brain.recording.records import RecordWriter, plain, read_records, row_json

SETTINGS = settings(max_examples=60, deadline=None, suppress_health_check=[HealthCheck.too_slow])

floats = st.floats()  # NaN and the infinities included
numpy_scalars = st.one_of(
    floats.map(np.float64),
    st.floats(width=32).map(np.float32),
    st.integers(-(2**31), 2**31 - 1).map(np.int64),
    st.booleans().map(np.bool_),
)
numpy_arrays = st.lists(floats, max_size=4).map(np.array) | st.lists(
    st.lists(floats, min_size=2, max_size=2), max_size=3
).map(np.array)
leaves = st.none() | st.booleans() | st.integers() | floats | st.text(max_size=6) | numpy_scalars | numpy_arrays
values = st.recursive(
    leaves,
    lambda inner: (
        st.lists(inner, max_size=4) | st.tuples(inner, inner) | st.dictionaries(st.text(max_size=5), inner, max_size=4)
    ),
    max_leaves=16,
)
rows = st.dictionaries(st.text(max_size=8), values, max_size=6)


def slow(row: dict) -> str:
    return json.dumps(plain(row), separators=(",", ":"))


@SETTINGS
@given(rows)
def test_a_row_is_written_as_plain_would_write_it(row):
    assert row_json(row) == slow(row)


def test_a_decision_row_with_numpy_values_and_a_nan_reads_back_with_none(tmp_path):
    finite = {"kind": "decision", "d_success": np.float64(0.25), "v_unit": np.array([0.1, 0.9]), "go": np.bool_(True)}
    broken = {**finite, "d_failure": math.nan, "v_unit": np.array([math.inf, 0.5])}
    writer = RecordWriter(tmp_path / "records.jsonl")
    writer.write_many([finite, broken])
    writer.close()
    back = read_records(tmp_path)
    assert back[0] == {"kind": "decision", "d_success": 0.25, "v_unit": [0.1, 0.9], "go": True}
    assert back[1]["d_failure"] is None and back[1]["v_unit"] == [None, 0.5]
