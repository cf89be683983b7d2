"""The run's parts and what each may depend on (issue 14, part 4).

Protocols talk to an abstract module service (:mod:`sfl_brain.protocols.service`), so they run with every
module in one process without Zenoh, and over Zenoh unchanged. The supervisor decides restarts and
retries from typed events, and publishes what happens as typed events.
"""

from __future__ import annotations

import dataclasses
import json
import subprocess
import sys

import pytest

from sfl_brain import messages as m
from sfl_brain.events import (
    Events,
    ModuleAlive,
    ModuleDied,
    ProgressUpdated,
    Restarted,
    TrialInterrupted,
    TrialRecorded,
)
from sfl_brain.protocols import PROTOCOLS, Conductor
from sfl_brain.protocols.local import LocalModules, run_local
from sfl_brain.protocols.service import Interrupted, RunError
from sfl_brain.scenario import load

from ..conftest import ROOT, SCENARIOS

LEARN = SCENARIOS / "analytic_learn.yaml"
ZENOH_SIDE = (
    "zenoh",
    "sfl_brain.runtime.supervisor",
    "sfl_brain.runtime.inbox",
    "sfl_brain.runtime.pairs",
    "sfl_brain.runtime.watch",
    "sfl_brain.runtime.bus",
    "sfl_brain.runtime.host",
    "sfl_brain.runtime.processes",
    "sfl_brain.runtime.ticklink",
)


def stable(rows):
    """Rows without their wall and CPU times."""
    return [{k: v for k, v in r.items() if k not in ("wall_ms", "cpu_body_s", "cpu_controller_s")} for r in rows]


def python(code: str) -> subprocess.CompletedProcess:
    """``code`` in a fresh interpreter (nothing imported yet), from the repository root."""
    return subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, cwd=ROOT, timeout=300)


@pytest.mark.parametrize(
    "module", ["sfl_brain.protocols", "sfl_brain.protocols.local", "sfl_brain.protocols.service", "sfl_brain.events"]
)
def test_the_protocol_side_imports_nothing_of_zenoh_or_the_supervisor(module):
    done = python(f"import json, sys, {module}; print(json.dumps(sorted(sys.modules)))")
    assert done.returncode == 0, done.stderr
    loaded = set(json.loads(done.stdout))
    assert module in loaded
    assert not loaded & set(ZENOH_SIDE), f"{module} imports {sorted(loaded & set(ZENOH_SIDE))}"


def test_a_learning_run_in_one_process_works_without_zenoh():
    """``import zenoh`` fails in that interpreter; the learn protocol runs all its trials anyway and
    gives the records it gives here."""
    code = (
        "import sys, json; sys.modules['zenoh'] = None\n"
        "from sfl_brain.protocols.local import run_local\n"
        "from sfl_brain.scenario import load\n"
        f"rows = run_local(load({str(LEARN)!r}, ['protocol.trials=8']))\n"
        "print(json.dumps(rows))\n"
    )
    done = python(code)
    assert done.returncode == 0, done.stderr
    rows = json.loads(done.stdout)
    assert sum(r["kind"] == "trial" for r in rows) == 8
    assert stable(rows) == stable(run_local(load(LEARN, ["protocol.trials=8"])))


class Flaky(LocalModules):
    """In-process modules whose body worker is interrupted on trial ``trial``, ``times`` times."""

    def __init__(self, plan, trial: int, times: int, fault=Interrupted) -> None:
        super().__init__(plan)
        self.trial, self.left, self.fault = trial, times, fault

    def submit(self, target, message, timeout):
        if isinstance(message, m.TrialRequest) and message.trial_id == self.trial and self.left:
            self.left -= 1
            ticket = self._next
            self._next += 1
            self._outcomes[ticket] = self.fault("the body worker went away")
            return ticket
        return super().submit(target, message, timeout)


def run_over(modules, plan, run_dir):
    """Run ``plan``'s protocol over ``modules``; return (the events it published, the trial rows)."""
    events, seen = Events(), []
    events.subscribe((TrialInterrupted, TrialRecorded, ProgressUpdated), seen.append)
    PROTOCOLS[plan.scenario.protocol.kind](Conductor(plan, modules, events, run_dir))
    return seen, [e.row for e in seen if isinstance(e, TrialRecorded)]


def test_an_interrupted_trial_is_sent_again_and_the_records_do_not_show_it(tmp_path):
    plan = load(LEARN, ["protocol.trials=6"])
    seen, rows = run_over(Flaky(plan, trial=2, times=2), plan, tmp_path)
    interrupted = [e for e in seen if isinstance(e, TrialInterrupted)]
    assert [(e.trial, e.attempt) for e in interrupted] == [(2, 1), (2, 2)]
    assert interrupted[0].reason == "the body worker went away"
    _, clean = run_over(LocalModules(plan), plan, tmp_path)
    assert stable(rows) == stable(clean)
    # the progress is published after each recorded trial
    kinds = [type(e) for e in seen if not isinstance(e, TrialInterrupted)]
    assert kinds[-2:] == [TrialRecorded, ProgressUpdated] and kinds.count(TrialRecorded) == 6


def test_a_trial_interrupted_too_often_or_failed_ends_the_run(tmp_path):
    plan = load(LEARN, ["protocol.trials=6"])
    with pytest.raises(RunError, match="trial 3 interrupted 4 times: the body worker went away"):
        run_over(Flaky(plan, trial=3, times=99), plan, tmp_path)
    with pytest.raises(RunError, match="^the body worker went away$"):  # a RunError is never retried
        run_over(Flaky(plan, trial=3, times=1, fault=RunError), plan, tmp_path)


def test_events_go_to_the_handlers_of_their_exact_type_in_order():
    events, got = Events(), []
    events.subscribe(ModuleAlive, lambda e: got.append(("first", e)))
    events.subscribe((ModuleAlive, Restarted), lambda e: got.append(("second", e)))
    events.publish(ModuleAlive("acc"))
    events.publish(Restarted("body", -9, 1, 3))
    events.publish(TrialInterrupted(0, "x", 1))  # nobody listens: nothing happens
    assert got == [
        ("first", ModuleAlive("acc")),
        ("second", ModuleAlive("acc")),
        ("second", Restarted("body", -9, 1, 3)),
    ]
    with pytest.raises(dataclasses.FrozenInstanceError):
        ModuleAlive("acc").name = "ofc"


# ---------------------------------------------------------------- the supervisor's decisions (no processes)
def supervisor(tmp_path, *sets):
    """A supervisor of the walker (acc, vigilance, ofc, body, controller) whose children are made
    up: nothing is spawned, a respawn is only counted."""
    from sfl_brain.runtime.processes import Child
    from sfl_brain.runtime.supervisor import Supervisor

    plan = load(SCENARIOS / "quickstart.yaml", list(sets))
    sup = Supervisor(plan, tmp_path, "test")
    published = []
    sup.events.subscribe((ModuleDied, Restarted), published.append)
    sup.spawned = []
    sup._spawn = lambda child: (sup.spawned.append(child.name), setattr(child, "generation", child.generation + 1))
    for inst in plan.instances:
        sup.children[inst.name] = Child(inst, tmp_path / f"{inst.name}.log", generation=1, alive=True)
    (tmp_path / "acc.log").write_text("acc ready\nsomething went wrong\n")
    return sup, published


def test_a_dead_controller_interrupts_its_bodys_trial_and_is_restarted_by_policy(tmp_path):
    from sfl_brain.runtime.processes import Exited
    from sfl_brain.runtime.supervisor import Pending

    sup, published = supervisor(tmp_path, "modules.controller.restart=on-failure")
    sup.pending[7] = Pending("body", m.Rejected(consecutive=0))
    sup.pending[8] = Pending("acc", m.Rejected(consecutive=0))
    sup._handle(Exited("controller", 1, generation=0))  # an earlier start's exit: ignored
    assert not sup.pending[7].done and not published
    sup._handle(Exited("controller", -9, generation=1))
    assert isinstance(sup.pending[7].outcome, Interrupted) and "`controller` exited with code -9" in str(
        sup.pending[7].outcome
    )
    assert not sup.pending[8].done  # a brain module's request is not the controller's
    assert published == [Restarted("controller", -9, 1, sup.children["controller"].instance.max_restarts)]
    assert sup.spawned == ["controller"]


def test_a_dead_brain_module_ends_the_run_naming_it(tmp_path):
    from sfl_brain.runtime.processes import Exited

    sup, published = supervisor(tmp_path, "modules.body.restart=on-failure")
    with pytest.raises(RunError, match=r"module `acc` \(.*\) died with exit code -9; its log"):
        sup._handle(Exited("acc", -9, generation=1))
    assert sup.spawned == []
    (died,) = published
    assert isinstance(died, ModuleDied) and died.exit_code == -9 and "something went wrong" in died.log_tail


def test_retry_is_decided_by_the_remote_fault_type():
    from sfl_brain.runtime.supervisor import remote_fault
    from sfl_brain.runtime.ticklink import LinkError

    cut = remote_fault("body", "body.trial", f"{LinkError.__name__}: interrupted: no command for tick 5 within 1 s")
    assert type(cut) is Interrupted
    assert str(cut) == "`body` failed on `body.trial`: LinkError: interrupted: no command for tick 5 within 1 s"
    failed = remote_fault("body", "body.trial", "ValueError: LinkError in a message is not a LinkError")
    assert type(failed) is RunError


def test_a_signal_that_lands_in_a_callback_is_raised_where_the_run_waits(tmp_path):
    """Ctrl-C of `sfl run`: its handler does not raise (in a Zenoh callback on the main thread the exception would be
    logged and dropped) but asks the supervisor to raise at its wait, which it wakes."""
    import os
    import signal
    import threading
    import time

    from sfl_brain.runtime.supervisor import Pending

    sup, _ = supervisor(tmp_path)
    sup.pending[7] = Pending("body", m.Rejected(consecutive=0))  # never answered
    swallowed, timer = [], None

    def callback_on_the_main_thread():  # as Zenoh runs one: what it raises is logged, not propagated
        try:
            signal.raise_signal(signal.SIGINT)  # the handler runs here, inside the callback
        except BaseException as exc:  # noqa: BLE001
            swallowed.append(exc)

    previous = signal.signal(signal.SIGINT, lambda *_: sup.raise_at_wait(KeyboardInterrupt))
    try:
        callback_on_the_main_thread()
        assert swallowed == []
        with pytest.raises(KeyboardInterrupt):
            sup.wait_any([7], timeout=5)
        # a signal while the run already waits wakes it at once
        sup, _ = supervisor(tmp_path)
        timer = threading.Timer(0.3, os.kill, (os.getpid(), signal.SIGINT))  # its handler runs in the main thread
        timer.start()
        began = time.monotonic()
        with pytest.raises(KeyboardInterrupt):
            sup._next_event(timeout=30)  # woken by the handler's Wake, not by the time-out
        assert time.monotonic() - began < 5
    finally:
        if timer is not None:
            timer.join()
        signal.signal(signal.SIGINT, previous)


def import_graph() -> dict[str, set[str]]:
    """Which of our modules each module of ``sfl_brain`` imports, anywhere in it (a function's deferred import and
    a ``TYPE_CHECKING`` one count: each is a dependency a reader follows)."""
    import ast

    package = ROOT / "sfl_brain"

    def name_of(path):
        parts = list(path.relative_to(ROOT).with_suffix("").parts)
        return ".".join(parts[:-1] if parts[-1] == "__init__" else parts)

    modules = {name_of(p): p for p in package.rglob("*.py")}
    graph = {}
    for name, path in modules.items():
        here = name if path.name == "__init__.py" else name.rsplit(".", 1)[0]
        deps = set()
        for node in ast.walk(ast.parse(path.read_text())):
            if isinstance(node, ast.ImportFrom):
                base = here.split(".")[: len(here.split(".")) - node.level + 1] if node.level else []
                target = ".".join([*base, *([node.module] if node.module else [])])
                deps |= {f"{target}.{a.name}" if f"{target}.{a.name}" in modules else target for a in node.names}
            elif isinstance(node, ast.Import):
                deps |= {a.name for a in node.names}
        graph[name] = {d for d in deps if d in modules and d != name}
    return graph


def circles(graph: dict[str, set[str]]) -> list[list[str]]:
    """The strongly connected groups of more than one module (Tarjan)."""
    index: dict[str, int] = {}
    low: dict[str, int] = {}
    stack: list[str] = []
    found = []

    def visit(v):
        index[v] = low[v] = len(index)
        stack.append(v)
        for w in graph[v]:
            if w not in index:
                visit(w)
                low[v] = min(low[v], low[w])
            elif w in stack:
                low[v] = min(low[v], index[w])
        if low[v] == index[v]:
            group = []
            while (w := stack.pop()) != v:
                group.append(w)
            if group:
                found.append(sorted([v, *group]))

    for v in graph:
        if v not in index:
            visit(v)
    return found


def test_no_module_imports_itself_back_through_others():
    """No circle of imports (issue 22: ``events`` <-> ``protocols`` <-> ``records`` and ``host`` <-> ``rrlog`` were
    broken): each layer can be read, and tested, after the ones it uses."""
    graph = import_graph()
    assert {"sfl_brain.protocols.conductor", "sfl_brain.events", "sfl_brain.proposers.sfl"} <= set(graph)
    assert "sfl_brain.events" in graph["sfl_brain.protocols.conductor"]  # the graph sees our imports
    assert circles(graph) == []
    assert circles({"a": {"b"}, "b": {"c"}, "c": {"a"}, "d": {"a"}}) == [["a", "b", "c"]]


# ---------------------------------------------------------------- the packages' order (issue 30)
#: ``sfl_brain``'s layers, lowest first: a module may import its own layer and those before it, never one after.
#: The contract a plugin writer imports is the top-level modules; the two doors (the ``sfl`` command and the
#: Gymnasium environments) are top-level too, but stand on everything. ``docs/architecture.md`` tells the same order.
LAYERS = (
    (
        "contract",
        (
            "sfl_brain",
            "sfl_brain._moved",
            "sfl_brain.messages",
            "sfl_brain.module",
            "sfl_brain.telemetry",
            "sfl_brain.registry",
            "sfl_brain.signals",
            "sfl_brain.body",
            "sfl_brain.conformance",
            "sfl_brain.status",
            "sfl_brain.events",
        ),
    ),
    ("proposers", ("sfl_brain.proposers",)),
    ("scenario", ("sfl_brain.scenario",)),
    ("recording", ("sfl_brain.recording",)),
    ("protocols", ("sfl_brain.protocols",)),
    ("runtime", ("sfl_brain.runtime",)),
    ("study", ("sfl_brain.study",)),
    ("report", ("sfl_brain.report",)),
    ("doors", ("sfl_brain.cli", "sfl_brain.gym")),
)


def layer_of(module: str) -> int:
    """The index in :data:`LAYERS` of ``module``: the layer naming it or the package holding it."""
    for index, (_, members) in enumerate(LAYERS):
        if module in members or any(module.startswith(f"{m}.") for m in members if m != "sfl_brain"):
            return index
    raise LookupError(f"{module} is in no layer of LAYERS: place it")


def upward_imports(graph: dict[str, set[str]]) -> list[str]:
    """Every import of a later layer, as ``importer (layer) imports imported (layer)``."""
    name = [n for n, _ in LAYERS]
    return sorted(
        f"{a} ({name[layer_of(a)]}) imports {b} ({name[layer_of(b)]})"
        for a, deps in graph.items()
        for b in deps
        if layer_of(b) > layer_of(a)
    )


def test_every_module_is_in_a_layer_and_imports_only_its_own_layer_and_those_below():
    """contract <- proposers <- scenario <- recording <- protocols <- runtime <- study <- report <- doors."""
    graph = import_graph()
    assert {layer_of(module) for module in graph} == set(range(len(LAYERS)))  # every layer is found, none empty
    assert upward_imports(graph) == []


def test_the_layer_check_fails_on_an_import_against_the_order():
    graph = import_graph()
    inverted = {**graph, "sfl_brain.scenario.plan": graph["sfl_brain.scenario.plan"] | {"sfl_brain.runtime.run"}}
    assert upward_imports(inverted) == ["sfl_brain.scenario.plan (scenario) imports sfl_brain.runtime.run (runtime)"]
    contract = {**graph, "sfl_brain.body": graph["sfl_brain.body"] | {"sfl_brain.recording.rrlog"}}
    assert upward_imports(contract) == ["sfl_brain.body (contract) imports sfl_brain.recording.rrlog (recording)"]
    with pytest.raises(LookupError, match="sfl_brain.plugins.x is in no layer"):
        layer_of("sfl_brain.plugins.x")


def test_the_paths_of_before_the_packages_import_the_same_modules():
    """``sfl_brain.records`` and the other flat paths of before issue 30 still import, as the very module at the new
    path; the old modules that became packages hand out their names."""
    import importlib

    from sfl_brain._moved import MOVED

    for old, new in MOVED.items():
        assert importlib.import_module(old) is importlib.import_module(new), old
    from sfl_brain.report import write_report
    from sfl_brain.report.report import write_report as new_write_report
    from sfl_brain.runtime import Supervisor as OldSupervisor
    from sfl_brain.runtime.supervisor import Supervisor
    from sfl_brain.study import plan_study
    from sfl_brain.study.study import plan_study as new_plan_study

    assert (OldSupervisor, write_report, plan_study) == (Supervisor, new_write_report, new_plan_study)
    with pytest.raises(AttributeError, match="module 'sfl_brain.runtime' has no attribute 'nothing'"):
        _ = importlib.import_module("sfl_brain.runtime").nothing


#: imports the package makes where it runs without them (each inside ``try: ... except ImportError``), and what it
#: then does: liveness reads /proc and falls back to psutil; provenance names the OpenBLAS core if threadpoolctl is
#: there; pydantic_core ships inside pydantic.
OPTIONAL_IMPORTS = {"psutil", "threadpoolctl", "pydantic_core"}


def _normal(name: str) -> str:
    return name.lower().replace("_", "-").replace(".", "-")


def test_the_package_imports_only_what_it_declares():
    """A user installs ``pip install -e .`` (or an extra) and nothing else: every third-party module that the package
    imports is one of its dependencies or extras (pandas, for one, is not: it was only in the test extra, and a
    report that used it failed on a user's install)."""
    import ast
    import importlib.metadata
    import re
    import tomllib

    project = tomllib.loads((ROOT / "pyproject.toml").read_text())["project"]
    requirements = project["dependencies"] + [r for extra in project["optional-dependencies"].values() for r in extra]
    declared = {_normal(re.match(r"[A-Za-z0-9_.-]+", r).group(0)) for r in requirements}
    distributions = importlib.metadata.packages_distributions()
    undeclared = []
    for root in ("sfl_brain", "modules", "bodies"):
        for path in sorted((ROOT / root).rglob("*.py")):
            for node in ast.walk(ast.parse(path.read_text(), str(path))):
                if isinstance(node, ast.Import):
                    names = [alias.name for alias in node.names]
                elif isinstance(node, ast.ImportFrom) and node.level == 0 and node.module:
                    names = [node.module]
                else:
                    continue
                for name in names:
                    top = name.split(".")[0]
                    if top in sys.stdlib_module_names or top == "sfl_brain" or top in OPTIONAL_IMPORTS:
                        continue
                    owners = {_normal(d) for d in distributions.get(top, [top])}
                    if not owners & declared:
                        undeclared.append(f"{path.relative_to(ROOT)}:{node.lineno} imports {name} ({sorted(owners)})")
    assert not undeclared, "imports of packages pyproject.toml does not declare:\n" + "\n".join(undeclared)
