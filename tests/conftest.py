from __future__ import annotations

import subprocess
import sys
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
