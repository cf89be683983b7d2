"""Telemetry: what a body, a controller or a brain module has to show, as typed data.

Bodies, controllers and brain modules import no viewer library. On a logged trial they hand
typed items (scalar series, 2-D line strips, arrows, boxes, events, map snapshots) to
``self.telemetry``, a :class:`TelemetrySink`; the runtime gives each hosted module a sink that turns
the items into Rerun columns (:mod:`sfl_brain.rerun_sink`), and a test gives it a
:class:`CaptureTelemetry` and reads the items back. Without a sink (``None``) nothing is computed.

Times are seconds on the ``sim_time`` timeline (trial k of a body whose trials last ``duration``
starts at ``k * duration``); ``trial`` is the trial timeline's index. Paths are relative to the
module's own entity (``body``, ``controller``, ``acc``): ``joints/hip_l`` from the body becomes
``body/joints/hip_l`` in the recording.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Protocol

import numpy as np


@dataclass(frozen=True)
class Scalars:
    """A scalar signal over a trial: ``values[i]`` at ``times[i]`` s; ``unit`` for the reader."""

    path: str
    trial: int
    times: np.ndarray
    values: np.ndarray
    unit: str = ""


@dataclass(frozen=True)
class Strips2D:
    """Pictures made of 2-D line strips (a walker's links): frame i at ``times[i]`` is the
    ``per_frame`` strips ``strips[i * per_frame:(i + 1) * per_frame]`` (each an (n, 2) array, m)."""

    path: str
    trial: int
    times: np.ndarray
    strips: list[np.ndarray]
    per_frame: int
    colors: np.ndarray  # (per_frame, 3) uint8, the same for every frame
    radius: float = 0.006


@dataclass(frozen=True)
class Arrows2D:
    """Arrows at given times (a push, a contact force): origins and vectors (n, 2) in m."""

    path: str
    trial: int
    times: np.ndarray
    origins: np.ndarray
    vectors: np.ndarray
    color: tuple[int, int, int] = (220, 60, 200)


@dataclass(frozen=True)
class Boxes3D:
    """Boxes at given times (a humanoid's links): frame i holds ``per_frame`` boxes, centres and
    half sizes in m, rotations as quaternions (x, y, z, w)."""

    path: str
    trial: int
    times: np.ndarray
    centers: np.ndarray  # (frames * per_frame, 3)
    half_sizes: np.ndarray  # (per_frame, 3)
    quaternions: np.ndarray  # (frames * per_frame, 4)
    per_frame: int
    colors: np.ndarray  # (per_frame, 3) uint8


@dataclass(frozen=True)
class Event:
    """Something that happened at one instant of a trial (a pattern switch, a push, a fall)."""

    path: str
    trial: int
    time: float
    text: str
    level: str = "INFO"


@dataclass(frozen=True)
class MapSnapshots:
    """A self-organising map after each of ``trials`` (trial timeline): its neurons' weights
    ``(k, size, dim)`` in the unit space, which are active ``(k, size)``, and its grid edges
    ``(k, edges, 2, dim)``."""

    path: str
    trials: np.ndarray
    weights: np.ndarray
    active: np.ndarray
    edges: np.ndarray
    color: tuple[int, int, int]


Telemetry = Scalars | Strips2D | Arrows2D | Boxes3D | Event | MapSnapshots


class TelemetrySink(Protocol):
    """Where a module's telemetry goes (the runtime's Rerun sink, a test's capture)."""

    def emit(self, item: Telemetry) -> None: ...


@dataclass
class CaptureTelemetry:
    """A sink that keeps every item, for tests and for use in another simulator loop."""

    items: list = field(default_factory=list)

    def emit(self, item: Telemetry) -> None:
        self.items.append(item)

    def of(self, kind: type) -> list:
        return [i for i in self.items if isinstance(i, kind)]

    def paths(self) -> set[str]:
        return {i.path for i in self.items}


def series(path: str, trial: int, times: np.ndarray, values, unit: str = "") -> Scalars:
    """A :class:`Scalars` item from anything array-like (float64)."""
    return Scalars(path, trial, np.asarray(times, dtype=float), np.asarray(values, dtype=float), unit)
