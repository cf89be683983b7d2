"""Finding module implementations: by registered name, ``package.module:Class`` or ``file.py:Class``.

Registered names come from the ``sfl_brain.modules`` entry-point group, so a third-party
package registers its own modules in its ``pyproject.toml`` without touching this one.
"""

from __future__ import annotations

import difflib
import importlib
import importlib.util
import signal
import sys
import threading
import time
from importlib.metadata import entry_points
from pathlib import Path

from .module import Module

GROUP = "sfl_brain.modules"


class ImplError(LookupError):
    """An implementation reference that does not resolve; ``suggestion`` is the nearest name."""

    def __init__(self, message: str, suggestion: str | None = None) -> None:
        super().__init__(message)
        self.suggestion = suggestion


def registered() -> dict[str, str]:
    """Registered implementations: name -> ``package.module:Class``."""
    return {ep.name: ep.value for ep in entry_points(group=GROUP)}


def nearest(name: str, choices) -> str | None:
    """The valid name a user most likely meant by ``name`` (None when none is close): case does not count, so
    ``CMA`` finds ``cma`` and ``Distance`` finds ``distance``."""
    by_lower: dict[str, str] = {}
    for choice in choices:
        by_lower.setdefault(str(choice).lower(), choice)
    found = difflib.get_close_matches(str(name).lower(), list(by_lower), n=1, cutoff=0.5)
    return by_lower[found[0]] if found else None


class _ImportTimeout(BaseException):
    """Raised by the alarm in :func:`_guarded`; a BaseException so a module's ``except Exception``
    does not swallow it."""


def _guarded(what: str, load, timeout: float | None):
    """Run ``load()`` (an import) and turn anything it raises into an :class:`ImplError`.

    Only KeyboardInterrupt passes through: a module that raises SystemExit (``sys.exit()``) or any
    other BaseException on import is reported, not obeyed. With ``timeout`` (seconds), an import
    that takes longer is interrupted by SIGALRM where that is possible (POSIX, main thread); an
    alarm already set (e.g. by pytest-timeout) is put back afterwards with its remaining time.
    A hang in C code that never returns to Python, and ``os._exit()``, are not caught.
    """
    previous = signal.getsignal(signal.SIGALRM) if hasattr(signal, "setitimer") else None
    pending = signal.getitimer(signal.ITIMER_REAL)[0] if previous is not None else 0.0
    alarm = (
        timeout is not None
        and previous is not None
        and threading.current_thread() is threading.main_thread()
        and not (pending and pending <= timeout)  # an earlier alarm fires first anyway
    )
    armed = alarm

    def expire(signum, frame):
        if armed:
            raise _ImportTimeout

    if alarm:
        started = time.monotonic()
        signal.signal(signal.SIGALRM, expire)
        signal.setitimer(signal.ITIMER_REAL, timeout)
    try:
        try:
            return load()
        finally:
            armed = False
    except ImplError:
        raise
    except KeyboardInterrupt:
        raise
    except _ImportTimeout:
        raise ImplError(f"importing {what} did not finish within {timeout:g} s (timeouts.ready)") from None
    except BaseException as exc:  # noqa: BLE001 - SystemExit and friends on import are reported
        text = str(exc)
        raise ImplError(f"importing {what} failed: {type(exc).__name__}" + (f": {text}" if text else "")) from None
    finally:
        if alarm:
            signal.setitimer(signal.ITIMER_REAL, 0)
            signal.signal(signal.SIGALRM, previous)
            if pending:
                signal.setitimer(signal.ITIMER_REAL, max(pending - (time.monotonic() - started), 0.001))


def _load_file(path: Path):
    """Import a module from a file (once per process; a failed import is forgotten, so a fixed file
    is read again)."""
    module_name = f"sfl_user_{abs(hash(str(path)))}"
    if module_name in sys.modules:
        return sys.modules[module_name]
    spec = importlib.util.spec_from_file_location(module_name, path)
    if spec is None or spec.loader is None:
        raise ImplError(f"cannot import {path}")
    module = importlib.util.module_from_spec(spec)
    sys.modules[module_name] = module
    try:
        spec.loader.exec_module(module)
    except BaseException:
        sys.modules.pop(module_name, None)
        raise
    return module


def resolve(impl: str, base_dir: Path | None = None, timeout: float | None = None) -> tuple[type[Module], str]:
    """Return (class, canonical reference usable from any working directory).

    Raises :class:`ImplError` for anything that goes wrong, including an import that raises,
    calls ``sys.exit()`` or (with ``timeout`` seconds) does not finish.
    """
    table = registered()
    if impl in table:
        reference = table[impl]
    elif ":" in impl:
        reference = impl
    else:
        raise ImplError(f"no registered implementation {impl!r}", nearest(impl, table))
    target, _, class_name = reference.rpartition(":")
    if not target or not class_name or "\0" in reference:
        raise ImplError(f"expected 'package.module:Class' or 'path/file.py:Class'; got {impl!r}")
    if target.endswith(".py"):
        path = Path(target)
        try:
            if not path.is_absolute():
                candidates = [(base_dir or Path.cwd()) / path, Path.cwd() / path]
                path = next((c for c in candidates if c.is_file()), candidates[0])
            found = path.is_file()
            path = path.resolve()
        except OSError as exc:
            raise ImplError(f"cannot look for file {target}: {exc.strerror}") from None
        if not found:
            raise ImplError(f"file {target} not found (looked in {base_dir or Path.cwd()})")
        module = _guarded(str(path), lambda: _load_file(path), timeout)
        reference = f"{path}:{class_name}"
    else:
        module = _guarded(target, lambda: importlib.import_module(target), timeout)
    try:
        cls = getattr(module, class_name, None)
    except Exception as exc:  # a module-level __getattr__ that raises
        raise ImplError(f"{target}: looking up {class_name!r} failed: {type(exc).__name__}: {exc}") from None
    if cls is None:
        names = [n for n, v in vars(module).items() if isinstance(v, type) and issubclass(v, Module)]
        raise ImplError(f"{target} has no class {class_name!r}", nearest(class_name, names))
    if not (isinstance(cls, type) and issubclass(cls, Module)):
        raise ImplError(f"{reference} is not a sfl_brain Module subclass")
    return cls, reference
