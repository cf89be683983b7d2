import re

import msgspec
import numpy as np
import pytest

from sfl_brain import messages as m

packb = msgspec.msgpack.encode


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
            packb([m.SCHEMA_VERSION, "controller.sensors", [0, 1, msgspec.msgpack.Ext(1, b"\x02|O\x00")]]),
            "object arrays",
        ),
        (
            packb([m.SCHEMA_VERSION, "controller.sensors", [0, 1, msgspec.msgpack.Ext(1, b"\x03<f8\x01\x09")]]),
            "not msgpack",
        ),
        (m.encode(m.Ack(detail="x")).replace(b"ack", b"zzz"), "unknown message tag 'zzz'"),
    ],
)
def test_malformed_payloads_raise_message_error(payload, text):
    with pytest.raises(m.MessageError, match=text):
        m.decode(payload)


def test_packed_stream_messages_roundtrip_and_fall_back_for_other_arrays():
    frame = m.SensorFrame(trial_id=3, tick=-7, values=np.array([0.5, -1.0, 5e-324]))  # a subnormal: still exact
    data = m.encode(frame)
    assert data[0] == 0xC1 and len(data) == 3 + len("controller.sensors") + 16 + 24
    back = m.decode(data)
    assert type(back) is m.SensorFrame and (back.trial_id, back.tick) == (3, -7) and back.values.dtype == np.float64
    with pytest.raises(AttributeError, match="immutable"):
        back.tick = 0
    np.testing.assert_array_equal(back.values, frame.values)
    # not a float64 vector: the general layout carries it unchanged
    for values in (np.arange(4, dtype=np.int32), np.zeros((2, 2))):
        data = m.encode(m.MotorCommand(trial_id=0, tick=1, values=values))
        assert data[0] != 0xC1
        back = m.decode(data)
        assert back.values.dtype == values.dtype and back.values.shape == values.shape


def test_wrong_field_type_is_rejected():
    bad = packb([m.SCHEMA_VERSION, "ofc.grade", ["high"]])
    with pytest.raises(m.MessageError, match="ofc.grade.eta"):
        m.decode(bad)
    bad = packb([m.SCHEMA_VERSION, "controller.reset", [1, 2, "not a dict", [], [], False, 0.0, 0.01]])
    with pytest.raises(m.MessageError, match="controller.reset.params"):
        m.decode(bad)


def test_messages_are_frozen_keyword_only_structs():
    assert m.Ack() == m.Ack(detail="") and m.Ack(detail="x").detail == "x"  # defaults
    reset = m.ControllerReset(trial_id=1, seed=2, params={}, sensors=[], commands=[])
    assert (reset.log, reset.dt) == (False, 0.01)
    with pytest.raises(TypeError, match="Missing required argument 'values'"):
        m.SensorFrame(trial_id=0, tick=1)
    with pytest.raises(TypeError, match="positional"):
        m.SensorFrame(0, 1, np.zeros(2))
    with pytest.raises(TypeError, match="Unexpected keyword argument 'bogus'"):
        m.Ack(bogus=1)
    with pytest.raises(AttributeError, match="immutable"):
        reset.seed = 3
    assert msgspec.structs.replace(reset, seed=5).seed == 5


def test_a_users_message_is_a_keyword_only_message_subclass():
    @m.message("test.user_defined")
    class Probe(m.Message, kw_only=True):
        x: float
        n: int = 3

    try:
        with pytest.raises(TypeError, match="positional"):
            Probe(1.0)
        back = m.decode(m.encode(Probe(x=2.5)))
        assert type(back) is Probe and (back.x, back.n) == (2.5, 3)
        with pytest.raises(TypeError, match="subclass of sfl_brain.messages.Message"):
            m.message("test.not_a_message")(type("Plain", (), {}))

        class Positional(m.Message):
            x: float

        with pytest.raises(TypeError, match=r"declare `class Positional\(Message, kw_only=True\)`"):
            m.message("test.positional")(Positional)
    finally:
        m._REGISTRY.pop("test.user_defined", None)


def test_decoder_for_a_type_gives_what_decode_gives_for_any_payload():
    frame = m.SensorFrame(trial_id=3, tick=4, values=np.array([1.5, -2.0]))
    payloads = [
        m.encode(frame),  # packed, the expected type
        m.encode(m.MotorCommand(trial_id=3, tick=4, values=np.zeros(2))),  # packed, another type
        m.encode(m.SensorFrame(trial_id=3, tick=4, values=np.zeros((2, 2)))),  # msgpack layout
        m.encode(m.Ack(detail="x")),  # not a stream message at all
        m.encode(frame)[:-3],  # the expected prefix, cut short
        b"\xc1",
        b"garbage",
    ]
    fast = m.decoder_for(m.SensorFrame)
    assert m.decoder_for(m.Ack) is m.decode  # nothing to gain without a packed layout
    for payload in payloads:
        try:
            expected = m.decode(payload)
        except m.MessageError as exc:
            with pytest.raises(m.MessageError, match=re.escape(str(exc))):
                fast(payload)
            continue
        got = fast(payload)
        assert type(got) is type(expected)
        for name in expected._FIELDS:
            np.testing.assert_array_equal(getattr(got, name), getattr(expected, name))
