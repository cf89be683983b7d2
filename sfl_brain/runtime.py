"""The supervisor: start one process per module, watch them, route requests, stop them all.

``Supervisor`` owns the child processes and a Zenoh session. Everything that can
happen while a protocol waits (a reply, a module coming alive or going silent, a
process exiting) arrives on one event queue, so waiting for a reply also notices a
dead module at once instead of at a time-out. Bodies and controllers may be
restarted by policy (they hold no state between trials); a trial they were running
is retried. A brain module that dies ends the run with its name and log tail.
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
from .messages import Message, MessageError, decode, encode
from .placement import assign, usable_cpus
from .scenario import Instance, Plan

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
        # a core of its own for each body worker and controller process, as lockstep.pin_cpus says
        self.placement = assign(plan.lockstep_processes, usable_cpus(), plan.scenario.lockstep.pin_cpus)

    # ------------------------------------------------------------------ lifecycle
    def start(self) -> None:
        self.session = bus.open_session(self.listen, self.connect)
        self._liveliness = self.session.liveliness().declare_subscriber(
            bus.alive_key(self.run_id, "**"),
            zenoh.handlers.Callback(self._on_liveliness, indirect=False),
            history=True,
        )
        (self.run_dir / "logs").mkdir(parents=True, exist_ok=True)
        (self.run_dir / "rerun").mkdir(parents=True, exist_ok=True)
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
            "realtime": self.realtime,
            "tick_timeout": self.plan.scenario.timeouts.tick,
            "spin": self.plan.scenario.lockstep.spin_us * 1e-6,
            "colocated": hosted_spec(colocated),
            "cpus": self.placement.get(inst.name),
        }
        return spec

    def listen_for_children(self) -> list[str]:
        host = "127.0.0.1"
        for ep in self.listen:
            if ep.startswith("tcp/"):
                host = ep[4:].rsplit(":", 1)[0]
        return [f"tcp/{host}:0"]

    def _spawn(self, child: Child) -> None:
        spec = json.dumps(self.spec_for(child.instance))
        logf = open(child.log_path, "ab")  # noqa: SIM115 - handed to the child
        child.generation += 1
        child.alive = False
        child.proc = subprocess.Popen(
            [sys.executable, "-m", "sfl_brain.host", spec],
            stdin=subprocess.PIPE,
            stdout=logf,
            stderr=subprocess.STDOUT,
            start_new_session=True,  # Ctrl-C reaches the supervisor only; it stops the children
        )
        logf.close()
        generation = child.generation
        threading.Thread(target=self._wait_exit, args=(child, child.proc, generation), daemon=True).start()

    def _wait_exit(self, child: Child, proc: subprocess.Popen, generation: int) -> None:
        code = proc.wait()
        self.events.put(("exit", child.name, code, generation))

    def _on_liveliness(self, sample: zenoh.Sample) -> None:
        name = bus.instance_from_alive_key(sample.key_expr)
        self.events.put(("alive" if sample.kind == zenoh.SampleKind.PUT else "gone", name))

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
                else:
                    pending.result = RunError(f"no reply from `{pending.target}` to `{pending.message.TAG}`")
            pending.done = kind == "drop" or pending.result is not None
            return
        name = event[1]
        child = self.children.get(name)
        if kind == "alive":
            if child is not None:
                child.alive = True
                log.info("%s is alive", name)
            elif name.startswith(self.plan.body_spec + ".") and name not in self.external_workers:
                self.external_workers.append(name)  # a worker joined from elsewhere (sfl worker)
                log.info("external worker %s joined", name)
            return
        if kind == "gone":
            if child is None:
                if name in self.external_workers:
                    self.external_workers.remove(name)
                    self._interrupt(name, f"worker `{name}` left")
                return
            if child.stopping:
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
        events = self.events

        def on_reply(reply: zenoh.Reply) -> None:
            if reply.ok is not None:
                try:
                    events.put(("reply", token, decode(reply.ok.payload.to_bytes())))
                except MessageError as exc:
                    events.put(("reply", token, RunError(f"malformed reply from `{target}`: {exc}")))
            else:
                text = reply.err.payload.to_string()
                exc_type = Interrupted if text.startswith("LinkError") else RunError
                events.put(("reply", token, exc_type(f"`{target}` failed on `{message.TAG}`: {text}")))

        self.session.get(
            bus.key(self.run_id, target, message.TAG),
            zenoh.handlers.Callback(on_reply, lambda: events.put(("drop", token)), indirect=False),
            payload=encode(message),
            timeout=timeout,
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
        """Body workers that are alive now (launched and joined from elsewhere)."""
        own = [n for n in self.plan.bodies if self.children[n].alive]
        return own + list(self.external_workers)

    def pids(self) -> list[int]:
        return [c.proc.pid for c in self.children.values() if c.proc is not None]


def kill_quietly(pid: int) -> None:
    try:
        os.kill(pid, signal.SIGKILL)
    except ProcessLookupError:
        pass
