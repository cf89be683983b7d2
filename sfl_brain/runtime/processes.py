"""Module processes: start one with its spec on stdin, report its exit, stop them all.

Each module instance runs as ``python -m sfl_brain.runtime.host --name NAME``, forked from the run's fork server
(:mod:`.zygote`) where there is one (the name is for ``ps``; the
spec, with the run secret, goes on stdin, which stays open: its end tells the host that the
parent is gone). A thread per process waits for its exit and posts an :class:`Exited` to the
supervisor's queue; nothing else here runs in the background. Nothing here imports Zenoh.
"""

from __future__ import annotations

import json
import logging
import os
import signal
import subprocess
import sys
import threading
import time
from collections.abc import Callable, Iterable
from dataclasses import dataclass
from pathlib import Path

from ..scenario.plan import Instance
from .zygote import Forked, ForkServer

log = logging.getLogger("sfl.processes")


@dataclass
class Child:
    """One module instance's process, across its restarts."""

    instance: Instance
    log_path: Path
    proc: subprocess.Popen | Forked | None = None
    restarts: int = 0
    alive: bool = False
    stopping: bool = False
    #: how many times it was started: an exit or a token of an earlier start is not this one's
    generation: int = 0
    #: of the current start: its liveliness token must carry it
    nonce: str = ""
    #: why the supervisor is ending it (``hung: ...``), until its exit is handled
    hung: str = ""

    @property
    def name(self) -> str:
        return self.instance.name

    @property
    def starting(self) -> bool:
        """Its process runs but is not alive yet (its liveliness token not seen), and is not being stopped."""
        return not self.alive and not self.stopping and self.proc is not None and self.proc.poll() is None


@dataclass(frozen=True)
class Exited:
    """Start ``generation`` of module ``name`` exited with ``exit_code`` (negative: killed by that signal)."""

    name: str
    exit_code: int
    generation: int


def start(child: Child, spec: dict, on_exit: Callable[[Exited], None], server: ForkServer | None = None) -> None:
    """Start ``child``'s host process, ``spec`` on its stdin and output to its log; ``on_exit`` gets the exit.
    With a fork ``server`` (:mod:`.zygote`) the process is forked from it, else (or once it is gone) started anew."""
    logf = open(child.log_path, "ab")  # noqa: SIM115 - handed to the child
    child.generation += 1
    child.alive = False
    proc = server.spawn(child.name, logf) if server is not None else None
    if proc is None:
        proc = subprocess.Popen(
            [sys.executable, "-m", "sfl_brain.runtime.host", "--name", child.name],  # the name only, for ps
            stdin=subprocess.PIPE,
            stdout=logf,
            stderr=subprocess.STDOUT,
            start_new_session=True,  # Ctrl-C reaches the supervisor only; it stops the children
        )
    child.proc = proc
    logf.close()
    try:  # the spec (with the secret) on stdin, never on the command line; stdin stays open
        proc.stdin.write(json.dumps(spec).encode() + b"\n")
        proc.stdin.flush()
    except OSError:  # it died at once: its exit event reports it
        pass
    name, generation = child.name, child.generation
    threading.Thread(
        target=lambda: on_exit(Exited(name, proc.wait(), generation)), daemon=True, name=f"exit-{name}"
    ).start()


def stop_all(children: Iterable[Child], grace: float = 3.0) -> None:
    """Stop every child: SIGTERM, then SIGKILL after ``grace`` seconds; close their stdin."""
    procs = []
    for child in children:
        child.stopping = True
        if child.proc is not None and child.proc.poll() is None:
            try:
                child.proc.send_signal(signal.SIGTERM)
            except ProcessLookupError:
                pass
            procs.append((child, child.proc))
    deadline = time.monotonic() + grace
    for child, proc in procs:
        try:
            proc.wait(timeout=max(0.0, deadline - time.monotonic()))
        except subprocess.TimeoutExpired:
            proc.kill()
            proc.wait()
            log.warning("module `%s` did not exit within %g s of SIGTERM: killed", child.name, grace)
    for _, proc in procs:
        if proc.stdin:
            try:
                proc.stdin.close()
            except OSError:
                pass


def exits_soon(proc: subprocess.Popen, grace: float = 1.0) -> bool:
    """True if the process has exited or exits within ``grace`` s (its sockets close before it is reaped)."""
    try:
        proc.wait(timeout=grace)
        return True
    except subprocess.TimeoutExpired:
        return False


def running(proc: subprocess.Popen | None) -> bool:
    """Whether ``proc`` still runs: not exited, and not a zombie waiting to be reaped (where ``/proc`` says so; the
    thread that waits for its exit holds ``Popen``'s lock, so ``poll()`` cannot tell that until it is reaped)."""
    if proc is None or proc.returncode is not None:
        return False
    try:
        with open(f"/proc/{proc.pid}/stat", "rb") as f:
            stat = f.read()
    except FileNotFoundError:
        return False
    except OSError:  # no /proc here
        return proc.poll() is None
    return stat[stat.rindex(b")") + 2 : stat.rindex(b")") + 3] not in (b"Z", b"X")


def log_tail(path: Path, lines: int = 12) -> str:
    """The last ``lines`` lines of a log file, indented ('' if it cannot be read)."""
    try:
        text = path.read_text(errors="replace").splitlines()
    except OSError:
        return ""
    return "\n".join("    " + line for line in text[-lines:])


def kill_quietly(pid: int) -> None:
    """SIGKILL ``pid`` if it still exists."""
    try:
        os.kill(pid, signal.SIGKILL)
    except ProcessLookupError:
        pass
