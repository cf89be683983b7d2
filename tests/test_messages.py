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
        (b"\xc1garbage", "not msgpack"),
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


def test_wrong_field_type_is_rejected():
    bad = msgpack.packb([m.SCHEMA_VERSION, "ofc.grade", ["high"]])
    with pytest.raises(m.MessageError, match="ofc.grade.eta"):
        m.decode(bad)
