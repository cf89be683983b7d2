"""Lockstep round trip per control tick: raw Zenoh vs the framework's body<->controller link vs one process.

    python benchmarks/bus.py [--ticks 10000] [--blocks 20] [--spin-us 200] [--pin never|auto|always]

The pings and pongs are placed as ``sfl run`` places a body worker and its controller process
under ``pin_cpus`` ``--pin`` (default ``never``, as a scenario; see ``sfl_brain.placement``).

(raw) a bare Zenoh pub/sub ping-pong between two processes (100-byte payload), both sides
    blocking in a ring channel's recv();
(raw, polling) the same, but the ping polls try_recv() for up to --spin-us before it blocks, as
    a body does (``lockstep.spin_us``); the faster of the two raw patterns is the goal's baseline;
(example) the same ping-pong as zenoh-python's own z_ping.py / z_pong.py examples (the pong
    answers in a subscriber callback, the ping waits on the default FIFO channel), the usual
    pattern of a "raw Zenoh Python round trip", shown for reference;
(typed) the polling raw pattern carrying the framework's typed messages, written by hand: the
    pong decodes the SensorFrame, calls the open-loop controller's handler and encodes its
    MotorCommand; the ping encodes and decodes. No host, no BusLink: this splits the framework's
    cost into the typed codec and dispatch, and the runtime around them;
(framework) the body's BusLink to a controller hosted by ``sfl_brain.host`` in another process:
    a SensorFrame out, a MotorCommand back, typed, encoded, dispatched (the open-loop controller),
    waiting as a body does (``SpinThenSleep`` with --spin-us);
    raw and framework run in interleaved blocks so that both see the same machine load;
(one process) the same exchange through InProcessLink.
It also times ``sfl run`` start-up (five module processes) to the first trial.
"""

from __future__ import annotations

import argparse
import json
import subprocess
import sys
import textwrap
import time
from pathlib import Path

import numpy as np
import zenoh

sys.path.insert(0, str(Path(__file__).resolve().parent))
from _common import controller_spec, spawn_host, stats, wait_alive  # noqa: E402

from sfl_brain import bus  # noqa: E402
from sfl_brain.body import InProcessLink  # noqa: E402
from sfl_brain.host import BusLink  # noqa: E402
from sfl_brain.messages import ControllerReset, SensorFrame, decode, encode  # noqa: E402
from sfl_brain.modules.controllers.open_loop import OpenLoopController  # noqa: E402
from sfl_brain.placement import assign, pin, usable_cpus  # noqa: E402

# every pong: placed (argv[2], JSON cores or null), then a session that connects to the ping (argv[1])
PREAMBLE = textwrap.dedent("""
    import json, sys, threading, zenoh
    sys.path.insert(0, {root!r})
    from sfl_brain import bus
    from sfl_brain.placement import pin
    pin(json.loads(sys.argv[2]))
    s = bus.open_session(["tcp/127.0.0.1:0"], [sys.argv[1]])
""")
PONG = textwrap.dedent("""
    sub = s.declare_subscriber("{prefix}/ping", zenoh.handlers.RingChannel(64))
    pub = s.declare_publisher("{prefix}/pong")
    tok = s.liveliness().declare_token("{prefix}/pong")
    while True:
        smp = sub.recv()
        if smp.payload.to_bytes() == b"stop": break
        pub.put(smp.payload)
    s.close()
""")
# zenoh-python's examples/z_pong.py, on its own keys
PONG_EXAMPLE = textwrap.dedent("""
    done = threading.Event()
    pub = s.declare_publisher("bench/ex/pong", congestion_control=zenoh.CongestionControl.BLOCK)
    def pong(smp):
        if smp.payload.to_bytes() == b"stop": done.set()
        else: pub.put(smp.payload)
    s.declare_subscriber("bench/ex/ping", pong)
    tok = s.liveliness().declare_token("bench/ex/pong")
    done.wait()
    s.close()
""")
# (typed): the raw pong with the framework's codec and the open-loop controller, by hand
PONG_TYPED = textwrap.dedent("""
    from sfl_brain.messages import ControllerReset, decode, encode
    from sfl_brain.modules.controllers.open_loop import OpenLoopController
    controller = OpenLoopController()
    controller.handle(ControllerReset(trial_id=0, seed=0, params={}, sensors=["s"] * 8,
                                      commands=list(controller.WRITES)))
    sub = s.declare_subscriber("bench/typed/ping", zenoh.handlers.RingChannel(64))
    pub = s.declare_publisher("bench/typed/pong")
    tok = s.liveliness().declare_token("bench/typed/pong")
    while True:
        data = sub.recv().payload.to_bytes()
        if data == b"stop": break
        pub.put(encode(controller.handle(decode(data))))
    s.close()
""")
SENSORS = ["hip_l", "hip_r", "knee_l", "knee_r", "contact_l", "contact_r", "slope", "pitch"]
COMMANDS = ["v_hip_l", "v_hip_r", "v_knee_l", "v_knee_r"]


class Raw:
    """A bare ping-pong. ``raw``: both sides blocking in a ring channel's recv(); ``polling``: the
    same, the ping polling for up to ``spin`` seconds first. ``example``: zenoh-python's
    z_ping/z_pong (callback pong, FIFO ping). ``typed``: the polling pattern with the framework's
    messages, codec and controller, by hand."""

    def __init__(self, session, endpoint, kind, cpus, spin=0.0):
        root = str(Path(__file__).resolve().parents[1])
        prefix, script = {
            "raw": ("bench", PONG.format(prefix="bench")),
            "polling": ("bench/poll", PONG.format(prefix="bench/poll")),
            "example": ("bench/ex", PONG_EXAMPLE),
            "typed": ("bench/typed", PONG_TYPED),
        }[kind]
        self.spin = spin if kind in ("polling", "typed") else 0.0
        source = PREAMBLE.format(root=root) + script
        self.proc = subprocess.Popen([sys.executable, "-c", source, endpoint, json.dumps(cpus)])
        wait_alive(session, f"{prefix}/pong")
        if kind == "example":
            self.pub = session.declare_publisher(f"{prefix}/ping", congestion_control=zenoh.CongestionControl.BLOCK)
            self.sub = session.declare_subscriber(f"{prefix}/pong")
        else:
            self.pub = session.declare_publisher(f"{prefix}/ping")
            self.sub = session.declare_subscriber(f"{prefix}/pong", zenoh.handlers.RingChannel(64))
        self.typed = kind == "typed"
        self.payload = b"x" * 100
        self.values = np.zeros(len(SENSORS))
        self.tick = 0

    def wait(self):
        """Poll for up to ``spin`` seconds, then block."""
        try_recv, clock = self.sub.try_recv, time.perf_counter
        deadline = clock() + self.spin
        while (sample := try_recv()) is None and clock() < deadline:
            pass
        return sample if sample is not None else self.sub.recv()

    def block(self, ticks):
        times = []
        pub, recv, payload = self.pub, self.wait if self.spin else self.sub.recv, self.payload
        for _ in range(ticks):
            if self.typed:
                frame = SensorFrame(trial_id=0, tick=self.tick, values=self.values)
                self.tick += 1
                t = time.perf_counter()
                pub.put(encode(frame))
                decode(recv().payload.to_bytes())
            else:
                t = time.perf_counter()
                pub.put(payload)
                recv()
            times.append(time.perf_counter() - t)
        return times

    def close(self):
        self.pub.put(b"stop")
        self.proc.wait(timeout=10)
        self.sub.undeclare()
        self.pub.undeclare()


class Framework:
    """The body's BusLink to an open-loop controller hosted by ``sfl_brain.host``."""

    def __init__(self, session, endpoint, cpus, spin):
        run_id = "benchbus"
        reference = "sfl_brain.modules.controllers.open_loop:OpenLoopController"
        self.proc = spawn_host(controller_spec(run_id, reference, endpoint, cpus))
        wait_alive(session, bus.alive_key(run_id, "controller"))
        self.link = BusLink(session, run_id, "body", "controller", 10.0, spin)
        self.link.reset(ControllerReset(trial_id=0, seed=0, params={}, sensors=SENSORS, commands=COMMANDS))
        self.values = np.zeros(len(SENSORS))
        self.tick = 0

    def block(self, ticks):
        times = []
        step, values = self.link.step, self.values
        for _ in range(ticks):
            frame = SensorFrame(trial_id=0, tick=self.tick, values=values)
            self.tick += 1
            t = time.perf_counter()
            step(frame)
            times.append(time.perf_counter() - t)
        return times

    def close(self):
        self.link.close()
        self.proc.terminate()
        self.proc.wait(timeout=10)


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
            run(
                plan,
                Path(tmp) / "run",
                on_ready=lambda sup, s, f=first: f.setdefault("ready", s),
                on_progress=lambda p, f=first, t0=t0: f.setdefault("trial", time.perf_counter() - t0),
            )
        ready.append((first["ready"], first["trial"]))
    return np.array(ready)


def main() -> None:
    parser = argparse.ArgumentParser()
    parser.add_argument("--ticks", type=int, default=10000)
    parser.add_argument("--blocks", type=int, default=20)
    parser.add_argument("--spin-us", type=float, default=200.0, help="lockstep.spin_us")
    parser.add_argument("--pin", choices=["never", "auto", "always"], default="never", help="lockstep.pin_cpus")
    args = parser.parse_args()
    spin = args.spin_us * 1e-6
    # every variant placed as sfl run places a body and its controller process (lockstep.pin_cpus)
    cpus = usable_cpus()
    placed = assign(["body", "controller"], cpus, args.pin)
    pin(placed.get("body"))
    endpoint = bus.free_endpoint()
    session = bus.open_session([endpoint], [])
    sides = {}
    try:
        for kind in ("raw", "polling", "example", "typed"):
            sides[kind] = Raw(session, endpoint, kind, placed.get("controller"), spin)
        sides["framework"] = Framework(session, endpoint, placed.get("controller"), spin)
        times = {kind: [] for kind in sides}
        blocks = {kind: [] for kind in sides}  # the median of each block
        for side in sides.values():
            side.block(300)  # warm up
        block = max(args.ticks // args.blocks, 1)
        for _ in range(args.blocks):  # interleaved blocks, so that all see the same machine load
            for kind, side in sides.items():
                t = side.block(block)
                times[kind] += t
                blocks[kind].append(np.median(t))
    finally:
        for side in sides.values():
            side.close()
        session.close()
    # the goal's baseline: the faster bare pattern, blocking or polling
    base = min(("raw", "polling"), key=lambda kind: np.median(times[kind]))
    raw_t, example_t, typed_t, framework_t = times[base], times["example"], times["typed"], times["framework"]
    paired = np.array(blocks["framework"]) / np.array(blocks[base])
    over_typed = np.array(blocks["framework"]) / np.array(blocks["typed"])
    local = in_process_round_trips(args.ticks)
    where = f"pin {args.pin}: " + (
        f"ping on cores {placed['body']}, pong on {placed['controller']}" if placed else "not pinned"
    )
    print(f"lockstep round trip per tick, {args.ticks} ticks, {where}, spin {args.spin_us:g} us")
    print(f"  raw zenoh pub/sub (2 processes)      {stats(times['raw'])}")
    print(f"  the same, ping polling first         {stats(times['polling'])}")
    print(f"  zenoh's z_ping/z_pong (2 processes)  {stats(example_t)}")
    print(f"  typed messages by hand (2 processes) {stats(typed_t)}")
    print(f"  sfl BusLink <-> host (2 processes)   {stats(framework_t)}")
    print(f"  sfl InProcessLink (1 process)        {stats(local)}")
    ratio = np.median(framework_t) / np.median(raw_t)
    added = (np.median(framework_t) - np.median(raw_t)) * 1e6
    label = "raw" if base == "raw" else "raw polling"
    print(
        f"  framework / {label} (medians, the faster raw pattern): {ratio:.2f}  (goal <= 1.20); "
        f"the framework adds {added:.1f} us per tick"
    )
    q1, q2, q3 = np.percentile(paired, [25, 50, 75])
    print(
        f"  framework / {label}, block by block ({len(paired)} pairs of adjacent blocks): "
        f"median {q2:.2f}, IQR {q1:.2f}-{q3:.2f}"
    )
    print(f"  framework / z_ping-z_pong (medians): {np.median(framework_t) / np.median(example_t):.2f}")
    q1, q2, q3 = np.percentile(over_typed, [25, 50, 75])
    print(
        f"  framework / typed messages by hand, block by block: median {q2:.2f}, IQR {q1:.2f}-{q3:.2f}; "
        f"by hand, the typed messages add {(np.median(typed_t) - np.median(raw_t)) * 1e6:.1f} us per tick to raw"
    )
    pin(cpus)  # sfl run places its own processes
    s = startup()
    print(
        f"sfl run start-up, 5 module processes: ready {np.median(s[:, 0]):.2f} s, first trial done "
        f"{np.median(s[:, 1]):.2f} s (median of {len(s)}; goal <= 2 s)"
    )


if __name__ == "__main__":
    main()
