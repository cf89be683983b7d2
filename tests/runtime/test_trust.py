"""A run trusts only its own members: strangers cannot connect, and inside the mesh whatever is not
signed with the run secret, or not of the current trial and tick, is dropped and counted."""

from __future__ import annotations

import json
import os

import numpy as np
import psutil
import pytest

from sfl_brain import messages as m
from sfl_brain.protocols.local import run_local
from sfl_brain.recording.records import read_records
from sfl_brain.runtime import bus
from sfl_brain.scenario import load

from ..conftest import SCENARIOS, TickStranger, listening_run

VOLATILE = {"wall_ms", "worker", "cpu_body_s", "cpu_controller_s"}
# a short walker run: 5 processes (body and controller apart), 300 ticks a trial
WALKER = SCENARIOS / "quickstart.yaml"
WALKER_SETS = ("protocol.trials=40", "modules.body.params.duration=3", "record.body_every=0")


def stable(rows):
    return [{k: v for k, v in r.items() if k not in VOLATILE} for r in rows]


def counters(run_dir) -> dict[str, int]:
    total: dict[str, int] = {}
    for path in (run_dir / "logs").glob("*.counters.json"):
        for reason, n in json.loads(path.read_text())["dropped"].items():
            total[reason] = total.get(reason, 0) + n
    return total


class Stranger:
    """Everything a peer inside the mesh, without the run secret, can throw at a run; ``link``: a session
    of its own on a pair's lockstep link too (this user may connect to it), for frames and commands."""

    def __init__(self, session, run_id: str, instances: list[str], link=None) -> None:
        self.s = session
        self.link = link
        self.run_id = run_id
        self.instances = instances
        self.rng = np.random.default_rng(0)
        self.wrong = bus.Seal("not-the-run-secret")
        self.tokens = []
        # a queryable on every key of the run, answering every request with garbage
        self.queryable = session.declare_queryable(f"sfl/{run_id}/**", self._answer_garbage)

    def _answer_garbage(self, query) -> None:
        try:
            query.reply(query.key_expr, self.rng.bytes(40))
            query.reply_err(b"LinkError: forged")
        finally:
            query.drop()

    def frame(self, cls, trial_id, tick, n=8):
        return m.encode(cls(trial_id=trial_id, tick=tick, values=np.zeros(n)))

    def spray(self, round_: int) -> None:
        s, rng, run = self.s, self.rng, self.run_id
        wrong_type = m.encode(m.Ack(detail="not what you expect"))
        for inst in self.instances:
            for tag in m._REGISTRY:
                k = bus.key(run, inst, tag)
                s.put(k, rng.bytes(int(rng.integers(0, 64))))
                s.put(k, wrong_type)
                if m._REGISTRY[tag].STREAM:
                    continue
                # requests: unsigned garbage, an unsigned valid message, one signed with a wrong secret
                payloads = [rng.bytes(int(rng.integers(0, 64))), wrong_type, self.wrong.seal_request(k, wrong_type)[1]]
                for payload in payloads:
                    s.get(k, lambda reply: None, payload=payload, timeout=2.0)
        # other trials' and ticks' frames and commands, with and without a (guessed) nonce
        for trial_id, tick in ((9999, 0), (0, round_), (round_ % 5, round_ % 300), (-1, -1)):
            for cls, key_ in ((m.SensorFrame, "controller/controller.sensors"), (m.MotorCommand, "body/body.command")):
                data = self.frame(cls, trial_id, tick, 8 if cls is m.SensorFrame else 4)
                for on in filter(None, (s, self.link)):
                    on.put(f"sfl/{run}/{key_}", data)
                    on.put(f"sfl/{run}/{key_}", data + rng.bytes(8))
                    on.put(f"sfl/{run}/{key_}", rng.bytes(int(rng.integers(0, 64))))
        for on in filter(None, (s, self.link)):
            on.put(f"sfl/{run}/body/body.command", b"")  # the body's own wake-up payload
        # forged liveliness tokens: no proof, a wrong proof, module names that exist, a worker, the run's
        forged = [
            bus.alive_key(run, "acc"),
            bus.alive_key(run, "controller", "0123-4567"),
            bus.alive_key(run, "body", self.wrong.alive_proof(run, "body", "beef")),
            bus.alive_key(run, "vigilance", "x"),
            bus.alive_key(run, "body.ext9", self.wrong.alive_proof(run, "body.ext9", "cafe")),  # a worker registration
            bus.alive_key(run, "@run", "0-0"),
            bus.alive_key(run, "ofc", f"{round_}-{rng.bytes(4).hex()}"),
        ]
        # ... declared now, and the previous round's undeclared (a forged token that goes away)
        for token in self.tokens:
            token.undeclare()
        self.tokens = [s.liveliness().declare_token(k) for k in forged]

    def close(self) -> None:
        for token in self.tokens:
            token.undeclare()
        self.queryable.undeclare()


def test_garbage_on_every_key_of_a_running_run_changes_nothing(tmp_path):
    """Random bytes, wrong types, other trials' frames and commands, forged tokens (also for module
    names that exist, then undeclared), forged worker registrations, unsigned requests and replies,
    on every key of a running walker run: its records equal a clean run's, and the drops are counted."""
    out = tmp_path / "run"
    instances = ["acc", "vigilance", "ofc", "body", "controller"]
    with listening_run(WALKER, out, *WALKER_SETS, modules=5) as run:
        # the body and its controller tick on a link of their own, off the mesh: the stranger joins it too
        link = TickStranger(out)
        stranger = Stranger(run.session, run.run_id, instances, link)
        rounds = 0
        try:
            while run.proc.poll() is None:
                stranger.spray(rounds)
                rounds += 1
                try:  # pace the rounds (each covers every key): the run goes on meanwhile
                    run.proc.wait(timeout=0.5)
                except Exception:
                    pass
        finally:
            stranger.close()
            link.close()
        stderr = run.proc.stderr.read()
    assert run.proc.returncode == 0, stderr
    assert rounds >= 3
    clean = run_local(load(WALKER, list(WALKER_SETS)))
    assert stable(read_records(out)) == stable(clean)
    dropped = counters(out)
    for reason in ("unauthenticated", "malformed", "foreign"):
        assert dropped.get(reason, 0) > 0, (dropped, stderr[-3000:])
    # the supervisor dropped the forged tokens and registrations (logged once per kind)
    assert "supervisor: dropped unauthenticated liveliness token" in stderr, stderr
    assert "supervisor: dropped unauthenticated reply" in stderr, stderr
    assert stderr.count("supervisor: dropped unauthenticated liveliness token") == 1
    assert "sfl: module" not in stderr  # no module was killed or restarted
    assert not (out / "secret").exists()  # the secret file goes with the run


def test_a_peer_without_the_secret_is_answered_nothing(tmp_path):
    """Zenoh lets a stranger on loopback join the mesh (transport authentication is the user's, see
    docs/reliability.md), but nothing it sends without the secret is answered or applied."""
    from sfl_brain.runtime.host import RemoteError, request

    out = tmp_path / "run"
    with listening_run(SCENARIOS / "analytic_learn.yaml", out, "protocol.trials=100000", modules=4) as run:
        key_expr = bus.key(run.run_id, "vigilance", "vigilance.rejected")
        # a member's signed request is answered
        assert isinstance(
            request(run.session, key_expr, m.Rejected(consecutive=0), 10.0, seal=bus.Seal(run.secret)), m.Threshold
        )
        for seal in (None, bus.Seal("wrong-secret")):
            # a made-up nonce and MAC in front of a valid message
            unsigned = bytes(24) + m.encode(m.Rejected(consecutive=0)) if seal is None else None
            if seal is None:
                replies = list(run.session.get(key_expr, payload=unsigned, timeout=5.0))
                assert [r.ok for r in replies] == [None]  # an error, never an answer
                assert (
                    replies[0].err.payload.to_string() == "unauthenticated request: not signed with this run's secret"
                )
            else:
                with pytest.raises(RemoteError):
                    request(run.session, key_expr, m.Rejected(consecutive=0), 2.0, seal=seal)
        modules = psutil.Process(run.proc.pid).children(recursive=True)
        run.proc.kill()  # its modules see their parent go (stdin closes) and exit
        run.proc.wait(timeout=30)
        _, alive = psutil.wait_procs(modules, timeout=30)
        assert not alive, f"modules still running after their run was killed: {alive}"
    counters = out / "logs" / "vigilance.counters.json"  # written as the module exits
    assert json.loads(counters.read_text())["dropped"].get("unauthenticated", 0) >= 2


def test_a_signed_request_cannot_be_replayed_or_moved(tmp_path):
    """Inside the mesh, a request signed for one key does not work on another, and a replay is dropped."""
    from sfl_brain.runtime.host import NoReply, request

    out = tmp_path / "run"
    with listening_run(SCENARIOS / "analytic_learn.yaml", out, "protocol.trials=100000", modules=4) as run:
        seal = bus.Seal(run.secret)
        key_expr = bus.key(run.run_id, "vigilance", "vigilance.rejected")
        reply = request(run.session, key_expr, m.Rejected(consecutive=0), 10.0, seal=seal)
        assert isinstance(reply, m.Threshold)  # a member's signed request is answered
        nonce, sealed = seal.seal_request(key_expr, m.encode(m.Rejected(consecutive=0)))
        first = list(run.session.get(key_expr, payload=sealed, timeout=5.0))
        again = list(run.session.get(key_expr, payload=sealed, timeout=5.0))
        assert [r.ok is not None for r in first] == [True]
        assert again == [] or all(r.ok is None for r in again)  # the replay: no answer
        moved = list(run.session.get(bus.key(run.run_id, "ofc", "ofc.grade"), payload=sealed, timeout=5.0))
        assert [r.err.payload.to_string() for r in moved] == [
            "unauthenticated request: not signed with this run's secret"
        ]
        # signed with another secret: the host refuses it, and its unsigned refusal is no reply to us
        with pytest.raises(NoReply):
            request(run.session, key_expr, m.Rejected(consecutive=0), 2.0, seal=bus.Seal("wrong"))
        modules = psutil.Process(run.proc.pid).children(recursive=True)
        run.proc.kill()
        run.proc.wait(timeout=30)
        _, alive = psutil.wait_procs(modules, timeout=30)  # each writes its counters as it exits
        assert not alive, f"modules still running after their run was killed: {alive}"
    dropped = json.loads((out / "logs" / "vigilance.counters.json").read_text())["dropped"]
    assert dropped.get("stale", 0) >= 1
    assert json.loads((out / "logs" / "ofc.counters.json").read_text())["dropped"]["unauthenticated"] >= 1


def test_seal_refuses_what_another_secret_signed():
    ours, theirs = bus.Seal("a" * 32), bus.Seal("b" * 32)
    nonce, sealed = ours.seal_request("sfl/r/acc/acc.evaluate", b"payload")
    assert ours.open_request("sfl/r/acc/acc.evaluate", sealed) == (nonce, b"payload")
    assert theirs.open_request("sfl/r/acc/acc.evaluate", sealed) is None
    assert ours.open_request("sfl/r/ofc/acc.evaluate", sealed) is None  # moved to another key
    assert ours.open_request("sfl/r/acc/acc.evaluate", sealed[:-1] + b"X") is None  # tampered
    reply = ours.seal_reply(nonce, b"answer")
    assert ours.open_reply(nonce, reply) == b"answer"
    assert ours.open_reply(os.urandom(8), reply) is None  # a reply to another request
    proof = ours.alive_proof("r", "acc", "1234")
    assert ours.check_alive("r", "acc", proof) == "1234"
    assert ours.check_alive("r", "ofc", proof) is None
    assert theirs.check_alive("r", "acc", proof) is None
    assert ours.check_alive("r", "acc", None) is None


@pytest.mark.parametrize(
    "path, ok",
    [
        ("acc.npz", True),
        ("maps/acc.npz", True),
        ("../escape.npz", False),
        ("/tmp/elsewhere/acc.npz", False),
        ("link/acc.npz", False),  # a symlink inside the run folder that points out of it
    ],
)
def test_the_acc_writes_its_maps_only_inside_its_run_folder(tmp_path, path, ok):
    from sfl_brain.modules.acc import ACC

    run_dir = tmp_path / "run"
    (run_dir / "maps").mkdir(parents=True)
    outside = tmp_path / "outside"
    outside.mkdir()
    (run_dir / "link").symlink_to(outside)
    acc = ACC(ACC.Params(shape=(3, 3), dim=2), seed=0)
    acc.run_dir = run_dir
    if ok:
        acc.handle(m.Finish(path=path, prune=False))
        assert (run_dir / path).exists()
    else:
        with pytest.raises(ValueError, match="refusing to write .* outside the run folder"):
            acc.handle(m.Finish(path=path, prune=False))
        assert not list(outside.iterdir()) and not (tmp_path / "escape.npz").exists()
