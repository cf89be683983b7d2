from __future__ import annotations

import contextlib
import json
import os
import subprocess
import sys
import threading
import time
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
SCENARIOS = ROOT / "scenarios"


def pytest_xdist_auto_num_workers(config) -> int:
    """``-n auto``: a worker per core this process may use (``taskset`` and container limits respected), not per
    core the machine has."""
    from sfl_brain.runtime.placement import usable_cpus

    return len(usable_cpus()) or os.cpu_count() or 1


def pytest_sessionstart(session) -> None:
    """What this test run computes with, printed first even under ``-q`` (issue 35): a failure on a fresh machine
    starts from these. Printed once, by the process that reports (not by each xdist worker)."""
    reporter = session.config.pluginmanager.get_plugin("terminalreporter")
    if reporter is None or hasattr(session.config, "workerinput"):
        return
    for line in what_computes():
        reporter.write_line(line)


def what_computes() -> list[str]:
    """The versions of what computes and checks, and the numeric platform (``sfl_brain.recording.provenance``)."""
    from sfl_brain.recording.provenance import DISTRIBUTIONS, describe_platform, numeric_platform, versions

    found = versions((*DISTRIBUTIONS, "gymnasium", "cma", "optuna", "scikit-learn", "distributed", "pytest-xdist"))
    return [
        "sfl-brain test run with " + ", ".join(f"{k} {v}" for k, v in found.items()),
        f"numeric platform: {describe_platform(numeric_platform())}",
    ]


def pytest_configure(config) -> None:
    """Under pytest-xdist (``-n N``, the default ``-n auto`` in pyproject.toml), worker ``i`` of ``N`` runs on its
    own share of the usable cores (``cores[i::N]``), and so does every process its tests start (they inherit it).

    A run places its body and controller on one of the cores it may use (``lockstep.pin_cpus: auto``): without
    shares, two workers' runs would pin their pairs to the same last core and leave the other idle, and a body
    starved there can miss its liveliness lease. With shares, each worker's runs see the cores of its share
    only, as under ``taskset``, which the framework respects."""
    cache_bytecode(config)
    worker = os.environ.get("PYTEST_XDIST_WORKER", "")
    count = int(os.environ.get("PYTEST_XDIST_WORKER_COUNT", "1"))
    if not worker.startswith("gw") or count < 2 or not hasattr(os, "sched_setaffinity"):
        return
    from sfl_brain.runtime.placement import pin, usable_cpus

    cores = usable_cpus()
    os.environ.setdefault(ALL_CORES, ",".join(map(str, cores)))
    if len(cores) >= count:
        pin(cores[int(worker[2:]) % count :: count])  # a worker that replaces a crashed one is gw<count> or more


#: the temporary bytecode cache of a test session started with PYTHONDONTWRITEBYTECODE set (see cache_bytecode)
BYTECODE_CACHE = "SFL_TEST_BYTECODE_CACHE"


def cache_bytecode(config) -> None:
    """Under ``PYTHONDONTWRITEBYTECODE``, every process a test starts (about 600 module hosts and ``sfl`` commands)
    compiled ``sfl_brain``, ``modules`` and ``bodies`` from source again: an editable install has no bytecode
    that pip compiled, and nothing may write it. That is about 0.1 s of CPU per process. The session (the process
    that starts the xdist workers, before it starts them) gives itself and everything it starts a bytecode cache
    outside the source tree instead (``PYTHONPYCACHEPREFIX``, a temporary folder removed at its end), so the
    source tree stays as the variable asked and each file is compiled once per session."""
    if os.environ.get(BYTECODE_CACHE) or not os.environ.get("PYTHONDONTWRITEBYTECODE"):
        return  # a worker (the session set it up) or a machine that writes bytecode anyway
    import shutil
    import tempfile

    cache = tempfile.mkdtemp(prefix="sfl-test-pycache-")
    os.environ[BYTECODE_CACHE] = os.environ["PYTHONPYCACHEPREFIX"] = cache
    del os.environ["PYTHONDONTWRITEBYTECODE"]
    sys.pycache_prefix, sys.dont_write_bytecode = cache, False
    config.add_cleanup(lambda: shutil.rmtree(cache, ignore_errors=True))


#: the cores the test session may use, before each xdist worker was pinned to its share
ALL_CORES = "SFL_TEST_ALL_CORES"


def all_cores() -> list[int]:
    """The cores the whole test session may use (a worker's own share is ``usable_cpus()``)."""
    from sfl_brain.runtime.placement import usable_cpus

    saved = os.environ.get(ALL_CORES)
    return [int(c) for c in saved.split(",")] if saved else usable_cpus()


def on_all_cores() -> None:
    """A ``preexec_fn``: the child runs on every core of the test session, not on its worker's share (a test of
    how a run places its processes on the cores it may use)."""
    os.sched_setaffinity(0, all_cores())


def argv_of(process) -> list[str]:
    """A ``psutil.Process``'s command line as ``ps`` shows it, word by word: a module process forked from its run's
    fork server (:mod:`sfl_brain.runtime.zygote`) sets its title as one string, ``... host --name NAME``."""
    return " ".join(process.cmdline()).split()


def sfl(*args: str, timeout: float = 300, **kw) -> subprocess.CompletedProcess:
    """Run the real ``sfl`` command in a subprocess."""
    return subprocess.run(
        [sys.executable, "-m", "sfl_brain.cli", *args],
        capture_output=True,
        text=True,
        timeout=timeout,
        cwd=kw.pop("cwd", ROOT),
        **kw,
    )


def sfl_run(scenario, out, *sets: str, extra: tuple[str, ...] = (), **kw) -> subprocess.CompletedProcess:
    """``sfl run SCENARIO --set S... --out OUT --quiet`` with any ``extra`` options."""
    settings = [arg for s in sets for arg in ("--set", s)]
    return sfl("run", str(scenario), *settings, *extra, "--out", str(out), "--quiet", **kw)


def start_sfl_run(scenario, out, *sets: str, **kw) -> subprocess.Popen:
    """``sfl run SCENARIO --set S... --out OUT --quiet`` in the background, its output on text pipes (``kw``: more
    ``Popen`` arguments, e.g. ``start_new_session=True`` for a process group a signal can reach as a whole)."""
    settings = [arg for s in sets for arg in ("--set", s)]
    return subprocess.Popen(
        [sys.executable, "-m", "sfl_brain.cli", "run", str(scenario), *settings, "--out", str(out), "--quiet"],
        cwd=ROOT,
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
        **kw,
    )


@pytest.fixture
def write_scenario(tmp_path):
    def write(text: str, name: str = "scenario.yaml") -> Path:
        path = tmp_path / name
        path.write_text(text)
        return path

    return write


class Lines:
    """A process's text stream, read line by line by a thread: wait for a line with a deadline."""

    def __init__(self, stream) -> None:
        self.lines: list[str] = []
        self.ended = False
        self._changed = threading.Condition()
        threading.Thread(target=self._read, args=(stream,), daemon=True).start()

    def _read(self, stream) -> None:
        for line in stream:
            with self._changed:
                self.lines.append(line)
                self._changed.notify_all()
        with self._changed:
            self.ended = True
            self._changed.notify_all()

    def expect(self, text: str, timeout: float) -> str:
        """The first line holding ``text``, once it is read; AssertionError after ``timeout`` s or at the end."""
        with self._changed:
            self._changed.wait_for(lambda: self._find(text) is not None or self.ended, timeout)
            line = self._find(text)
        assert line is not None, f"no line with {text!r} within {timeout:g} s; read: {''.join(self.lines)!r}"
        return line

    def _find(self, text: str) -> str | None:
        return next((line for line in self.lines if text in line), None)


def poll_until(predicate, what: str, timeout: float = 60.0, proc: subprocess.Popen | None = None) -> None:
    """Wait for ``predicate()`` where nothing announces it (a file growing): checked every 50 ms until
    ``timeout`` s. AssertionError naming ``what`` at the deadline, or at once if ``proc`` ends first."""
    deadline = time.monotonic() + timeout
    while not predicate():
        if proc is not None and proc.poll() is not None:
            said = ""
            if proc.stderr is not None and not proc.stderr.closed:
                said = proc.stderr.read()[-3000:]  # what the run said: the reason a flaky end can be diagnosed
            raise AssertionError(f"the process ended (code {proc.returncode}) before {what}; its stderr:\n{said}")
        if time.monotonic() > deadline:
            raise AssertionError(f"timed out after {timeout:g} s waiting for {what}")
        time.sleep(0.05)


def trials_recorded(run_dir: Path) -> int:
    """Trial rows in a run folder's records so far."""
    path = Path(run_dir) / "records.jsonl"
    return path.read_bytes().count(b'"kind":"trial"') if path.exists() else 0


def wait_for_trials(run_dir: Path, trials: int, proc: subprocess.Popen, timeout: float = 120.0) -> None:
    """Wait until a running ``sfl run`` has recorded ``trials`` trials (the records file is all it shows)."""
    poll_until(lambda: trials_recorded(run_dir) >= trials, f"{trials} trials in {run_dir}/records.jsonl", timeout, proc)


@contextlib.contextmanager
def listening_run(scenario, out, *sets: str, modules: int, extra: tuple[str, ...] = ()):
    """Start ``sfl run --listen`` and join its mesh as one more peer (with the run secret, read from
    the run folder) once all ``modules`` are alive.

    Yields a namespace: proc, session, run_id, endpoint, secret, join (the printed join command);
    the caller waits for the process.
    """
    import types

    from sfl_brain.runtime import bus

    endpoint = bus.free_endpoint()
    settings = [arg for s in sets for arg in ("--set", s)]
    proc = subprocess.Popen(
        [sys.executable, "-m", "sfl_brain.cli", "run", str(scenario), *settings, *extra]
        + ["--listen", endpoint, "--out", str(out), "--quiet"],
        cwd=ROOT,
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
    )
    try:
        line = Lines(proc.stdout).expect("run id", 120)
        run_id = line.split("run id ")[1].split(";")[0]
        secret = (Path(out) / "secret").read_text().strip()
        with bus.open_session(["tcp/127.0.0.1:0"], [endpoint]) as session:
            # wait until this new peer sees every module of the run (gossip has reached it), or the run ends
            names: set[str] = set()
            settled = threading.Event()

            def on_token(sample):
                names.add(bus.parse_alive_key(sample.key_expr)[0])
                if len(names) >= modules:
                    settled.set()

            threading.Thread(target=lambda: (proc.wait(), settled.set()), daemon=True).start()
            watch = session.liveliness().declare_subscriber(bus.alive_key(run_id, "*", "*"), on_token, history=True)
            assert settled.wait(60), f"the run's modules did not all come alive within 60 s (seen: {sorted(names)})"
            assert proc.poll() is None, "the run ended before its modules were seen: " + proc.stderr.read()
            watch.undeclare()
            yield types.SimpleNamespace(
                proc=proc, session=session, run_id=run_id, endpoint=endpoint, secret=secret, join=line
            )
    except BaseException:
        proc.kill()
        raise


@contextlib.contextmanager
def joined_run(scenario, out, *sets: str, modules: int):
    """:func:`listening_run`, yielding (process, Zenoh session, run id)."""
    with listening_run(scenario, out, *sets, modules=modules) as run:
        yield run.proc, run.session, run.run_id


class TickStranger:
    """A process of this user on a running run's lockstep link (``logs/placement.json``), which it may reach
    (the link's folder is this user's): ``put(key, payload)`` sends to the controller's end, on a socket
    link (``lockstep.link: socket``) over a connection of its own, on a Zenoh link on a session of its own.
    The body's end of a socket link only connects: nothing put to the body's keys reaches it."""

    def __init__(self, run_dir: Path) -> None:
        from sfl_brain.runtime import bus, ticklink

        links = json.loads((Path(run_dir) / "logs" / "placement.json").read_text())["lockstep_links"]
        self.endpoint = links["controller"]["listen"][0]
        self.on_socket = ticklink.is_socket(self.endpoint)
        self.session = None if self.on_socket else bus.open_tick_session([], [self.endpoint])
        self.sock = None
        self.sent = 0

    def put(self, key: str, payload: bytes) -> None:
        import socket

        from sfl_brain.runtime import ticklink

        if self.session is not None:
            self.session.put(key, payload)
            self.sent += 1
            return
        if not key.endswith("controller.sensors"):
            return
        try:
            if self.sock is None:
                self.sock = socket.socket(socket.AF_UNIX, socket.SOCK_SEQPACKET)
                self.sock.connect(ticklink.path_of(self.endpoint))
            self.sock.send(payload)
            self.sent += 1
        except OSError:  # an empty message ends the connection (end of file): connect again next time
            self.close_socket()

    def close_socket(self) -> None:
        if self.sock is not None:
            self.sock.close()
            self.sock = None

    def close(self) -> None:
        self.close_socket()
        if self.session is not None:
            self.session.close()
