"""Shared helpers for the benchmarks: medians and percentiles printed side by side."""

from __future__ import annotations

import json
import subprocess
import sys
import time

import numpy as np


def stats(samples_s) -> str:
    a = np.asarray(samples_s) * 1e6
    return f"median {np.median(a):8.1f} us   p99 {np.percentile(a, 99):8.1f} us"


def spawn_host(spec: dict) -> subprocess.Popen:
    return subprocess.Popen(
        [sys.executable, "-m", "sfl_brain.host", json.dumps(spec)],
        stdin=subprocess.PIPE,
        stderr=subprocess.DEVNULL,
    )


def wait_alive(session, key: str, timeout: float = 30.0) -> None:
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        if list(session.liveliness().get(key, timeout=1.0)):
            return
    raise RuntimeError(f"{key} not alive")


def controller_spec(run_id: str, reference: str, endpoint: str, cpus: list[int] | None = None) -> dict:
    """Host spec of a controller process that answers a body named ``body`` on ``endpoint``,
    pinned to ``cpus`` as ``sfl run`` pins a controller process (None: not pinned)."""
    return {
        "run_id": run_id,
        "instance": "controller",
        "spec_name": "controller",
        "reference": reference,
        "params": {},
        "seed": 0,
        "routes": {"body.command": "body"},
        "listen": ["tcp/127.0.0.1:0"],
        "connect": [endpoint],
        "rrd": None,
        "viewer": None,
        "tick_timeout": 10.0,
        "cpus": cpus,
    }
