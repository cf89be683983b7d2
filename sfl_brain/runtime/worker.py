"""``sfl worker``: serve trials for a running ``sfl run --listen`` from another terminal or machine.

The worker is a body worker with its controller in the same process. It proves that it belongs
to the run with the run secret (from ``--secret-file`` or ``SFL_RUN_SECRET``, never the command
line): its liveliness token (its registration) carries a proof made from it, and it signs its
replies with it. It waits for the run's own token (``sfl/<run>/@alive/@run/...``)
for up to ``wait`` seconds and gives up with a clear error if none answers; once joined, it exits
with code 0 when that token goes away (the run ended, even by kill -9), and stops on Ctrl-C
(exit code 130) or SIGTERM.
"""

from __future__ import annotations

import os
import shlex
import signal
import sys
import threading
from pathlib import Path

import zenoh

from ..scenario.plan import Plan, instance_seed
from . import bus
from .supervisor import RUN_TOKEN, hosted_spec

SECRET_ENV = "SFL_RUN_SECRET"
#: exit codes: the run ended (0), no run answered (1), bad input such as no secret (2), Ctrl-C (130)
EXIT_DONE, EXIT_NO_RUN, EXIT_BAD_INPUT, EXIT_INTERRUPTED = 0, 1, 2, 130


class WorkerError(RuntimeError):
    """The worker cannot join (no secret, no run answering): one line for the user."""

    def __init__(self, message: str, code: int = EXIT_NO_RUN) -> None:
        super().__init__(message)
        self.code = code


def join_command(
    scenario: str,
    endpoint: str,
    run_id: str,
    *,
    overrides: tuple[str, ...] | list[str] = (),
    seed: int | None = None,
    secret_file: str | Path | None = None,
) -> str:
    """The ``sfl worker`` command line that joins this run with its scenario, overrides and seed."""
    parts = ["sfl", "worker", scenario, "--connect", endpoint, "--run-id", run_id]
    for item in overrides:
        parts += ["--set", item]
    if seed is not None:
        parts += ["--seed", str(seed)]
    if secret_file is not None:
        parts += ["--secret-file", str(secret_file)]
    text = " ".join(shlex.quote(p) for p in parts)
    if secret_file is not None:
        text += f" (on another machine: copy that file, or set {SECRET_ENV} to its content)"
    return text


def lease_ms(plan: Plan) -> int:
    """A worker's Zenoh lease (``timeouts.lease``, in ms): the run gives it up after this long without a word."""
    return int(plan.scenario.timeouts.lease * 1000)


def worker_spec(plan: Plan, run_id: str, name: str, connect: list[str], secret: str) -> dict:
    """The host spec of an external body worker (its controller in-process)."""
    body = next(i for i in plan.instances if i.spec_name == plan.body_spec)
    ctrl = body.colocated or next((i for i in plan.instances if i.name == body.routes.get("controller.sensors")), None)
    return {
        "run_id": run_id,
        "instance": f"{plan.body_spec}.{name}",
        "spec_name": plan.body_spec,
        "reference": body.reference,
        "params": body.params,
        "seed": instance_seed(plan.scenario.seed, plan.body_spec),
        "routes": {},
        "listen": ["tcp/127.0.0.1:0"],
        "connect": list(connect),
        "rrd": None,
        "viewer": None,
        "tick_timeout": plan.scenario.timeouts.tick,
        # on another machine the run cannot see this process, only hear it: its lease is the test (timeouts.lease)
        "lease_ms": lease_ms(plan),
        "trial_seconds": plan.trial_seconds,
        "watch_stdin": False,
        "colocated": hosted_spec(ctrl),
        "secret": secret,
        "nonce": os.urandom(8).hex(),
    }


class RunWatch:
    """Watches the run's own liveliness token: ``found`` once it is seen (with a valid proof),
    ``ended`` once it goes away."""

    def __init__(self, session: zenoh.Session, run_id: str, secret: str) -> None:
        self.run_id = run_id
        self.seal = bus.Seal(secret)
        self.found = threading.Event()
        self.ended = threading.Event()
        self._keys: set[str] = set()
        self._sub = session.liveliness().declare_subscriber(
            bus.alive_key(run_id, RUN_TOKEN, "*"),
            zenoh.handlers.Callback(self._on_token, indirect=False),
            history=True,
        )

    def _on_token(self, sample: zenoh.Sample) -> None:
        name, proof = bus.parse_alive_key(sample.key_expr)
        if name != RUN_TOKEN or self.seal.check_alive(self.run_id, name, proof) is None:
            return  # not the run's: ignored
        key_expr = str(sample.key_expr)
        if sample.kind == zenoh.SampleKind.PUT:
            self._keys.add(key_expr)
            self.found.set()
        elif key_expr in self._keys:
            self.ended.set()


def resolve_secret(secret_file: str | Path | None) -> str:
    try:
        secret = bus.read_secret(SECRET_ENV, secret_file)
    except OSError as exc:
        raise WorkerError(f"cannot read --secret-file {secret_file}: {exc.strerror or exc}", EXIT_BAD_INPUT) from None
    if not secret:
        raise WorkerError(
            f"no run secret: pass --secret-file (the run folder's `secret`) or set {SECRET_ENV}", EXIT_BAD_INPUT
        )
    return secret


def run_worker(
    plan: Plan,
    connect: list[str],
    run_id: str,
    name: str = "ext0",
    *,
    secret: str,
    wait: float = 30.0,
    zenoh_config: str | None = None,
    say=print,
) -> int:
    """Join run ``run_id`` at ``connect`` and serve trials until it ends; returns the exit code."""
    from .host import serve

    spec = worker_spec(plan, run_id, name, connect, secret)
    spec["zenoh_config"] = zenoh_config
    interrupted = threading.Event()
    previous = signal.signal(signal.SIGINT, lambda *_: interrupted.set())
    try:
        try:
            session = bus.open_session(
                ["tcp/127.0.0.1:0"], list(connect), zenoh_config=zenoh_config, lease_ms=lease_ms(plan)
            )
        except Exception as exc:
            raise WorkerError(f"cannot open a Zenoh session to {', '.join(connect)}: {exc}") from None
        try:
            watch = RunWatch(session, run_id, secret)
            say(f"sfl: worker {spec['instance']} waiting for run {run_id} at {', '.join(connect)} (up to {wait:g} s)")
            step = 0.1
            waited = 0.0
            while not watch.found.wait(step):
                waited += step
                if interrupted.is_set():
                    return EXIT_INTERRUPTED
                if waited >= wait:
                    raise WorkerError(
                        f"no run {run_id} answered at {', '.join(connect)} within {wait:g} s "
                        "(is it still running, with --listen on that endpoint? are the run id and the secret its own?)"
                    )
            say(f"sfl: worker {spec['instance']} joined run {run_id}")
            stop = threading.Event()
            threading.Thread(target=lambda: (watch.ended.wait(), stop.set()), daemon=True, name="run-watch").start()
            if interrupted.is_set():
                return EXIT_INTERRUPTED
            signal.signal(signal.SIGINT, previous)  # serve() installs its own (Ctrl-C stops the worker)
            code = serve(spec, on_sigint=True, stop_event=stop)
            if code:
                return code
            if watch.ended.is_set():
                say(f"sfl: run {run_id} ended; worker {spec['instance']} stops")
                return EXIT_DONE
            return EXIT_INTERRUPTED
        finally:
            session.close()
    finally:
        signal.signal(signal.SIGINT, previous)
        sys.stdout.flush()
