"""Typed messages and the one codec that moves them over the bus.

Every message is a frozen, keyword-only ``msgspec.Struct`` registered under a short
tag (``acc.evaluate``). On the wire a message is a msgpack array
``[SCHEMA_VERSION, tag, [field values...]]``; numpy arrays travel as a msgpack
extension (a small dtype/shape header, then the raw bytes), so a frame of sensor
values costs one copy. msgspec builds a message in about 50 ns and encodes it in C:
the runtime builds several per control tick.

Lockstep stream messages (``packed=True``: scalar int/float fields, then one float64
vector) have a second, fixed layout for the control-tick hot path: byte ``0xC1`` (never
the first byte of msgpack), the schema version, the tag, the scalars as little-endian
int64/float64 and the vector's raw bytes. ``decode`` reads both layouts.

``decode`` raises :class:`MessageError` for anything it cannot turn back into a
registered message of the right schema version and field types; the runtime logs
and drops such input, it never crashes on it. A well-formed message with NaN or an
infinity in any field (a float, an array, a value in a dict or list) raises
:class:`NonFiniteError` instead: that is an error of its sender, which stops what it
belongs to. A field with no value holds None. ``Module.handle`` applies the same check
(:func:`check_finite`) to what a module receives and replies without the codec.
"""

from __future__ import annotations

import math
import struct
import types
import typing
from typing import Any, ClassVar

import msgspec
import numpy as np

SCHEMA_VERSION = 2
_NDARRAY_EXT = 1

_REGISTRY: dict[str, type[Message]] = {}


class MessageError(ValueError):
    """A payload that is not a well-formed message of this schema."""


class NonFiniteError(ValueError):
    """A message field holds NaN or an infinity (a field with no value holds None).

    ``message`` names the message (``vigilance.threshold (Threshold)``), ``field`` the field and,
    inside an array, dict or list, where the first bad value sits (``values[3]``,
    ``metrics['energy']``); ``value`` is that value. ``module`` names the module that received or
    sent it (``CautiousVigilance 'vigilance'``) and ``role`` what it did (``replied``,
    ``received``, ``sensed``, ``sent``), or both are None when only the codec saw it.
    ``header`` holds the message's scalar fields when they are known (a packed message's
    ``trial_id`` and ``tick``), so a link can tell whether the message was meant for it.

    Not a :class:`MessageError`: a malformed payload may be noise and is dropped, but a
    well-formed message with a non-finite value is an error of its sender.
    """

    def __init__(
        self,
        message: str,
        field: str,
        value: Any,
        module: Any = None,
        role: str | None = None,
        header: dict | None = None,
    ) -> None:
        if module is not None and not isinstance(module, str):  # a Module: its class and instance name
            module = f"{type(module).__name__} {module.entity!r}"
        if isinstance(value, np.generic):
            value = value.item()  # nan, not np.float64(nan), in the text
        self.message = message
        self.field = field
        self.value = value
        self.module = module
        self.role = role
        self.header = header or {}
        who = f"{module} {role or 'handled'} " if module else ""
        super().__init__(f"{who}{message}: {field} = {value!r}, not a finite number")

    def __reduce__(self):
        return NonFiniteError, (self.message, self.field, self.value, self.module, self.role, self.header)

    def named(self, module: Any, role: str) -> NonFiniteError:
        """The same error, said of ``module`` that ``role`` (received, replied, sent) the message."""
        return NonFiniteError(self.message, self.field, self.value, module, role, self.header)


class Message(msgspec.Struct, frozen=True, array_like=True):
    """Base of all messages. A message is declared keyword-only and registered under a tag::

        @message("ofc.grade")
        class Grade(Message, kw_only=True):
            eta: float

    It is frozen; ``msgspec.structs.replace(msg, eta=0.5)`` makes a changed copy. (msgspec does not
    inherit ``kw_only``, and a metaclass that added it would make every construction 3x slower.)
    """

    TAG: ClassVar[str] = ""
    #: True for lockstep streams (pub/sub, reply published back); False for request/reply.
    STREAM: ClassVar[bool] = False
    _FIELDS: ClassVar[tuple[str, ...]] = ()
    _CHECKS: ClassVar[tuple[tuple[int, str, tuple[type, ...]], ...]] = ()
    #: the hot-path layout of a ``packed=True`` message, or None
    _PACKED: ClassVar[Packed | None] = None


def _checker(annotation: Any):
    """A cheap isinstance check for a field annotation, or None for no check."""
    origin = typing.get_origin(annotation)
    if annotation is float:
        return (int, float)
    if annotation is int:
        return int
    if annotation is bool:
        return bool
    if annotation is str:
        return str
    if annotation is np.ndarray:
        return np.ndarray
    container = origin or annotation  # dict and dict[str, float] alike
    if container is dict:
        return dict
    if container in (list, tuple):
        return (list, tuple)
    if origin in (types.UnionType, typing.Union):
        parts = [_checker(a) for a in typing.get_args(annotation)]
        if any(p is None for p in parts):
            return None
        flat: list[type] = []
        for p in parts:
            flat.extend(p if isinstance(p, tuple) else (p,))
        return tuple(flat)
    if annotation is type(None):
        return type(None)
    return None


# --- finiteness --------------------------------------------------------------------
_isfinite = math.isfinite
_SHORT = 32  # up to this many values, sum(v.tolist()) is the cheapest test of a float64 vector


def all_finite(v: np.ndarray) -> bool:
    """True when the array holds no NaN or infinity.

    A short 1-D float vector (a control tick's) takes one Python sum: NaN and infinities
    propagate through it, so a finite sum proves every value finite; only a sum that overflowed
    takes the exact test.
    """
    kind = v.dtype.kind
    if kind == "f" or kind == "c":
        if kind == "f" and v.ndim == 1 and v.size <= _SHORT and _isfinite(sum(v.tolist())):
            return True
        return bool(np.isfinite(v).all())
    if kind == "O":
        return all(first_nonfinite(x) is None for x in v.flat)
    return True  # integers, booleans, strings: finite by construction


def _array_index(v: np.ndarray) -> tuple[str, Any]:
    """``[i, j]`` and the value of the first non-finite entry of ``v`` (which has one)."""
    flat = v.reshape(-1)
    if v.dtype.kind == "O":
        i = next(i for i, x in enumerate(flat) if first_nonfinite(x) is not None)
    else:
        i = int(np.flatnonzero(~np.isfinite(flat))[0])
    if v.ndim == 0:
        return "", flat[0]
    return "[" + ", ".join(str(int(j)) for j in np.unravel_index(i, v.shape)) + "]", flat[i]


def _first_in(items) -> tuple[str, Any] | None:
    """The first non-finite value among (index or key, value) pairs, as ``[index]...``."""
    for key, item in items:
        c = item.__class__
        if c is float:
            if _isfinite(item):
                continue
            return f"[{key!r}]", item
        if c is str or c is int or c is bool or item is None:
            continue
        bad = first_nonfinite(item)
        if bad is not None:
            return f"[{key!r}]{bad[0]}", bad[1]
    return None


def first_nonfinite(value: Any) -> tuple[str, Any] | None:
    """Where the first NaN or infinity in ``value`` sits and that value, or None.

    Where is ``""`` for the value itself, else its indices and keys (``[3]``, ``['energy'][1]``,
    ``[2, 0]`` in a 2-D array; `` (a key)`` for a dict key). Looks into arrays, dicts, lists and
    tuples.
    """
    cls = value.__class__
    if cls is float:
        return None if _isfinite(value) else ("", value)
    if cls is int or cls is bool or cls is str or value is None:
        return None
    if isinstance(value, np.ndarray):
        return None if all_finite(value) else _array_index(value)
    if isinstance(value, dict):
        for key in value:
            if key.__class__ is not str and first_nonfinite(key) is not None:
                return " (a key)", key
        return _first_in(value.items())
    if isinstance(value, list | tuple):
        return _first_in(enumerate(value))
    if isinstance(value, float | np.floating | complex | np.complexfloating):
        return None if np.isfinite(value) else ("", value)
    return None


def message_name(cls: type[Message]) -> str:
    """``tag (Class)``: how errors name a message."""
    return f"{cls.TAG} ({cls.__name__})"


def check_finite(msg: Message, module: Any = None, role: str | None = None) -> None:
    """Raise :class:`NonFiniteError` for the first field of ``msg`` that holds NaN or an infinity;
    ``module`` (a name, or a Module) and ``role`` say who had it and what it did."""
    for name in msg._FIELDS:
        bad = first_nonfinite(getattr(msg, name))
        if bad is not None:
            header = {n: getattr(msg, n) for n in msg._FIELDS if type(getattr(msg, n)) is int}
            raise NonFiniteError(message_name(type(msg)), name + bad[0], bad[1], module, role, header)


def _packed_nonfinite(cls: type[Message], names: tuple[str, ...], scalars: tuple, vector: np.ndarray):
    """The error for a packed message with a non-finite scalar or vector value."""
    *heads, last = names
    header = dict(zip(heads, scalars, strict=True))
    bad = next(((n, x) for n, x in header.items() if not _isfinite(x)), None)
    if bad is None:
        where, value = _array_index(vector)
        bad = last + where, value
    return NonFiniteError(message_name(cls), *bad, header={n: x for n, x in header.items() if type(x) is int})


_PACKED_MARK = 0xC1
_F8 = np.dtype("<f8")
#: the decoders of packed messages by their prefix (mark, schema version, tag length, tag)
_PACKED_DECODERS: dict[bytes, Any] = {}


class Packed(typing.NamedTuple):
    """How a ``packed=True`` message is laid out: ``prefix | scalars | vector``, with an encoder
    and a decoder compiled for its fields (the control tick runs each of them twice)."""

    prefix: bytes  # 0xC1, schema version, tag length, tag
    encode: Any  # message -> bytes, or None when a field does not fit the layout (msgpack then)
    decode: Any  # payload -> message, or None when the payload does not fit the layout


def _compile(lines: list[str], namespace: dict[str, Any]):
    exec("\n".join(lines), namespace)
    return namespace["f"]


def _packed_layout(cls, names: tuple[str, ...], hints: dict) -> Packed:
    *scalars, vector = names
    codes = {int: "q", float: "d"}
    if hints[vector] is not np.ndarray or any(hints[n] not in codes for n in scalars):
        raise TypeError(f"{cls.__name__}: packed messages are int/float fields then one np.ndarray")
    tag = cls.TAG.encode()
    prefix = bytes((_PACKED_MARK, SCHEMA_VERSION, len(tag))) + tag
    layout = struct.Struct("<" + "".join(codes[hints[n]] for n in scalars))
    start = len(prefix) + layout.size
    head = struct.Struct(f"<{len(prefix)}s" + layout.format[1:])  # the prefix and the scalars, packed at once
    namespace = {"prefix": prefix, "pack": head.pack, "unpack": layout.unpack_from, "error": struct.error}
    namespace |= {"ndarray": np.ndarray, "frombuffer": np.frombuffer, "F8": _F8, "cls": cls}
    encoder = _compile(
        [
            "def f(m):",
            f"    v = m.{vector}",
            "    if type(v) is ndarray and v.dtype == F8 and v.ndim == 1:",
            "        try:",
            f"            return pack({', '.join(['prefix'] + [f'm.{n}' for n in scalars])}) + v.tobytes()",
            "        except error:",  # a scalar of another type: the general layout reports it
            "            pass",
            "    return None",
        ],
        dict(namespace),
    )
    # the field types need no check: unpacking the scalars and viewing the vector make them; the
    # values' finiteness does (one sum for a short vector, see all_finite)
    floats = [f"isfinite(s[{i}])" for i, n in enumerate(scalars) if hints[n] is float]
    fields = [f"{n}=s[{i}]" for i, n in enumerate(scalars)] + [f"{vector}=v"]
    namespace |= {"isfinite": _isfinite, "all_finite": all_finite}
    namespace |= {"nonfinite": _packed_nonfinite, "names": names}
    decoder = _compile(
        [
            "def f(data):",
            f"    n = len(data) - {start}",
            "    if n < 0 or n & 7:",
            "        return None",
            f"    s = unpack(data, {len(prefix)})",
            f"    v = frombuffer(data, F8, n >> 3, {start})",
            f"    if not (n <= {8 * _SHORT} and isfinite(sum(v.tolist())) or all_finite(v))"
            + "".join(f" or not {c}" for c in floats)
            + ":",
            "        raise nonfinite(cls, names, s, v)",
            f"    return cls({', '.join(fields)})",
        ],
        dict(namespace),
    )
    return Packed(prefix, encoder, decoder)


def message(tag: str, *, stream: bool = False, packed: bool = False):
    """Class decorator: register a :class:`Message` subclass under ``tag``.

    ``packed``: also give it the fixed hot-path layout (see the module docstring).
    """

    def wrap(cls):
        if not (isinstance(cls, type) and issubclass(cls, Message)):
            raise TypeError(f"@message({tag!r}) decorates a subclass of sfl_brain.messages.Message, not {cls!r}")
        if cls.__match_args__:  # fields that may be given by position
            raise TypeError(
                f"@message({tag!r}): message fields are keyword-only; declare "
                f"`class {cls.__name__}(Message, kw_only=True)`"
            )
        if tag in _REGISTRY:
            raise ValueError(f"message tag {tag!r} registered twice")
        hints = typing.get_type_hints(cls)
        names = cls.__struct_fields__
        cls.TAG = tag
        cls.STREAM = stream
        cls._FIELDS = names
        cls._CHECKS = tuple(
            (i, n, c if isinstance(c, tuple) else (c,))
            for i, n in enumerate(names)
            if (c := _checker(hints[n])) is not None
        )
        _REGISTRY[tag] = cls
        if packed:
            cls._PACKED = _packed_layout(cls, names, hints)
            _PACKED_DECODERS[cls._PACKED.prefix] = cls._PACKED.decode
        return cls

    return wrap


def registered() -> dict[str, type[Message]]:
    """All registered message types by tag (a copy)."""
    return dict(_REGISTRY)


_HEADERS: dict[tuple[Any, tuple[int, ...]], bytes] = {}


def _array_header(dtype: np.dtype, shape: tuple[int, ...]) -> bytes:
    """``len(dtype.str) | dtype.str | ndim | shape as uint32...``, cached per (dtype, shape)."""
    header = _HEADERS.get((dtype, shape))
    if header is None:
        code = dtype.str.encode()
        header = bytes((len(code),)) + code + struct.pack(f"<B{len(shape)}I", len(shape), *shape)
        if len(_HEADERS) < 1024:
            _HEADERS[(dtype, shape)] = header
    return header


def _enc_hook(obj: Any) -> Any:
    if isinstance(obj, np.ndarray):
        if obj.dtype.hasobject:
            raise TypeError("cannot encode an object array")
        return msgspec.msgpack.Ext(_NDARRAY_EXT, _array_header(obj.dtype, obj.shape) + obj.tobytes())
    if isinstance(obj, np.generic):
        return obj.item()
    raise TypeError(f"cannot encode {type(obj).__name__}")


_LAYOUTS: dict[bytes, tuple[np.dtype, int, tuple[int, ...]]] = {}


def _ext_hook(code: int, data: memoryview) -> Any:
    if code != _NDARRAY_EXT:
        raise MessageError(f"unknown extension type {code}")
    n = data[0]
    ndim = data[1 + n]
    offset = 2 + n + 4 * ndim
    header = bytes(data[:offset])
    layout = _LAYOUTS.get(header)
    if layout is None:
        dtype = np.dtype(header[1 : 1 + n].decode())
        if dtype.hasobject:
            raise MessageError("object arrays are not accepted")
        layout = (dtype, offset, struct.unpack_from(f"<{ndim}I", data, 2 + n))
        if len(_LAYOUTS) < 1024:
            _LAYOUTS[header] = layout
    dtype, offset, shape = layout
    return np.frombuffer(data, dtype=dtype, offset=offset).reshape(shape)


_encode_msgpack = msgspec.msgpack.Encoder(enc_hook=_enc_hook).encode
_decode_msgpack = msgspec.msgpack.Decoder(ext_hook=_ext_hook).decode


def encode(msg: Message) -> bytes:
    """Serialise a registered message to bytes."""
    packed = msg._PACKED
    if packed is not None:
        data = packed.encode(msg)
        if data is not None:
            return data
    return _encode_msgpack((SCHEMA_VERSION, msg.TAG, msg))  # a message is an array of its fields


def _packed_error(data: bytes) -> MessageError:
    """Why a payload that starts with 0xC1 is not a packed message."""
    if len(data) < 3:
        return MessageError(f"packed payload of {len(data)} bytes is too short")
    if data[1] != SCHEMA_VERSION:
        return MessageError(f"schema version {data[1]}, this side speaks {SCHEMA_VERSION}")
    tag = data[3 : 3 + data[2]]
    if data[: 3 + data[2]] not in _PACKED_DECODERS:
        return MessageError(f"unknown packed message tag {tag!r}")
    return MessageError(f"{tag.decode()}: packed payload of {len(data)} bytes does not fit its layout")


def decode(data: bytes) -> Message:
    """Turn bytes back into a message, or raise :class:`MessageError` saying why not, or
    :class:`NonFiniteError` naming the message and the field that holds NaN or an infinity."""
    if data[:1] == b"\xc1":
        decoder = _PACKED_DECODERS.get(data[: 3 + data[2]]) if len(data) > 2 else None
        msg = decoder(data) if decoder is not None else None
        if msg is None:
            raise _packed_error(data)
        return msg
    try:
        obj = _decode_msgpack(data)
    except MessageError:
        raise
    except Exception as exc:  # msgspec, the ext hook's struct and numpy calls: garbage of many kinds
        raise MessageError(f"not msgpack: {exc}") from None
    if type(obj) is not list or len(obj) != 3:
        raise MessageError("expected [schema_version, tag, fields]")
    version, tag, values = obj
    if version != SCHEMA_VERSION:
        raise MessageError(f"schema version {version!r}, this side speaks {SCHEMA_VERSION}")
    cls = _REGISTRY.get(tag) if type(tag) is str else None
    if cls is None:
        raise MessageError(f"unknown message tag {tag!r}")
    if type(values) is not list or len(values) != len(cls._FIELDS):
        raise MessageError(f"{tag}: expected {len(cls._FIELDS)} fields {cls._FIELDS}")
    for i, name, check in cls._CHECKS:
        value = values[i]
        if not isinstance(value, check) or (value is True or value is False) and bool not in check:
            raise MessageError(f"{tag}.{name}: expected {check}, got {type(value).__name__}")
    msg = cls(**dict(zip(cls._FIELDS, values, strict=True)))
    check_finite(msg)
    return msg


def decoder_for(cls: type[Message]):
    """A :func:`decode` for a key that carries ``cls``: the same result for every payload, but a
    packed ``cls`` is recognised by its prefix at once (a lockstep link decodes two per tick)."""
    packed = cls._PACKED
    if packed is None:
        return decode
    prefix, fast = packed.prefix, packed.decode

    def decode_expected(data: bytes) -> Message:
        if data.startswith(prefix):
            msg = fast(data)
            if msg is not None:
                return msg
        return decode(data)  # anything else, or a malformed cls: decode says what it is

    return decode_expected


# ---------------------------------------------------------------------------
# The messages of the framework. Brain modules and bodies speak these.
# ---------------------------------------------------------------------------


@message("ack")
class Ack(Message, kw_only=True):
    """Generic acknowledgement (reply to commands that return nothing)."""

    detail: str = ""


# --- ACC: success and failure maps (thesis §3.3) ---------------------------


@message("acc.evaluate")
class Evaluate(Message, kw_only=True):
    """Evaluate candidate vectors (rows, unit coordinates) against both maps at threshold s_vig."""

    candidates: np.ndarray
    s_vig: float


@message("acc.evaluation")
class Evaluation(Message, kw_only=True):
    """d_s, d_f (3.1)-(3.2) and the go decision (EWS = 0, eq. 3.3) for each candidate."""

    d_success: np.ndarray
    d_failure: np.ndarray
    go: np.ndarray


@message("acc.learn")
class Learn(Message, kw_only=True):
    """Learn one trial: success -> success map with reward rho (5.1); failure -> failure map."""

    v: np.ndarray
    success: bool
    rho: float
    #: the success's quality eta (efficiency, (5.8)): what the success neurons learn as their reward; None: not graded
    eta: float | None = None


@message("acc.learned")
class Learned(Message, kw_only=True):
    """Sum of squared weight changes of the map that learnt (convergence), sample counts, and the winner of each map
    for the trial's vector before it learnt (neuron indices; -1: not given)."""

    change: float
    n_success_samples: int
    n_failure_samples: int
    success_winner: int = -1
    failure_winner: int = -1


@message("acc.exploit")
class Exploit(Message, kw_only=True):
    """For each condition value on ``axis``, the success neuron whose weight there is closest."""

    axis: int
    conditions: np.ndarray


@message("acc.exploit_table")
class ExploitTable(Message, kw_only=True):
    conditions: np.ndarray
    weights: np.ndarray


@message("acc.finish")
class Finish(Message, kw_only=True):
    """End of learning: prune orphan failure neurons and checkpoint the maps to ``path``."""

    path: str
    prune: bool


# --- Vigilance (§3.3.4, (4.14), §5.6.3) ------------------------------------


@message("vigilance.start")
class VigilanceStart(Message, kw_only=True):
    """Ask the threshold for the first trial."""


@message("vigilance.trial_done")
class TrialDone(Message, kw_only=True):
    """A trial finished; ``trial_index`` is the number of trials done so far."""

    trial_index: int
    success: bool
    n_success: int
    n_failure: int


@message("vigilance.rejected")
class Rejected(Message, kw_only=True):
    """``consecutive`` no-go decisions in a row."""

    consecutive: int


@message("vigilance.threshold")
class Threshold(Message, kw_only=True):
    """The threshold s_vig in force and the band it was drawn from (low == high when fixed)."""

    s_vig: float
    low: float
    high: float


# --- OFC: qualitative adaptive reward (§5.4.2) -----------------------------


@message("ofc.grade")
class Grade(Message, kw_only=True):
    """Grade a successful trial of quality eta (5.8)."""

    eta: float


@message("ofc.reward")
class Reward(Message, kw_only=True):
    """The reward factor rho (5.2) and the running quality range (5.3)."""

    rho: float
    eta_min: float
    eta_max: float


# --- Bodies and controllers -------------------------------------------------


@message("body.trial")
class TrialRequest(Message, kw_only=True):
    """Run one trial. ``body_params`` / ``controller_params`` are physical values by name."""

    trial_id: int
    seed: int
    body_params: dict
    controller_params: dict
    log: bool


@message("body.result")
class TrialResult(Message, kw_only=True):
    """Outcome of a trial: success, quality eta, and body metrics (distance, velocity, ...); what it cost."""

    trial_id: int
    success: bool
    quality: float
    metrics: dict
    worker: str
    #: simulated seconds the body ran (control ticks x control_dt; 0 for a body without a clock, e.g. analytic)
    sim_s: float = 0.0
    #: CPU seconds the body worker's process spent on the trial (with a controller hosted in it); None: not measured
    cpu_body_s: float | None = None
    #: CPU seconds the controller's own process spent on the trial; None: hosted in the body's process, or unknown
    cpu_controller_s: float | None = None


@message("controller.reset")
class ControllerReset(Message, kw_only=True):
    """Start of a trial: the controller's learnt parameters and the body's signal layout."""

    trial_id: int
    seed: int
    params: dict
    sensors: list
    commands: list
    #: log this trial's neuron activities (the body logs its motion on the same trial)
    log: bool = False
    #: sim_time of tick 0 and the control tick, s (to place the activities on the ``sim_time`` timeline)
    t0: float = 0.0
    dt: float = 0.01


@message("controller.sensors", stream=True, packed=True)
class SensorFrame(Message, kw_only=True):
    """One control tick of sensor values (layout: the body's ``SENSORS``)."""

    trial_id: int
    tick: int
    values: np.ndarray


@message("body.command", stream=True, packed=True)
class MotorCommand(Message, kw_only=True):
    """One control tick of commands (layout: the body's ``COMMANDS``), e.g. motor voltages."""

    trial_id: int
    tick: int
    values: np.ndarray
