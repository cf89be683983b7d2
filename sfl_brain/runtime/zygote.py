"""A run's fork server: module processes forked from one process that imported what they share, once.

Every module host imports the same numpy, pydantic, Zenoh, msgspec and ``sfl_brain`` (about 0.45 s of CPU), and a
body its physics engine, before it does anything of its own. A run starts five or more of them, and again at every
restart. The fork server (``python -m sfl_brain.runtime.zygote``, one per supervisor) imports them once; each
module process is then a fork of it (a few milliseconds) that runs :func:`sfl_brain.runtime.host.main` exactly as
``python -m sfl_brain.runtime.host --name NAME`` would: the spec on its stdin (a pipe the supervisor writes and
holds, whose end still tells the host that its parent is gone), its output to its log, a session of its own
(``setsid``), and ``ps`` showing ``... sfl_brain.runtime.host --name NAME`` (``setproctitle``).

What it never imports: Rerun. Importing Rerun starts a tokio runtime's threads, and a fork carries none of a
process's threads, so a module would inherit a runtime with no workers. The server checks after its imports and
ends if Rerun (or any thread but numpy's BLAS pool) came in; the supervisor then starts processes as before.
Neither does it import a module from a file (``path/file.py:Class``): a user's import may do anything, and it
must fail in its own module's process, named.

The supervisor talks to it over a ``SOCK_SEQPACKET`` socket pair: ``fork NAME`` with the child's stdin and log as
passed descriptors, answered ``pid PID``; ``exit PID CODE`` when a child ends (the server is its parent and
reaps it; ``CODE`` as :attr:`subprocess.Popen.returncode`: negative for a signal). :class:`ForkServer` is that
end: :meth:`ForkServer.spawn` returns a :class:`Forked`, which answers what the supervisor asks of a
``subprocess.Popen`` (``pid``, ``stdin``, ``poll``, ``wait``, ``send_signal``, ``kill``, ``returncode``).
The server ends when the supervisor closes its end or dies. ``SFL_FORK_SERVER=0`` turns it off; it is on
Linux 5.3 or later only (:func:`enabled`).
"""

from __future__ import annotations

import importlib
import logging
import os
import select
import signal
import socket
import subprocess
import sys
import threading

log = logging.getLogger("sfl.zygote")

#: what every module host imports (the host imports the rest of what it shares)
PRELOAD = ("sfl_brain.runtime.host", "sfl_brain.registry")
#: the project's own packages: only their modules are imported ahead (a user's may do anything at import)
OWN = ("sfl_brain.", "modules.", "bodies.")
MAX_MESSAGE = 4096
#: how long a fork request may wait for its answer (it takes milliseconds) before the server counts as gone
SPAWN_TIMEOUT = 10.0


def enabled() -> bool:
    """Whether runs fork their module processes: not with ``SFL_FORK_SERVER=0``, and only on Linux 5.3 or later
    (pidfds, by which the supervisor signals and watches exactly the process it forked; elsewhere, as on macOS,
    where forking a process that imported numpy is not safe either, each process starts anew)."""
    if os.environ.get("SFL_FORK_SERVER", "1") == "0" or not hasattr(os, "pidfd_open"):
        return False
    try:
        os.close(os.pidfd_open(os.getpid()))
    except OSError:  # a kernel before 5.3
        return False
    return True


def preloads(references: list[str]) -> list[str]:
    """The modules to import ahead for module ``references`` (``package.module:Class``): the project's own only."""
    names = []
    for ref in references:
        target = ref.rpartition(":")[0]
        if target and not target.endswith(".py") and target.startswith(OWN) and target not in names:
            names.append(target)
    return names


# ---------------------------------------------------------------------------------------------- the server's end
def _threads() -> int:
    try:
        return len(os.listdir("/proc/self/task"))
    except OSError:
        return threading.active_count()


def serve(control: socket.socket, modules: list[str]) -> int:
    """Import ``modules``, then fork a module host per ``fork`` request until ``control`` closes."""
    import numpy  # noqa: F401 - its BLAS pool's threads (one per core, less one) are expected: counted here

    baseline = _threads()
    for name in (*PRELOAD, *modules):
        try:
            importlib.import_module(name)
        except BaseException as exc:  # noqa: BLE001 - the module's own process reports it, named
            print(f"sfl zygote: not preloaded {name}: {type(exc).__name__}: {exc}", file=sys.stderr)
    if "rerun" in sys.modules or _threads() > baseline or threading.active_count() > 1:
        print("sfl zygote: a preloaded module imported Rerun or started threads: not forking", file=sys.stderr)
        return 3
    wake_r, wake_w = os.pipe()
    os.set_blocking(wake_w, False)
    signal.set_wakeup_fd(wake_w)
    signal.signal(signal.SIGCHLD, lambda *_: None)
    signal.signal(signal.SIGINT, signal.SIG_IGN)  # Ctrl-C is the supervisor's; it closes this end
    control.sendall(b"ready")
    while True:
        readable, _, _ = select.select([control, wake_r], [], [])
        if wake_r in readable:
            os.read(wake_r, 512)
        _reap(control)
        if control not in readable:
            continue
        try:
            message, fds, _, _ = socket.recv_fds(control, MAX_MESSAGE, 2)
        except OSError:
            message, fds = b"", []
        if not message:  # the supervisor closed its end, or is gone: its children stop on their own stdin's end
            return 0
        name = message.decode()[len("fork ") :]
        pid = os.fork()
        if pid == 0:
            _child(name, fds, control, wake_r, wake_w)
        for fd in fds:
            os.close(fd)
        # a pidfd, opened before anything could reap it: the supervisor signals and watches this process, never a
        # later one that reuses its pid
        pidfd = os.pidfd_open(pid)
        try:
            socket.send_fds(control, [f"pid {pid}".encode()], [pidfd])
        finally:
            os.close(pidfd)


def _reap(control: socket.socket) -> None:
    """Reap every child that ended (the server's only children are the hosts it forked) and tell the supervisor."""
    while True:
        try:
            pid, status = os.waitpid(-1, os.WNOHANG)
        except ChildProcessError:  # no child at all
            return
        if not pid:
            return
        try:
            control.sendall(f"exit {pid} {os.waitstatus_to_exitcode(status)}".encode())
        except OSError:  # the supervisor closed its end: nobody to tell
            return


def _child(name: str, fds: list[int], *close: object) -> None:
    """In the forked child: become ``python -m sfl_brain.runtime.host --name NAME`` and never return."""
    code = 1
    try:
        signal.set_wakeup_fd(-1)
        for sig in (signal.SIGCHLD, signal.SIGINT, signal.SIGTERM):
            signal.signal(sig, signal.SIG_DFL)
        os.setsid()  # as start_new_session: Ctrl-C reaches the supervisor only
        stdin, logf = fds
        os.dup2(stdin, 0)
        os.dup2(logf, 1)
        os.dup2(logf, 2)
        for thing in (stdin, logf, *close):
            os.close(thing) if isinstance(thing, int) else thing.close()
        sys.stdin = open(0, encoding="utf-8", closefd=False)  # noqa: SIM115 - the process's own
        sys.stdout = open(1, "w", encoding="utf-8", buffering=1, closefd=False)  # noqa: SIM115
        sys.stderr = open(2, "w", encoding="utf-8", buffering=1, closefd=False)  # noqa: SIM115
        sys.argv = [sys.argv[0], "--name", name]
        import setproctitle

        setproctitle.setproctitle(f"{sys.executable} -m sfl_brain.runtime.host --name {name}")
        from . import host

        code = host.main(["--name", name])
        logging.shutdown()
    except SystemExit as exc:  # as the interpreter ends on it: None is 0, an int itself, anything else printed and 1
        code = 0 if exc.code is None else exc.code if isinstance(exc.code, int) else 1
        if code == 1 and not isinstance(exc.code, int):
            print(exc.code, file=sys.stderr)
    except BaseException:  # noqa: BLE001 - printed to its log, as an uncaught exception would be
        import traceback

        traceback.print_exc()
    finally:
        try:
            sys.stdout.flush()
            sys.stderr.flush()
        finally:
            os._exit(code)


def main() -> int:
    fd = int(sys.argv[1])
    control = socket.socket(fileno=fd)
    try:
        return serve(control, sys.argv[2:])
    finally:
        control.close()


# ------------------------------------------------------------------------------------------ the supervisor's end
class Forked:
    """A module process forked by the server, as much of :class:`subprocess.Popen` as the supervisor uses. Signals go
    through its pidfd, so never to a later process that reuses the pid: the server reaps a child at once, before the
    supervisor hears of its end."""

    def __init__(self, pid: int, pidfd: int, stdin=None) -> None:
        self.pid = pid
        self.pidfd = pidfd
        self.stdin = stdin
        self.returncode: int | None = None
        self._ended = threading.Event()
        self._lock = threading.Lock()  # the pidfd is closed at the end, never while a signal goes through it

    def _exited(self, code: int) -> None:
        with self._lock:
            if self.returncode is not None:
                return
            self.returncode = code
            if self.pidfd is not None:
                os.close(self.pidfd)
                self.pidfd = None
        self._ended.set()

    def poll(self) -> int | None:
        return self.returncode

    def wait(self, timeout: float | None = None) -> int:
        if not self._ended.wait(timeout):
            raise subprocess.TimeoutExpired(f"pid {self.pid}", timeout)
        return self.returncode

    def send_signal(self, sig: int) -> None:
        with self._lock:
            if self.returncode is not None:  # as Popen: an ended process is not signalled
                return
            try:
                signal.pidfd_send_signal(self.pidfd, sig)
            except ProcessLookupError:  # it ended, and its end is not reported yet (as Popen, bpo-40550)
                pass

    def terminate(self) -> None:
        self.send_signal(signal.SIGTERM)

    def kill(self) -> None:
        self.send_signal(signal.SIGKILL)


class ForkServer:
    """The supervisor's end of its fork server. :meth:`start` returns None where there is none (turned off, or it
    would not fork safely); :meth:`spawn` returns None once it is gone (the caller starts a process itself)."""

    def __init__(self, proc: subprocess.Popen, control: socket.socket) -> None:
        self.proc = proc
        self.control = control
        self.children: dict[int, Forked] = {}
        self._lock = threading.Lock()  # one fork request at a time: its answer is the next ``pid``
        self._unclaimed: list[Forked] = []  # forked, not yet handed to the caller that asked
        self._answered = threading.Condition()
        self.gone = False
        self._reader = threading.Thread(target=self._read, daemon=True, name="zygote-reader")

    @classmethod
    def start(cls, references: list[str], log_path, timeout: float = 60.0) -> ForkServer | None:
        if not enabled():
            return None
        ours, theirs = socket.socketpair(socket.AF_UNIX, socket.SOCK_SEQPACKET)
        try:
            with open(log_path, "ab") as logf:
                proc = subprocess.Popen(
                    [sys.executable, "-m", "sfl_brain.runtime.zygote", str(theirs.fileno()), *preloads(references)],
                    stdin=subprocess.DEVNULL,
                    stdout=logf,
                    stderr=subprocess.STDOUT,
                    pass_fds=[theirs.fileno()],
                    start_new_session=True,
                )
        except BaseException:
            ours.close()
            raise
        finally:
            theirs.close()
        ours.settimeout(timeout)
        try:
            ready = ours.recv(MAX_MESSAGE) == b"ready"
        except OSError:
            ready = False
        ours.settimeout(None)
        if not ready:
            ours.close()
            _end(proc)
            log.info("no fork server (see %s): module processes start on their own", log_path)
            return None
        server = cls(proc, ours)
        server._reader.start()
        return server

    def spawn(self, name: str, logf) -> Forked | None:
        """Fork the host of module ``name``, its output to ``logf`` (an open file); None if the server is gone."""
        read, write = os.pipe()
        try:
            with self._lock:
                if self.gone:
                    return None
                try:
                    socket.send_fds(self.control, [f"fork {name}".encode()], [read, logf.fileno()])
                except OSError:
                    return None
                with self._answered:
                    if not self._answered.wait_for(lambda: self._unclaimed or self.gone, SPAWN_TIMEOUT):
                        log.warning("the fork server did not fork within %g s: processes start anew", SPAWN_TIMEOUT)
                        self.gone = True  # a stopped or wedged server: no more requests to it
                    if not self._unclaimed:
                        return None
                    child = self._unclaimed.pop(0)
                child.stdin = os.fdopen(write, "wb")
                write = None
                return child
        finally:
            os.close(read)
            if write is not None:
                os.close(write)

    def _read(self) -> None:
        while True:
            try:
                data, fds, _, _ = socket.recv_fds(self.control, MAX_MESSAGE, 1)
                message = data.decode()
            except OSError:
                message, fds = "", []
            if not message:
                break
            kind, _, rest = message.partition(" ")
            if kind == "pid":
                with self._answered:  # made here, so that an exit that comes at once finds it
                    child = self.children[int(rest)] = Forked(int(rest), fds[0])
                    self._unclaimed.append(child)
                    self._answered.notify_all()
            elif kind == "exit":
                pid, code = map(int, rest.split())
                child = self.children.pop(pid, None)
                if child is not None:
                    child._exited(code)
        with self._answered:  # the server is gone: nothing reports its children's ends any more
            self.gone = True
            self._answered.notify_all()
        for child in list(self.children.values()):
            threading.Thread(target=_watch_orphan, args=(child,), daemon=True).start()

    def close(self) -> None:
        """End the server (its children are the supervisor's to stop, before)."""
        try:
            self.control.shutdown(socket.SHUT_RDWR)
        except OSError:
            pass
        self.control.close()
        _end(self.proc)
        self._reader.join(timeout=5)


def _end(proc: subprocess.Popen, grace: float = 5.0) -> None:
    """Wait for the server to end (its end of the socket closed), killing it after ``grace`` s."""
    try:
        proc.wait(timeout=grace)
    except subprocess.TimeoutExpired:
        proc.kill()
        proc.wait()


def _watch_orphan(child: Forked) -> None:
    """A child whose server ended: its end is seen on its pidfd (readable once it ended, reaped or not); its exit
    code is unknown (255)."""
    while child.returncode is None:
        fd = child.pidfd
        try:
            ended = fd is not None and bool(select.select([fd], [], [], 0.05)[0])
        except (OSError, ValueError):  # closed by its reported end meanwhile
            ended = False
        if ended:
            log.warning("module process %d ended after its fork server: exit code unknown", child.pid)
            child._exited(255)
            return


if __name__ == "__main__":
    sys.exit(main())
