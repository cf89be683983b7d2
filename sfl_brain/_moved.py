"""Where the modules of the flat ``sfl_brain`` went (issue 30), so that an import of an old path keeps working.

``import sfl_brain.records`` gives the very module ``sfl_brain.recording.records`` (the same object: a
monkeypatch or an ``isinstance`` through either name sees one module). New code imports the new path;
:mod:`sfl_brain.scenario` and :mod:`sfl_brain.protocols` need no entry, their packages export what the modules did;
the old modules ``runtime``, ``report`` and ``study`` are now packages of those names, which hand out the old
module's names on first use (see their ``__getattr__``).
"""

from __future__ import annotations

import importlib
import importlib.abc
import importlib.machinery
import sys

#: old path -> new path
MOVED = {
    "sfl_brain.records": "sfl_brain.recording.records",
    "sfl_brain.tables": "sfl_brain.recording.tables",
    "sfl_brain.rrlog": "sfl_brain.recording.rrlog",
    "sfl_brain.rerun_sink": "sfl_brain.recording.rerun_sink",
    "sfl_brain.recorded": "sfl_brain.recording.recorded",
    "sfl_brain.provenance": "sfl_brain.recording.provenance",
    "sfl_brain.metrics": "sfl_brain.recording.metrics",
    "sfl_brain.local": "sfl_brain.protocols.local",
    "sfl_brain.service": "sfl_brain.protocols.service",
    "sfl_brain.host": "sfl_brain.runtime.host",
    "sfl_brain.ticklink": "sfl_brain.runtime.ticklink",
    "sfl_brain.bus": "sfl_brain.runtime.bus",
    "sfl_brain.processes": "sfl_brain.runtime.processes",
    "sfl_brain.placement": "sfl_brain.runtime.placement",
    "sfl_brain.liveness": "sfl_brain.runtime.liveness",
    "sfl_brain.worker": "sfl_brain.runtime.worker",
    "sfl_brain.run": "sfl_brain.runtime.run",
    "sfl_brain.progress": "sfl_brain.runtime.progress",
    "sfl_brain.study_dask": "sfl_brain.study.cluster",
    "sfl_brain.study_view": "sfl_brain.study.view",
    "sfl_brain.report_ch5": "sfl_brain.report.ch5",
    "sfl_brain.report_conditions": "sfl_brain.report.conditions",
    "sfl_brain.report_cpg": "sfl_brain.report.cpg",
    "sfl_brain.report_study": "sfl_brain.report.study",
    "sfl_brain.report_sweep": "sfl_brain.report.sweep",
    "sfl_brain.report_terrain": "sfl_brain.report.terrain",
    "sfl_brain.poincare": "sfl_brain.report.poincare",
    "sfl_brain.stats": "sfl_brain.report.stats",
}


class _Alias(importlib.abc.MetaPathFinder, importlib.abc.Loader):
    """Finds an old path in :data:`MOVED` and loads it as the module at its new path."""

    def find_spec(self, fullname, path=None, target=None):
        if fullname not in MOVED:
            return None
        return importlib.machinery.ModuleSpec(fullname, self)

    def create_module(self, spec):
        return importlib.import_module(MOVED[spec.name])

    def exec_module(self, module):
        """Nothing to run: the module at the new path is already imported."""


def install() -> None:
    """Put the finder last on :data:`sys.meta_path` (a module that exists always wins), once."""
    if not any(isinstance(finder, _Alias) for finder in sys.meta_path):
        sys.meta_path.append(_Alias())


def forward(package: str, module: str):
    """A module ``__getattr__`` for ``package``, once a module itself: a name it lacks that is not one of its
    submodules is looked up in ``module`` (imported then, so importing the package stays light)."""
    import pkgutil

    submodules = {info.name for info in pkgutil.iter_modules(sys.modules[package].__path__)}

    def __getattr__(name: str):
        if name.startswith("__") or name in submodules:  # ``from . import bus`` asks before it imports
            raise AttributeError(f"module {package!r} has no attribute {name!r}")
        try:
            return getattr(importlib.import_module(module), name)
        except AttributeError:
            raise AttributeError(f"module {package!r} has no attribute {name!r}") from None

    return __getattr__
