"""The supervisor: the run's modules as processes on a Zenoh mesh, behind the protocols' request surface.

:class:`Supervisor` implements :class:`~sfl_brain.protocols.service.ModuleService` over Zenoh. It starts one
process per module (:mod:`sfl_brain.runtime.processes`), watches their liveliness tokens, sends requests
and applies the restart policy. Everything that can happen while a protocol waits (a reply, a
module coming alive or going silent, a process exiting) is a typed value on one queue, handled in
the waiting thread, so waiting for a reply also notices a dead module at once instead of at a
time-out. Zenoh callbacks only put on that queue; so does the run's signal handler
(:meth:`Supervisor.raise_at_wait`), so Ctrl-C is raised in the waiting thread, never inside a callback.

A module process on this machine is judged by its progress, not by the wall clock (:mod:`.liveness`): while
the run waits on it (a request in flight, or its start), the supervisor samples it every :data:`WATCH_PERIOD` s and
counts the time it had the CPU without progress (a reply, a request or tick counted on the run's progress board); a
body worker and its controller process count as one. A process stopped (SIGSTOP, a suspended laptop), starved or
niced is waited for; one that had the CPU for its ``timeouts`` without progress is hung (:class:`ModuleHung`): a
body worker or controller is killed (and restarted by its policy, the trial retried), a brain module fails the run.
The Zenoh sessions of the run's own processes have a lease of a day (:data:`bus.LOCAL_LEASE_MS`): silence is no
test on one machine. A worker on another machine (``sfl worker``) cannot be seen: its own lease (``timeouts.lease``)
is the test, and ``timeouts.trial`` of wall time caps its trial.

Faults are types. A request whose target exits, leaves, or answers with a :class:`~sfl_brain.runtime.ticklink.LinkError`
(its controller died or hung mid-trial) ends :class:`~sfl_brain.protocols.service.Interrupted`: the protocol may
send it again. Bodies and controllers may be restarted by policy (they hold no state between
trials); a brain module that dies ends the run with :class:`~sfl_brain.protocols.service.RunError`, naming it
with its log tail. What the supervisor sees is published on :attr:`Supervisor.events`
(:class:`~sfl_brain.events.ModuleAlive`, :class:`~sfl_brain.events.Restarted`, ...); the run decides
what to show of it.

Each run has a secret (``Supervisor.secret``), handed to the children on their stdin with the
rest of their spec: their sessions authenticate each other with it, requests and replies are
signed with it, and a liveliness token counts only with a proof made from it (for a child, with
the nonce of its current spawn). What fails these checks is dropped and counted in
``Supervisor.dropped``. The supervisor declares its own token (instance ``@run``): a worker
joined with ``sfl worker`` stops when it goes away.
"""

from __future__ import annotations

import itertools
import logging
import os
import queue
import shutil
import tempfile
import time
from pathlib import Path

import zenoh

from ..body import Body, Controller
from ..events import Events, ModuleAlive, ModuleDied, ModuleHung, ModuleSilent, Restarted, WorkerJoined, WorkerLeft
from ..messages import Message, SensorFrame
from ..protocols.service import Interrupted, Outcome, RunError
from ..scenario.plan import Instance, Plan
from ..status import EnvironmentProblem
from . import bus, processes
from .inbox import (  # noqa: F401 - RETRYABLE: ``sfl_brain.runtime.RETRYABLE`` of before issue 30
    RETRYABLE,
    HungController,
    Pending,
    QueryEnded,
    Replied,
    TokenDeclared,
    TokenGone,
    Wake,
    remote_fault,
    send_request,
)
from .liveness import ProgressBoard
from .pairs import UNIX_PATH_MAX, Pairs, initial_placement, lockstep_pairs  # noqa: F401 - as before issue 30
from .processes import Child, Exited, kill_quietly, log_tail
from .ticklink import WATCHED_WAIT, ControllerHung, LinkError  # noqa: F401 - LinkError: as RETRYABLE
from .watch import WATCH_PERIOD, HangWatch, watched_units  # noqa: F401 - watched_units: as before issue 30
from .zygote import ForkServer

__all__ = ["RUN_TOKEN", "Interrupted", "RunError", "Supervisor", "hosted_spec", "kill_quietly", "log_tail"]

log = logging.getLogger("sfl.runtime")

#: the instance name of the supervisor's own liveliness token
RUN_TOKEN = "@run"


def hosted_spec(inst: Instance | None) -> dict | None:
    """How a host builds a module it runs in-process (a controller colocated with its body)."""
    if inst is None:
        return None
    return {"reference": inst.reference, "params": inst.params, "seed": inst.seed, "spec_name": inst.spec_name}


def restartable(child: Child) -> bool:
    """Its policy restarts it (``restart: on-failure``), and it holds no state between trials."""
    inst = child.instance
    return inst.restart == "on-failure" and issubclass(inst.cls, Body | Controller)


class Supervisor:
    """The run's module processes behind :class:`~sfl_brain.protocols.service.ModuleService`: started
    (:meth:`start`), asked (:meth:`submit`, :meth:`wait_any`), watched and restarted while the protocol waits, and
    stopped (:meth:`stop`). Where they run is :attr:`pairs`'s; who is hung, :attr:`watch`'s."""

    def __init__(
        self,
        plan: Plan,
        run_dir: Path,
        run_id: str,
        *,
        listen: list[str] | None = None,
        connect: list[str] | None = None,
        viewer: str | None = None,
        realtime: bool = False,
        record: bool = True,
        zenoh_config: str | Path | None = None,
        secret: str | None = None,
        events: Events | None = None,
    ) -> None:
        self.plan = plan
        self.run_dir = run_dir
        self.run_id = run_id
        self.endpoint = bus.free_endpoint() if not listen else None
        self.listen = listen or [self.endpoint]
        self.connect = connect or []
        self.viewer = viewer
        self.realtime = realtime
        self.record = record
        #: the lifecycle and faults of the run's modules, published as they are handled
        self.events = events or Events()
        self._inbox: queue.SimpleQueue = queue.SimpleQueue()
        #: what every wait raises from now on (:meth:`raise_at_wait`), None while the run goes on
        self._stop_with: type[BaseException] | None = None
        self.children: dict[str, Child] = {}
        self.pending: dict[int, Pending] = {}
        self._tickets = itertools.count()
        self.session: zenoh.Session | None = None
        self._liveliness = None
        #: workers joined from elsewhere (``sfl worker``), in the order they joined: the nonce of each's registration
        self._external: dict[str, str] = {}
        #: a user's Zenoh configuration file (JSON5: TLS, ...), merged under ours for every session of the run
        self.zenoh_config = str(zenoh_config) if zenoh_config else None
        #: the run secret (never on a command line); ``secret_file`` holds it for ``sfl worker`` on this machine
        self.secret = secret or bus.new_secret()
        self.seal = bus.Seal(self.secret)
        self.secret_file: Path | None = None
        self._drops = bus.Drops(log, "supervisor")
        #: what the supervisor dropped, by reason: forged or stale liveliness tokens and worker
        #: registrations, unsigned replies
        self.dropped: dict[str, int] = self._drops.counts
        self._token = None
        #: each body worker and its controller process on a core of their own and on their lockstep link
        self.pairs = Pairs(plan, run_dir, self.events)
        #: the run's private folder (only this user may enter): the lockstep links' sockets, the progress board
        self.private: str | None = None
        #: what each module process got done (:mod:`.liveness`), and the look at those the run waits on
        self.board: ProgressBoard | None = None
        self.watch = HangWatch(plan, self.events)
        #: the run's fork server (:mod:`.zygote`), which the module processes are forked from; None without one
        self.forks: ForkServer | None = None

    # ------------------------------------------------------------------ lifecycle
    def start(self) -> None:
        """Open the run's session, place the processes, start one per module and wait as long as they start."""
        self._open_session()
        (self.run_dir / "logs").mkdir(parents=True, exist_ok=True)
        (self.run_dir / "rerun").mkdir(parents=True, exist_ok=True)
        self.private = tempfile.mkdtemp(prefix="sfl-")  # 0700: only this user may connect, read or write
        self.board = ProgressBoard(self.private, [inst.name for inst in self.plan.instances])
        self.pairs.link(self.private)
        self._declare_run()
        references = [i.reference for i in self.plan.instances]
        references += [i.colocated.reference for i in self.plan.instances if i.colocated is not None]
        if self.forks is None:  # a second start keeps the first one's server
            self.forks = ForkServer.start(references, self.run_dir / "logs" / "zygote.log")
        for inst in self.plan.instances:
            child = Child(inst, self.run_dir / "logs" / f"{inst.name}.log")
            self.children[inst.name] = child
            self._spawn(child)
        while not all(c.alive for c in self.children.values()):  # as long as they start (the watch says)
            self._handle(self._next_event(WATCH_PERIOD), starting=True)
            self._watch(starting=True)

    def _open_session(self) -> None:
        """The run's Zenoh session, and its subscriber to the modules' liveliness tokens."""
        if self.endpoint is None:
            bus.check_listen(self.listen)  # a port in use: one clear line, not a Zenoh traceback
        try:
            self.session = bus.open_session(
                self.listen, self.connect, zenoh_config=self.zenoh_config, lease_ms=bus.LOCAL_LEASE_MS
            )
        except Exception as exc:  # zenoh.ZError: an endpoint it cannot listen on, a bad config file
            first = str(exc).strip().splitlines()[0] if str(exc).strip() else type(exc).__name__
            raise EnvironmentProblem(
                f"cannot open the run's Zenoh session (listen {', '.join(self.listen)}): {first}"
            ) from None
        self._liveliness = self.session.liveliness().declare_subscriber(
            bus.alive_key(self.run_id, "**"),
            zenoh.handlers.Callback(self._on_liveliness, indirect=False),
            history=True,
        )

    def _declare_run(self) -> None:
        """The run's own liveliness token, and where others may join it (``sfl worker``) the secret, readable by this
        user only."""
        if self.endpoint is None:
            path = self.run_dir / "secret"
            fd = os.open(path, os.O_WRONLY | os.O_CREAT | os.O_TRUNC, 0o600)
            with os.fdopen(fd, "w") as f:
                f.write(self.secret + "\n")
            self.secret_file = path
        run_proof = self.seal.alive_proof(self.run_id, RUN_TOKEN, os.urandom(8).hex())
        self._token = self.session.liveliness().declare_token(bus.alive_key(self.run_id, RUN_TOKEN, run_proof))

    def spec_for(self, inst: Instance) -> dict:
        """What the host of ``inst`` reads on its stdin: the module, its links, its place, the run's secret."""
        spec = {
            "run_id": self.run_id,
            "instance": inst.name,
            "spec_name": inst.spec_name,
            "reference": inst.reference,
            "params": inst.params,
            "seed": inst.seed,
            "routes": inst.routes,
            "listen": ["tcp/127.0.0.1:0"] if self.endpoint else self.listen_for_children(),
            "connect": [self.endpoint] if self.endpoint else self.listen,
            "rrd": str(self.run_dir / "rerun" / f"{inst.name}.rrd") if self.record else None,
            "viewer": self.viewer,
            "record": self.plan.scenario.record.model_dump(mode="json"),  # what and how often to show
            "trial_seconds": self.plan.trial_seconds,  # where each trial starts on sim_time
            "realtime": self.realtime,
            "tick_timeout": self.plan.scenario.timeouts.tick,
            "lease_ms": bus.LOCAL_LEASE_MS,
            "progress": self._progress_spec(inst),
            "spin": self.plan.scenario.lockstep.spin_us * 1e-6,
            "colocated": hosted_spec(inst.colocated),
            "cpus": self.pairs.placement.of(inst.name),
            "tick": self.pairs.ticks.get(inst.name),
            "run_dir": str(self.run_dir),
            "secret": self.secret,
            "zenoh_config": self.zenoh_config,
        }
        return spec

    def _progress_spec(self, inst: Instance) -> dict | None:
        """A host's slot on the progress board, and for a body worker its controller process's slot."""
        if self.board is None:
            return None
        spec = self.board.spec(inst.name)
        controller = inst.routes.get(SensorFrame.TAG)
        if controller in self.board.slots:
            spec["controller"] = self.board.slots[controller]
        return spec

    def listen_for_children(self) -> list[str]:
        host = "127.0.0.1"
        for ep in self.listen:
            if ep.startswith("tcp/"):
                host = ep[4:].rsplit(":", 1)[0]
        return [f"tcp/{host}:0"]

    def _spawn(self, child: Child) -> None:
        child.nonce = os.urandom(8).hex()
        spec = self.spec_for(child.instance)
        spec["nonce"] = child.nonce
        processes.start(child, spec, self._inbox.put, self.forks)

    def stop(self, grace: float = 3.0) -> None:
        """Stop every child: SIGTERM, then SIGKILL after ``grace`` seconds; close the session."""
        self.watch.settle(self.children)  # a process seen stopped that has run again since: said before it ends
        try:
            processes.stop_all(self.children.values(), grace)
        finally:
            if self.forks is not None:
                self.forks.close()
                self.forks = None
        if self._liveliness is not None:
            self._liveliness.undeclare()
            self._liveliness = None
        if self._token is not None:
            self._token.undeclare()
            self._token = None
        if self.secret_file is not None:
            self.secret_file.unlink(missing_ok=True)
            self.secret_file = None
        if self.board is not None:
            self.board.close()
            self.board = None
        if self.private is not None:
            shutil.rmtree(self.private, ignore_errors=True)
            self.private = None
        if self.session is not None:
            self.session.close()
            self.session = None

    # ------------------------------------------------------------------ events
    def raise_at_wait(self, exc_type: type[BaseException]) -> None:
        """Make the waiting thread raise ``exc_type`` where it waits for an event (now, if it is waiting): how a
        signal handler stops the run. Safe in a signal handler: ``SimpleQueue.put`` is reentrant."""
        self._stop_with = exc_type
        self._inbox.put(Wake())

    def _next_event(self, timeout: float | None):
        if self._stop_with is not None:
            raise self._stop_with
        try:
            event = self._inbox.get(timeout=timeout)
        except queue.Empty:
            event = None
        if self._stop_with is not None:
            raise self._stop_with
        return event

    def _handle(self, event, starting: bool = False) -> None:
        match event:
            case Replied(ticket, outcome):
                pending = self.pending.get(ticket)
                if pending is not None and not pending.done:
                    pending.outcome, pending.done = outcome, True
                    if isinstance(outcome, Interrupted):
                        self._controller_exiting(pending.target)
            case QueryEnded(ticket):
                self._query_ended(ticket)
            case TokenDeclared(name, nonce):
                self._token_declared(name, nonce)
            case TokenGone(name, nonce):
                self._token_gone(name, nonce)
            case Exited(name, exit_code, generation):
                self._exited(name, exit_code, generation, starting)
            case HungController(body):
                controller = self._controller_of(body)
                if controller is not None:
                    limit = self.plan.scenario.timeouts.tick
                    hung = ModuleHung(
                        controller.name, limit, "timeouts.tick", limit, "answering a tick (its body says)"
                    )
                    self._end_hung(controller.name, hung)

    def _controller_of(self, body: str) -> Child | None:
        """The process of body worker ``body``'s controller; None when the controller is colocated or there is none."""
        child = self.children.get(body)
        return None if child is None else self.children.get(child.instance.routes.get(SensorFrame.TAG, ""))

    def _controller_exiting(self, body: str) -> None:
        """A body worker's trial was cut short: if its controller process is dying (the body saw its link close while
        the process still tears down), it is no longer alive, so that the trial waits for its restart instead of
        going back to it (its exit, handled next, restarts it)."""
        controller = self._controller_of(body)
        if controller is not None and controller.alive and controller.proc is not None:
            if processes.exits_soon(controller.proc, grace=0.2):
                controller.alive = False

    def _query_ended(self, ticket: int) -> None:
        pending = self.pending.get(ticket)
        if pending is None or pending.done:
            return
        child = self.children.get(pending.target)
        if child is not None and child.proc is not None and processes.exits_soon(child.proc):
            return  # it died mid-request: its Exited decides (interrupt and restart, or fail)
        if child is None and pending.target in self._external:
            pending.outcome = Interrupted(f"worker `{pending.target}` did not answer")
        elif pending.target in self.plan.bodies:
            # a body worker that is alive but whose trial got no reply (its link to us dropped
            # under load): the trial is lost, not the run; it is retried like a crash
            pending.outcome = Interrupted(f"no reply from body worker `{pending.target}`")
        else:
            pending.outcome = RunError(f"no reply from `{pending.target}` to `{pending.message.TAG}`")
        pending.done = True

    # ------------------------------------------------------------------ who is there (liveliness tokens)
    def _on_liveliness(self, sample: zenoh.Sample) -> None:
        name, proof = bus.parse_alive_key(sample.key_expr)
        nonce = self.seal.check_alive(self.run_id, name, proof)
        if nonce is None:  # no proof, or a forged one
            self._drops("unauthenticated", "liveliness token", str(sample.key_expr))
            return
        kind = TokenDeclared if sample.kind == zenoh.SampleKind.PUT else TokenGone
        self._inbox.put(kind(name, nonce))

    def _token_declared(self, name: str, nonce: str) -> None:
        if name == RUN_TOKEN:
            return  # our own token (or another supervisor's of this run id)
        child = self.children.get(name)
        if child is not None:
            if nonce != child.nonce:  # signed, but not by the process we spawned last
                self._drops("stale", "liveliness token", f"{name} with the nonce of another spawn")
                return
            child.alive = True
            self.events.publish(ModuleAlive(name))
        elif not name.startswith(self.plan.body_spec + "."):
            self._drops("foreign", "liveliness token", f"{name} is no module of this run")
        elif name in self._external:
            if nonce != self._external[name]:
                self._drops("stale", "worker registration", f"{name} is already registered")
        else:
            self._external[name] = nonce  # a worker joined from elsewhere (sfl worker)
            self.events.publish(WorkerJoined(name))

    def _token_gone(self, name: str, nonce: str) -> None:
        if name == RUN_TOKEN:
            return
        child = self.children.get(name)
        if child is None:
            if nonce == self._external.get(name):
                del self._external[name]
                self._interrupt(name, f"worker `{name}` left")
                self.events.publish(WorkerLeft(name))
            return
        if child.stopping or nonce != child.nonce:  # a previous spawn's token going away
            return
        child.alive = False
        if child.proc is not None and child.proc.poll() is None:  # it runs: waited for, judged by its progress
            self.events.publish(ModuleSilent(name))

    # ------------------------------------------------------------------ faults: restart, interrupt, fail
    def _exited(self, name: str, exit_code: int, generation: int, starting: bool) -> None:
        child = self.children.get(name)
        if child is None or child.stopping or generation != child.generation:
            return
        child.alive = False
        cause, child.hung = child.hung, ""
        self._interrupt(name, f"module `{name}` {cause + ': killed' if cause else f'exited with code {exit_code}'}")
        inst = child.instance
        if restartable(child) and child.restarts < inst.max_restarts:
            child.restarts += 1
            self.events.publish(Restarted(name, exit_code, child.restarts, inst.max_restarts, cause))
            self._spawn(child)
            return
        died = ModuleDied(
            name, inst.reference, exit_code, str(child.log_path), log_tail(child.log_path), starting, cause
        )
        self.events.publish(died)
        raise RunError(died.describe())

    def _watch(self, starting: bool = False) -> None:
        """End the processes the run waits on that had the CPU past their time without progress (:mod:`.watch`);
        while they start, one that no policy restarts fails the run."""
        for name, hung in self.watch.hung(self.board, self.children, self.pending):
            child = self.children[name]
            if starting and not restartable(child):
                self.events.publish(hung)
                raise RunError(
                    f"modules not ready: {hung.describe()}; its log ({child.log_path}):\n{log_tail(child.log_path)}"
                )
            self._end_hung(name, hung)

    def _end_hung(self, name: str, hung: ModuleHung) -> None:
        """A hung process: a brain module fails the run (its learnt state is never thrown away); a body worker or
        controller is killed, and its exit interrupts its trial and restarts it by its policy."""
        child = self.children[name]
        self.events.publish(hung)
        if not issubclass(child.instance.cls, Body | Controller):
            raise RunError(f"{hung.describe()}; its log ({child.log_path}):\n{log_tail(child.log_path)}")
        if child.proc is not None and child.proc.poll() is None:
            child.hung = f"hung: it could run for {hung.seconds:.1f} s and did not finish {hung.doing} ({hung.key})"
            child.alive = False  # no trial goes to it (nor to its body) until its restart is alive
            child.proc.kill()

    def _interrupt(self, name: str, why: str) -> None:
        affected = {name}
        # a body's trial is lost when its controller dies (every module routes to the controller: only bodies drive it)
        for body in self.plan.bodies:
            if self.children[body].instance.routes.get(SensorFrame.TAG) == name:
                affected.add(body)
        for pending in self.pending.values():
            if not pending.done and pending.target in affected:
                pending.outcome, pending.done = Interrupted(why), True

    # ------------------------------------------------------------------ requests (ModuleService)
    def submit(self, target: str, message: Message, timeout: float) -> int:
        """Send ``message`` to ``target``. A module process of this run is waited for as long as it makes progress or
        is denied the CPU; ``timeout`` is the CPU time it may take without progress (:meth:`_watch`). A worker on
        another machine has ``timeout`` s of wall time."""
        ticket = next(self._tickets)
        self.pending[ticket] = Pending(target, message, limit=timeout)
        wait = WATCHED_WAIT if target in self.children else timeout
        send_request(self.session, self.seal, self._drops, self._inbox.put, self.run_id, ticket, target, message, wait)
        return ticket

    def wait_any(self, tickets: list[int], timeout: float | None = None) -> list[tuple[int, Outcome]]:
        """Block until at least one of ``tickets`` completes; return the completed (ticket, outcome)."""
        deadline = None if timeout is None else time.monotonic() + timeout
        while True:
            done = [(t, self.pending[t].outcome) for t in tickets if self.pending[t].done]
            if done:
                for t, _ in done:
                    del self.pending[t]
                return done
            remaining = None if deadline is None else deadline - time.monotonic()
            if remaining is not None and remaining <= 0:
                return []
            self._handle(self._next_event(WATCH_PERIOD if remaining is None else min(WATCH_PERIOD, remaining)))
            self._watch()
            self.pairs.yield_cores(self.children)

    def workers(self) -> list[str]:
        """Body workers that can run a trial now (launched and joined from elsewhere): alive, and
        their controller process too, so a trial retried after a controller restart starts as soon
        as the replacement is up (not after a tick time-out)."""
        own = []
        for name in self.plan.bodies:
            controller = self._controller_of(name)
            # running: a controller that has just died may not be handled yet (its body saw its link close first)
            if self.children[name].alive and (
                controller is None or (controller.alive and processes.running(controller.proc))
            ):
                own.append(name)
        return own + list(self._external)

    def wait_for_workers(self, timeout: float) -> None:
        """Handle what arrives within ``timeout`` s (one event): a module coming back, a worker joining."""
        self._handle(self._next_event(min(timeout, WATCH_PERIOD)))
        self._watch()

    def coming(self) -> bool:
        """A body worker or controller process of this run is starting (a restart): it will be a worker soon, or be
        found hung (``timeouts.ready``)."""
        return any(c.starting for c in self.children.values() if issubclass(c.instance.cls, Body | Controller))

    def pids(self) -> list[int]:
        return [c.proc.pid for c in self.children.values() if c.proc is not None]
