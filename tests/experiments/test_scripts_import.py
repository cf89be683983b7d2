"""Every script under ``docs/experiments/`` and ``docs/calibration/`` still imports what it uses from the package
(``baselines_page.py`` named functions a refactor of ``sfl_brain.report.study`` had renamed, and nothing ran it
until its studies ended). Their ``main`` needs run folders, hours of them; their imports are checked here."""

from __future__ import annotations

import importlib.util
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]
SCRIPTS = sorted([*(ROOT / "docs" / "experiments").glob("*.py"), *(ROOT / "docs" / "calibration").glob("*.py")])


@pytest.mark.parametrize("script", SCRIPTS, ids=[s.name for s in SCRIPTS])
def test_the_script_imports(script):
    spec = importlib.util.spec_from_file_location(f"script_{script.stem}", script)
    module = importlib.util.module_from_spec(spec)
    sys.modules[spec.name] = module  # as an import would (its dataclasses look themselves up there)
    spec.loader.exec_module(module)  # module level only: main() is behind `if __name__ == "__main__"`
    assert callable(getattr(module, "main", None)), f"{script.name}: no main()"
