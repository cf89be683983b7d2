"""The physical floor of a lockstep pair: two processes taking turns, one tick after the other.

A body (this process) does its tick's work (a callable: the planar walker's physics, or a calibrated
loop), sends a frame (240 bytes) and waits for the command (96 bytes) that its controller (a child
process) sends back after its own work. How the two wait and where they run is all that differs
between the variants:

* ``pipe``: an OS pipe each way, both blocking in ``read``: the cheapest blocking hand-over there is;
* ``socket``: a Unix ``SOCK_SEQPACKET`` socket pair, both blocking in ``recv``: the transport of
  ``lockstep.link: socket`` (``sfl_brain.runtime.ticklink``), bare;
* ``shm``: a shared-memory sequence number each way, both spinning: no wake-up at all, but each
  side holds a core (on a shared core, or beside a busy process, it starves the other); the
  controller spins only while the body runs ticks, and sleeps in between (it must not be a busy
  neighbour of the other variants);
* ``zenoh``: bare Zenoh pub/sub, both blocking in a ring channel's ``recv()``, on the run's mesh
  configuration (``bus.config``) or on the lockstep link (``bus.tick_config``: lowlatency, no QoS);

each placed ``one core`` (both pinned to the same core, as ``lockstep.pin_cpus: auto`` places a
pair), ``two cores`` (one each, as ``pin_cpus`` used to) or ``free`` (not pinned). ``one_process``
is the same work without a second process. A calibrated work (:func:`calibrate`, :func:`work`) is a
count of interpreter loop iterations, not a wall-clock wait, so a tick that is preempted does not
pass for work done.

``Busy`` starts a process that spins, unpinned: a busy neighbour (a viewer, another run).
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
import textwrap
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
FRAME, COMMAND = 240, 96  # bytes a tick: a planar walker's sensor frame and motor command, about


def calibrate(us: float) -> int:
    """Loop iterations that take ``us`` microseconds here (the fastest of a few tries)."""
    n = 100_000
    best = min(_timed(n) for _ in range(5))
    return max(int(n * us * 1e-6 / best), 0)


def _timed(n: int) -> float:
    t = time.perf_counter()
    for _ in range(n):
        pass
    return time.perf_counter() - t


def work(n: int) -> None:
    for _ in range(n):
        pass


def one_process(ticks: int, tick, controller_n: int = 0) -> float:
    """Seconds for ``ticks`` ticks of both sides' work in one process: ``tick()`` (the body's), then the
    controller's loop."""
    t = time.perf_counter()
    for _ in range(ticks):
        tick()
        work(controller_n)
    return time.perf_counter() - t


# every pong: pinned first (argv[1]: JSON cores or null), gone with its parent, then its own set-up
PREAMBLE = textwrap.dedent("""
    import json, os, sys, threading, time
    sys.path.insert(0, {root!r})
    from sfl_brain.runtime.placement import pin
    pin(json.loads(sys.argv[1]))
    PARENT = os.getppid()
    def orphaned():
        while os.getppid() == PARENT:
            time.sleep(0.5)
        os._exit(1)
    threading.Thread(target=orphaned, daemon=True).start()
    N = {controller_n}
    def work(n):
        for _ in range(n):
            pass
""")
PONG_PIPE = textwrap.dedent("""
    r, w = int(sys.argv[2]), int(sys.argv[3])
    reply = b"c" * {command}
    while True:
        data = os.read(r, 65536)
        if not data or data == b"stop":
            break
        work(N)
        os.write(w, reply)
""")
PONG_SHM = textwrap.dedent("""
    import mmap
    f = open(sys.argv[2], "r+b")
    shm = mmap.mmap(f.fileno(), 8)
    buf = memoryview(shm)
    go = int(sys.argv[3])
    seen = 0
    while os.read(go, 1) == b"g":  # spin only during the body's runs: idle, it must not be a busy neighbour
        while True:
            while buf[0] == seen:  # the body's sequence number (mod 256)
                pass
            seen = buf[0]
            if buf[2] == 1:  # the run's end
                buf[1] = seen
                break
            work(N)
            buf[1] = seen  # the command for this tick
    buf.release()
    shm.close()
    f.close()
""")
PONG_ZENOH = textwrap.dedent("""
    import zenoh
    from sfl_brain.runtime import bus
    os.environ.setdefault("ZENOH_RUNTIME", bus.RUNTIME)
    link, typed = sys.argv[2], sys.argv[4] == "typed"
    conf = bus.config([], [sys.argv[3]]) if link == "mesh" else bus.tick_config([], [sys.argv[3]])
    s = zenoh.open(conf)
    sub = s.declare_subscriber("floor/frame", zenoh.handlers.RingChannel(64))
    pub = s.declare_publisher("floor/command")
    reply = b"c" * {command}
    if typed:  # the framework's codec and the open-loop controller, by hand (no host, no checks)
        from sfl_brain.messages import ControllerReset, SensorFrame, decoder_for, encode
        from sfl_brain.modules.controllers.open_loop import OpenLoopController
        controller = OpenLoopController()
        controller.handle(ControllerReset(trial_id=0, seed=0, params={{}}, sensors={sensors!r}, commands={commands!r}))
        decode_frame = decoder_for(SensorFrame)
    while True:
        data = sub.recv().payload.to_bytes()
        if data == b"stop":
            break
        work(N)
        if typed:
            reply = encode(controller.handle(decode_frame(data[:-8]), checked=True)) + data[-8:]
        pub.put(reply)
    s.close()
""")
PONG_SOCKET = textwrap.dedent("""
    import socket
    sock = socket.socket(fileno=int(sys.argv[2]))  # AF_UNIX, SOCK_SEQPACKET: as sfl_brain.runtime.ticklink
    typed = sys.argv[3] == "typed"
    reply = b"c" * {command}
    if typed:  # the framework's codec and the open-loop controller, by hand (no host, no checks)
        from sfl_brain.messages import ControllerReset, SensorFrame, decoder_for, encode
        from sfl_brain.modules.controllers.open_loop import OpenLoopController
        controller = OpenLoopController()
        controller.handle(ControllerReset(trial_id=0, seed=0, params={{}}, sensors={sensors!r}, commands={commands!r}))
        decode_frame = decoder_for(SensorFrame)
    recv, send = sock.recv, sock.send
    while True:
        data = recv(65537)
        if not data or data == b"stop":
            break
        work(N)
        if typed:
            reply = encode(controller.handle(decode_frame(data[:-8]), checked=True)) + data[-8:]
        send(reply)
    sock.close()
""")
PONG_CONTROLLER = textwrap.dedent("""
    import importlib, socket
    from sfl_brain.messages import SensorFrame, decode, decoder_for, encode
    sock = socket.socket(fileno=int(sys.argv[2]))  # AF_UNIX, SOCK_SEQPACKET
    module, _, name = sys.argv[3].partition(":")
    controller = getattr(importlib.import_module(module), name)()
    decode_frame, recv, send, handle = decoder_for(SensorFrame), sock.recv, sock.send, controller.handle
    while True:
        data = recv(65537)
        if not data or data == b"stop":
            break
        msg = decode_frame(data) if data[0] == 0xC1 else decode(data)  # a frame, or the reset
        send(encode(handle(msg, checked=True)))
    sock.close()
""")
SENSORS = ("hip_l", "hip_r", "knee_l", "knee_r", "contact_l", "contact_r", "slope", "pitch")


class HandLink:
    """A body's link to a real controller in a child process over a bare ``SOCK_SEQPACKET`` socket, written by
    hand: the framework's typed messages and the controller's own handler, but no host, no nonce, no checks, no
    watchdog: what the framework's socket link and host do, less the framework (``reference``: the controller's
    class, ``module:Class``; ``cores``: where the child runs)."""

    def __init__(self, reference: str, cores) -> None:
        import socket

        from sfl_brain.messages import MotorCommand, decoder_for

        self.sock, theirs = socket.socketpair(socket.AF_UNIX, socket.SOCK_SEQPACKET)
        source = PREAMBLE.format(root=str(ROOT), controller_n=0) + PONG_CONTROLLER
        fd = theirs.fileno()
        self.proc = subprocess.Popen(
            [sys.executable, "-c", source, json.dumps(cores), str(fd), reference], pass_fds=(fd,)
        )
        theirs.close()
        self._decode = decoder_for(MotorCommand)

    def reset(self, msg) -> None:
        from sfl_brain.messages import encode

        self.sock.send(encode(msg))
        self.sock.recv(65537)  # the Ack

    def step(self, frame):
        from sfl_brain.messages import encode

        self.sock.send(encode(frame))
        return self._decode(self.sock.recv(65537))

    def close(self) -> None:
        self.sock.send(b"stop")
        self.proc.wait(timeout=10)
        self.sock.close()


COMMANDS = ("v_hip_l", "v_hip_r", "v_knee_l", "v_knee_r")


class Pair:
    """A body here and its controller in a child process, exchanging one tick at a time over ``kind``
    (``pipe``, ``socket`` (a Unix ``SOCK_SEQPACKET`` pair, as ``lockstep.link: socket``), ``shm``, ``zenoh-mesh`` or
    ``zenoh-tick``; ``socket-typed``, ``zenoh-tick-typed``: with the framework's codec and the open-loop controller
    by hand, both sides); ``mine`` and ``theirs``: the cores of each
    (None: not pinned); the body pins itself only while it runs ticks."""

    def __init__(self, kind: str, controller_n: int, mine, theirs, tmp: Path) -> None:
        self.kind, self.mine = kind, mine
        source = PREAMBLE.format(root=str(ROOT), controller_n=controller_n)
        args: list[str] = []
        self._close = []
        if kind == "pipe":
            self.r, pong_w = os.pipe()
            pong_r, self.w = os.pipe()
            source += PONG_PIPE.format(command=COMMAND)
            args = [str(pong_r), str(pong_w)]
            self.proc = subprocess.Popen(
                [sys.executable, "-c", source, json.dumps(theirs), *args], pass_fds=(pong_r, pong_w)
            )
            os.close(pong_r)
            os.close(pong_w)
        elif kind.startswith("socket"):
            import socket

            self.typed = kind.endswith("-typed")
            self.sock, theirs_sock = socket.socketpair(socket.AF_UNIX, socket.SOCK_SEQPACKET)
            source += PONG_SOCKET.format(command=COMMAND, sensors=list(SENSORS), commands=list(COMMANDS))
            fd = theirs_sock.fileno()
            typed = "typed" if self.typed else "raw"
            self.proc = subprocess.Popen(
                [sys.executable, "-c", source, json.dumps(theirs), str(fd), typed], pass_fds=(fd,)
            )
            theirs_sock.close()
        elif kind == "shm":
            import mmap

            self.path = tmp / f"floor{os.getpid()}-{id(self)}.shm"
            self.path.write_bytes(bytes(8))
            self._file = open(self.path, "r+b")  # noqa: SIM115 - closed in close()
            self.shm = mmap.mmap(self._file.fileno(), 8)
            self.buf = memoryview(self.shm)
            go, self.go = os.pipe()
            source += PONG_SHM
            self.proc = subprocess.Popen(
                [sys.executable, "-c", source, json.dumps(theirs), str(self.path), str(go)], pass_fds=(go,)
            )
            os.close(go)
        else:
            import zenoh

            from sfl_brain.runtime import bus

            link = kind.split("-")[1]
            self.typed = kind.endswith("-typed")
            if link == "mesh":
                endpoint = bus.free_endpoint()
                conf = bus.config([endpoint], [])
            else:
                endpoint = bus.tick_endpoint(tmp, f"floor{os.getpid()}-{id(self)}")
                conf = bus.tick_config([endpoint], [])
            os.environ.setdefault("ZENOH_RUNTIME", bus.RUNTIME)
            self.session = zenoh.open(conf)
            self.pub = self.session.declare_publisher("floor/frame")
            self.sub = self.session.declare_subscriber("floor/command", zenoh.handlers.RingChannel(64))
            source += PONG_ZENOH.format(command=COMMAND, sensors=list(SENSORS), commands=list(COMMANDS))
            typed = "typed" if self.typed else "raw"
            self.proc = subprocess.Popen([sys.executable, "-c", source, json.dumps(theirs), link, endpoint, typed])
            deadline = time.monotonic() + 30
            while not self.pub.matching_status.matching:
                if time.monotonic() > deadline or self.proc.poll() is not None:
                    raise RuntimeError(f"{kind}: the controller did not subscribe")
                time.sleep(0.01)
        self.seq = 0

    def run(self, ticks: int, tick) -> float:
        """Seconds for ``ticks`` ticks: the body's work (``tick()``), the frame out, the command back."""
        from _common import Pinned

        with Pinned(self.mine):
            return getattr(self, "_run_" + self.kind.partition("-")[0])(ticks, tick)

    def _run_pipe(self, ticks: int, tick) -> float:
        r, w, frame = self.r, self.w, b"f" * FRAME
        read, write = os.read, os.write
        t = time.perf_counter()
        for _ in range(ticks):
            tick()
            write(w, frame)
            read(r, 65536)
        return time.perf_counter() - t

    def _run_socket(self, ticks: int, tick) -> float:
        send, recv, frame = self.sock.send, self.sock.recv, b"f" * FRAME
        if self.typed:
            return self._run_typed(ticks, tick)
        t = time.perf_counter()
        for _ in range(ticks):
            tick()
            send(frame)
            recv(65537)
        return time.perf_counter() - t

    def _run_shm(self, ticks: int, tick) -> float:
        buf = self.buf
        seq = self.seq
        os.write(self.go, b"g")  # the controller spins from now on
        t = time.perf_counter()
        for _ in range(ticks):
            tick()
            seq = (seq + 1) % 256
            buf[0] = seq
            while buf[1] != seq:
                pass
        elapsed = time.perf_counter() - t
        buf[2] = 1  # the run's end: the controller goes back to sleep
        seq = (seq + 1) % 256
        buf[0] = seq
        while buf[1] != seq:
            pass
        buf[2] = 0
        self.seq = seq
        return elapsed

    def _run_zenoh(self, ticks: int, tick) -> float:
        put, recv, frame = self.pub.put, self.sub.recv, b"f" * FRAME
        if self.typed:
            return self._run_typed(ticks, tick)
        t = time.perf_counter()
        for _ in range(ticks):
            tick()
            put(frame)
            recv()
        return time.perf_counter() - t

    def _run_typed(self, ticks: int, tick) -> float:
        """The framework's messages by hand: a SensorFrame encoded with a stream nonce, the MotorCommand decoded."""
        import numpy as np

        from sfl_brain.messages import MotorCommand, SensorFrame, decoder_for, encode

        decode_command = decoder_for(MotorCommand)
        values, nonce = np.zeros(len(SENSORS)), bytes(8)
        t = time.perf_counter()
        if self.kind.startswith("socket"):
            send, recv = self.sock.send, self.sock.recv
            for _ in range(ticks):
                tick()
                send(encode(SensorFrame(trial_id=0, tick=self.seq, values=values)) + nonce)
                decode_command(recv(65537)[:-8])
                self.seq += 1
            return time.perf_counter() - t
        put, recv_sample = self.pub.put, self.sub.recv
        for _ in range(ticks):
            tick()
            put(encode(SensorFrame(trial_id=0, tick=self.seq, values=values)) + nonce)
            decode_command(recv_sample().payload.to_bytes()[:-8])
            self.seq += 1
        return time.perf_counter() - t

    def close(self) -> None:
        if self.kind == "pipe":
            os.write(self.w, b"stop")
            self.proc.wait(timeout=10)
            os.close(self.r)
            os.close(self.w)
        elif self.kind.startswith("socket"):
            self.sock.send(b"stop")
            self.proc.wait(timeout=10)
            self.sock.close()
        elif self.kind == "shm":
            os.write(self.go, b"s")
            os.close(self.go)
            self.proc.wait(timeout=10)
            self.buf.release()
            self.shm.close()
            self._file.close()
            self.path.unlink()
        else:
            self.pub.put(b"stop")
            self.proc.wait(timeout=10)
            self.sub.undeclare()
            self.pub.undeclare()
            self.session.close()


class Busy:
    """A process that spins (unpinned) until closed: one busy neighbour."""

    def __init__(self) -> None:
        self.proc = subprocess.Popen([sys.executable, "-c", "while True: pass"])

    def close(self) -> None:
        self.proc.kill()
        self.proc.wait()


def machine_load() -> str:
    """The load averages over 1, 5 and 15 minutes, and the cores: how busy the machine was."""
    one, five, fifteen = os.getloadavg()
    return f"load average {one:.2f} {five:.2f} {fifteen:.2f} on {os.cpu_count()} cores"
