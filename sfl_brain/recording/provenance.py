"""What produced a run, and what decides the last bits of its floats.

``provenance()`` is written to every run folder (``provenance.json``) and printed at the start of the test run. Its
``numeric_platform`` names what makes the same scenario and seed give float-for-float the same records on one machine
and not always on another (``docs/records.md``, "Reproducibility"): numpy picks its SIMD kernels when it is imported,
by the CPU it finds (on a CPU with AVX-512 its ``exp``, ``tanh``, ``sin`` of float64 arrays come from Intel's SVML,
elsewhere from the C library, and they differ in the last bit on a few percent of inputs); OpenBLAS picks its kernels
(``@``, ``np.dot``) the same way; and pymunk and PyBullet are compiled code of their own versions. Two machines with
the same ``numeric_platform`` and package versions give the same records bit for bit.
"""

from __future__ import annotations

import os
import platform
import subprocess
import sys
from datetime import UTC, datetime
from pathlib import Path

#: the distributions whose versions a run records (what computes, moves and stores its numbers)
DISTRIBUTIONS = (
    "sfl-brain",
    "numpy",
    "scipy",
    "eclipse-zenoh",
    "rerun-sdk",
    "pymunk",
    "pybullet",
    "pydantic",
    "msgspec",
    "pyarrow",
)

#: a pathspec of what runs write into the source tree (docs/results): outputs, not changes to the code that ran
OUTPUTS = ":!docs/results"


def versions(distributions=DISTRIBUTIONS) -> dict[str, str]:
    """The installed version of each distribution (those not installed are left out)."""
    from importlib import metadata

    found = {}
    for dist in distributions:
        try:
            found[dist] = metadata.version(dist)
        except metadata.PackageNotFoundError:
            continue
    return found


def numeric_platform() -> dict:
    """The machine as the floats see it: the CPU architecture, the C library (its ``exp``, ``sin``...), the SIMD
    kernels numpy dispatches to on this CPU (``baseline`` compiled in, ``dispatched`` chosen at import), and the
    OpenBLAS core type (None when it cannot be read without loading anything new)."""
    import numpy as np

    try:
        from numpy._core import _multiarray_umath as umath
    except ImportError:  # numpy 1.x
        from numpy.core import _multiarray_umath as umath
    features = umath.__cpu_features__
    libc, libc_version = platform.libc_ver()
    return {
        "machine": platform.machine(),
        "libc": f"{libc} {libc_version}".strip() or None,
        "numpy": np.__version__,
        "numpy_simd": {
            "baseline": list(umath.__cpu_baseline__),
            "dispatched": [target for target in umath.__cpu_dispatch__ if features.get(target)],
        },
        "blas": _blas_core(),
    }


def describe_platform(numeric: dict | None) -> str:
    """A numeric platform (:func:`numeric_platform`) in one line: ``x86_64, glibc 2.36, numpy 2.4.6 SIMD X86_V2
    dispatching X86_V3, OpenBLAS Haswell``."""
    if not numeric:
        return "numeric platform not recorded"
    simd = numeric.get("numpy_simd") or {}
    parts = [numeric.get("machine") or "?", numeric.get("libc") or ""]
    numpy = f"numpy {numeric['numpy']} " if numeric.get("numpy") else "numpy "
    baseline, dispatched = "+".join(simd.get("baseline") or []), "+".join(simd.get("dispatched") or [])
    parts.append(numpy + f"SIMD {baseline or '?'} dispatching {dispatched or 'nothing'}")
    parts.append(f"OpenBLAS {numeric['blas']}" if numeric.get("blas") else "")
    return ", ".join(p for p in parts if p)


def _blas_core() -> str | None:
    """OpenBLAS's core type (e.g. ``Haswell``, ``SkylakeX``), read by threadpoolctl when it is installed."""
    try:
        from threadpoolctl import threadpool_info
    except ImportError:
        return None
    for lib in threadpool_info():
        if lib.get("internal_api") == "openblas":
            return lib.get("architecture")
    return None


def source_commit(source: Path) -> tuple[str | None, bool | None]:
    """The commit checked out in ``source`` and whether its code has uncommitted changes (what runs write into
    ``docs/results`` does not count); ``(None, None)`` outside a git checkout."""
    try:
        head = subprocess.run(
            ["git", "-C", str(source), "rev-parse", "HEAD"], capture_output=True, text=True, timeout=5
        )
        if head.returncode != 0:
            return None, None
        status = subprocess.run(
            ["git", "-C", str(source), "status", "--porcelain", "--untracked-files=no", "--", ".", OUTPUTS],
            capture_output=True,
            text=True,
            timeout=5,
        )
        return head.stdout.strip(), bool(status.stdout.strip())
    except (OSError, subprocess.SubprocessError):
        return None, None


def provenance() -> dict:
    """What produced a run: package versions, Python, the platform and its numeric platform, the source commit."""
    source = Path(__file__).resolve().parents[1]
    commit, dirty = source_commit(source)
    return {
        "versions": versions(),
        "python": sys.version.split()[0],
        "platform": platform.platform(),
        "numeric_platform": numeric_platform(),
        "cpus": os.cpu_count(),
        "commit": commit,
        "uncommitted_changes": dirty,
        "source": str(source),
        "started": datetime.now(UTC).isoformat(timespec="seconds"),
    }


def made_here() -> str:
    """The line a page that a script writes itself (not ``sfl report``, whose pages say it of their runs) puts under its
    title: the commit and numeric platform it was computed with, and the day."""
    made = provenance()
    commit = f"`{made['commit'][:7]}`" if made["commit"] else "no git commit"
    dirty = " (with uncommitted changes)" if made["uncommitted_changes"] else ""
    return f"Made at {commit}{dirty}, {made['started'][:10]}, on {describe_platform(made['numeric_platform'])}."
