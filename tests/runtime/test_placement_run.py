"""A run places its lockstep pair and says so: real processes, the placement the OS reports, the link."""

from __future__ import annotations

import json
import os

import pytest

from sfl_brain.protocols.local import run_local
from sfl_brain.recording.records import read_records
from sfl_brain.runtime.placement import Pair, place, usable_cpus
from sfl_brain.scenario import load

from ..conftest import SCENARIOS, all_cores, on_all_cores, sfl_run

QUICK = SCENARIOS / "quickstart.yaml"
SETS = ("protocol.trials=6", "record.body_every=0", "modules.body.params.duration=3")
VOLATILE = {"wall_ms", "worker", "cpu_body_s", "cpu_controller_s"}


def stable(rows):
    return [{k: v for k, v in r.items() if k not in VOLATILE} for r in rows]


def logs(out) -> dict[str, str]:
    return {p.stem: p.read_text() for p in (out / "logs").glob("*.log")}


def answer_reset(query) -> None:
    """A controller's reset answered as its host answers it (a run without a secret)."""
    from sfl_brain.messages import Ack, ControllerReset, decode, encode
    from sfl_brain.runtime import bus

    seal = bus.Seal(None)
    nonce, body = seal.open_request(str(query.key_expr), query.payload.to_bytes())
    assert type(decode(body)) is ControllerReset
    query.reply(query.key_expr, seal.seal_reply(nonce, encode(Ack())))
    query.drop()


@pytest.mark.parametrize("link", ["socket", "zenoh"])
def test_a_run_pins_its_pair_to_one_core_logs_it_and_ticks_on_its_lockstep_link(tmp_path, link):
    out = tmp_path / "run"
    # on every core of the machine, also under pytest-xdist (whose workers each have a core of their own)
    done = sfl_run(QUICK, out, *SETS, f"lockstep.link={link}", preexec_fn=on_all_cores)
    assert done.returncode == 0, done.stderr
    machine = all_cores()
    placed = json.loads((out / "logs" / "placement.json").read_text())
    busy = {int(core): share for core, share in placed["load"].items()}  # what other work kept each core busy with
    assert (len(busy) == len(machine)) == (len(machine) > 1) and all(0 <= share <= 1 for share in busy.values())
    expected = place([Pair("body", "controller")], ["acc", "vigilance", "ofc"], machine, "auto", busy)
    assert f"sfl: {expected.describe()}" in done.stdout.splitlines()  # the line a user sees
    assert placed["cores"] == {name: list(cores) for name, cores in expected.cores.items()}
    assert placed["mode"] == "auto" and placed["usable_cores"] == machine
    text = logs(out)
    if expected.cores:  # as the OS says: both on one core (the least busy), the brain modules on quiet others
        pair_core = f"pinned to cores {expected.of('body')}"
        assert pair_core in text["body"] and pair_core in text["controller"]
        assert expected.of("body") == expected.of("controller") and len(expected.of("body")) == 1
        if expected.of("acc"):
            assert f"pinned to cores {expected.of('acc')}" in text["acc"]
    # the frames and commands went over the pair's own link: the controller listens, the body connects
    endpoint = placed["lockstep_links"]["controller"]["listen"][0]
    scheme, kind = {"socket": ("seqpacket/", "socket"), "zenoh": ("unixsock-stream/", "lowlatency")}[link]
    assert placed["lockstep_links"]["body"] == {"connect": [endpoint]} and endpoint.startswith(scheme)
    assert placed["ticks_on"].startswith("lockstep links (" + ("Unix sockets" if link == "socket" else "Zenoh"))
    assert f"lockstep link ({kind}): listening on {endpoint}" in text["controller"]
    assert f"lockstep link ({kind}): connecting to {endpoint}" in text["body"]
    assert not os.path.exists(os.path.dirname(endpoint.removeprefix(scheme)))  # removed with the run
    # over processes, the same trials as in one process
    assert stable(read_records(out)) == stable(run_local(load(QUICK, list(SETS))))


@pytest.mark.skipif(not hasattr(os, "sched_setaffinity"), reason="no CPU affinity on this OS")
def test_a_run_limited_to_one_core_by_taskset_pins_nothing(tmp_path):
    out = tmp_path / "run"
    core = usable_cpus()[-1]
    done = sfl_run(QUICK, out, *SETS, preexec_fn=lambda: os.sched_setaffinity(0, {core}))
    assert done.returncode == 0, done.stderr
    line = f"sfl: lockstep placement (lockstep.pin_cpus: auto, usable cores {core}): nothing pinned: one usable core"
    assert line in done.stdout.splitlines()
    assert all("pinned to cores" not in text for text in logs(out).values())
    assert json.loads((out / "logs" / "placement.json").read_text())["cores"] == {}


@pytest.mark.skipif(len(all_cores()) < 2, reason="one core: nothing is pinned")
def test_a_pairs_core_that_other_work_comes_to_keep_busy_makes_the_placement_yield(tmp_path):
    """The supervisor's look at the cores (``Pairs.yield_cores``, every RECHECK_S s) with real processes: a
    body and a controller pinned to one core, and a process that comes to spin there. The placement yields: a new
    placement on the load measured (the pair on a quiet core, or nothing pinned), every process moved as it says,
    the user told, placement.json keeping the first placement under ``earlier``."""
    import subprocess
    import sys

    import psutil

    from sfl_brain.events import PlacementYielded
    from sfl_brain.runtime.placement import Placement
    from sfl_brain.runtime.processes import Child
    from sfl_brain.runtime.supervisor import Supervisor

    from ..conftest import poll_until

    plan = load(QUICK, list(SETS))
    cores = all_cores()
    share = os.sched_getaffinity(0)
    os.sched_setaffinity(0, cores)  # the supervisor watches the cores it may use: all of them, not this worker's share
    try:
        sup = Supervisor(plan, tmp_path, "yield")
    finally:
        os.sched_setaffinity(0, share)
    pairs = sup.pairs
    (tmp_path / "logs").mkdir()
    pair = (cores[-1],)
    rest = tuple(cores[:-1])
    placed = {"body": pair, "controller": pair, "acc": rest, "vigilance": rest, "ofc": rest}
    pairs.placement = Placement("auto", tuple(cores), placed, "body and controller share the last core")
    pairs.write()
    told = []
    sup.events.subscribe(PlacementYielded, told.append)
    sleeper = [sys.executable, "-c", "import time; time.sleep(600)"]
    procs = []
    try:
        for inst in plan.instances:
            proc = subprocess.Popen(sleeper, preexec_fn=lambda c=placed[inst.name]: os.sched_setaffinity(0, c))
            procs.append(proc)
            sup.children[inst.name] = Child(inst, tmp_path / f"{inst.name}.log", proc=proc, alive=True)
        spin = subprocess.Popen(
            [sys.executable, "-c", "while True: pass"], preexec_fn=lambda: os.sched_setaffinity(0, set(pair))
        )
        procs.append(spin)
        pairs.yield_cores(sup.children)  # the first look starts the measurement
        poll_until(lambda: (pairs.yield_cores(sup.children), told)[1], "the placement to yield", timeout=60)
        # every process where the new placement says (the pair on a quiet core, or on every core)
        moved = {name: psutil.Process(child.proc.pid).cpu_affinity() for name, child in sup.children.items()}
    finally:
        for proc in procs:
            proc.kill()
            proc.wait()
    (event,) = told
    assert event.busy.startswith(f"core {pair[0]} ") and event.placement == pairs.placement.describe()
    assert pairs.placement.of("body") != list(pair) and pairs.placement.of("body") == pairs.placement.of("controller")
    assert moved == {name: pairs.placement.of(name) or cores for name in sup.children}
    assert moved["body"] != list(pair)
    written = json.loads((tmp_path / "logs" / "placement.json").read_text())
    assert written["earlier"][0]["cores"] == {name: list(c) for name, c in placed.items()}
    assert written["cores"] == {name: list(c) for name, c in pairs.placement.cores.items()}


def test_on_its_link_the_body_takes_only_its_trials_command_and_counts_the_rest(tmp_path):
    """The body's end of a lockstep link connects to its controller only (nothing else can reach it), and even
    from there it takes only the command with this trial's nonce, trial and tick: the rest is counted and dropped."""
    import threading

    import numpy as np
    import zenoh

    from sfl_brain.messages import ControllerReset, MotorCommand, SensorFrame, decode, encode
    from sfl_brain.runtime import bus
    from sfl_brain.runtime.ticklink import BusLink

    endpoint = bus.tick_endpoint(tmp_path, "0")
    mesh = bus.open_session([bus.free_endpoint()], [])
    controller_end = bus.open_tick_session([endpoint], [])
    body_end = bus.open_tick_session([], [endpoint])

    queryable = mesh.declare_queryable(bus.key("r", "controller", ControllerReset.TAG), answer_reset)
    frames = controller_end.declare_subscriber(
        bus.key("r", "controller", SensorFrame.TAG), zenoh.handlers.RingChannel(8)
    )
    commands = controller_end.declare_publisher(bus.key("r", "body", MotorCommand.TAG))

    def answer():  # garbage, another trial's nonce, a stale tick, then the command
        data = frames.recv().payload.to_bytes()
        nonce, frame = data[-8:], decode(data[:-8])

        def command(trial, tick):
            return encode(MotorCommand(trial_id=trial, tick=tick, values=np.ones(2)))

        for payload in (b"\x00garbage", command(7, 0) + bytes(8), command(frame.trial_id, 5) + nonce, b"\xc1" + nonce):
            commands.put(payload)
        commands.put(command(frame.trial_id, frame.tick) + nonce)

    link = BusLink(mesh, "r", "body", "controller", timeout=10.0, ticks=body_end)
    try:
        link.reset(ControllerReset(trial_id=7, seed=0, params={}, sensors=["a"], commands=["b", "c"]))
        threading.Thread(target=answer, daemon=True).start()
        got = link.step(SensorFrame(trial_id=7, tick=0, values=np.zeros(1)))
        assert (got.trial_id, got.tick, list(got.values)) == (7, 0, [1.0, 1.0])
        assert link.drops.counts == {"foreign": 2, "stale": 1, "malformed": 1}
    finally:
        link.close()
        queryable.undeclare()
        for session in (body_end, controller_end, mesh):
            session.close()


def test_on_its_socket_link_the_body_takes_only_its_trials_command_and_a_dead_controller_ends_the_tick(tmp_path):
    """``lockstep.link: socket``: the body's end takes only the command with this trial's nonce, trial and tick
    (the rest is counted and dropped); when the controller's end goes away the waiting tick ends at once (not
    after the tick timeout), and the next trial connects again, to the controller's restart."""
    import socket
    import threading
    import time

    import numpy as np

    from sfl_brain.messages import ControllerReset, MotorCommand, SensorFrame, decode, encode
    from sfl_brain.runtime import bus, ticklink
    from sfl_brain.runtime.ticklink import LinkError, SocketLink

    endpoint = ticklink.endpoint(tmp_path, "0")
    mesh = bus.open_session([bus.free_endpoint()], [])

    def command(trial, tick):
        return encode(MotorCommand(trial_id=trial, tick=tick, values=np.ones(2)))

    def listen():
        server = socket.socket(socket.AF_UNIX, socket.SOCK_SEQPACKET)
        server.bind(ticklink.path_of(endpoint))
        server.listen(1)
        return server

    queryable = mesh.declare_queryable(bus.key("r", "controller", ControllerReset.TAG), answer_reset)
    link = SocketLink(mesh, "r", "body", "controller", timeout=10.0, endpoint=endpoint)
    server = listen()
    try:

        def answer():  # garbage, another trial's nonce, a stale tick, then the command; then it dies
            conn, _ = server.accept()
            data = conn.recv(65536)
            nonce, frame = data[-8:], decode(data[:-8])
            stale = command(frame.trial_id, 5) + nonce
            for payload in (b"\x00garbage", command(7, 0) + bytes(8), stale, b"\xc1" + nonce):
                conn.send(payload)
            conn.send(command(frame.trial_id, frame.tick) + nonce)
            conn.recv(65536)  # the next frame, never answered
            conn.close()
            server.close()
            os.unlink(ticklink.path_of(endpoint))

        threading.Thread(target=answer, daemon=True).start()
        link.reset(ControllerReset(trial_id=7, seed=0, params={}, sensors=["a"], commands=["b", "c"]))
        got = link.step(SensorFrame(trial_id=7, tick=0, values=np.zeros(1)))
        assert (got.trial_id, got.tick, list(got.values)) == (7, 0, [1.0, 1.0])
        assert link.drops.counts == {"foreign": 2, "stale": 1, "malformed": 1}
        t = time.perf_counter()
        with pytest.raises(LinkError, match="closed at tick 1"):
            link.step(SensorFrame(trial_id=7, tick=1, values=np.zeros(1)))
        assert time.perf_counter() - t < 2.0  # at once, not after the 10-s tick timeout
        # the restarted controller listens again a little later; the next trial's reset connects to it
        threading.Timer(0.3, lambda: setattr(link, "restarted", listen())).start()
        link.reset(ControllerReset(trial_id=8, seed=0, params={}, sensors=["a"], commands=["b", "c"]))
        assert link.channel.connected
        link.restarted.close()
    finally:
        link.close()
        queryable.undeclare()
        mesh.close()


def test_idle_connections_of_another_process_cannot_lock_the_body_out_of_its_controllers_socket(tmp_path):
    """A process of this user that fills the controller's connection slots with idle connections gives way: a new
    connection closes the oldest one that never carried a frame the controller answered, so the body, which
    connects anew after each restart, still gets its commands; the slots it took are counted."""
    import socket

    from sfl_brain.runtime import ticklink

    endpoint = ticklink.endpoint(tmp_path, "0")
    refused = []
    server = ticklink.Server(
        endpoint, lambda data: b"command" if data == b"frame" else None, on_refused=lambda: refused.append(1)
    )
    strangers = []
    body = ticklink.Channel(endpoint)
    try:
        for _ in range(ticklink.MAX_CONNECTIONS):  # every slot taken, and nothing sent
            stranger = socket.socket(socket.AF_UNIX, socket.SOCK_SEQPACKET)
            stranger.connect(ticklink.path_of(endpoint))
            strangers.append(stranger)
        assert body.connect(timeout=5.0)
        body.send(b"frame")
        assert body.recv() == b"command"
        assert refused == [1]
        strangers[0].settimeout(5.0)
        assert strangers[0].recv(16) == b""  # the oldest idle one was closed
        # a proven connection keeps its slot: more strangers close idle ones, never the body's
        for _ in range(ticklink.MAX_CONNECTIONS):
            stranger = socket.socket(socket.AF_UNIX, socket.SOCK_SEQPACKET)
            stranger.connect(ticklink.path_of(endpoint))
            strangers.append(stranger)
        body.send(b"frame")
        assert body.recv() == b"command"
    finally:
        body.close()
        for stranger in strangers:
            stranger.close()
        server.close()
