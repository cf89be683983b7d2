"""Every chapter script under ``docs/experiments/`` parses as bash, and every scenario, script and file it names
exists. Running one takes hours; a renamed scenario would otherwise be found only then."""

from __future__ import annotations

import re
import subprocess
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]
SCRIPTS = sorted((ROOT / "docs" / "experiments").glob("*.sh"))
NAMED = re.compile(r"\b((?:scenarios|docs/experiments|docs/calibration|benchmarks)/[\w./-]+\.(?:yaml|py|sh))\b")


def test_there_are_chapter_scripts():
    assert any(s.name == "chapter5_heldout.sh" for s in SCRIPTS), [s.name for s in SCRIPTS]


@pytest.mark.parametrize("script", SCRIPTS, ids=[s.name for s in SCRIPTS])
def test_the_script_parses_and_names_only_files_that_exist(script):
    checked = subprocess.run(["bash", "-n", str(script)], capture_output=True, text=True)
    assert checked.returncode == 0, checked.stderr
    named = set(NAMED.findall(script.read_text()))
    missing = sorted(n for n in named if not (ROOT / n).exists())
    assert not missing, f"{script.name} names {missing}"
