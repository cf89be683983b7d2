"""Host one module in its own process: ``python -m sfl_brain.runtime.host`` with the JSON spec on stdin.

The spec (first line of stdin) holds the run secret, so it never shows on a command line (and
has no argv size limit); the rest of stdin stays open, and its end means the parent is gone.
``python -m sfl_brain.runtime.host SPEC_JSON`` (the spec as argument) is still read, for hosts started by
hand or by the benchmarks: without a secret, anyone on the bus may sign messages.

The host opens a Zenoh peer session, answers each request type the module
handles on ``sfl/<run>/<instance>/<tag>``, publishes replies to stream messages
(lockstep ticks) to the instance named in its routes, and declares a liveliness
token once it is ready. A body worker and its controller process also open their
lockstep link (``spec["tick"]``: a ``seqpacket/`` endpoint is a socket link, :mod:`sfl_brain.runtime.ticklink`,
:class:`~.ticklink.SocketLink`; a ``unixsock-stream/`` one a Zenoh session, :func:`bus.open_tick_session`,
:class:`~.ticklink.BusLink`), which carries their frames and commands; a host whose spec names cores
(``spec["cpus"]``, from :mod:`sfl_brain.runtime.placement`) pins itself to them before any session starts.
Requests are handed to one loop in the main thread (a trial may run for seconds);
lockstep stream messages are answered by a thread that blocks in the subscriber's
channel. A lock makes sure the module never sees two messages at once.

A malformed, unsigned, stale or foreign message is dropped and counted by reason (a request
gets an error reply); each kind is logged once. At exit the counts go to
``<run_dir>/logs/<instance>.counters.json``. A controller answers only frames of the trial its
last reset started, with that reset's nonce, tick after tick. The host exits on SIGTERM, or when
its parent goes away (stdin closes).
"""

from __future__ import annotations

import functools
import json
import logging
import os
import queue
import signal
import sys
import threading
import time
from collections import deque
from collections.abc import Callable
from pathlib import Path
from typing import Any

import msgspec
import zenoh

from ..body import Body, Controller, InProcessLink
from ..messages import (
    ControllerReset,
    Message,
    MessageError,
    MotorCommand,
    NonFiniteError,
    SensorFrame,
    TrialRequest,
    TrialResult,
    decode,
    decoder_for,
    encode,
)
from ..module import Module
from ..registry import resolve
from ..telemetry import Rates, TelemetryTee
from . import bus, ticklink
from .bus import NoReply, RemoteError
from .liveness import ProgressSlot, cpu_sample
from .placement import keep_nice_in_own_session, pin
from .ticklink import (
    BusLink,
    SocketLink,
    TickLink,
)

log = logging.getLogger("sfl.host")

STOP = object()


def request(
    session: zenoh.Session,
    key_expr: str,
    msg: Message,
    timeout: float,
    *,
    seal: bus.Seal | None = None,
    nonce: bytes | None = None,
) -> Message:
    """Send ``msg``, signed by ``seal`` (no secret: an empty key), to the queryable at ``key_expr``
    and return its decoded reply. Replies not signed for this request are ignored."""
    seal = seal or bus.Seal(None)
    nonce, payload = seal.seal_request(key_expr, encode(msg), nonce)
    sent = time.monotonic()
    replies = session.get(
        key_expr,
        payload=payload,
        timeout=timeout,
        target=zenoh.QueryTarget.ALL,
        consolidation=zenoh.ConsolidationMode.NONE,  # every reply as it comes: a stranger's cannot hold ours
    )
    for reply in replies:
        if reply.ok is not None:
            data = seal.open_reply(nonce, reply.ok.payload.to_bytes())
            if data is not None:
                return decode(data)
            continue
        text = seal.open_reply(nonce, reply.err.payload.to_bytes())
        if text is None:  # Zenoh's own "Timeout", or a stranger's error
            continue
        raise RemoteError(text.decode(errors="replace"))
    waited = time.monotonic() - sent
    if waited < timeout - 0.5:  # the query ended early: no queryable answered (a module gone, or none there yet)
        raise NoReply(f"no reply from {key_expr}: the query ended after {waited:.2f} s with no answer (gone?)")
    raise NoReply(f"no reply from {key_expr} within {timeout:g} s")


def make_module(reference: str, params: dict, seed: int, entity: str) -> Module:
    cls, _ = resolve(reference)
    module = cls(cls.Params.model_validate(params), seed=seed)
    module.entity = entity
    return module


def make_recording(run_id: str, rrd: str | None, viewer: str | None):
    if not rrd and not viewer:
        return None
    import rerun as rr

    from ..recording.rerun_sink import attach_sinks

    rec = rr.RecordingStream("sfl-brain", recording_id=run_id)
    attach_sinks(rec, rrd, viewer)
    return rec


class LazyRecording:
    """The process's Rerun recording, opened by the first sink made on it (:meth:`get`): a process whose module
    says it emits no telemetry (``emits_telemetry = False``: the OFC, vigilance) makes none, never imports Rerun
    (about 0.8 s of CPU) and leaves no part in ``rerun/``. ``opened``: the recording, None until then."""

    def __init__(self, run_id: str, rrd: str | None, viewer: str | None) -> None:
        self.run_id, self.rrd, self.viewer = run_id, rrd, viewer
        self.opened = None

    def get(self):
        if self.opened is None:
            self.opened = make_recording(self.run_id, self.rrd, self.viewer)
        return self.opened


def make_telemetry(
    rec: LazyRecording | None,
    module: Module,
    record: dict | None,
    run_dir: Path | None,
    part: str,
    live: bool = False,
    trial_seconds: float | None = None,
) -> TelemetryTee | None:
    """The telemetry sink of a hosted module: its Rerun columns on ``rec`` under the module's
    entity and, with a run folder, its map snapshots as ``<run_dir>/maps/<part>.parquet`` (merged
    into ``maps.parquet`` at the end of the run); sampled at the rates of the scenario's ``record:``.
    ``live``: a viewer watches, so series are sent at least every 2 s. ``trial_seconds``: where each
    trial starts on ``sim_time`` (``Plan.trial_seconds``). None when the run does not record (nothing is
    computed to be shown), and for a module that says it emits none (:attr:`~sfl_brain.module.Module.emits_telemetry`).
    The recording opens here, before the module is ready, so that importing Rerun never falls inside a request's
    time-out; the map table at its first snapshot."""
    if rec is None or not module.emits_telemetry:
        return None
    from ..recording.rerun_sink import RerunTelemetry
    from ..recording.tables import MapTable

    rates = Rates.from_record(record)
    table = MapTable(run_dir / "maps" / f"{part}.parquet", module=module.entity) if run_dir is not None else None
    rerun = RerunTelemetry(rec.get(), module.entity, rates, trial_seconds, batch_seconds=2.0 if live else None)
    return TelemetryTee(rerun, table, rates=rates)


class CountedLink(InProcessLink):
    """A controller hosted in the body worker's process (``colocate: true``); each tick counts on the progress board."""

    def __init__(self, controller: Controller, progress: Callable[[], None]) -> None:
        super().__init__(controller)
        self.progress = progress

    def step(self, frame: SensorFrame) -> MotorCommand:
        command = super().step(frame)
        self.progress()
        return command


class Host:
    #: request nonces remembered to refuse a replayed request
    SEEN = 4096

    def __init__(self, spec: dict[str, Any]) -> None:
        self.spec = spec
        self.run_id = spec["run_id"]
        self.instance = spec["instance"]
        self.inbox: queue.SimpleQueue = queue.SimpleQueue()
        self._publishers: dict[str, Any] = {}
        self._lock = threading.Lock()  # the module sees one message at a time
        self._stopping = False
        self._stop_asked = False  # stop() was called: the main loop leaves before the next request
        self.link: TickLink | None = None  # a body's link to its controller in another process
        self.ticks: zenoh.Session | None = None  # the lockstep link of a body worker or its controller process
        # what serve() opens besides, closed at its end: the recording and the telemetry sinks (after their
        # modules), a controller hosted in this body worker, a controller's end of a socket lockstep link, the
        # stream threads on a Zenoh lockstep link and the request queryables
        self._rec = None
        self._sinks: list = []
        self._colocated: Controller | None = None
        self._server: ticklink.Server | None = None
        self._streams: list[tuple[str, Any, threading.Thread]] = []
        self._declared: list = []
        self.seal = bus.Seal(spec.get("secret"))
        self.drops = bus.Drops(log, self.instance)
        self._seen: deque[bytes] = deque(maxlen=self.SEEN)
        self._seen_set: set[bytes] = set()
        # the lockstep stream of the current trial: [nonce, trial_id, next tick] (set by a controller reset)
        self._stream: list | None = None
        self.run_dir = Path(spec["run_dir"]) if spec.get("run_dir") else None
        #: this process's slot on the run's progress board (:mod:`.liveness`), None for a host started by hand
        board = spec.get("progress")
        self.board = ProgressSlot(board["path"], board["slot"]) if board else None
        self.progress = self.board.bump if self.board is not None else (lambda: None)

    def controller_pid(self) -> Callable[[], int] | None:
        """How a body worker finds its controller's process (from the board; it changes with each restart), or None
        where the run has no board (a host started by hand: its link judges the controller by the wall clock)."""
        slot = (self.spec.get("progress") or {}).get("controller")
        if self.board is None or slot is None:
            return None
        return functools.partial(self.board.pid_of, slot)

    def stop(self) -> None:
        """Leave the main loop; a trial in progress is interrupted at its next tick (from any thread). Requests
        still queued are not answered: a flood of them (garbage on the bus) must not hold the exit back past the
        supervisor's grace, after which it kills the process before it writes its counters."""
        self._stop_asked = True
        self.inbox.put(STOP)
        if self.link is not None:
            self.link.interrupt()
        # the counts so far, at once: the main thread may be held up (a reply to a peer that reads slowly), and a
        # host that does not exit within the supervisor's grace is killed before it writes them at its end
        self.write_counters()

    # callbacks only enqueue; the main loop does the work
    def _enqueue(self, item) -> None:
        self.inbox.put(item)

    def _reply_key(self, tag: str) -> str:
        return bus.key(self.run_id, self.spec["routes"][tag], tag)

    def serve(self) -> None:
        """Build the module, open the run's session and the lockstep link, answer the module's messages until the
        host stops, and close whatever was opened, whatever happened."""
        spec = self.spec
        self.module = make_module(spec["reference"], spec["params"], spec["seed"], spec["spec_name"])
        self.module.run_dir = self.run_dir  # where the module may write files (None: anywhere)
        self.session = bus.open_session(
            spec["listen"],
            spec["connect"],
            zenoh_config=spec.get("zenoh_config"),
            lease_ms=spec.get("lease_ms", bus.LEASE_MS),
        )
        try:
            listen_end, connect_end = self._open_tick_link()
            self._open_recording()
            if isinstance(self.module, Body):
                self._wire_body(connect_end)
            self._declare_handlers(listen_end)
            proof = self.seal.alive_proof(self.run_id, self.instance, spec.get("nonce") or os.urandom(8).hex())
            token = self.session.liveliness().declare_token(bus.alive_key(self.run_id, self.instance, proof))
            log.info("%s ready (%s)", self.instance, spec["reference"])
            self._loop()
            token.undeclare()
        finally:
            self._close()

    def _open_tick_link(self) -> tuple[str | None, str | None]:
        """A body worker's and its controller process's lockstep link (``{"listen": ...}`` for the controller,
        ``{"connect": ...}`` for the body), or the mesh when the spec names none. A Zenoh link is opened here
        (:attr:`ticks`); a socket link's ends are returned, (listen, connect), for the server and the body's link."""
        tick = self.spec.get("tick") or {}
        ends = [f"listening on {e}" for e in tick.get("listen", [])] + [
            f"connecting to {e}" for e in tick.get("connect", [])
        ]
        listen_end = next((e for e in tick.get("listen", []) if ticklink.is_socket(e)), None)
        connect_end = next((e for e in tick.get("connect", []) if ticklink.is_socket(e)), None)
        socket_end = listen_end or connect_end
        if socket_end is not None:  # lockstep.link: socket (sfl_brain.runtime.ticklink)
            log.info("lockstep link (socket): %s", ", ".join(ends))
        elif tick:  # lockstep.link: zenoh
            self.ticks = bus.open_tick_session(tick.get("listen", []), tick.get("connect", []))
            log.info("lockstep link (lowlatency): %s", ", ".join(ends))
        return listen_end, connect_end

    def _open_recording(self) -> None:
        """The process's Rerun recording, and the module's telemetry into it."""
        rrd, viewer = self.spec.get("rrd"), self.spec.get("viewer")
        self._rec = LazyRecording(self.run_id, rrd, viewer) if rrd or viewer else None
        self.module.telemetry = self._telemetry(self.module, self.instance)

    def _telemetry(self, module: Module, part: str) -> TelemetryTee | None:
        """A module's telemetry sinks (closed at the end, after the module); ``part``: its name in the run folder."""
        spec = self.spec
        live = bool(spec.get("viewer"))
        telemetry = make_telemetry(
            self._rec, module, spec.get("record"), self.run_dir, part, live, spec.get("trial_seconds")
        )
        self._sinks.append(telemetry)
        return telemetry

    def _wire_body(self, connect_end: str | None) -> None:
        """A body worker's link to its controller: hosted here (``colocate: true``), or in its own process over the
        lockstep link (a socket when ``connect_end`` names one; else Zenoh, the lockstep session or the mesh)."""
        spec = self.spec
        self.module.worker = self.instance
        self.module.realtime = bool(spec.get("realtime"))
        colocated = spec.get("colocated")
        if colocated:
            self._colocated = make_module(
                colocated["reference"], colocated["params"], colocated["seed"], colocated["spec_name"]
            )
            self._colocated.telemetry = self._telemetry(self._colocated, f"{self.instance}.controller")
            self.module.link = CountedLink(self._colocated, self.progress)
        elif self.module.COMMANDS:  # the body's end: its own socket to the controller, or the bus
            link, transport = (
                (SocketLink, {"endpoint": connect_end}) if connect_end is not None else (BusLink, {"ticks": self.ticks})
            )
            self.link = link(
                self.session,
                self.run_id,
                self.instance,
                spec["routes"][SensorFrame.TAG],
                spec["tick_timeout"],
                spec.get("spin", 0.0),
                secret=spec.get("secret"),
                drops=self.drops,
                controller_pid=self.controller_pid(),
                progress=self.progress,
                **transport,
            )
            self.module.link = self.link

    def _declare_handlers(self, listen_end: str | None) -> None:
        """Answer each message type the module handles: a request on a queryable (its queries go to the main loop);
        a lockstep stream message on the socket link's server (``listen_end``) or in a thread that blocks on a
        subscriber of the lockstep session (or the mesh)."""
        ticks = self.ticks or self.session
        for message_type in type(self.module).handles:
            key_expr = bus.key(self.run_id, self.instance, message_type.TAG)
            if message_type.STREAM and listen_end is not None:  # a thread per connection blocks in recv()
                if self._server is not None:
                    raise ValueError(f"{self.instance}: a socket lockstep link carries one stream message type")
                answer = functools.partial(self._stream_answer, message_type, decoder_for(message_type))
                self._server = ticklink.Server(
                    listen_end,
                    answer,
                    on_refused=lambda: self.drops("foreign", "lockstep connection", "too many connections"),
                    on_oversized=lambda n, t=message_type.TAG: self.drops("malformed", f"{t} frame", f"{n} B"),
                )
            elif message_type.STREAM:  # one thread blocks in recv(): no Python handoff per tick
                subscriber = ticks.declare_subscriber(key_expr, zenoh.handlers.RingChannel(64))
                thread = threading.Thread(
                    target=self._stream_loop,
                    args=(subscriber, message_type),
                    daemon=True,
                    name=f"stream-{message_type.TAG}",
                )
                thread.start()
                self._streams.append((key_expr, subscriber, thread))
            else:
                callback = zenoh.handlers.Callback(self._enqueue, indirect=False)
                self._declared.append(self.session.declare_queryable(key_expr, callback))

    def _close(self) -> None:
        """Close what :meth:`serve` opened, the lockstep threads and links first, the sessions last; then write the
        drop counters."""
        self._stopping = True
        if self._server is not None:
            self._server.close()
        ticks = self.ticks or self.session
        for key_expr, subscriber, thread in self._streams:
            ticks.put(key_expr, b"")  # wakes the stream thread, which sees _stopping
            thread.join(timeout=2.0)
            if not thread.is_alive():
                subscriber.undeclare()
        for d in self._declared:
            d.undeclare()
        if self.link is not None:
            self.link.close()
        for p in self._publishers.values():
            p.undeclare()
        self.module.close()
        if self._colocated is not None:
            self._colocated.close()  # its last logged trial's neurons
        for sink in self._sinks:
            if sink is not None:
                sink.close()
        if self._rec is not None and self._rec.opened is not None:
            from ..recording.rrlog import close_recording

            problem = close_recording(self._rec.opened)
            if problem is not None:
                log.warning("%s: the Rerun recording did not reach the disk (%s)", self.instance, problem)
        if self.ticks is not None:
            self.ticks.close()
        self.session.close()
        self.write_counters()
        # the board stays mapped until the process exits: a lockstep thread still returning may count a tick

    def write_counters(self) -> None:
        """``<run_dir>/logs/<instance>.counters.json``: ``{"dropped": {reason: n}}``."""
        if self.run_dir is None:
            return
        try:
            self.drops.write(self.run_dir / "logs" / f"{self.instance}.counters.json")
        except OSError as exc:
            log.warning("%s: could not write its drop counters: %s", self.instance, exc)

    def _loop(self) -> None:
        inbox = self.inbox
        while True:
            try:
                item = inbox.get(timeout=1.0)
            except queue.Empty:
                continue
            if item is STOP or self._stop_asked:
                self._drop_queued(item)
                return
            with self._lock:
                self._answer(item)
                try:
                    self.module.run_deferred()
                except Exception:
                    log.exception("%s: deferred work failed", self.instance)

    def _drop_queued(self, item) -> None:
        """Let go of the requests still queued at stop, unanswered (their queriers learn at once that nobody will)."""
        while True:
            if item is not STOP:
                item.drop()
            try:
                item = self.inbox.get_nowait()
            except queue.Empty:
                return

    def _fresh(self, nonce: bytes) -> bool:
        """False for a request nonce seen before (a replay)."""
        if nonce in self._seen_set:
            return False
        if len(self._seen) == self._seen.maxlen:
            self._seen_set.discard(self._seen[0])
        self._seen.append(nonce)
        self._seen_set.add(nonce)
        return True

    def _answer(self, query: zenoh.Query) -> None:
        nonce = None
        try:
            payload = query.payload
            data = payload.to_bytes() if payload is not None else b""
            if len(data) < bus.Seal.NONCE + bus.Seal.MAC:
                self.drops("malformed", "request", f"on {query.key_expr}: too short to be signed")
                query.reply_err("malformed request: too short to be a signed request")
                return
            opened = self.seal.open_request(str(query.key_expr), data)
            if opened is None:
                self.drops("unauthenticated", "request", f"on {query.key_expr}: not signed with this run's secret")
                query.reply_err("unauthenticated request: not signed with this run's secret")
                return
            nonce, body = opened
            if not self._fresh(nonce):
                self.drops("stale", "request", f"on {query.key_expr}: a replayed request")
                return
            msg = decode(body)
            reply = self._trial(msg) if type(msg) is TrialRequest else self.module.handle(msg, checked=True)
            self.progress()
            if type(msg) is ControllerReset:  # the trial whose frames this controller answers from now on
                self._stream = [nonce, msg.trial_id, 0]
            query.reply(query.key_expr, self.seal.seal_reply(nonce, encode(reply)))
        except MessageError as exc:
            self.drops("malformed", "request", f"on {query.key_expr}: {exc}")
            query.reply_err(self.seal.seal_reply(nonce, f"malformed request: {exc}".encode()))
        except Exception as exc:  # the module failed on this request: report, keep serving
            log.exception("%s: error handling request on %s", self.instance, query.key_expr)
            if nonce is not None:
                query.reply_err(self.seal.seal_reply(nonce, f"{type(exc).__name__}: {exc}".encode()))
        finally:
            query.drop()

    def _trial(self, request: TrialRequest) -> TrialResult:
        """Run a trial on this body worker and say what it cost: the CPU seconds of this process (a controller hosted
        in it included) and of its controller's own process, read around the whole trial, never per tick."""
        controller = self._controller_cpu()
        started = time.process_time()
        result = self.module.handle(request, checked=True)
        cpu_body = time.process_time() - started
        if isinstance(result, TrialResult):
            ended = self._controller_cpu()
            same = controller is not None and ended is not None and controller[0] == ended[0]
            result = msgspec.structs.replace(
                result, cpu_body_s=cpu_body, cpu_controller_s=ended[1] - controller[1] if same else None
            )
        return result

    def _controller_cpu(self) -> tuple[int, float] | None:
        """(pid, CPU seconds so far) of this body worker's controller process; None for a controller hosted here, one
        of a host started by hand (no progress board) or a process that cannot be read."""
        find = self.controller_pid() if self._colocated is None and self.link is not None else None
        pid = find() if find is not None else 0
        sample = cpu_sample(pid) if pid > 0 else None
        return (pid, sample.cpu) if sample is not None else None

    def _stream_loop(self, subscriber, message_type: type[Message]) -> None:
        """Answer lockstep stream messages arriving on a Zenoh subscriber (:meth:`_stream_reply`); publish
        each reply, with the trial's nonce, to the instance the routes name."""
        reply_to, recv, publishers = self._stream_reply, subscriber.recv, self._publishers
        decode_stream = decoder_for(message_type)
        while True:
            data = recv().payload.to_bytes()
            if self._stopping:
                return
            reply = reply_to(message_type, decode_stream, data)
            if reply is not None:
                publisher = publishers.get(reply.TAG)
                if publisher is None:
                    key_expr = self._reply_key(reply.TAG)
                    publisher = publishers[reply.TAG] = (self.ticks or self.session).declare_publisher(key_expr)
                publisher.put(encode(reply) + data[-8:])  # the nonce it came with: the trial's (checked)

    def _stream_answer(self, message_type: type[Message], decode_stream, data: bytes) -> bytes | None:
        """What a socket lockstep link sends back for ``data``: the reply with the trial's nonce, or None."""
        reply = self._stream_reply(message_type, decode_stream, data)
        return None if reply is None else encode(reply) + data[-8:]

    def _stream_reply(self, message_type: type[Message], decode_stream, data: bytes) -> Message | None:
        """The reply to one lockstep stream message, or None: check the trial's nonce, decode, check trial and
        tick, handle. What fails is dropped and counted."""
        drops, why = self.drops, ""
        try:
            msg = decode_stream(data[:-8])
        except (MessageError, NonFiniteError) as exc:  # a body checks its own sensors: not from it
            msg, why = None, str(exc)
        with self._lock:  # the checks and the handler see one stream: a reset cannot come in between
            stream = self._stream
            if stream is None or data[-8:] != stream[0]:
                drops("foreign", f"{message_type.TAG} frame", "not the current trial's stream nonce")
                return None
            if msg is None:
                drops("malformed", f"{message_type.TAG} frame", why)
                return None
            if type(msg) is not message_type:
                drops("malformed", f"{message_type.TAG} frame", f"a {getattr(msg, 'TAG', msg)}")
                return None
            tick = getattr(msg, "tick", None)
            if tick is not None and (msg.trial_id != stream[1] or tick != stream[2]):
                drops(
                    "stale",
                    f"{message_type.TAG} frame",
                    f"trial {msg.trial_id} tick {tick} while expecting trial {stream[1]} tick {stream[2]}",
                )
                return None
            stream[2] += 1
            try:
                reply = self.module.handle(msg, checked=True)  # decoded: checked by the codec
            except Exception:
                log.exception("%s: error handling a stream message", self.instance)
                return None
            self.progress()
        return reply


def _watch_parent(host: Host) -> None:
    """Stop when the parent closes our stdin (it exited, even by kill -9)."""
    try:
        while sys.stdin.buffer.read(1024):
            pass
    except (OSError, ValueError):
        pass
    host.stop()


def _on_signal(host: Host, wake_r: int) -> None:
    while os.read(wake_r, 1):
        host.stop()


def read_spec(argv: list[str]) -> dict:
    """The spec: the first line of stdin (``sfl run``, which passes ``--name INSTANCE`` for ``ps`` to
    show), or the first argument (by hand, benchmarks)."""
    if argv and argv[0] != "--name":
        return json.loads(argv[0])
    line = sys.stdin.buffer.readline()
    if not line:
        raise SystemExit("sfl_brain.runtime.host: expected the JSON spec on the first line of stdin")
    return json.loads(line)


def main(argv: list[str] | None = None) -> int:
    argv = sys.argv[1:] if argv is None else argv
    return serve(read_spec(argv))


def serve(spec: dict, *, on_sigint: bool = False, stop_event: threading.Event | None = None) -> int:
    """Host ``spec`` until SIGTERM, the parent's end (stdin closes, unless ``watch_stdin`` is false),
    or ``stop_event``; ``on_sigint`` also stops on Ctrl-C (``sfl worker``). Returns an exit code."""
    logging.basicConfig(
        level=spec.get("log_level") or os.environ.get("SFL_LOG_LEVEL", "INFO"),
        format=f"%(asctime)s {spec['instance']} %(levelname)s %(message)s",
        stream=sys.stderr,
    )
    keep_nice_in_own_session()  # a niced run stays niced against other sessions (autogroup)
    if spec.get("cpus"):
        pin(spec["cpus"])  # before the session's threads start: they inherit it
        log.info("pinned to cores %s", sorted(os.sched_getaffinity(0)))
    host = Host(spec)
    # SIGTERM: the main thread may sit in a trial (blocked in Rust), where Python handlers do not run;
    # the C handler writes to a wakeup fd, and a thread that reads it stops the host at once
    wake_r, wake_w = os.pipe()
    os.set_blocking(wake_w, False)
    signal.set_wakeup_fd(wake_w)
    signal.signal(signal.SIGTERM, lambda *_: None)
    # Ctrl-C is the supervisor's to handle, unless this process is on its own (sfl worker)
    signal.signal(signal.SIGINT, (lambda *_: None) if on_sigint else signal.SIG_IGN)
    threading.Thread(target=_on_signal, args=(host, wake_r), daemon=True).start()
    if spec.get("watch_stdin", True):
        threading.Thread(target=_watch_parent, args=(host,), daemon=True).start()
    if stop_event is not None:
        threading.Thread(target=lambda: (stop_event.wait(), host.stop()), daemon=True).start()
    try:
        host.serve()
    except Exception:
        log.exception("%s failed", spec["instance"])
        return 1
    return 0


if __name__ == "__main__":
    code = main()
    logging.shutdown()
    sys.stderr.flush()
    os._exit(code)  # the session is closed; do not wait on foreign threads at exit
