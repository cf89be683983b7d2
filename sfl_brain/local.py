"""Run a plan's protocol with every module in this one process (no bus).

The same protocol code and the same messages as ``sfl run``, minus Zenoh: used by the
tests of brain-module properties, by the benchmarks as the one-process baseline, and to
show that the processes-over-Zenoh run gives identical records.
"""

from __future__ import annotations

import json
import tempfile
from pathlib import Path

from .body import Body, InProcessLink
from .host import make_module
from .messages import Message, decode, encode
from .protocols import PROTOCOLS, Conductor
from .records import RecordWriter, read_records
from .scenario import Plan


class _NoRerun:
    def decisions(self, rows):
        pass

    def trial(self, row):
        pass


class LocalSupervisor:
    """Hosts every instance of a plan in-process; the Supervisor's request surface."""

    def __init__(self, plan: Plan, through_codec: bool = True) -> None:
        self.plan = plan
        self.through_codec = through_codec
        self.modules = {}
        for inst in plan.instances:
            module = make_module(inst.reference, inst.params, inst.seed, inst.spec_name)
            if isinstance(module, Body):
                module.worker = inst.name
                if module.COMMANDS:
                    ctrl = inst.colocated or next(
                        i for i in plan.instances if i.name == inst.routes["controller.sensors"]
                    )
                    module.link = InProcessLink(make_module(ctrl.reference, ctrl.params, ctrl.seed, ctrl.spec_name))
            self.modules[inst.name] = module
        self._results: dict[int, Message] = {}
        self._next = 0

    def _deliver(self, target: str, message: Message) -> Message:
        module = self.modules[target]
        if self.through_codec:
            reply = decode(encode(module.handle(decode(encode(message)), checked=True)))
        else:
            reply = module.handle(message)
        module.run_deferred()
        return reply

    def submit(self, target: str, message: Message, timeout: float) -> int:
        token = self._next
        self._next += 1
        self._results[token] = self._deliver(target, message)
        return token

    def wait_any(self, tokens, timeout=None):
        return [(t, self._results.pop(t)) for t in tokens]

    def workers(self) -> list[str]:
        return list(self.plan.bodies)


def run_local(plan: Plan, run_dir: Path | None = None, through_codec: bool = True) -> list[dict]:
    """Run the plan's protocol in-process; return the record rows."""
    tmp = None
    if run_dir is None:
        tmp = tempfile.TemporaryDirectory()
        run_dir = Path(tmp.name)
    run_dir.mkdir(parents=True, exist_ok=True)
    writer = RecordWriter(run_dir / "records.jsonl")
    try:
        conductor = Conductor(plan, LocalSupervisor(plan, through_codec), writer, _NoRerun(), run_dir)
        PROTOCOLS[plan.scenario.protocol.kind](conductor)
    finally:
        writer.close()
    rows = read_records(run_dir)
    if tmp is not None:
        tmp.cleanup()
    return json.loads(json.dumps(rows))
