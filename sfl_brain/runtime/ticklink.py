"""The socket lockstep link: a body worker and its controller process exchange their ticks over a Unix
socket of their own, two system calls per message, no thread in between.

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
import socket
import sys
import threading
import time
from collections.abc import Callable
from pathlib import Path

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
