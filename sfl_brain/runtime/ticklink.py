"""The lockstep tick link: a body worker and its controller process exchange their ticks over a Unix socket of
their own, two system calls per message, no thread in between (or over a Zenoh session of their own).

The socket's two ends are :class:`Channel` (the body's) and :class:`Server` (the controller's host's); the body's
end of a link over either transport is a :class:`TickLink`: :class:`SocketLink` over the socket, :class:`BusLink`
over Zenoh, with the same reset, nonce checks and time-outs (:class:`LinkError`, :class:`ControllerHung`).

Why not Zenoh for these two keys: a lockstep tick is a chain of hand-overs (frame out, frame in,
command out, command in), and the hand-over is most of its cost. Over a Zenoh session each message
wakes Zenoh's receiving thread, which then wakes the Python thread that waits for it: four wake-ups
a tick where a socket read by the waiting thread itself takes two. Measured side by side on this
project's 2-core VM (``benchmarks/bus.py``, ``benchmarks/planar.py``, ``docs/results/benchmarks.md``),
two processes taking turns on one core cost 1.08-1.35x one process over a pipe or this socket and
1.8-2.0x over Zenoh's lowlatency transport. So, as dora-rs nodes reach their daemon over shared
memory or a local socket and daemons on other machines talk over Zenoh, the per-tick frames and
commands of a pair on one machine take this socket, and everything else (requests, replies,
liveliness, the run secret's checks, workers on other machines) stays on the run's Zenoh mesh.
``lockstep.link: zenoh`` puts the ticks back on a Zenoh session of their own
(:func:`sfl_brain.runtime.bus.open_tick_session`).

The socket is ``SOCK_SEQPACKET`` (a message is read whole, in order, connection-oriented: the end of
the other process is seen at once as end of file). It lives in a folder only this user may enter
(``sfl run`` makes it with ``mkdtemp``), so only this user's processes can connect; what they send
is checked as any tick is (the trial's stream nonce, then trial and tick), and what fails is
dropped and counted. The controller's end (:class:`Server`) listens and answers each connection in a
thread of its own that blocks in ``recv``; the body's end (:class:`Channel`) connects, sends a frame
and blocks in ``recv`` for the command. Linux only (``SOCK_SEQPACKET`` on Unix sockets); elsewhere
``sfl run`` falls back to the Zenoh link.

This module is part of the runtime: brain modules and bodies never see it.
"""

from __future__ import annotations

import logging
import os
import queue
import socket
import statistics
import sys
import threading
import time
from collections.abc import Callable
from pathlib import Path

import zenoh

from ..messages import (
    ControllerReset,
    MessageError,
    MotorCommand,
    SensorFrame,
    decode,
    decoder_for,
    encode,
)
from . import bus
from .liveness import NoProgressClock, cpu_sample
from .placement import usable_cpus

log = logging.getLogger("sfl.ticklink")

#: the scheme of a socket link's endpoint in a host spec (``seqpacket/<path>``)
SCHEME = "seqpacket/"

#: the largest tick message (a frame or a command with its nonce); a longer one is dropped as malformed
MAX_MESSAGE = 65536

#: connections a controller's end serves at once (its body's, and a few of other processes of this user: see Server)
MAX_CONNECTIONS = 8

#: how often a connecting end tries again while the listening end is not there yet (a restart)
RETRY_S = 0.01


def available() -> bool:
    """True where a socket link can be made: Linux, whose Unix sockets have ``SOCK_SEQPACKET`` and whose
    ``shutdown`` wakes a thread blocked in ``accept`` or ``recv`` (what :meth:`Server.close` and
    :meth:`Channel.wake` rely on; not checked elsewhere)."""
    if not sys.platform.startswith("linux") or not hasattr(socket, "SOCK_SEQPACKET"):
        return False
    try:
        socket.socket(socket.AF_UNIX, socket.SOCK_SEQPACKET).close()
    except OSError:
        return False
    return True


def endpoint(folder: str | Path, pair: str) -> str:
    """The socket link's endpoint for pair ``pair``: a Unix socket in ``folder``."""
    return f"{SCHEME}{Path(folder) / pair}.sock"


def is_socket(endpoint: str) -> bool:
    return endpoint.startswith(SCHEME)


def path_of(endpoint: str) -> str:
    return endpoint[len(SCHEME) :]


class LinkClosed(ConnectionError):
    """The other end went away, or the link was woken (:meth:`Channel.wake`)."""


class Channel:
    """The body's end: connects to the controller's socket, sends a frame, waits for the command."""

    def __init__(self, endpoint: str) -> None:
        self.path = path_of(endpoint)
        self.sock: socket.socket | None = None
        self._lock = threading.Lock()  # wake() from another thread against connect/close

    @property
    def connected(self) -> bool:
        return self.sock is not None

    def connect(self, timeout: float, stopping: Callable[[], bool] = lambda: False) -> bool:
        """Connect within ``timeout`` seconds (trying again every 10 ms while nobody listens: the
        controller is still starting, or restarting); False if it did not."""
        deadline = time.monotonic() + timeout
        while not stopping():
            sock = socket.socket(socket.AF_UNIX, socket.SOCK_SEQPACKET)
            # a full backlog (a controller that does not accept: stopped, or hung holding the GIL) would block
            # connect() for good: it gets the time left, and counts as not listening
            sock.settimeout(max(deadline - time.monotonic(), RETRY_S))
            try:
                sock.connect(self.path)
            except (FileNotFoundError, ConnectionRefusedError, TimeoutError, BlockingIOError):
                sock.close()
                if time.monotonic() >= deadline:
                    return False
                time.sleep(RETRY_S)
                continue
            sock.settimeout(None)
            with self._lock:
                self.sock = sock
            return True
        return False

    def drain(self) -> bool:
        """Drop what waits to be read (late commands of an interrupted trial); False if the other end
        has gone (the link is then closed) or there is no link."""
        try:
            while self.try_recv() is not None:
                pass
        except LinkClosed:
            return False
        return True

    def send(self, data: bytes) -> None:
        if len(data) > MAX_MESSAGE:
            raise ValueError(
                f"a lockstep message of {len(data)} B is over the socket link's {MAX_MESSAGE} B: "
                "fewer sensors, or the controller in the body worker (colocate: true)"
            )
        try:
            self.sock.send(data)  # type: ignore[union-attr]
        except (OSError, AttributeError):
            self.close()
            raise LinkClosed("the link is closed") from None

    def recv(self, flags: int = 0) -> bytes | None:
        """The next message; blocks (with ``flags`` ``socket.MSG_DONTWAIT``: None if none is there yet).
        Raises LinkClosed at the other end's end (or a wake)."""
        try:
            data = self.sock.recv(MAX_MESSAGE + 1, flags)  # type: ignore[union-attr]
        except BlockingIOError:
            return None
        except (OSError, AttributeError):
            data = b""
        if not data:
            self.close()
            raise LinkClosed("the link is closed")
        return data  # over MAX_MESSAGE: cut short, and then refused by the caller's checks (no nonce at its end)

    def try_recv(self) -> bytes | None:
        """The next message if one is there (None if not); raises LinkClosed as :meth:`recv`."""
        return self.recv(socket.MSG_DONTWAIT)

    def wake(self) -> None:
        """Make a waiting :meth:`recv` (from another thread) return at once with LinkClosed; the link
        is then closed, and the next trial connects again."""
        with self._lock:
            sock = self.sock
            if sock is not None:
                try:
                    sock.shutdown(socket.SHUT_RDWR)
                except OSError:
                    pass

    def close(self) -> None:
        with self._lock:
            sock, self.sock = self.sock, None
        if sock is not None:
            sock.close()


class Server:
    """The controller's end: listens on the socket and answers every message of every connection
    with ``answer(data)`` (bytes to send back, or None), one thread per connection, blocking in
    ``recv``. A message over :data:`MAX_MESSAGE` bytes goes to ``on_oversized``.

    At most :data:`MAX_CONNECTIONS` connections are served at once. A connection proves itself by a
    message that ``answer`` replies to (a frame with the trial's nonce: only the body has it). When
    all slots are taken, a new connection closes the oldest one that has not proved itself (counted
    by ``on_refused``): idle connections of another process of this user cannot lock the body out,
    whose connection is new at each restart or reconnect. Only when every slot has proved itself is
    the new one refused."""

    def __init__(
        self,
        endpoint: str,
        answer: Callable[[bytes], bytes | None],
        *,
        on_refused: Callable[[], None] = lambda: None,
        on_oversized: Callable[[int], None] = lambda n: None,
    ) -> None:
        self.path = path_of(endpoint)
        self.answer = answer
        self.on_refused = on_refused
        self.on_oversized = on_oversized
        try:
            os.unlink(self.path)  # left by a controller process that died (this one is its restart)
        except FileNotFoundError:
            pass
        self.listener = socket.socket(socket.AF_UNIX, socket.SOCK_SEQPACKET)
        self.listener.bind(self.path)
        self.listener.listen(MAX_CONNECTIONS)
        self._closing = False
        self._lock = threading.Lock()
        self._connections: dict[socket.socket, bool] = {}  # in the order they came; True: proved itself
        self._threads: list[threading.Thread] = []
        self._acceptor = threading.Thread(target=self._accept, name="ticklink-accept", daemon=True)
        self._acceptor.start()

    def _accept(self) -> None:
        while True:
            try:
                conn, _ = self.listener.accept()
            except OSError:  # closed (shutdown wakes accept with EINVAL)
                return
            try:
                self._admit(conn)
            except Exception:  # never die silently: later connections would wait in the backlog for good
                log.exception("lockstep link %s: could not serve a connection", self.path)
                conn.close()
            if self._closing:
                return

    def _admit(self, conn: socket.socket) -> None:
        with self._lock:
            if self._closing:
                conn.close()
                return
            if len(self._connections) >= MAX_CONNECTIONS:
                unproven = next((c for c, proved in self._connections.items() if not proved), None)
                self.on_refused()
                if unproven is None:
                    conn.close()
                    return
                del self._connections[unproven]
                try:
                    unproven.shutdown(socket.SHUT_RDWR)  # its thread returns and closes it
                except OSError:
                    pass
            self._connections[conn] = False
            thread = threading.Thread(target=self._serve, args=(conn,), name="ticklink-serve", daemon=True)
            self._threads = [t for t in self._threads if t.is_alive()] + [thread]
        thread.start()

    def _serve(self, conn: socket.socket) -> None:
        recv, send, answer, limit = conn.recv, conn.send, self.answer, MAX_MESSAGE
        proved = False
        try:
            while True:
                try:
                    data = recv(limit + 1)
                except OSError:
                    return
                if not data or self._closing:
                    return
                if len(data) > limit:
                    self.on_oversized(len(data))
                    continue
                reply = answer(data)
                if reply is not None:
                    try:
                        send(reply)
                    except OSError:
                        return
                    if not proved:
                        proved = True
                        with self._lock:
                            if conn in self._connections:
                                self._connections[conn] = True
        finally:
            with self._lock:
                self._connections.pop(conn, None)
            conn.close()

    def close(self, timeout: float = 2.0) -> None:
        """Stop listening, end every connection (their threads return), remove the socket file."""
        with self._lock:
            self._closing = True
            connections = list(self._connections)
            threads = list(self._threads)
        for sock in (self.listener, *connections):
            try:
                sock.shutdown(socket.SHUT_RDWR)
            except OSError:
                pass
        self._acceptor.join(timeout)
        for thread in threads:
            thread.join(timeout)
        self.listener.close()
        try:
            os.unlink(self.path)
        except OSError:
            pass


# ---------------------------------------------------------------- the body's end of a tick link, over either transport
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
#: s: how long a reset query that ends unanswered at once (no controller's queryable matched yet) is asked again
#: before the controller counts as gone; a restarted controller's queryable reaches the body's session within it
RESET_DISCOVERY = 2.0


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
        spin: float = 0.0,
        *,
        secret: str | None = None,
        drops: bus.Drops | None = None,
        controller_pid: Callable[[], int] | None = None,
        progress: Callable[[], None] | None = None,
        **transport,
    ) -> None:
        """``transport``: what the subclass's :meth:`_open` takes (``ticks=`` for :class:`BusLink`,
        ``endpoint=`` for :class:`SocketLink`)."""
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
        self._open(body, **transport)
        threading.Thread(target=self._watch, name="ticklink-watchdog", daemon=True).start()

    def _open(self, body: str) -> None:
        """Open the body's end of the link to the controller (``body``: its instance name)."""
        raise NotImplementedError

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
        (an error reply raises :class:`~.bus.RemoteError`), or the query ends unanswered (the controller went away)."""
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

        def ask() -> None:
            self.session.get(
                self.reset_key,
                zenoh.handlers.Callback(on_reply, lambda: replies.put(None), indirect=False),
                payload=payload,
                timeout=wait,
                target=zenoh.QueryTarget.ALL,
                consolidation=zenoh.ConsolidationMode.NONE,  # every reply as it comes: a stranger's cannot hold ours
            )

        sent = time.monotonic()
        ask()
        while True:
            try:
                answer = replies.get(timeout=0.05)
            except queue.Empty:
                if self._abort is not None:
                    raise self._fault(f"the reset of trial {msg.trial_id}") from None
                continue
            if answer is None:
                waited = time.monotonic() - sent
                if waited < min(wait, RESET_DISCOVERY):
                    # ended at once with no answer: no queryable matched yet. A restarted controller's link can be up
                    # before its reset queryable reaches this session; nobody got the reset, so it is asked again
                    time.sleep(0.02)
                    ask()
                    continue
                raise LinkError(
                    f"controller reset for trial {msg.trial_id}: no reply from {self.reset_key} after {waited:.2f} s"
                )
            ok, data = answer
            if ok:
                decode(data)
                return
            raise bus.RemoteError(data.decode(errors="replace"))

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

    def _open(self, body: str, ticks: zenoh.Session | None = None) -> None:
        """Publish frames and take commands on ``ticks`` (None: the mesh), and follow the controller's liveliness."""
        run_id, controller = self.run_id, self.controller
        self.ticks = ticks or self.session
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
        # the controller's signed liveliness tokens: when the one we saw goes away, it died
        self._controller_tokens: set[str] = set()
        self._liveliness = self.session.liveliness().declare_subscriber(
            bus.alive_key(run_id, controller, "*") if self.seal.secret else bus.alive_key(run_id, controller),
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

    def _open(self, body: str, endpoint: str) -> None:
        """The body's end of the pair's socket (it connects at the first reset)."""
        self.channel = Channel(endpoint)

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
                if len(data) > MAX_MESSAGE:
                    self.drops("malformed", "command", f"over {MAX_MESSAGE} B")
                    continue
                command = check_command(data, frame, nonce, self.drops)
                if command is not None:
                    self.progress()
                    return command
        except LinkClosed:
            if self._abort is not None:
                raise self._fault(f"tick {frame.tick}") from None
            why = f"the lockstep link to `{self.controller}` closed at tick {frame.tick} (it went away)"
            raise LinkError("interrupted: " + why) from None
        finally:
            self._waiting_since = None

    def close(self) -> None:
        self._closed.set()
        self.channel.close()
