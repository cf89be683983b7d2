"""Zenoh plumbing: session configuration, key expressions, and request helpers.

Every key the framework uses is built here:

* ``sfl/<run_id>/<instance>/<tag>``: messages for one module instance;
* ``sfl/<run_id>/@alive/<instance>``: liveliness token of a running module.

Sessions listen and connect on 127.0.0.1 with multicast scouting off unless the
user passes other endpoints; peers find each other by gossip through the first
endpoint, so the mesh is direct between every pair of processes.
"""

from __future__ import annotations

import json
import socket

import zenoh

#: keep-alive lease: a silent peer is declared gone after this many ms
LEASE_MS = 1000


def key(run_id: str, instance: str, tag: str) -> str:
    return f"sfl/{run_id}/{instance}/{tag}"


def alive_key(run_id: str, instance: str = "*") -> str:
    return f"sfl/{run_id}/@alive/{instance}"


def instance_from_alive_key(key_expr: str) -> str:
    return str(key_expr).rsplit("/", 1)[-1]


def free_endpoint(host: str = "127.0.0.1") -> str:
    """A TCP endpoint on a free loopback port."""
    with socket.socket() as s:
        s.bind((host, 0))
        return f"tcp/{host}:{s.getsockname()[1]}"


def config(listen: list[str] | None = None, connect: list[str] | None = None) -> zenoh.Config:
    """A peer configuration: loopback, multicast scouting off, short lease."""
    conf = zenoh.Config()
    conf.insert_json5("mode", '"peer"')
    conf.insert_json5("listen/endpoints", json.dumps(listen if listen is not None else ["tcp/127.0.0.1:0"]))
    conf.insert_json5("connect/endpoints", json.dumps(connect or []))
    conf.insert_json5("scouting/multicast/enabled", "false")
    conf.insert_json5("transport/link/tx/lease", str(LEASE_MS))
    conf.insert_json5("transport/link/tx/keep_alive", "4")
    return conf


def open_session(listen: list[str] | None = None, connect: list[str] | None = None) -> zenoh.Session:
    return zenoh.open(config(listen, connect))
