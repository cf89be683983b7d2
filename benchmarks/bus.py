"""Lockstep round trip per control tick: raw Zenoh vs the framework's body<->controller link vs one process.

    python benchmarks/bus.py [--ticks 5000]

(raw) a bare Zenoh pub/sub ping-pong between two processes (100-byte payload);
(framework) the body's BusLink to a controller hosted by ``sfl_brain.host`` in another process:
    a SensorFrame out, a MotorCommand back, typed, encoded, dispatched (the open-loop controller);
(one process) the same exchange through InProcessLink.
It also times ``sfl run`` start-up (five module processes) to the first trial.
"""

from __future__ import annotations

import argparse
import subprocess
import sys
import textwrap
import time
from pathlib import Path

import numpy as np
import zenoh

sys.path.insert(0, str(Path(__file__).resolve().parent))
from _common import controller_spec, spawn_host, stats, wait_alive  # noqa: E402

from modules.controllers.open_loop import OpenLoopController  # noqa: E402
from sfl_brain import bus  # noqa: E402
from sfl_brain.body import InProcessLink  # noqa: E402
from sfl_brain.host import BusLink  # noqa: E402
from sfl_brain.messages import ControllerReset, SensorFrame  # noqa: E402

PONG = textwrap.dedent("""
    import sys, zenoh
    sys.path.insert(0, {root!r})
    from sfl_brain import bus
    s = bus.open_session(["tcp/127.0.0.1:0"], [sys.argv[1]])
    tok = s.liveliness().declare_token("bench/pong")
    sub = s.declare_subscriber("bench/ping"); pub = s.declare_publisher("bench/pong")
    while True:
        smp = sub.recv()
        if smp.payload.to_bytes() == b"stop": break
        pub.put(smp.payload)
    s.close()
""")
SENSORS = ["hip_l", "hip_r", "knee_l", "knee_r", "contact_l", "contact_r", "slope", "pitch"]
COMMANDS = ["v_hip_l", "v_hip_r", "v_knee_l", "v_knee_r"]


def raw_round_trips(session, endpoint, ticks):
    proc = subprocess.Popen([sys.executable, "-c", PONG.format(root=str(Path(__file__).resolve().parents[1])),
                             endpoint])
    wait_alive(session, "bench/pong")
    import queue

    pub = session.declare_publisher("bench/ping")
    q = queue.SimpleQueue()
    sub = session.declare_subscriber("bench/pong", zenoh.handlers.Callback(lambda s: q.put(s.payload.to_bytes()),
                                                                              indirect=False))
    payload = b"x" * 100
    times = []
    for i in range(ticks + 200):
        t = time.perf_counter()
        pub.put(payload)
        q.get()
        if i >= 200:
            times.append(time.perf_counter() - t)
    pub.put(b"stop")
    proc.wait(timeout=10)
    sub.undeclare()
    pub.undeclare()
    return times


def framework_round_trips(session, endpoint, ticks):
    run_id = "benchbus"
    spec = controller_spec(run_id, "modules.controllers.open_loop:OpenLoopController", endpoint)
    proc = spawn_host(spec)
    wait_alive(session, bus.alive_key(run_id, "controller"))
    link = BusLink(session, run_id, "body", "controller", 10.0)
    link.reset(ControllerReset(trial_id=0, seed=0, params={}, sensors=SENSORS, commands=COMMANDS))
    values = np.zeros(len(SENSORS))
    times = []
    for i in range(ticks + 200):
        frame = SensorFrame(trial_id=0, tick=i, values=values)
        t = time.perf_counter()
        link.step(frame)
        if i >= 200:
            times.append(time.perf_counter() - t)
    link.close()
    proc.terminate()
    proc.wait(timeout=10)
    return times


def in_process_round_trips(ticks):
    link = InProcessLink(OpenLoopController())
    link.reset(ControllerReset(trial_id=0, seed=0, params={}, sensors=SENSORS, commands=COMMANDS))
    values = np.zeros(len(SENSORS))
    times = []
    for i in range(ticks):
        frame = SensorFrame(trial_id=0, tick=i, values=values)
        t = time.perf_counter()
        link.step(frame)
        times.append(time.perf_counter() - t)
    return times


def startup(repeats=3):
    import tempfile

    from sfl_brain.run import run
    from sfl_brain.scenario import load

    ready = []
    root = Path(__file__).resolve().parents[1]
    for _ in range(repeats):
        plan = load(root / "scenarios" / "quickstart.yaml", ["protocol.trials=1", "record.body_every=0"])
        first = {}
        t0 = time.perf_counter()
        with tempfile.TemporaryDirectory() as tmp:
            run(plan, Path(tmp) / "run", on_ready=lambda sup, s: first.setdefault("ready", s),
                on_progress=lambda p: first.setdefault("trial", time.perf_counter() - t0))
        ready.append((first["ready"], first["trial"]))
    return np.array(ready)


def main() -> None:
    parser = argparse.ArgumentParser()
    parser.add_argument("--ticks", type=int, default=5000)
    args = parser.parse_args()
    endpoint = bus.free_endpoint()
    session = bus.open_session([endpoint], [])
    try:
        raw = raw_round_trips(session, endpoint, args.ticks)
        framework = framework_round_trips(session, endpoint, args.ticks)
    finally:
        session.close()
    local = in_process_round_trips(args.ticks)
    print(f"lockstep round trip per tick, {args.ticks} ticks")
    print(f"  raw zenoh pub/sub (2 processes)     {stats(raw)}")
    print(f"  sfl BusLink <-> host (2 processes)  {stats(framework)}")
    print(f"  sfl InProcessLink (1 process)       {stats(local)}")
    ratio = np.median(framework) / np.median(raw)
    print(f"  framework / raw (medians): {ratio:.2f}  (goal <= 1.20)")
    s = startup()
    print(f"sfl run start-up, 5 module processes: ready {np.median(s[:, 0]):.2f} s, first trial done "
          f"{np.median(s[:, 1]):.2f} s (median of {len(s)}; goal <= 2 s)")


if __name__ == "__main__":
    main()
