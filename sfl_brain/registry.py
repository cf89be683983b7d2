"""Finding module implementations: by registered name, ``package.module:Class`` or ``file.py:Class``.

Registered names come from the ``sfl_brain.modules`` entry-point group, so a third-party
package registers its own modules in its ``pyproject.toml`` without touching this one.
"""

from __future__ import annotations

import difflib
import importlib
import importlib.util
import sys
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
    found = difflib.get_close_matches(name, list(choices), n=1, cutoff=0.5)
    return found[0] if found else None


def _load_file(path: Path, class_name: str):
    module_name = f"sfl_user_{abs(hash(str(path)))}"
    if module_name in sys.modules:
        module = sys.modules[module_name]
    else:
        spec = importlib.util.spec_from_file_location(module_name, path)
        if spec is None or spec.loader is None:
            raise ImplError(f"cannot import {path}")
        module = importlib.util.module_from_spec(spec)
        sys.modules[module_name] = module
        spec.loader.exec_module(module)
    return module, class_name


def resolve(impl: str, base_dir: Path | None = None) -> tuple[type[Module], str]:
    """Return (class, canonical reference usable from any working directory)."""
    table = registered()
    if impl in table:
        reference = table[impl]
    elif ":" in impl:
        reference = impl
    else:
        raise ImplError(f"no registered implementation {impl!r}", nearest(impl, table))
    target, _, class_name = reference.rpartition(":")
    if target.endswith(".py"):
        path = Path(target)
        if not path.is_absolute():
            candidates = [(base_dir or Path.cwd()) / path, Path.cwd() / path]
            path = next((c for c in candidates if c.exists()), candidates[0])
        if not path.exists():
            raise ImplError(f"file {target} not found (looked in {base_dir or Path.cwd()})")
        path = path.resolve()
        try:
            module, class_name = _load_file(path, class_name)
        except ImplError:
            raise
        except Exception as exc:
            raise ImplError(f"importing {path} failed: {type(exc).__name__}: {exc}") from None
        reference = f"{path}:{class_name}"
    else:
        try:
            module = importlib.import_module(target)
        except Exception as exc:
            raise ImplError(f"importing {target} failed: {type(exc).__name__}: {exc}") from None
    cls = getattr(module, class_name, None)
    if cls is None:
        names = [n for n, v in vars(module).items() if isinstance(v, type) and issubclass(v, Module)]
        raise ImplError(f"{target} has no class {class_name!r}", nearest(class_name, names))
    if not (isinstance(cls, type) and issubclass(cls, Module)):
        raise ImplError(f"{reference} is not a sfl_brain Module subclass")
    return cls, reference
