from __future__ import annotations

import contextlib
import subprocess
import sys
import time
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
SCENARIOS = ROOT / "scenarios"


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


@pytest.fixture
def write_scenario(tmp_path):
    def write(text: str, name: str = "scenario.yaml") -> Path:
        path = tmp_path / name
        path.write_text(text)
        return path

    return write


def wait_for(predicate, timeout: float = 60.0) -> bool:
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        if predicate():
            return True
        time.sleep(0.05)
    return False


@contextlib.contextmanager
def listening_run(scenario, out, *sets: str, modules: int, extra: tuple[str, ...] = ()):
    """Start ``sfl run --listen`` and join its mesh as one more peer (with the run secret, read from
    the run folder) once all ``modules`` are alive.

    Yields a namespace: proc, session, run_id, endpoint, secret, join (the printed join command);
    the caller waits for the process.
    """
    import types

    from sfl_brain import bus

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
        line = proc.stdout.readline()
        assert "run id" in line, line + proc.stderr.read() if proc.poll() is not None else line
        run_id = line.split("run id ")[1].split(";")[0]
        secret = (Path(out) / "secret").read_text().strip()
        with bus.open_session(["tcp/127.0.0.1:0"], [endpoint]) as session:
            # wait until this new peer sees every module of the run (gossip has reached it)
            alive = bus.alive_key(run_id, "*", "*")

            names: set[str] = set()
            watch = session.liveliness().declare_subscriber(
                alive, lambda sample: names.add(bus.parse_alive_key(sample.key_expr)[0]), history=True
            )

            def seen():
                if proc.poll() is not None:
                    return True
                replies = session.liveliness().get(alive, timeout=1.0)
                names.update(bus.parse_alive_key(r.ok.key_expr)[0] for r in replies if r.ok)
                return len(names) >= modules

            assert wait_for(seen), "the run's modules did not all come alive"
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
