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
:class:`SocketLink`; a ``unixsock-stream/`` one a Zenoh session, :func:`bus.open_tick_session`,
:class:`BusLink`), which carries their frames and commands; a host whose spec names cores (``spec["cpus"]``, from
:mod:`sfl_brain.runtime.placement`) pins itself to them before any session starts.
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
import statistics
import sys
import threading
import time
from collections import deque
from collections.abc import Callable
from pathlib import Path
from typing import Any

import zenoh

from ..body import Body, Controller, InProcessLink
from ..messages import (
    ControllerReset,
    Message,
    MessageError,
    MotorCommand,
    NonFiniteError,
    SensorFrame,
    decode,
    decoder_for,
    encode,
)
from ..module import Module
from ..registry import resolve
from ..telemetry import Rates, TelemetryTee
from . import bus, ticklink
from .liveness import NoProgressClock, ProgressSlot, cpu_sample
from .placement import pin, usable_cpus

log = logging.getLogger("sfl.host")

STOP = object()
_decode_command = decoder_for(MotorCommand)


class LinkError(RuntimeError):
    """The controller did not answer during a trial (it died or hung): the trial is interrupted."""


class ControllerHung(LinkError):
    """The controller process had the CPU for ``timeouts.tick`` seconds without answering a tick or a reset
    (:mod:`.liveness`): it is hung. The trial is interrupted, and the supervisor ends the controller (it is
    restarted by its policy)."""


#: how long a body waits for its controller's reset reply when it can watch the controller's process: as long as
#: the controller lives and is not hung (its watchdog decides); the query itself only ends with the process
WATCHED_WAIT = 24 * 3600.0


class SpinThenSleep:
    """How a body waits for each command: poll for up to ``budget`` seconds, then sleep in recv().

    Polling keeps the body on its core with warm caches, and the controller wakes on the other
    one: on 2 idle cores, walker trials of a full E3.2 run were 1-5% shorter. But a polling body
    takes a core that the controller or anything else running may need, and then every tick
    waits for a time slice: beside one busy loop, plain polling made a trial 28% longer. So it
    measures, as Aeron's idle strategies are tuned but online: every ``CYCLE`` ticks, ``EXPLORE``
    of them wait the other way, and the way whose median tick (put to put, physics included) was
    shorter is kept for the next cycle (medians: one tick in a hundred takes a scheduling
    hiccup, which would sway a mean of eight). ``budget`` 0 always sleeps at once.
    """

    CYCLE, EXPLORE = 128, 8

    def __init__(self, budget: float) -> None:
        self.budget = budget
        self.prefer_spin = budget > 0
        self.restart()

    def restart(self) -> None:
        """A new trial: the first tick's period is not a tick's."""
        self.tick = 0
        self.spin = self.prefer_spin
        self.last: float | None = None
        self.periods: tuple[list[float], list[float]] = ([], [])  # this cycle's tick times, by way (index: spun)

    def next_tick(self, now: float) -> bool:
        """Account the tick that ended at ``now`` (``time.perf_counter``) to the way it waited;
        say whether this one polls."""
        if not self.budget:
            return False
        if self.last is not None:
            self.periods[self.spin].append(now - self.last)
        self.last = now
        self.tick += 1
        phase = self.tick % self.CYCLE
        if phase == 0:  # end of a cycle: keep the faster way
            other, preferred = self.periods[not self.prefer_spin], self.periods[self.prefer_spin]
            if other and preferred and statistics.median(other) < statistics.median(preferred):
                self.prefer_spin = not self.prefer_spin
            self.periods = ([], [])
        self.spin = self.prefer_spin if phase >= self.EXPLORE else not self.prefer_spin
        return self.spin


def check_command(data: bytes, frame: SensorFrame, nonce: bytes, drops: bus.Drops) -> MotorCommand | None:
    """The command in ``data`` if it answers ``frame``: this trial's stream ``nonce`` at its end, a
    :class:`MotorCommand` of the frame's trial and tick; None (dropped and counted) if not."""
    if data[-8:] != nonce:
        drops("foreign", "command", "not this trial's stream nonce")
        return None
    try:
        command = _decode_command(data[:-8])
    except MessageError as exc:
        drops("malformed", "command", str(exc))
        return None
    if type(command) is not MotorCommand:
        drops("malformed", "command", f"a {getattr(command, 'TAG', command)} on the command key")
        return None
    if command.trial_id != frame.trial_id or command.tick != frame.tick:
        drops("stale", "command", f"trial {command.trial_id} tick {command.tick} while waiting for tick {frame.tick}")
        return None
    return command


#: why a tick or a reset ends when the body worker's host stops
STOPPING = "the body worker is stopping"


class TickLink:
    """What a body's link to its controller in another process does on either transport (:class:`SocketLink`,
    :class:`BusLink`): the reset, a signed request on the mesh whose nonce becomes the trial's stream nonce;
    a watchdog that ends a tick (or a reset) whose answer is overdue (:class:`ControllerHung`); :meth:`interrupt`
    when the host stops. With ``controller_pid`` (the controller's process, from the run's progress board) overdue
    means the controller had the CPU for ``timeout`` seconds and did not answer: a controller that is starved,
    niced or stopped (SIGSTOP, a suspended laptop) is waited for (:mod:`.liveness`); without it (a host
    started by hand) ``timeout`` seconds of wall time. A body that may use one core only (a 1-core machine, or sharing
    its core with its controller, ``lockstep.pin_cpus``) never polls: polling needs a core for the
    controller to answer on, or it starves the controller it waits for."""

    def __init__(
        self,
        session: zenoh.Session,
        run_id: str,
        body: str,
        controller: str,
        timeout: float,
        spin: float,
        secret: str | None,
        drops: bus.Drops | None,
        controller_pid: Callable[[], int] | None = None,
        progress: Callable[[], None] | None = None,
    ) -> None:
        self.session = session
        self.run_id = run_id
        self.controller = controller
        self.timeout = timeout
        #: the controller's current process id (0 while unknown), or None: judge it by the wall clock
        self.controller_pid = controller_pid
        #: counts a tick on the run's progress board
        self.progress = progress or (lambda: None)
        self.seal = bus.Seal(secret)
        self.drops = drops or bus.Drops(log, body)
        self.waiter = SpinThenSleep(spin if len(usable_cpus()) > 1 else 0.0)
        self.reset_key = bus.key(run_id, controller, ControllerReset.TAG)
        self.nonce = b""  # this trial's stream nonce (set by reset)
        self._waiting_since: float | None = None  # a tick's or the reset's wait for the controller, since
        self._abort: str | None = None  # why the waiting tick must end (overdue command, stopping)
        self._abort_as: type[LinkError] = LinkError
        self._stopping = False
        self._closed = threading.Event()

    def _start_watchdog(self) -> None:
        threading.Thread(target=self._watch, name="ticklink-watchdog", daemon=True).start()

    def _wake(self, reason: str) -> None:
        """End the waiting tick (or reset) with :meth:`_fault` (``reason`` with ``{what}`` filled in)."""
        raise NotImplementedError

    def _fault(self, what: str) -> LinkError:
        """The error that ends the wait for ``what`` (``tick 12``, ``the reset of trial 3``): why the watchdog or a
        stop ended it (:class:`ControllerHung` for a hung controller)."""
        return self._abort_as("interrupted: " + (self._abort or "").format(what=what))

    def _watch(self) -> None:
        """Every ``timeout / 4`` s (at most 1 s): end a wait for the controller that is overdue (see the class)."""
        period = min(max(self.timeout / 4, 0.01), 1.0)
        clock, watching = NoProgressClock(), None
        while not self._closed.wait(period):
            since = self._waiting_since
            if since is None or self._abort is not None:
                watching = None
                continue
            if since != watching:  # another wait: a clock of its own
                watching = since
                clock.reset()
            pid = self.controller_pid() if self.controller_pid is not None else None
            if pid is None:  # nothing to watch: the wall clock
                if time.perf_counter() - since > self.timeout and self._abort is None:
                    self._abort_as = ControllerHung
                    self._wake(f"no answer to {{what}} within {self.timeout:g} s")
                continue
            had = clock.update([cpu_sample(pid)] if pid else [None], since)
            if had > self.timeout and self._abort is None and self._waiting_since == since:
                self._abort_as = ControllerHung
                self._wake(
                    f"the controller `{self.controller}` (pid {pid}) could run for {had:.1f} s and did not answer "
                    f"{{what}} (timeouts.tick {self.timeout:g} s): hung"
                )

    def interrupt(self) -> None:
        """Make a waiting (or the next) tick raise LinkError: the host is stopping."""
        self._stopping = True
        self._abort_as = LinkError
        self._wake(STOPPING)

    def reset(self, msg: ControllerReset) -> None:
        """A new trial: drop what an earlier one left on the link, wait for the link to be up (a restarted
        controller's comes up with its process, within ``timeout``), then send the reset (a signed request whose
        nonce is the new trial's stream nonce) and wait for its reply as for a tick's command (the watchdog)."""
        if self._stopping:
            raise LinkError(f"interrupted: {STOPPING}")
        self._drop_stale()
        self.waiter.restart()
        self.nonce = os.urandom(bus.Seal.NONCE)
        if not self._link_up():
            raise LinkError(f"trial {msg.trial_id}: no lockstep link to `{self.controller}` within {self.timeout:g} s")
        self._abort, self._abort_as = None, LinkError
        watched = self.controller_pid is not None
        self._waiting_since = time.perf_counter()
        try:
            self._ask_reset(msg, WATCHED_WAIT if watched else self.timeout)
        finally:
            self._waiting_since = None

    def _ask_reset(self, msg: ControllerReset, wait: float) -> None:
        """Send the signed reset and wait for its reply, until the watchdog ends the wait, the controller answers
        (an error reply raises :class:`RemoteError`), or the query ends unanswered (the controller went away)."""
        nonce, payload = self.seal.seal_request(self.reset_key, encode(msg), self.nonce)
        replies: queue.SimpleQueue = queue.SimpleQueue()
        seal = self.seal

        def on_reply(reply: zenoh.Reply) -> None:  # in Zenoh's thread: only opens and hands over
            if reply.ok is not None:
                data = seal.open_reply(nonce, reply.ok.payload.to_bytes())
                if data is not None:
                    replies.put((True, data))
            else:
                text = seal.open_reply(nonce, reply.err.payload.to_bytes())
                if text is not None:  # not Zenoh's own "Timeout", nor a stranger's
                    replies.put((False, text))

        sent = time.monotonic()
        self.session.get(
            self.reset_key,
            zenoh.handlers.Callback(on_reply, lambda: replies.put(None), indirect=False),
            payload=payload,
            timeout=wait,
            target=zenoh.QueryTarget.ALL,
            consolidation=zenoh.ConsolidationMode.NONE,  # every reply as it comes: a stranger's cannot hold ours
        )
        while True:
            try:
                answer = replies.get(timeout=0.05)
            except queue.Empty:
                if self._abort is not None:
                    raise self._fault(f"the reset of trial {msg.trial_id}") from None
                continue
            if answer is None:
                waited = time.monotonic() - sent
                raise LinkError(
                    f"controller reset for trial {msg.trial_id}: no reply from {self.reset_key} after {waited:.2f} s"
                )
            ok, data = answer
            if ok:
                decode(data)
                return
            raise RemoteError(data.decode(errors="replace"))

    def _drop_stale(self) -> None:
        """Drop the commands (and wake-ups) an interrupted trial left on the link."""
        raise NotImplementedError

    def _link_up(self) -> bool:
        """Wait up to ``timeout`` for the link to the controller to be up; False if it is not."""
        raise NotImplementedError


class BusLink(TickLink):
    """A body's link to a controller in another process: lockstep pub/sub per tick.

    Frames and commands go over ``ticks``, the pair's lockstep link (:func:`bus.open_tick_session`;
    None: over the run's mesh, ``session``, as for a host started by hand); the reset request and the
    controller's liveliness over the mesh. A trial starts once the link is up (the controller's
    frame subscriber is matched), within ``timeout``.

    The body's thread publishes a frame and waits in the subscriber's ring channel for the
    command (no Python thread handoff on the tick path): it polls for up to ``spin`` seconds
    while that pays (:class:`SpinThenSleep`), then blocks. A body that may use one core only
    (pinned with its controller, ``sfl_brain.runtime.placement``) never polls. A watchdog thread wakes the body with
    an empty payload if a command is overdue, so a hung controller interrupts the trial after
    ``timeout`` seconds instead of blocking forever; a controller whose liveliness token goes
    away (it died) interrupts it at once.

    Every reset is a signed request whose nonce (8 random bytes) becomes the trial's stream
    nonce: it is appended to each frame and must end each command (a bytes compare per tick,
    no MAC), and a command must also carry the frame's trial and tick. Anything else is dropped
    and counted in ``drops``.
    """

    def __init__(
        self,
        session: zenoh.Session,
        run_id: str,
        body: str,
        controller: str,
        timeout: float,
        spin: float = 0.0,
        *,
        secret: str | None = None,
        drops: bus.Drops | None = None,
        ticks: zenoh.Session | None = None,
        controller_pid: Callable[[], int] | None = None,
        progress: Callable[[], None] | None = None,
    ) -> None:
        super().__init__(session, run_id, body, controller, timeout, spin, secret, drops, controller_pid, progress)
        self.ticks = ticks or session
        self.command_key = bus.key(run_id, body, MotorCommand.TAG)
        self.publisher = self.ticks.declare_publisher(bus.key(run_id, controller, SensorFrame.TAG))
        self.subscriber = self.ticks.declare_subscriber(self.command_key, zenoh.handlers.RingChannel(64))
        # the link is up when the controller's frame subscriber is matched
        self._linked = threading.Event()
        self._matching = self.publisher.declare_matching_listener(
            zenoh.handlers.Callback(self._on_matching, indirect=False)
        )
        if self.publisher.matching_status.matching:
            self._linked.set()
        self._start_watchdog()
        # the controller's signed liveliness tokens: when the one we saw goes away, it died
        self._controller_tokens: set[str] = set()
        self._liveliness = session.liveliness().declare_subscriber(
            bus.alive_key(run_id, controller, "*") if secret else bus.alive_key(run_id, controller),
            zenoh.handlers.Callback(self._on_controller_token, indirect=False),
            history=True,
        )

    def _on_controller_token(self, sample: zenoh.Sample) -> None:
        key_expr = str(sample.key_expr)
        if self.seal.secret:
            instance, proof = bus.parse_alive_key(key_expr)
            if instance != self.controller or self.seal.check_alive(self.run_id, instance, proof) is None:
                self.drops("unauthenticated", "liveliness token", key_expr)
                return
        if sample.kind == zenoh.SampleKind.PUT:
            self._controller_tokens.add(key_expr)
        elif key_expr in self._controller_tokens:
            self._controller_tokens.discard(key_expr)
            if self._waiting_since is not None and self._abort is None:
                self._wake(f"the controller `{self.controller}` went away at {{what}}")

    def _on_matching(self, status: zenoh.MatchingStatus) -> None:
        (self._linked.set if status.matching else self._linked.clear)()

    def _wake(self, reason: str) -> None:
        """End the waiting tick as :meth:`TickLink._wake`; an empty payload wakes recv()."""
        self._abort = reason
        if not self._closed.is_set():
            try:
                self.ticks.put(self.command_key, b"")
            except Exception:  # the session is already closing: nothing waits any more
                pass

    def _drop_stale(self) -> None:
        while self.subscriber.try_recv() is not None:
            pass

    def _link_up(self) -> bool:
        return self._linked.wait(self.timeout)  # the controller's frame subscriber is matched

    def step(self, frame: SensorFrame) -> MotorCommand:
        clock = time.perf_counter
        if not self._stopping:
            self._abort, self._abort_as = None, LinkError
        nonce = self.nonce
        self.publisher.put(encode(frame) + nonce)
        # the bookkeeping runs while the controller works on the frame, not before it is sent
        now = self._waiting_since = clock()
        spin = self.waiter.next_tick(now)
        subscriber = self.subscriber
        try:
            while True:
                sample = None
                if spin:
                    try_recv, deadline = subscriber.try_recv, now + self.waiter.budget
                    while (sample := try_recv()) is None and clock() < deadline:
                        pass
                    spin = False  # after a wake-up or a dropped message: sleep
                data = (sample if sample is not None else subscriber.recv()).payload.to_bytes()
                if self._abort is not None:
                    raise self._fault(f"tick {frame.tick}")
                if not data:
                    continue  # a late wake-up from an earlier tick
                command = check_command(data, frame, nonce, self.drops)
                if command is not None:
                    self.progress()
                    return command
        finally:
            self._waiting_since = None

    def close(self) -> None:
        self._closed.set()
        self._liveliness.undeclare()
        self._matching.undeclare()
        self.subscriber.undeclare()
        self.publisher.undeclare()


class SocketLink(TickLink):
    """A body's link to its controller process over their socket lockstep link (:mod:`sfl_brain.runtime.ticklink`,
    ``lockstep.link: socket``, the default where the OS has one): the body's thread sends a frame and
    blocks in ``recv`` for the command, two system calls and no thread in between.

    As :class:`BusLink`: every frame and command carries the trial's stream nonce, a command must answer
    the frame's trial and tick, and anything else is dropped and counted. A controller that dies closes
    its end of the socket, which ends the waiting tick at once (end of file; no liveliness token needed);
    the watchdog ends an overdue one. Either closes the link, and the next trial connects again (to a
    restarted controller: within ``timeout``)."""

    def __init__(
        self,
        session: zenoh.Session,
        run_id: str,
        body: str,
        controller: str,
        timeout: float,
        spin: float = 0.0,
        *,
        endpoint: str,
        secret: str | None = None,
        drops: bus.Drops | None = None,
        controller_pid: Callable[[], int] | None = None,
        progress: Callable[[], None] | None = None,
    ) -> None:
        super().__init__(session, run_id, body, controller, timeout, spin, secret, drops, controller_pid, progress)
        self.channel = ticklink.Channel(endpoint)
        self._start_watchdog()

    def _wake(self, reason: str) -> None:
        self._abort = reason
        self.channel.wake()

    def _drop_stale(self) -> None:
        self.channel.drain()  # and a link whose controller went away is closed: it connects again below

    def _link_up(self) -> bool:
        return self.channel.connected or self.channel.connect(self.timeout, lambda: self._stopping)

    def step(self, frame: SensorFrame) -> MotorCommand:
        clock, channel = time.perf_counter, self.channel
        if self._stopping:  # interrupt() sets it before it wakes: a wake that found no socket is not lost
            raise LinkError(f"interrupted: {STOPPING}")
        self._abort, self._abort_as = None, LinkError
        nonce = self.nonce
        try:
            channel.send(encode(frame) + nonce)
            now = self._waiting_since = clock()  # after the send: the controller works meanwhile
            spin = self.waiter.next_tick(now)
            while True:
                data = None
                if spin:
                    deadline = now + self.waiter.budget
                    while (data := channel.try_recv()) is None and clock() < deadline:
                        pass
                    spin = False
                if data is None:
                    data = channel.recv()
                if len(data) > ticklink.MAX_MESSAGE:
                    self.drops("malformed", "command", f"over {ticklink.MAX_MESSAGE} B")
                    continue
                command = check_command(data, frame, nonce, self.drops)
                if command is not None:
                    self.progress()
                    return command
        except ticklink.LinkClosed:
            if self._abort is not None:
                raise self._fault(f"tick {frame.tick}") from None
            why = f"the lockstep link to `{self.controller}` closed at tick {frame.tick} (it went away)"
            raise LinkError("interrupted: " + why) from None
        finally:
            self._waiting_since = None

    def close(self) -> None:
        self._closed.set()
        self.channel.close()


class RemoteError(RuntimeError):
    """A module answered a request with an error, or nobody answered."""


class NoReply(RemoteError):
    """Nobody answered a request within its timeout."""


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


def make_telemetry(
    rec,
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
    computed to be shown)."""
    if rec is None:
        return None
    from ..recording.rerun_sink import RerunTelemetry
    from ..recording.tables import MapTable

    rates = Rates.from_record(record)
    table = MapTable(run_dir / "maps" / f"{part}.parquet", module=module.entity) if run_dir is not None else None
    rerun = RerunTelemetry(rec, module.entity, rates, trial_seconds, batch_seconds=2.0 if live else None)
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
        spec = self.spec
        self.module = make_module(spec["reference"], spec["params"], spec["seed"], spec["spec_name"])
        self.module.run_dir = self.run_dir  # where the module may write files (None: anywhere)
        self.session = bus.open_session(
            spec["listen"],
            spec["connect"],
            zenoh_config=spec.get("zenoh_config"),
            lease_ms=spec.get("lease_ms", bus.LEASE_MS),
        )
        declared = []
        streams: list[tuple[str, Any, threading.Thread]] = []
        rec = None
        sinks = []  # telemetry sinks to close at exit (after their modules)
        controller = None  # a controller hosted in this body worker
        server = None  # a controller's end of a socket lockstep link
        ticks = self.session
        try:
            # a body worker and its controller process: their lockstep link ({"listen": ...} for the
            # controller, {"connect": ...} for the body), or the mesh when the spec names none
            tick = spec.get("tick") or {}
            ends = [f"listening on {e}" for e in tick.get("listen", [])] + [
                f"connecting to {e}" for e in tick.get("connect", [])
            ]
            listen_end = next((e for e in tick.get("listen", []) if ticklink.is_socket(e)), None)
            connect_end = next((e for e in tick.get("connect", []) if ticklink.is_socket(e)), None)
            socket_end = listen_end or connect_end
            if socket_end is not None:  # lockstep.link: socket (sfl_brain.runtime.ticklink)
                log.info("lockstep link (socket): %s", ", ".join(ends))
            elif tick:  # lockstep.link: zenoh
                self.ticks = ticks = bus.open_tick_session(tick.get("listen", []), tick.get("connect", []))
                log.info("lockstep link (lowlatency): %s", ", ".join(ends))
            rec = make_recording(self.run_id, spec.get("rrd"), spec.get("viewer"))
            live = bool(spec.get("viewer"))
            seconds = spec.get("trial_seconds")
            self.module.telemetry = make_telemetry(
                rec, self.module, spec.get("record"), self.run_dir, self.instance, live, seconds
            )
            sinks.append(self.module.telemetry)
            if isinstance(self.module, Body):
                self.module.worker = self.instance
                self.module.realtime = bool(spec.get("realtime"))
                colocated = spec.get("colocated")
                if colocated:
                    controller = make_module(
                        colocated["reference"], colocated["params"], colocated["seed"], colocated["spec_name"]
                    )
                    controller.telemetry = make_telemetry(
                        rec, controller, spec.get("record"), self.run_dir, f"{self.instance}.controller", live, seconds
                    )
                    sinks.append(controller.telemetry)
                    self.module.link = CountedLink(controller, self.progress)
                elif self.module.COMMANDS and connect_end is not None:
                    self.link = SocketLink(
                        self.session,
                        self.run_id,
                        self.instance,
                        spec["routes"][SensorFrame.TAG],
                        spec["tick_timeout"],
                        spec.get("spin", 0.0),
                        endpoint=connect_end,
                        secret=spec.get("secret"),
                        drops=self.drops,
                        controller_pid=self.controller_pid(),
                        progress=self.progress,
                    )
                    self.module.link = self.link
                elif self.module.COMMANDS:
                    self.link = BusLink(
                        self.session,
                        self.run_id,
                        self.instance,
                        spec["routes"][SensorFrame.TAG],
                        spec["tick_timeout"],
                        spec.get("spin", 0.0),
                        secret=spec.get("secret"),
                        drops=self.drops,
                        ticks=self.ticks,
                        controller_pid=self.controller_pid(),
                        progress=self.progress,
                    )
                    self.module.link = self.link
            for message_type in type(self.module).handles:
                key_expr = bus.key(self.run_id, self.instance, message_type.TAG)
                if message_type.STREAM and listen_end is not None:  # a thread per connection blocks in recv()
                    if server is not None:
                        raise ValueError(f"{self.instance}: a socket lockstep link carries one stream message type")
                    answer = functools.partial(self._stream_answer, message_type, decoder_for(message_type))
                    server = ticklink.Server(
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
                    streams.append((key_expr, subscriber, thread))
                else:
                    callback = zenoh.handlers.Callback(self._enqueue, indirect=False)
                    declared.append(self.session.declare_queryable(key_expr, callback))
            proof = self.seal.alive_proof(self.run_id, self.instance, spec.get("nonce") or os.urandom(8).hex())
            token = self.session.liveliness().declare_token(bus.alive_key(self.run_id, self.instance, proof))
            log.info("%s ready (%s)", self.instance, spec["reference"])
            self._loop()
            token.undeclare()
        finally:
            self._stopping = True
            if server is not None:
                server.close()
            for key_expr, subscriber, thread in streams:
                ticks.put(key_expr, b"")  # wakes the stream thread, which sees _stopping
                thread.join(timeout=2.0)
                if not thread.is_alive():
                    subscriber.undeclare()
            for d in declared:
                d.undeclare()
            if self.link is not None:
                self.link.close()
            for p in self._publishers.values():
                p.undeclare()
            self.module.close()
            if controller is not None:
                controller.close()  # its last logged trial's neurons
            for sink in sinks:
                if sink is not None:
                    sink.close()
            if rec is not None:
                from ..recording.rrlog import close_recording

                problem = close_recording(rec)
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
            reply = self.module.handle(msg, checked=True)
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
