"""Run a plan's protocol with every module in this one process: no bus, no Zenoh, no processes.

The same protocol code and the same messages as ``sfl run``: :class:`LocalModules` is the
:class:`~sfl_brain.protocols.service.ModuleService` that hands each request straight to its module (through
the codec, as on the wire, unless told not to). Used by the tests of brain-module properties, by
the benchmarks as the one-process baseline, and to show that the processes-over-Zenoh run gives
identical records. Nothing this module imports needs Zenoh.
"""

from __future__ import annotations

import json
import tempfile
import time
from pathlib import Path

import msgspec

from ..body import Body, InProcessLink
from ..events import Events
from ..messages import Message, TrialResult, decode, encode
from ..module import Module
from ..recording.records import RecordWriter, read_records, record_to
from ..registry import resolve
from ..scenario.plan import Instance, Plan
from . import PROTOCOLS
from .conductor import Conductor
from .service import Outcome


def build(inst: Instance) -> Module:
    """The module of one plan instance, as a host process builds it (``host.make_module``)."""
    cls, _ = resolve(inst.reference)
    module = cls(cls.Params.model_validate(inst.params), seed=inst.seed)
    module.entity = inst.spec_name
    return module


def controller_of(plan: Plan, body: Instance) -> Instance:
    """The controller instance that drives the body worker ``body`` (colocated in it or a process of its own)."""
    return body.colocated or next(i for i in plan.instances if i.name == body.routes["controller.sensors"])


def build_body(plan: Plan, inst: Instance) -> Body:
    """The body worker ``inst`` of the plan, with its controller behind an :class:`InProcessLink` when it takes
    commands: what a trial request runs on in one process (here and in ``sfl_brain.gym``)."""
    body = build(inst)
    body.worker = inst.name
    if body.COMMANDS:
        body.link = InProcessLink(build(controller_of(plan, inst)))
    return body


class LocalModules:
    """Every instance of a plan in this process; a request is answered when it is submitted."""

    def __init__(self, plan: Plan, through_codec: bool = True) -> None:
        self.plan = plan
        self.through_codec = through_codec
        self.modules: dict[str, Module] = {}
        for inst in plan.instances:
            self.modules[inst.name] = build_body(plan, inst) if inst.name in plan.bodies else build(inst)
        self._outcomes: dict[int, Outcome] = {}
        self._next = 0

    def _deliver(self, target: str, message: Message) -> Message:
        module = self.modules[target]
        started = time.process_time()
        if self.through_codec:
            reply = decode(encode(module.handle(decode(encode(message)), checked=True)))
        else:
            reply = module.handle(message)
        if isinstance(reply, TrialResult):  # the one process's CPU seconds, its controller's included
            reply = msgspec.structs.replace(reply, cpu_body_s=time.process_time() - started)
        module.run_deferred()
        return reply

    def submit(self, target: str, message: Message, timeout: float) -> int:
        ticket = self._next
        self._next += 1
        self._outcomes[ticket] = self._deliver(target, message)
        return ticket

    def wait_any(self, tickets: list[int], timeout: float | None = None) -> list[tuple[int, Outcome]]:
        return [(t, self._outcomes.pop(t)) for t in tickets]

    def workers(self) -> list[str]:
        return list(self.plan.bodies)

    def wait_for_workers(self, timeout: float) -> None:
        """Never needed: every body of the plan is a worker, always."""

    def coming(self) -> bool:
        return False


def run_local(plan: Plan, run_dir: Path | None = None, through_codec: bool = True) -> list[dict]:
    """Run the plan's protocol in-process; return the record rows."""
    tmp = None
    if run_dir is None:
        tmp = tempfile.TemporaryDirectory()
        run_dir = Path(tmp.name)
    run_dir.mkdir(parents=True, exist_ok=True)
    writer = RecordWriter(run_dir / "records.jsonl")
    events = Events()
    record_to(events, writer, decisions=plan.scenario.record.decisions)
    try:
        conductor = Conductor(plan, LocalModules(plan, through_codec), events, run_dir)
        PROTOCOLS[plan.scenario.protocol.kind](conductor)
    finally:
        writer.close()
    rows = read_records(run_dir)
    if tmp is not None:
        tmp.cleanup()
    return json.loads(json.dumps(rows))
