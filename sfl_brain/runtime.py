"""The supervisor: start one process per module, watch them, route requests, stop them all.

``Supervisor`` owns the child processes and a Zenoh session. Everything that can
happen while a protocol waits (a reply, a module coming alive or going silent, a
process exiting) arrives on one event queue, so waiting for a reply also notices a
dead module at once instead of at a time-out. Bodies and controllers may be
restarted by policy (they hold no state between trials); a trial they were running
is retried. A brain module that dies ends the run with its name and log tail.

Each run has a secret (``Supervisor.secret``), handed to the children on their stdin with the
rest of their spec: their sessions authenticate each other with it, requests and replies are
signed with it, and a liveliness token counts only with a proof made from it (for a child, with
the nonce of its current spawn). What fails these checks is dropped and counted in
``Supervisor.dropped``. The supervisor declares its own token (instance ``@run``): a worker
joined with ``sfl worker`` stops when it goes away.
"""

from __future__ import annotations

import itertools
import json
import logging
import os
import queue
import signal
import subprocess
import sys
import threading
import time
from dataclasses import dataclass, field
from pathlib import Path

import zenoh

from . import bus
from .messages import Message, MessageError, NonFiniteError, decode, encode
from .placement import assign, usable_cpus
from .scenario import Instance, Plan
from .status import EnvironmentProblem

log = logging.getLogger("sfl.runtime")


class RunError(RuntimeError):
    """The run cannot go on (a module died, did not start, or failed a request)."""


class Interrupted(RuntimeError):
    """A request whose target died before answering (the request may be retried)."""


@dataclass
class Child:
    instance: Instance
    log_path: Path
    proc: subprocess.Popen | None = None
    restarts: int = 0
    alive: bool = False
    stopping: bool = False
    generation: int = 0
    nonce: str = ""  # of the current spawn: its liveliness token must carry it

    @property
    def name(self) -> str:
        return self.instance.name


@dataclass
class Pending:
    target: str
    message: Message
    result: object = None
    done: bool = False
    extra: dict = field(default_factory=dict)


def log_tail(path: Path, lines: int = 12) -> str:
    try:
        text = path.read_text(errors="replace").splitlines()
    except OSError:
        return ""
    return "\n".join("    " + line for line in text[-lines:])


def _exits_soon(proc: subprocess.Popen, grace: float = 1.0) -> bool:
    """True if the process has exited or exits within ``grace`` s (its sockets close before it is reaped)."""
    try:
        proc.wait(timeout=grace)
        return True
    except subprocess.TimeoutExpired:
        return False


def hosted_spec(inst: Instance | None) -> dict | None:
    """How a host builds a module it runs in-process (a controller colocated with its body)."""
    if inst is None:
        return None
    return {"reference": inst.reference, "params": inst.params, "seed": inst.seed, "spec_name": inst.spec_name}


class Supervisor:
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
        self.events: queue.SimpleQueue = queue.SimpleQueue()
        self.children: dict[str, Child] = {}
        self.pending: dict[int, Pending] = {}
        self._tokens = itertools.count()
        self.session: zenoh.Session | None = None
        self._liveliness = None
        self.external_workers: list[str] = []
        self._external_nonces: dict[str, str] = {}
        #: a user's Zenoh configuration file (JSON5: TLS, ...), merged under ours for every session of the run
        self.zenoh_config = str(zenoh_config) if zenoh_config else None
        #: the run secret (never on a command line); ``secret_file`` holds it for ``sfl worker`` on this machine
        self.secret = secret or bus.new_secret()
        self.seal = bus.Seal(self.secret)
        self.secret_file: Path | None = None
        #: what the supervisor dropped, by reason: forged or stale liveliness tokens and worker
        #: registrations, unsigned replies
        self.dropped: dict[str, int] = {}
        self._drops = bus.Drops(log, "supervisor")
        self._drops.counts = self.dropped
        self._token = None
        # a core of its own for each body worker and controller process, as lockstep.pin_cpus says
        self.placement = assign(plan.lockstep_processes, usable_cpus(), plan.scenario.lockstep.pin_cpus)

    # ------------------------------------------------------------------ lifecycle
    def start(self) -> None:
        if self.endpoint is None:
            bus.check_listen(self.listen)  # a port in use: one clear line, not a Zenoh traceback
        try:
            self.session = bus.open_session(self.listen, self.connect, zenoh_config=self.zenoh_config)
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
        (self.run_dir / "logs").mkdir(parents=True, exist_ok=True)
        (self.run_dir / "rerun").mkdir(parents=True, exist_ok=True)
        if self.endpoint is None:  # others may join (sfl worker): the secret, readable by this user only
            path = self.run_dir / "secret"
            fd = os.open(path, os.O_WRONLY | os.O_CREAT | os.O_TRUNC, 0o600)
            with os.fdopen(fd, "w") as f:
                f.write(self.secret + "\n")
            self.secret_file = path
        run_proof = self.seal.alive_proof(self.run_id, RUN_TOKEN, os.urandom(8).hex())
        self._token = self.session.liveliness().declare_token(bus.alive_key(self.run_id, RUN_TOKEN, run_proof))
        for inst in self.plan.instances:
            child = Child(inst, self.run_dir / "logs" / f"{inst.name}.log")
            self.children[inst.name] = child
            self._spawn(child)
        deadline = time.monotonic() + self.plan.scenario.timeouts.ready
        while not all(c.alive for c in self.children.values()):
            remaining = deadline - time.monotonic()
            if remaining <= 0:
                waiting = [c.name for c in self.children.values() if not c.alive]
                raise RunError(f"modules not ready after {self.plan.scenario.timeouts.ready:g} s: {waiting}")
            self._handle(self._next_event(remaining), starting=True)

    def spec_for(self, inst: Instance) -> dict:
        colocated = inst.colocated
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
            "realtime": self.realtime,
            "tick_timeout": self.plan.scenario.timeouts.tick,
            "spin": self.plan.scenario.lockstep.spin_us * 1e-6,
            "colocated": hosted_spec(colocated),
            "cpus": self.placement.get(inst.name),
            "run_dir": str(self.run_dir),
            "secret": self.secret,
            "zenoh_config": self.zenoh_config,
        }
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
        logf = open(child.log_path, "ab")  # noqa: SIM115 - handed to the child
        child.generation += 1
        child.alive = False
        child.proc = subprocess.Popen(
            [sys.executable, "-m", "sfl_brain.host", "--name", child.name],  # the name only, for ps
            stdin=subprocess.PIPE,
            stdout=logf,
            stderr=subprocess.STDOUT,
            start_new_session=True,  # Ctrl-C reaches the supervisor only; it stops the children
        )
        logf.close()
        try:  # the spec (with the secret) on stdin, never on the command line; stdin stays open
            child.proc.stdin.write(json.dumps(spec).encode() + b"\n")
            child.proc.stdin.flush()
        except OSError:  # it died at once: its exit event reports it
            pass
        generation = child.generation
        threading.Thread(target=self._wait_exit, args=(child, child.proc, generation), daemon=True).start()

    def _wait_exit(self, child: Child, proc: subprocess.Popen, generation: int) -> None:
        code = proc.wait()
        self.events.put(("exit", child.name, code, generation))

    def _on_liveliness(self, sample: zenoh.Sample) -> None:
        name, proof = bus.parse_alive_key(sample.key_expr)
        nonce = self.seal.check_alive(self.run_id, name, proof)
        if nonce is None:  # no proof, or a forged one
            self._drops("unauthenticated", "liveliness token", str(sample.key_expr))
            return
        self.events.put(("alive" if sample.kind == zenoh.SampleKind.PUT else "gone", name, nonce))

    def stop(self, grace: float = 3.0) -> None:
        """Stop every child: SIGTERM, then SIGKILL after ``grace`` seconds."""
        procs = []
        for child in self.children.values():
            child.stopping = True
            if child.proc is not None and child.proc.poll() is None:
                try:
                    child.proc.send_signal(signal.SIGTERM)
                except ProcessLookupError:
                    pass
                procs.append(child.proc)
        deadline = time.monotonic() + grace
        for proc in procs:
            try:
                proc.wait(timeout=max(0.0, deadline - time.monotonic()))
            except subprocess.TimeoutExpired:
                proc.kill()
                proc.wait()
        for proc in procs:
            if proc.stdin:
                try:
                    proc.stdin.close()
                except OSError:
                    pass
        if self._liveliness is not None:
            self._liveliness.undeclare()
            self._liveliness = None
        if self._token is not None:
            self._token.undeclare()
            self._token = None
        if self.secret_file is not None:
            self.secret_file.unlink(missing_ok=True)
            self.secret_file = None
        if self.session is not None:
            self.session.close()
            self.session = None

    # ------------------------------------------------------------------ events
    def _next_event(self, timeout: float | None):
        try:
            return self.events.get(timeout=timeout)
        except queue.Empty:
            return None

    def _handle(self, event, starting: bool = False) -> None:
        if event is None:
            return
        kind = event[0]
        if kind in ("reply", "drop"):
            token = event[1]
            pending = self.pending.get(token)
            if pending is None or pending.done:
                return
            if kind == "reply":
                pending.result = event[2]
            elif pending.result is None:
                child = self.children.get(pending.target)
                if child is not None and child.proc is not None and _exits_soon(child.proc):
                    return  # it died mid-request: its exit event decides (interrupt and restart, or fail)
                if child is None and pending.target in self.external_workers:
                    pending.result = Interrupted(f"worker `{pending.target}` did not answer")
                elif pending.target in self.plan.bodies:
                    # a body worker that is alive but whose trial got no reply (its link to us dropped
                    # under load): the trial is lost, not the run; it is retried like a crash
                    pending.result = Interrupted(f"no reply from body worker `{pending.target}`")
                else:
                    pending.result = RunError(f"no reply from `{pending.target}` to `{pending.message.TAG}`")
            pending.done = kind == "drop" or pending.result is not None
            return
        name = event[1]
        child = self.children.get(name)
        if kind in ("alive", "gone") and name == RUN_TOKEN:
            return  # our own token (or another supervisor's of this run id)
        if kind == "alive":
            nonce = event[2]
            if child is not None:
                if nonce != child.nonce:  # signed, but not by the process we spawned last
                    self._drops("stale", "liveliness token", f"{name} with the nonce of another spawn")
                    return
                child.alive = True
                log.info("%s is alive", name)
            elif not name.startswith(self.plan.body_spec + "."):
                self._drops("foreign", "liveliness token", f"{name} is no module of this run")
            elif name in self.external_workers:
                if nonce != self._external_nonces.get(name):
                    self._drops("stale", "worker registration", f"{name} is already registered")
            else:
                self.external_workers.append(name)  # a worker joined from elsewhere (sfl worker)
                self._external_nonces[name] = nonce
                log.info("external worker %s joined", name)
            return
        if kind == "gone":
            nonce = event[2]
            if child is None:
                if name in self.external_workers and nonce == self._external_nonces.get(name):
                    self.external_workers.remove(name)
                    del self._external_nonces[name]
                    self._interrupt(name, f"worker `{name}` left")
                return
            if child.stopping or nonce != child.nonce:  # a previous spawn's token going away
                return
            child.alive = False
            if child.proc is not None and child.proc.poll() is None:
                log.warning("%s went silent (lease expired): killing it", name)
                child.proc.kill()
            return
        if kind == "exit":
            code, generation = event[2], event[3]
            if child is None or child.stopping or generation != child.generation:
                return
            child.alive = False
            self._interrupt(name, f"module `{name}` exited with code {code}")
            kind_of = child.instance.cls
            from .body import Body, Controller

            restartable = issubclass(kind_of, Body | Controller)
            if child.instance.restart == "on-failure" and restartable and child.restarts < child.instance.max_restarts:
                child.restarts += 1
                log.warning(
                    "module %s exited with code %s: restart %d/%d",
                    name,
                    code,
                    child.restarts,
                    child.instance.max_restarts,
                )
                print(
                    f"sfl: module `{name}` died (exit code {code}); restarting "
                    f"({child.restarts}/{child.instance.max_restarts})",
                    file=sys.stderr,
                )
                self._spawn(child)
                return
            raise RunError(
                f"module `{name}` ({child.instance.reference}) died with exit code {code}"
                f"{' before it was ready' if starting else ''}; its log ({child.log_path}):\n"
                f"{log_tail(child.log_path)}"
            )

    def _interrupt(self, name: str, why: str) -> None:
        affected = {name}
        # a body's trial is lost when its controller dies
        for inst_name, c in self.children.items():
            if c.instance.routes.get("controller.sensors") == name:
                affected.add(inst_name)
        for pending in self.pending.values():
            if not pending.done and pending.target in affected:
                pending.result = Interrupted(why)
                pending.done = True

    # ------------------------------------------------------------------ requests
    def submit(self, target: str, message: Message, timeout: float) -> int:
        token = next(self._tokens)
        self.pending[token] = Pending(target, message)
        events, seal, drops = self.events, self.seal, self._drops
        key_expr = bus.key(self.run_id, target, message.TAG)
        nonce, payload = seal.seal_request(key_expr, encode(message))

        def on_reply(reply: zenoh.Reply) -> None:
            if reply.ok is not None:
                data = seal.open_reply(nonce, reply.ok.payload.to_bytes())
                if data is None:
                    drops("unauthenticated", "reply", f"to `{message.TAG}` on {key_expr}")
                    return
                try:
                    events.put(("reply", token, decode(data)))
                except (MessageError, NonFiniteError) as exc:
                    events.put(("reply", token, RunError(f"malformed reply from `{target}`: {exc}")))
            else:
                data = seal.open_reply(nonce, reply.err.payload.to_bytes())
                if data is None:  # Zenoh's own "Timeout" (the drop event decides), or a stranger's
                    return
                text = data.decode(errors="replace")
                exc_type = Interrupted if text.startswith("LinkError") else RunError
                events.put(("reply", token, exc_type(f"`{target}` failed on `{message.TAG}`: {text}")))

        self.session.get(
            key_expr,
            zenoh.handlers.Callback(on_reply, lambda: events.put(("drop", token)), indirect=False),
            payload=payload,
            timeout=timeout,
            target=zenoh.QueryTarget.ALL,
            consolidation=zenoh.ConsolidationMode.NONE,  # every reply as it comes: a stranger's cannot hold ours
        )
        return token

    def wait_any(self, tokens: list[int], timeout: float | None = None) -> list[tuple[int, object]]:
        """Block until at least one of ``tokens`` completes; return the completed (token, result)."""
        deadline = None if timeout is None else time.monotonic() + timeout
        while True:
            done = [(t, self.pending[t].result) for t in tokens if self.pending[t].done]
            if done:
                for t, _ in done:
                    del self.pending[t]
                return done
            remaining = None if deadline is None else deadline - time.monotonic()
            if remaining is not None and remaining <= 0:
                return []
            self._handle(self._next_event(0.5 if remaining is None else min(0.5, remaining)))

    def wait_alive(self, name: str) -> None:
        deadline = time.monotonic() + self.plan.scenario.timeouts.ready
        child = self.children[name]
        while not child.alive:
            if time.monotonic() > deadline:
                raise RunError(f"module `{name}` did not come back within {self.plan.scenario.timeouts.ready:g} s")
            self._handle(self._next_event(0.5))

    def workers(self) -> list[str]:
        """Body workers that can run a trial now (launched and joined from elsewhere): alive, and
        their controller process too, so a trial retried after a controller restart starts as soon
        as the replacement is up (not after a tick time-out)."""
        own = []
        for name in self.plan.bodies:
            child = self.children[name]
            controller = self.children.get(child.instance.routes.get("controller.sensors", ""))
            if child.alive and (controller is None or controller.alive):
                own.append(name)
        return own + list(self.external_workers)

    def pids(self) -> list[int]:
        return [c.proc.pid for c in self.children.values() if c.proc is not None]


#: the instance name of the supervisor's own liveliness token
RUN_TOKEN = "@run"


def kill_quietly(pid: int) -> None:
    try:
        os.kill(pid, signal.SIGKILL)
    except ProcessLookupError:
        pass
