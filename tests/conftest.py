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
def joined_run(scenario, out, *sets: str, modules: int):
    """Start ``sfl run --listen`` and join its mesh as one more peer once all ``modules`` are alive.

    Yields (process, Zenoh session, run id); the caller waits for the process.
    """
    import zenoh

    from sfl_brain import bus

    endpoint = bus.free_endpoint()
    settings = [arg for s in sets for arg in ("--set", s)]
    proc = subprocess.Popen(
        [sys.executable, "-m", "sfl_brain.cli", "run", str(scenario), *settings]
        + ["--listen", endpoint, "--out", str(out), "--quiet"],
        cwd=ROOT,
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
    )
    try:
        line = proc.stdout.readline()
        assert "run id" in line, line
        run_id = line.split("run id ")[1].split(";")[0]
        with zenoh.open(bus.config(["tcp/127.0.0.1:0"], [endpoint])) as session:
            # wait until this new peer sees every module of the run (gossip has reached it)
            alive = bus.alive_key(run_id, "*")
            assert wait_for(lambda: len(list(session.liveliness().get(alive, timeout=1.0))) == modules)
            yield proc, session, run_id
    except BaseException:
        proc.kill()
        raise
