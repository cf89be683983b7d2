"""The typed-signal wiring and the telemetry seam (issue 14 parts 1-2): the pieces on their own; the
bodies, controllers and the ACC that use them are tested in ``test_recording.py``."""

from __future__ import annotations

import numpy as np
import pytest

from sfl_brain.signals import Signal, WiringError, table, wiring
from sfl_brain.telemetry import CaptureTelemetry, Event, Rates, Strips2D, rates_of, series

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

    from sfl_brain.recording.rerun_sink import RerunTelemetry

    rec = rr.RecordingStream("sfl-test", recording_id="telemetry-test")
    path = tmp_path / "t.rrd"
    rec.save(str(path))
    out = RerunTelemetry(rec, "body")
    for item in sink.items:
        out.emit(item)
    out.close()  # series and pictures are sent in chunks of several trials: close sends the rest
    rec.flush()
    rec.disconnect()
    from rerun.chunk import RrdReader

    rows, static, columns = {}, {}, {}
    for chunk in RrdReader(path).stream().to_chunks():
        counts = static if chunk.is_static else rows
        counts[str(chunk.entity_path)] = counts.get(str(chunk.entity_path), 0) + chunk.num_rows
        columns.setdefault(str(chunk.entity_path), []).append(chunk.to_record_batch())
    assert (
        rows.get("/body/joints/hip_l") == 5 and rows.get("/body/walker") == 2 and rows.get("/body/events/switch") == 1
    )
    # the unit in the series' name, the pictures' colours and radii once (static), the space y-up
    names = next(b for b in columns["/body/joints/hip_l"] if "SeriesLines:names" in b.schema.names)
    assert names.column("SeriesLines:names").to_pylist() == [["hip_l (deg)"]]
    assert static.get("/body/walker") == 1 and static.get("/body") == 1
    # 2-D strips are drawn in the plane z = 0 of a y-up 3-D space
    pictures = next(b for b in columns["/body/walker"] if "LineStrips3D:strips" in b.schema.names)
    first = pictures.column("LineStrips3D:strips").to_pylist()[0]
    assert [len(strip) for strip in first] == [2, 3] and all(point[2] == 0.0 for point in first[1])
    assert pictures.column("sim_time").to_pylist()[1].total_seconds() == 0.04


def test_rates_come_from_the_record_section_and_fix_the_sampling():
    rates = Rates.from_record({"body_every": 1, "signals_hz": 50.0, "pictures_hz": 0, "neurons": False})
    assert (rates.signals_hz, rates.pictures_hz, rates.neurons) == (50.0, 0, False)
    assert rates.signal_every(0.01) == 2 and rates.picture_every(0.01) == 1 and rates.sample_every(0.01) == 1
    assert Rates().signal_every(0.01) == 4 and Rates().sample_every(0.002) == 20  # 25 Hz at 100 Hz and 500 Hz ticks
    assert Rates.from_record(None) == Rates() and rates_of(None) == Rates() and rates_of(CaptureTelemetry()) == Rates()
