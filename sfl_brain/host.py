"""Host one module in its own process: ``python -m sfl_brain.host SPEC_JSON``.

The host opens a Zenoh peer session, answers each request type the module
handles on ``sfl/<run>/<instance>/<tag>``, publishes replies to stream messages
(lockstep ticks) to the instance named in its routes, and declares a liveliness
token once it is ready. Everything received is handed to one loop in the main
thread (callbacks only enqueue), so the module never sees two messages at once.

A malformed or unknown message is logged and dropped (a request gets an error
reply). The host exits on SIGTERM, or when its parent goes away (stdin closes).
"""

from __future__ import annotations

import json
import logging
import os
import queue
import signal
import sys
import threading
import time
from typing import Any

import zenoh

from . import bus
from .body import Body, InProcessLink
from .messages import ControllerReset, Message, MessageError, MotorCommand, SensorFrame, decode, encode
from .module import Module
from .registry import resolve

log = logging.getLogger("sfl.host")

STOP = object()


class LinkError(RuntimeError):
    """The controller did not answer during a trial (it died or hung): the trial is interrupted."""


class BusLink:
    """A body's link to a controller in another process: lockstep pub/sub per tick."""

    def __init__(self, session: zenoh.Session, run_id: str, body: str, controller: str, timeout: float) -> None:
        self.session = session
        self.timeout = timeout
        self.reset_key = bus.key(run_id, controller, ControllerReset.TAG)
        self.commands: queue.SimpleQueue = queue.SimpleQueue()
        self.publisher = session.declare_publisher(bus.key(run_id, controller, SensorFrame.TAG))
        self.subscriber = session.declare_subscriber(
            bus.key(run_id, body, MotorCommand.TAG), zenoh.handlers.Callback(self._on_command, indirect=False)
        )

    def _on_command(self, sample: zenoh.Sample) -> None:
        self.commands.put(sample.payload.to_bytes())

    def reset(self, msg: ControllerReset) -> None:
        while not self.commands.empty():
            self.commands.get_nowait()
        request(self.session, self.reset_key, msg, self.timeout)

    def step(self, frame: SensorFrame) -> MotorCommand:
        self.publisher.put(encode(frame))
        deadline = time.monotonic() + self.timeout
        while True:
            remaining = deadline - time.monotonic()
            try:
                data = self.commands.get(timeout=max(remaining, 0.0))
            except queue.Empty:
                raise LinkError(f"interrupted: no command for tick {frame.tick} within {self.timeout:g} s") from None
            try:
                command = decode(data)
            except MessageError as exc:
                log.warning("dropped malformed command: %s", exc)
                continue
            if not isinstance(command, MotorCommand) or command.trial_id != frame.trial_id or command.tick != frame.tick:
                log.warning("dropped unexpected message %s", getattr(command, "TAG", command))
                continue
            return command

    def close(self) -> None:
        self.subscriber.undeclare()
        self.publisher.undeclare()


class RemoteError(RuntimeError):
    """A module answered a request with an error, or nobody answered."""


def request(session: zenoh.Session, key_expr: str, msg: Message, timeout: float) -> Message:
    """Send ``msg`` to the queryable at ``key_expr`` and return its decoded reply."""
    replies = session.get(key_expr, payload=encode(msg), timeout=timeout)
    for reply in replies:
        if reply.ok is not None:
            return decode(reply.ok.payload.to_bytes())
        raise RemoteError(reply.err.payload.to_string())
    raise RemoteError(f"no reply from {key_expr} within {timeout:g} s")


def make_module(reference: str, params: dict, seed: int, entity: str) -> Module:
    cls, _ = resolve(reference)
    module = cls(cls.Params.model_validate(params), seed=seed)
    module.entity = entity
    return module


def make_recording(run_id: str, rrd: str | None, viewer: str | None):
    if not rrd and not viewer:
        return None
    import rerun as rr

    rec = rr.RecordingStream("sfl-brain", recording_id=run_id)
    if viewer:
        rec.connect_grpc(viewer)
    else:
        rec.save(rrd)
    return rec


class Host:
    def __init__(self, spec: dict[str, Any]) -> None:
        self.spec = spec
        self.run_id = spec["run_id"]
        self.instance = spec["instance"]
        self.inbox: queue.SimpleQueue = queue.SimpleQueue()
        self._publishers: dict[str, Any] = {}

    # callbacks only enqueue; the main loop does the work
    def _enqueue(self, item) -> None:
        self.inbox.put(item)

    def _reply_key(self, tag: str) -> str:
        return bus.key(self.run_id, self.spec["routes"][tag], tag)

    def serve(self) -> None:
        spec = self.spec
        self.module = make_module(spec["reference"], spec["params"], spec["seed"], spec["spec_name"])
        self.session = bus.open_session(spec["listen"], spec["connect"])
        declared = []
        link = None
        rec = None
        try:
            rec = make_recording(self.run_id, spec.get("rrd"), spec.get("viewer"))
            self.module.recording = rec
            if isinstance(self.module, Body):
                self.module.worker = self.instance
                self.module.realtime = bool(spec.get("realtime"))
                colocated = spec.get("colocated")
                if colocated:
                    controller = make_module(colocated["reference"], colocated["params"], colocated["seed"],
                                             colocated["spec_name"])
                    controller.recording = rec
                    self.module.link = InProcessLink(controller)
                elif self.module.COMMANDS:
                    link = BusLink(self.session, self.run_id, self.instance, spec["routes"][SensorFrame.TAG],
                                   spec["tick_timeout"])
                    self.module.link = link
            for message_type in type(self.module).handles:
                key_expr = bus.key(self.run_id, self.instance, message_type.TAG)
                callback = zenoh.handlers.Callback(self._enqueue, indirect=False)
                if message_type.STREAM:
                    declared.append(self.session.declare_subscriber(key_expr, callback))
                else:
                    declared.append(self.session.declare_queryable(key_expr, callback))
            token = self.session.liveliness().declare_token(bus.alive_key(self.run_id, self.instance))
            log.info("%s ready (%s)", self.instance, spec["reference"])
            self._loop()
            token.undeclare()
        finally:
            for d in declared:
                d.undeclare()
            if link is not None:
                link.close()
            for p in self._publishers.values():
                p.undeclare()
            self.module.close()
            if rec is not None:
                rec.flush()
                rec.disconnect()
            self.session.close()

    def _loop(self) -> None:
        inbox = self.inbox
        while True:
            try:
                item = inbox.get(timeout=1.0)
            except queue.Empty:
                continue
            if item is STOP:
                return
            if isinstance(item, zenoh.Query):
                self._answer(item)
            else:
                self._stream(item)

    def _answer(self, query: zenoh.Query) -> None:
        try:
            payload = query.payload
            if payload is None:
                raise MessageError("empty request")
            msg = decode(payload.to_bytes())
            reply = self.module.handle(msg)
            query.reply(query.key_expr, encode(reply))
        except MessageError as exc:
            log.warning("%s: dropped malformed request on %s: %s", self.instance, query.key_expr, exc)
            query.reply_err(f"malformed request: {exc}")
        except Exception as exc:  # the module failed on this request: report, keep serving
            log.exception("%s: error handling request on %s", self.instance, query.key_expr)
            query.reply_err(f"{type(exc).__name__}: {exc}")
        finally:
            query.drop()

    def _stream(self, sample: zenoh.Sample) -> None:
        try:
            msg = decode(sample.payload.to_bytes())
            reply = self.module.handle(msg)
        except MessageError as exc:
            log.warning("%s: dropped malformed message on %s: %s", self.instance, sample.key_expr, exc)
            return
        except Exception:
            log.exception("%s: error handling %s", self.instance, sample.key_expr)
            return
        if reply is not None:
            key_expr = self._reply_key(reply.TAG)
            publisher = self._publishers.get(key_expr)
            if publisher is None:
                publisher = self._publishers[key_expr] = self.session.declare_publisher(key_expr)
            publisher.put(encode(reply))


def _watch_parent(inbox: queue.SimpleQueue) -> None:
    """Stop when the parent closes our stdin (it exited, even by kill -9)."""
    try:
        while sys.stdin.buffer.read(1024):
            pass
    except (OSError, ValueError):
        pass
    inbox.put(STOP)


def main(argv: list[str] | None = None) -> int:
    argv = sys.argv[1:] if argv is None else argv
    spec = json.loads(argv[0])
    logging.basicConfig(level=spec.get("log_level", "INFO"),
                        format=f"%(asctime)s {spec['instance']} %(levelname)s %(message)s", stream=sys.stderr)
    host = Host(spec)
    signal.signal(signal.SIGTERM, lambda *_: host.inbox.put(STOP))
    signal.signal(signal.SIGINT, signal.SIG_IGN)  # Ctrl-C is the supervisor's to handle
    if spec.get("watch_stdin", True):
        threading.Thread(target=_watch_parent, args=(host.inbox,), daemon=True).start()
    try:
        host.serve()
    except Exception:
        log.exception("%s failed", spec["instance"])
        return 1
    return 0


if __name__ == "__main__":
    code = main()
    logging.shutdown()
    sys.stderr.flush()
    os._exit(code)  # the session is closed; do not wait on foreign threads at exit
