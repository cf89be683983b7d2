"""Zenoh plumbing: session configuration, key expressions, the run secret, and drop counters.

Every key the framework uses is built here:

* ``sfl/<run_id>/<instance>/<tag>``: messages for one module instance;
* ``sfl/<run_id>/@alive/<instance>/<proof>``: liveliness token of a running module (``<proof>``
  shows that its owner holds the run secret; no ``/<proof>`` for a host started without one).

Sessions listen and connect on 127.0.0.1 with multicast scouting off unless the
user passes other endpoints; peers find each other by gossip through the first
endpoint, so the mesh is direct between every pair of processes.

A body worker and its controller process exchange their per-tick frames and commands on a link of
their own, apart from the mesh: a Unix socket (:mod:`sfl_brain.runtime.ticklink`, ``lockstep.link: socket``,
the default), or :func:`open_tick_session` (Zenoh's lowlatency transport over a Unix socket,
``lockstep.link: zenoh``).

A run has a secret (:class:`Seal`): requests and replies carry a keyed MAC, liveliness tokens
a proof, and lockstep frames the current trial's nonce (see ``docs/wire.md``); what lacks them is
dropped and counted. Transport authentication and encryption (TLS, Zenoh user/password) are the
user's, through a Zenoh config file (:func:`open_session` says why not the secret by default).
"""

from __future__ import annotations

import errno
import hashlib
import hmac
import json
import logging
import os
import socket
import threading
from pathlib import Path

import zenoh

from ..status import EnvironmentProblem

#: keep-alive lease of a process on another machine (``sfl worker``; ``timeouts.lease``, in ms): its peers declare it
#: gone after this long without a word from it. A session declares its own lease, and its peers judge it by it.
LEASE_MS = 3000

#: the lease of every process of a run on its own machine (the supervisor and its module processes): a day. A
#: process that exits is seen at once (its closed sockets, its exit), so the lease would only catch one that is
#: stopped, starved or hung, and those are told apart by their progress and CPU (:mod:`.liveness`), not by
#: silence. With a lease of seconds, a module stopped (SIGSTOP) or starved for longer lost every link and every
#: request in flight, and on resuming dropped its own links to peers it had not heard from meanwhile (issue 34).
LOCAL_LEASE_MS = 24 * 3600 * 1000

#: Zenoh's async runtimes (``ZENOH_RUNTIME``, RON): all handed over to the transmit runtime's one
#: worker thread, instead of 2 receive workers and a thread each for transmit, accept, network and
#: application tasks. A lockstep tick is a chain of thread wake-ups (frame out, frame in, command out,
#: command in), and fewer threads to wake cost less on 2 cores: the body<->controller round trip of
#: benchmarks/bus.py went from 83-131 us to 65-95 us (medians, same load side by side), the raw Zenoh
#: ping-pong with it; a planar trial over processes gained ~5%. A ``ZENOH_RUNTIME`` of the user's is kept.
RUNTIME = "(rx: (handover: tx), acc: (handover: tx), app: (handover: tx), net: (handover: tx))"

#: how soon a lockstep link's connecting end tries again after its other end went away (a restart)
TICK_RETRY = {"period_init_ms": 10, "period_max_ms": 200, "period_increase_factor": 2}


def key(run_id: str, instance: str, tag: str) -> str:
    return f"sfl/{run_id}/{instance}/{tag}"


def alive_key(run_id: str, instance: str = "*", proof: str | None = None) -> str:
    """The liveliness key of ``instance``; ``proof`` (see :meth:`Seal.alive_proof`) is one more chunk."""
    return f"sfl/{run_id}/@alive/{instance}" + (f"/{proof}" if proof else "")


def parse_alive_key(key_expr) -> tuple[str, str | None]:
    """(instance, proof or None) of a liveliness key; anything after the proof makes it ('', None)."""
    parts = str(key_expr).split("/")
    try:
        rest = parts[parts.index("@alive") + 1 :]
    except ValueError:
        return "", None
    if len(rest) == 1:
        return rest[0], None
    if len(rest) == 2:
        return rest[0], rest[1]
    return "", None


def instance_from_alive_key(key_expr) -> str:
    return parse_alive_key(key_expr)[0]


def free_endpoint(host: str = "127.0.0.1") -> str:
    """A TCP endpoint on a free loopback port."""
    with socket.socket() as s:
        s.bind((host, 0))
        return f"tcp/{host}:{s.getsockname()[1]}"


def check_listen(endpoints: list[str]) -> None:
    """Raise EnvironmentProblem (one line) if a ``tcp/HOST:PORT`` endpoint cannot be bound."""
    for ep in endpoints:
        proto, _, address = ep.partition("/")
        if proto != "tcp" or ":" not in address:
            continue
        host, _, port = address.rpartition(":")
        host = host.strip("[]")
        try:
            port_n = int(port.split("#")[0])
        except ValueError:
            continue
        if port_n == 0:
            continue
        family = socket.AF_INET6 if ":" in host else socket.AF_INET
        with socket.socket(family, socket.SOCK_STREAM) as s:
            s.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)  # as Zenoh does: TIME_WAIT is fine
            try:
                s.bind((host, port_n))
            except OSError as exc:
                why = "port in use" if exc.errno == errno.EADDRINUSE else (exc.strerror or str(exc))
                raise EnvironmentProblem(f"cannot listen on {ep}: {why}") from None


def config(
    listen: list[str] | None = None,
    connect: list[str] | None = None,
    *,
    zenoh_config: str | Path | None = None,
    lease_ms: int = LEASE_MS,
) -> zenoh.Config:
    """A peer configuration: loopback, multicast scouting off, this session's lease (ms: how long its peers wait
    for a word from it).

    ``zenoh_config`` (a JSON5 file: TLS, user/password, ...) is loaded first and our settings go
    on top of it."""
    conf = zenoh.Config.from_file(str(zenoh_config)) if zenoh_config else zenoh.Config()
    conf.insert_json5("mode", '"peer"')
    conf.insert_json5("listen/endpoints", json.dumps(listen if listen is not None else ["tcp/127.0.0.1:0"]))
    conf.insert_json5("connect/endpoints", json.dumps(connect or []))
    conf.insert_json5("scouting/multicast/enabled", "false")
    conf.insert_json5("transport/link/tx/lease", str(int(lease_ms)))
    conf.insert_json5("transport/link/tx/keep_alive", "4")
    return conf


def tick_endpoint(folder: str | Path, pair: str) -> str:
    """The lockstep link's endpoint for pair ``pair``: a Unix socket in ``folder`` (a folder only this
    user may enter, so that only this user's processes can connect)."""
    return f"unixsock-stream/{Path(folder) / pair}.sock"


def tick_config(listen: list[str], connect: list[str], lease_ms: int = LOCAL_LEASE_MS) -> zenoh.Config:
    """The configuration of a lockstep link (see :func:`open_tick_session`)."""
    conf = zenoh.Config()
    conf.insert_json5("mode", '"peer"')
    conf.insert_json5("listen/endpoints", json.dumps(listen))
    conf.insert_json5("connect/endpoints", json.dumps(connect))
    conf.insert_json5("scouting/multicast/enabled", "false")
    conf.insert_json5("scouting/gossip/enabled", "false")  # the two ends only: never part of the run's mesh
    conf.insert_json5("scouting/delay", "0")  # open at once, whether the other end listens yet or not
    conf.insert_json5("connect/retry", json.dumps(TICK_RETRY))
    conf.insert_json5("transport/unicast/lowlatency", "true")
    conf.insert_json5("transport/unicast/qos/enabled", "false")  # lowlatency needs QoS off, at both ends
    conf.insert_json5("transport/link/tx/lease", str(int(lease_ms)))
    conf.insert_json5("transport/link/tx/keep_alive", "4")
    return conf


def open_tick_session(listen: list[str], connect: list[str], lease_ms: int = LOCAL_LEASE_MS) -> zenoh.Session:
    """A lockstep link: a Zenoh session of its own between a body worker and its controller process,
    carrying only their per-tick frames and commands.

    Zenoh's lowlatency transport (``transport/unicast/lowlatency``, QoS off at both ends) writes each
    message to the socket as it is put, instead of handing it to a batching pipeline that another
    thread drains: fewer wake-ups per tick (``benchmarks/bus.py``). It has no fragmentation: a
    message over one batch (64 KiB) would be dropped when shared memory does not carry it, so the
    run's requests, replies and liveliness (any size) stay on the run's mesh, and only frames and
    commands (under 1 KiB) take this link. The controller's end listens on a Unix socket in a folder
    only this user may enter (``tick_endpoint``); the body's end connects (and connects again within
    :data:`TICK_RETRY` after a restart). No gossip: the link is never part of the mesh."""
    os.environ.setdefault("ZENOH_RUNTIME", RUNTIME)
    return zenoh.open(tick_config(listen, connect, lease_ms))


def open_session(
    listen: list[str] | None = None,
    connect: list[str] | None = None,
    *,
    zenoh_config: str | Path | None = None,
    lease_ms: int = LEASE_MS,
) -> zenoh.Session:
    """Open a peer session (loopback, no multicast scouting), with the user's Zenoh config under ours; ``lease_ms``:
    how long its peers wait for a word from it (:data:`LOCAL_LEASE_MS` for the processes of a run on its machine).

    The run secret is not used as a Zenoh transport password: with ``transport/auth/usrpwd``, peers
    that find each other by gossip and connect both ways are refused (``Close(INVALID)``, zenoh issue
    #2577), and a mesh then misses links at random (seen here: a joining peer reached 2 of 4 modules
    in about one try in three). A run authenticates its members itself (:class:`Seal`); transport
    authentication and encryption (TLS, or user/password on links that connect one way) are the
    user's, through ``zenoh_config`` (``docs/reliability.md``)."""
    # read once per process, when Zenoh starts its runtimes (the first session): set it before that
    os.environ.setdefault("ZENOH_RUNTIME", RUNTIME)
    return zenoh.open(config(listen, connect, zenoh_config=zenoh_config, lease_ms=lease_ms))


def new_secret() -> str:
    import secrets

    return secrets.token_hex(16)


def read_secret(env: str = "SFL_RUN_SECRET", path: str | Path | None = None) -> str | None:
    """A run secret from a file (first line) or the environment variable ``env``."""
    if path:
        return Path(path).read_text().strip() or None
    return os.environ.get(env) or None


class Seal:
    """Sign and check what members of one run send each other, with the run secret.

    * A request is ``nonce (8 bytes) | MAC (16) | payload``; the MAC (keyed BLAKE2b) covers the
      key expression, the nonce and the payload, so a request cannot be moved to another module.
    * A reply (also an error reply) is ``MAC (16) | payload``, the MAC over the request's nonce
      and the payload: a reply answers one request only.
    * A liveliness token's proof is ``<nonce>-<MAC of run id, instance, nonce>``.

    Without a secret (a host started by hand, the benchmarks) the key is empty: the format is the
    same, but anyone can sign."""

    NONCE = 8
    MAC = 16

    def __init__(self, secret: str | None) -> None:
        self.secret = secret
        self.key = secret.encode() if secret else b""

    def _mac(self, *parts: bytes) -> bytes:
        h = hashlib.blake2b(key=self.key, digest_size=self.MAC)
        for p in parts:
            h.update(len(p).to_bytes(4, "little"))
            h.update(p)
        return h.digest()

    def seal_request(self, key_expr: str, payload: bytes, nonce: bytes | None = None) -> tuple[bytes, bytes]:
        """(nonce, sealed payload) of a request to ``key_expr``."""
        nonce = nonce or os.urandom(self.NONCE)
        return nonce, nonce + self._mac(b"request", str(key_expr).encode(), nonce, payload) + payload

    def open_request(self, key_expr: str, data: bytes) -> tuple[bytes, bytes] | None:
        """(nonce, payload) of a sealed request, or None if it is not signed with this secret."""
        head = self.NONCE + self.MAC
        if len(data) < head:
            return None
        nonce, mac, payload = data[: self.NONCE], data[self.NONCE : head], data[head:]
        if not hmac.compare_digest(mac, self._mac(b"request", str(key_expr).encode(), nonce, payload)):
            return None
        return nonce, payload

    def seal_reply(self, nonce: bytes, payload: bytes) -> bytes:
        return self._mac(b"reply", nonce, payload) + payload

    def open_reply(self, nonce: bytes, data: bytes) -> bytes | None:
        if len(data) < self.MAC:
            return None
        mac, payload = data[: self.MAC], data[self.MAC :]
        if not hmac.compare_digest(mac, self._mac(b"reply", nonce, payload)):
            return None
        return payload

    def alive_proof(self, run_id: str, instance: str, nonce: str) -> str | None:
        """The last chunk of ``instance``'s liveliness key; None without a secret (no chunk)."""
        if not self.secret:
            return None
        return f"{nonce}-{self._mac(b'alive', run_id.encode(), instance.encode(), nonce.encode()).hex()}"

    def check_alive(self, run_id: str, instance: str, proof: str | None) -> str | None:
        """The nonce of a valid proof, or None (forged, or no proof)."""
        if not proof or "-" not in proof or not instance:
            return None
        nonce, _, mac = proof.partition("-")
        expected = self._mac(b"alive", run_id.encode(), instance.encode(), nonce.encode()).hex()
        return nonce if hmac.compare_digest(mac.encode(), expected.encode()) else None


#: why a message was dropped
DROP_REASONS = ("unauthenticated", "malformed", "stale", "foreign")


class Drops:
    """Counts of dropped messages by reason; each reason (and detail kind) is logged once, not per message."""

    def __init__(self, logger: logging.Logger, who: str) -> None:
        self.log = logger
        self.who = who
        self.counts: dict[str, int] = {}
        self._logged: set[tuple[str, str]] = set()
        self._lock = threading.Lock()
        self._write_lock = threading.Lock()

    def __call__(self, reason: str, what: str, detail: str = "") -> None:
        with self._lock:
            self.counts[reason] = self.counts.get(reason, 0) + 1
            first = (reason, what) not in self._logged
            self._logged.add((reason, what))
        if first:
            self.log.warning(
                "%s: dropped %s %s%s (further drops of this kind are counted, not logged)",
                self.who,
                reason,
                what,
                f": {detail}" if detail else "",
            )

    def write(self, path: Path) -> None:
        """Write the counts to ``path`` (whole: a temporary file, then renamed), from any thread."""
        with self._write_lock:  # two writers (a stop, the end) never interleave, and the last counts land last
            with self._lock:
                counts = dict(self.counts)
            tmp = path.with_name(path.name + ".tmp")
            tmp.write_text(json.dumps({"dropped": counts}, indent=1) + "\n")
            os.replace(tmp, path)


class RemoteError(RuntimeError):
    """A module answered a request with an error, or nobody answered."""


class NoReply(RemoteError):
    """Nobody answered a request within its timeout."""
