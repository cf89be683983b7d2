"""Property tests of the message codec (Hypothesis): any bytes give a message or an error that
says why, every registered message survives the codec, packed messages bit for bit, and NaN or
an infinity anywhere is refused with the field named."""

from __future__ import annotations

import math
import types
import typing

import msgspec
import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from hypothesis.extra import numpy as hnp

from sfl_brain import messages as m

SETTINGS = settings(max_examples=250, deadline=None, suppress_health_check=[HealthCheck.too_slow])
MESSAGES = sorted(m.registered().values(), key=lambda cls: cls.TAG)
PACKED = [cls for cls in MESSAGES if cls._PACKED is not None]
NON_FINITE = st.sampled_from([math.nan, math.inf, -math.inf, -math.nan])

# --- valid field values, from each message's annotations -----------------------------------------

finite = st.floats(allow_nan=False, allow_infinity=False)
int64 = st.integers(-(2**63), 2**63 - 1)
leaves = st.none() | st.booleans() | int64 | finite | st.text(max_size=8)
plain = st.recursive(  # what a dict or list field holds: msgpack's own types, str keys
    leaves,
    lambda inner: st.lists(inner, max_size=4) | st.dictionaries(st.text(max_size=6), inner, max_size=4),
    max_leaves=12,
)
DTYPES = ["<f8", "<f4", "<f2", ">f8", "<c16", "<i8", "<i4", "|u1", "|b1"]


@st.composite
def arrays(draw, dtypes=DTYPES):
    dtype = np.dtype(draw(st.sampled_from(dtypes)))
    shape = draw(hnp.array_shapes(min_dims=0, max_dims=3, min_side=0, max_side=5))
    elements = None
    if dtype.kind in "fc":
        elements = {"allow_nan": False, "allow_infinity": False}
    return draw(hnp.arrays(dtype, shape, elements=elements))


def values_for(annotation) -> st.SearchStrategy:
    """Valid, finite values of a field annotation."""
    if annotation is float:
        return finite
    if annotation is int:
        return int64
    if annotation is bool:
        return st.booleans()
    if annotation is str:
        return st.text(max_size=12)
    if annotation is np.ndarray:
        return arrays()
    origin = typing.get_origin(annotation) or annotation
    if origin is dict:
        return st.dictionaries(st.text(max_size=6), plain, max_size=4)
    if origin is list:
        return st.lists(plain, max_size=4)
    if origin in (types.UnionType, typing.Union):
        return st.one_of(*[values_for(a) for a in typing.get_args(annotation)])
    if annotation is type(None):
        return st.none()
    raise AssertionError(f"no strategy for {annotation!r}: add one")


def fields_of(cls) -> dict[str, typing.Any]:
    return typing.get_type_hints(cls, include_extras=False)


@st.composite
def messages(draw, classes=MESSAGES):
    cls = draw(st.sampled_from(classes))
    hints = fields_of(cls)
    return cls(**{name: draw(values_for(hints[name])) for name in cls._FIELDS})


def same(a, b) -> bool:
    """Equal to the bit, arrays with their dtype and shape, floats with their sign (-0.0)."""
    if isinstance(a, np.ndarray):
        return (
            isinstance(b, np.ndarray)
            and a.dtype == b.dtype
            and a.shape == b.shape
            and a.tobytes() == np.ascontiguousarray(b).tobytes()
        )
    if isinstance(a, float):
        return type(b) is float and math.copysign(1, a) == math.copysign(1, b) and a == b
    if isinstance(a, dict):
        return type(b) is dict and a.keys() == b.keys() and all(same(a[k], b[k]) for k in a)
    if isinstance(a, list | tuple):
        return type(b) is list and len(a) == len(b) and all(same(x, y) for x, y in zip(a, b, strict=True))
    return type(a) is type(b) and a == b


# --- payloads: garbage, near misses and real messages ------------------------------------------


def packed_prefixes() -> list[bytes]:
    return [cls._PACKED.prefix for cls in PACKED]


@st.composite
def payloads(draw):
    """Bytes of every kind a key may carry: random, a packed prefix with anything after it, a
    msgpack envelope with random fields, a real message, and a real message cut or bit-flipped."""
    kind = draw(st.sampled_from(["bytes", "packed", "envelope", "message", "mutated"]))
    if kind == "bytes":
        return draw(st.binary(max_size=64))
    if kind == "packed":
        return draw(st.sampled_from(packed_prefixes())) + draw(st.binary(max_size=80))
    if kind == "envelope":
        tag = draw(st.sampled_from([cls.TAG for cls in MESSAGES] + ["no.such", ""]))
        version = draw(st.sampled_from([m.SCHEMA_VERSION, m.SCHEMA_VERSION, 1, "2"]))
        ext = st.builds(msgspec.msgpack.Ext, st.integers(-128, 127), st.binary(max_size=24))
        fields = draw(st.lists(plain | ext | st.floats() | arrays(), max_size=9))
        return msgspec.msgpack.encode([version, tag, fields], enc_hook=_hook)
    data = m.encode(draw(messages()))
    if kind == "message":
        return data
    data = bytearray(data)
    for _ in range(draw(st.integers(1, 4))):
        if not data:
            break
        i = draw(st.integers(0, len(data) - 1))
        data[i] ^= 1 << draw(st.integers(0, 7))
    return bytes(data[: draw(st.integers(0, len(data)))] if draw(st.booleans()) else data)


def _hook(obj):
    if isinstance(obj, np.ndarray):
        return m._enc_hook(obj)
    raise TypeError(type(obj))


def outcome(decode, data: bytes):
    """What ``decode`` makes of ``data``: ("message", tag, fields) or ("error", class, text)."""
    try:
        msg = decode(data)
    except (m.MessageError, m.NonFiniteError) as exc:
        return ("error", type(exc).__name__, str(exc))
    return ("message", msg.TAG, msg)


# --- the properties ------------------------------------------------------------------------------


@SETTINGS
@given(payloads())
def test_any_payload_decodes_to_a_message_or_an_error_that_says_why(data):
    try:
        msg = m.decode(data)
    except m.MessageError as exc:
        assert str(exc)
        return
    except m.NonFiniteError as exc:
        assert exc.field and exc.message in {m.message_name(cls) for cls in MESSAGES}
        return
    assert isinstance(msg, m.Message) and type(msg) in MESSAGES
    m.check_finite(msg)  # what decode returns is finite


@SETTINGS
@given(st.binary(max_size=256))
def test_arbitrary_bytes_never_raise_anything_else(data):
    for decode in [m.decode, *[m.decoder_for(cls) for cls in PACKED]]:
        outcome(decode, data)


@SETTINGS
@given(messages())
def test_every_message_type_round_trips(msg):
    back = m.decode(m.encode(msg))
    assert type(back) is type(msg)
    for name in msg._FIELDS:
        assert same(getattr(msg, name), getattr(back, name)), name


@SETTINGS
@given(st.sampled_from(PACKED), int64, int64, st.lists(finite, max_size=40))
def test_packed_messages_round_trip_bit_exactly(cls, trial_id, tick, values):
    msg = cls(trial_id=trial_id, tick=tick, values=np.array(values, dtype=np.float64).reshape(-1))
    data = m.encode(msg)
    assert data.startswith(cls._PACKED.prefix)  # the hot-path layout, not the fallback
    for decode in (m.decode, m.decoder_for(cls)):
        back = decode(data)
        assert type(back) is cls and (back.trial_id, back.tick) == (trial_id, tick)
        assert back.values.dtype == np.float64 and back.values.tobytes() == msg.values.tobytes()


@SETTINGS
@given(st.sampled_from(PACKED), st.lists(st.binary(min_size=8, max_size=8), max_size=40))
def test_packed_values_of_any_bits_are_kept_or_the_first_non_finite_is_named(cls, chunks):
    values = np.frombuffer(b"".join(chunks), dtype="<f8")
    data = m.encode(cls(trial_id=1, tick=2, values=values))
    bad = np.flatnonzero(~np.isfinite(values))
    for decode in (m.decode, m.decoder_for(cls)):
        if bad.size:
            with pytest.raises(m.NonFiniteError) as caught:
                decode(data)
            assert caught.value.field == f"values[{bad[0]}]" and caught.value.header == {"trial_id": 1, "tick": 2}
        else:
            assert decode(data).values.tobytes() == values.tobytes()


def holds_floats(annotation) -> bool:
    """Whether a field of this annotation can hold a float (a float, an array, a dict or list)."""
    if annotation in (float, np.ndarray):
        return True
    origin = typing.get_origin(annotation) or annotation
    if origin in (dict, list):
        return True
    if origin in (types.UnionType, typing.Union):
        return any(holds_floats(a) for a in typing.get_args(annotation))
    return False


FLOAT_FIELDS = [(cls, name) for cls in MESSAGES for name, hint in fields_of(cls).items() if holds_floats(hint)]


@st.composite
def poisoned(draw):
    """A valid message with one NaN or infinity put into one field; the path the error must name."""
    cls, name = draw(st.sampled_from(FLOAT_FIELDS))
    hints = fields_of(cls)
    fields = {n: draw(values_for(hints[n])) for n in cls._FIELDS}
    bad = draw(NON_FINITE)
    hint = hints[name]
    union = typing.get_origin(hint) in (types.UnionType, typing.Union)
    choice = draw(st.sampled_from([a for a in (typing.get_args(hint) if union else (hint,)) if holds_floats(a)]))
    kind = typing.get_origin(choice) or choice
    if kind is float:
        fields[name], path = bad, name
    elif kind is np.ndarray:
        dtype = draw(st.sampled_from(["<f8", "<f4", ">f8", "<c16"]))
        shape = draw(hnp.array_shapes(min_dims=1, max_dims=3, min_side=1, max_side=4))
        array = draw(hnp.arrays(dtype, shape, elements={"allow_nan": False, "allow_infinity": False}))
        index = draw(st.tuples(*[st.integers(0, n - 1) for n in shape]))
        array[index] = bad
        fields[name], path = array, f"{name}[{', '.join(map(str, index))}]"
    elif kind is dict:
        fields[name] = {**fields[name], "poisoned": [0.5, bad]}
        path = f"{name}['poisoned'][1]"
    else:
        fields[name] = [*fields[name], {"x": bad}]
        path = f"{name}[{len(fields[name]) - 1}]['x']"
    return cls(**fields), path


@SETTINGS
@given(poisoned())
def test_a_non_finite_value_in_any_field_is_refused_with_the_field_named(case):
    msg, path = case
    for decode in (m.decode, m.decoder_for(type(msg))):
        with pytest.raises(m.NonFiniteError) as caught:
            decode(m.encode(msg))
        assert caught.value.field == path and caught.value.message == m.message_name(type(msg))
        assert not math.isfinite(abs(complex(caught.value.value)))
    with pytest.raises(m.NonFiniteError) as caught:  # the same check without the codec (Module.handle)
        m.check_finite(msg, "Probe 'probe'", "replied")
    assert str(caught.value).startswith(f"Probe 'probe' replied {m.message_name(type(msg))}: {path} = ")


@SETTINGS
@given(payloads(), st.sampled_from(PACKED))
def test_decoder_for_agrees_with_decode_on_any_payload(data, cls):
    expected, got = outcome(m.decode, data), outcome(m.decoder_for(cls), data)
    assert expected[:2] == got[:2]
    if expected[0] == "error":
        assert expected[2] == got[2]
    else:
        for name in expected[2]._FIELDS:
            assert same(getattr(expected[2], name), getattr(got[2], name)), name
