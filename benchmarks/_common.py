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
        [sys.executable, "-m", "sfl_brain.runtime.host", json.dumps(spec)],
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


class HostedPair:
    """A body and its controller, each hosted by ``sfl_brain.runtime.host`` in a process of its own, as ``sfl run``
    hosts a body worker and its controller process: placed as ``lockstep.pin_cpus`` ``pin`` places them
    (or ``apart``: a core each, as ``pin_cpus: always`` did before issue 24), their frames and commands
    on a lockstep link of their own (``link`` "socket", as ``sfl run`` by default, or "zenoh": a Zenoh
    lowlatency session, ``lockstep.link: zenoh``) or on the mesh (``link`` "mesh"). ``body`` None:
    only the controller is hosted, and the caller is the body (``tick``: the link's endpoint)."""

    def __init__(
        self,
        session,
        endpoint: str,
        run_id: str,
        controller: str,
        body: str | None = None,
        *,
        pin: str = "auto",
        link: str = "socket",
        folder=None,
        controller_params: dict | None = None,
        body_params: dict | None = None,
        spin: float = 0.0,
    ) -> None:
        from sfl_brain.messages import SensorFrame
        from sfl_brain.runtime import bus
        from sfl_brain.runtime.placement import Pair, Placement, place, usable_cpus

        if pin == "apart":  # a core each, as lockstep.pin_cpus always placed a pair before issue 24
            cpus = usable_cpus()
            cores = {"body": (cpus[0],), "controller": (cpus[-1],)} if len(cpus) > 1 else {}
            self.placement = Placement("apart", tuple(cpus), cores, "body and controller on a core each")
        else:
            self.placement = place([Pair("body", "controller")], [], usable_cpus(), pin)
        from sfl_brain.runtime import ticklink

        self.link = link
        endpoints = {"socket": ticklink.endpoint, "zenoh": bus.tick_endpoint}
        self.tick = endpoints[link](folder, run_id) if link in endpoints else None
        spec = controller_spec(run_id, controller, endpoint, self.placement.of("controller"))
        spec.update(params=controller_params or {}, tick={"listen": [self.tick]} if self.tick else None)
        self.procs = [spawn_host(spec)]
        names = ["controller"]
        if body is not None:
            spec = controller_spec(run_id, body, endpoint, self.placement.of("body"))
            spec.update(
                instance="body",
                spec_name="body",
                params=body_params or {},
                routes={SensorFrame.TAG: "controller"},
                spin=spin,
                tick={"connect": [self.tick]} if self.tick else None,
            )
            self.procs.append(spawn_host(spec))
            names.append("body")
        for name in names:
            wait_alive(session, bus.alive_key(run_id, name))

    def where(self) -> str:
        return self.placement.reason

    def close(self) -> None:
        for proc in self.procs:
            proc.terminate()
            proc.wait(timeout=10)


class Pinned:
    """While in the block, this process runs on ``cores`` (None: as it was): a one-process figure on the core a
    pair runs on, so that both meet the same neighbours on a busy machine."""

    def __init__(self, cores) -> None:
        self.cores = cores

    def __enter__(self):
        from sfl_brain.runtime.placement import pin, usable_cpus

        self.before = usable_cpus()
        pin(self.cores)
        return self

    def __exit__(self, *exc):
        from sfl_brain.runtime.placement import pin

        pin(self.before)
