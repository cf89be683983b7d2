import dataclasses

import msgpack
import numpy as np
import pytest

from sfl_brain import messages as m


def test_roundtrip_keeps_arrays_and_types():
    msg = m.Evaluate(candidates=np.arange(6, dtype=float).reshape(3, 2), s_vig=-0.1)
    back = m.decode(m.encode(msg))
    assert isinstance(back, m.Evaluate)
    assert back.candidates.shape == (3, 2) and back.candidates.dtype == np.float64
    np.testing.assert_array_equal(back.candidates, msg.candidates)
    assert back.s_vig == -0.1


@pytest.mark.parametrize(
    "payload, text",
    [
        (b"\xc0\xc1garbage", "not msgpack"),
        (b"\xc1garbage", "schema version 103"),
        (b"\xc1", "too short"),
        (m.encode(m.SensorFrame(trial_id=1, tick=2, values=np.zeros(3)))[:-3], "does not fit its layout"),
        (m.encode(m.SensorFrame(trial_id=1, tick=2, values=np.zeros(3)))[:30], "does not fit its layout"),
        (
            m.encode(m.SensorFrame(trial_id=1, tick=2, values=np.zeros(3))).replace(b"controller", b"kontroller"),
            "unknown packed message tag",
        ),
        (b"\x93\x09\xa3ack\x91\xa0", "schema version 9"),
        (
            msgpack.packb([m.SCHEMA_VERSION, "controller.sensors", [0, 1, msgpack.ExtType(1, b"\x02|O\x00")]]),
            "object arrays",
        ),
        (
            msgpack.packb([m.SCHEMA_VERSION, "controller.sensors", [0, 1, msgpack.ExtType(1, b"\x03<f8\x01\x09")]]),
            "not msgpack",
        ),
        (m.encode(m.Ack(detail="x")).replace(b"ack", b"zzz"), "unknown message tag 'zzz'"),
    ],
)
def test_malformed_payloads_raise_message_error(payload, text):
    with pytest.raises(m.MessageError, match=text):
        m.decode(payload)


def test_packed_stream_messages_roundtrip_and_fall_back_for_other_arrays():
    frame = m.SensorFrame(trial_id=3, tick=-7, values=np.array([0.5, -1.0, np.inf]))
    data = m.encode(frame)
    assert data[0] == 0xC1 and len(data) == 3 + len("controller.sensors") + 16 + 24
    back = m.decode(data)
    assert type(back) is m.SensorFrame and (back.trial_id, back.tick) == (3, -7) and back.values.dtype == np.float64
    with pytest.raises(dataclasses.FrozenInstanceError):
        back.tick = 0  # built without __init__, still frozen
    np.testing.assert_array_equal(back.values, frame.values)
    # not a float64 vector: the general layout carries it unchanged
    for values in (np.arange(4, dtype=np.int32), np.zeros((2, 2))):
        data = m.encode(m.MotorCommand(trial_id=0, tick=1, values=values))
        assert data[0] != 0xC1
        back = m.decode(data)
        assert back.values.dtype == values.dtype and back.values.shape == values.shape


def test_wrong_field_type_is_rejected():
    bad = msgpack.packb([m.SCHEMA_VERSION, "ofc.grade", ["high"]])
    with pytest.raises(m.MessageError, match="ofc.grade.eta"):
        m.decode(bad)


def test_messages_keep_the_dataclass_constructor_contract():
    assert m.Ack() == m.Ack(detail="") and m.Ack(detail="x").detail == "x"  # defaults
    reset = m.ControllerReset(trial_id=1, seed=2, params={}, sensors=[], commands=[])
    assert (reset.log, reset.dt) == (False, 0.01)
    with pytest.raises(TypeError, match="missing 1 required keyword-only argument: 'values'"):
        m.SensorFrame(trial_id=0, tick=1)
    with pytest.raises(TypeError, match="positional"):
        m.SensorFrame(0, 1, np.zeros(2))
    with pytest.raises(TypeError, match="unexpected keyword argument 'bogus'"):
        m.Ack(bogus=1)
    with pytest.raises(dataclasses.FrozenInstanceError):
        reset.seed = 3
    assert dataclasses.replace(reset, seed=5).seed == 5
