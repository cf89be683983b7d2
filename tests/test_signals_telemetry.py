"""The typed-signal wiring and the telemetry seam (issue 14 parts 1-2: the pieces, not yet used by
the bodies and controllers)."""

from __future__ import annotations

import numpy as np
import pytest

from sfl_brain.signals import Signal, WiringError, table, wiring
from sfl_brain.telemetry import CaptureTelemetry, Event, Strips2D, series

BODY = (
    Signal("hip_l", "rad", -1.2, 1.2, "left hip angle"),
    Signal("hip_r", "rad", -1.2, 1.2, "right hip angle"),
    Signal("contact_l", "", 0, 1, "left foot on the ground"),
)


def test_wiring_matches_by_name_and_names_both_ends():
    assert wiring(BODY, ["hip_l", "hip_r", "contact_l"], provider="body", consumer="c", what="reads") is None
    index = wiring(BODY, ["contact_l", "hip_l"], provider="body", consumer="c", what="reads")
    assert index.tolist() == [2, 0]
    with pytest.raises(WiringError) as err:
        wiring(BODY, ["hip_left"], provider="body `PlanarBiped`", consumer="controller `Reflex`", what="reads sensors")
    assert str(err.value) == (
        "controller `Reflex` reads sensors hip_left (did you mean `hip_l`?) that body `PlanarBiped` does not have; "
        "it has ['hip_l', 'hip_r', 'contact_l']"
    )


def test_a_signal_is_checked_and_tabulated():
    with pytest.raises(ValueError, match="not an identifier"):
        Signal("hip l", "rad", 0, 1, "")
    with pytest.raises(ValueError, match="must not be above"):
        Signal("x", "", 1, 0, "")
    lines = table(BODY, "sensors")
    assert lines[0] == "sensors" and "hip_l" in lines[2] and "[-1.2, 1.2]" in lines[2]


def test_telemetry_is_captured_without_rerun_and_sent_to_it(tmp_path):
    sink = CaptureTelemetry()
    sink.emit(series("joints/hip_l", 3, np.arange(5) * 0.01, np.zeros(5), "deg"))
    sink.emit(Event("events/switch", 3, 0.02, "knee -> quiescent"))
    strips = [np.zeros((2, 2)), np.ones((3, 2))] * 2
    sink.emit(Strips2D("walker", 3, np.array([0.0, 0.04]), strips, 2, np.zeros((2, 3), np.uint8)))
    assert sink.paths() == {"joints/hip_l", "events/switch", "walker"}
    import rerun as rr

    from sfl_brain.rerun_sink import RerunTelemetry

    rec = rr.RecordingStream("sfl-test", recording_id="telemetry-test")
    path = tmp_path / "t.rrd"
    rec.save(str(path))
    out = RerunTelemetry(rec, "body")
    for item in sink.items:
        out.emit(item)
    rec.flush()
    rec.disconnect()
    from rerun.chunk import RrdReader

    rows = {}
    for chunk in RrdReader(path).stream().to_chunks():
        rows[str(chunk.entity_path)] = rows.get(str(chunk.entity_path), 0) + chunk.num_rows
    assert rows.get("/body/joints/hip_l") == 5 + 1  # five samples and the series name with its unit
    assert rows.get("/body/walker") == 2 and rows.get("/body/events/switch") == 1
