"""Telemetry: what a body, a controller or a brain module has to show, as typed data.

Bodies, controllers and brain modules import no viewer library. On a logged trial they hand
typed items (scalar series, 2-D line strips, arrows, boxes, events, map snapshots) to
``self.telemetry``, a :class:`TelemetrySink`; the runtime gives each hosted module a sink that turns
the items into Rerun columns (:mod:`sfl_brain.recording.rerun_sink`) and, for map snapshots, rows of
``maps.parquet`` (:mod:`sfl_brain.recording.tables`); a test gives it a :class:`CaptureTelemetry` and reads
the items back. Without a sink (``None``: the run does not record) nothing is computed.

A sink also says how much it wants to see (:class:`Rates`, from the scenario's ``record:``
section): samples of scalar signals and pictures of the body per simulated second, and whether
to show neuron activities. A body or controller samples its logged trial at those rates; the
recording's size and cost follow from them, not from the control tick.

Times are seconds on the ``sim_time`` timeline (trial k of a body whose trials last ``duration``
starts at ``k * duration``); ``trial`` is the trial timeline's index. Paths are relative to the
module's own entity (``body``, ``controller``, ``acc``): ``joints/hip_l`` from the body becomes
``body/joints/hip_l`` in the recording. 2-D pictures (strips, arrows) are in metres with y up
(the walker's sagittal plane).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Protocol

import numpy as np

#: colours of a success and of a failure, wherever an outcome is shown
SUCCESS = (40, 170, 60)
FAILURE = (210, 50, 50)


@dataclass(frozen=True)
class Scalars:
    """A scalar signal over a trial: ``values[i]`` at ``times[i]`` s; ``unit`` for the reader.

    ``color`` fixes the series' colour; ``points`` draws it as markers instead of a line (events
    such as a trial's start and end)."""

    path: str
    trial: int
    times: np.ndarray
    values: np.ndarray
    unit: str = ""
    color: tuple[int, int, int] | None = None
    points: bool = False


@dataclass(frozen=True)
class Strips2D:
    """Pictures made of 2-D line strips (a walker's links, the ground), metres, y up: frame i at
    ``times[i]`` is the ``per_frame`` strips ``strips[i * per_frame:(i + 1) * per_frame]`` (each an
    (n, 2) array). ``follow``: the view of the body follows this picture (one per body: the walker)."""

    path: str
    trial: int
    times: np.ndarray
    strips: list[np.ndarray]
    per_frame: int
    colors: np.ndarray  # (per_frame, 3) uint8, the same for every frame
    radius: float = 0.006
    follow: bool = False


@dataclass(frozen=True)
class Arrows2D:
    """Arrows at given times (a push, a contact force): origins and vectors (n, 2) in m, y up."""

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
    follow: bool = False  # the view of the body follows these boxes along x (one per body: the robot)


@dataclass(frozen=True)
class Event:
    """Something that happened at one instant of a trial (a trial's start or end, a pattern switch,
    a push, a fall); ``color`` marks it (green success, red failure)."""

    path: str
    trial: int
    time: float
    text: str
    level: str = "INFO"
    color: tuple[int, int, int] | None = None


@dataclass(frozen=True)
class MapSnapshots:
    """A self-organising map after each of ``trials`` (trial timeline): its neurons' weights
    ``(k, size, dim)`` in the unit space, which are active ``(k, size)``, and its grid edges
    ``(k, edges, 2, dim)``. ``final``: the maps as the run leaves them (after pruning, thesis
    §4.4.3), at the last trial's index. ``values``: a value per neuron to colour it by (the success map's learnt
    reward, Fig. 5.9), or None."""

    path: str
    trials: np.ndarray
    weights: np.ndarray
    active: np.ndarray
    edges: np.ndarray
    color: tuple[int, int, int]
    final: bool = False
    #: each neuron's learnt reward ``(k, size)`` (QARL: the eta it learnt; NaN where none), shown as its colour
    values: np.ndarray | None = None


@dataclass(frozen=True)
class MapWinners:
    """The neuron of a map that won each of ``trials``'s point (the one (3.1)-(3.2) measured it by, before the map
    learnt it): its index ``neurons`` (k,) and its weights ``positions`` (k, dim) in the unit space, as the map stood
    when it judged the point (its snapshot at that trial's index)."""

    path: str
    trials: np.ndarray
    neurons: np.ndarray
    positions: np.ndarray
    color: tuple[int, int, int]


Telemetry = Scalars | Strips2D | Arrows2D | Boxes3D | Event | MapSnapshots | MapWinners


@dataclass(frozen=True)
class Rates:
    """How much of a logged trial a sink wants (the scenario's ``record:`` section).

    ``signals_hz``: samples per simulated second of scalar signals (joint angles, motor commands,
    contacts, neuron activities; 0: every control tick); ``pictures_hz``: pictures of the body per
    simulated second (0: every control tick); ``neurons``: show the controller's neuron activities.
    """

    signals_hz: float = 25.0
    pictures_hz: float = 25.0
    neurons: bool = True

    @staticmethod
    def every(hz: float, dt: float) -> int:
        """Control ticks of ``dt`` s between two samples at ``hz`` per simulated second (at least 1)."""
        return max(1, int(round(1.0 / (hz * dt)))) if hz > 0 else 1

    def signal_every(self, dt: float) -> int:
        return self.every(self.signals_hz, dt)

    def picture_every(self, dt: float) -> int:
        return self.every(self.pictures_hz, dt)

    def sample_every(self, dt: float) -> int:
        """Ticks between two samples a body keeps: every signal sample and every picture."""
        return math.gcd(self.signal_every(dt), self.picture_every(dt))

    @classmethod
    def from_record(cls, record: dict | None) -> Rates:
        """The rates of a host spec's ``record`` section (missing keys: the defaults)."""
        record = record or {}
        names = ("signals_hz", "pictures_hz", "neurons")
        return cls(**{k: record[k] for k in names if record.get(k) is not None})


class TelemetrySink(Protocol):
    """Where a module's telemetry goes (the runtime's Rerun sink, a test's capture)."""

    rates: Rates

    def emit(self, item: Telemetry) -> None: ...


def rates_of(sink: TelemetrySink | None) -> Rates:
    """The rates ``sink`` asks for (the defaults for a sink that says nothing)."""
    return getattr(sink, "rates", None) or Rates()


@dataclass
class CaptureTelemetry:
    """A sink that keeps every item, for tests and for use in another simulator loop."""

    items: list = field(default_factory=list)
    rates: Rates = field(default_factory=Rates)

    def emit(self, item: Telemetry) -> None:
        self.items.append(item)

    def of(self, kind: type) -> list:
        return [i for i in self.items if isinstance(i, kind)]

    def paths(self) -> set[str]:
        return {i.path for i in self.items}

    def at(self, path: str) -> list:
        """The items sent to ``path``, in order."""
        return [i for i in self.items if i.path == path]


class TelemetryTee:
    """One module's telemetry to several sinks (the recording and the map table), with one set of rates."""

    def __init__(self, *sinks, rates: Rates | None = None) -> None:
        self.sinks = [s for s in sinks if s is not None]
        self.rates = rates or Rates()

    def emit(self, item: Telemetry) -> None:
        for sink in self.sinks:
            sink.emit(item)

    def close(self) -> None:
        for sink in self.sinks:
            close = getattr(sink, "close", None)
            if close is not None:
                close()


def series(
    path: str,
    trial: int,
    times: np.ndarray,
    values,
    unit: str = "",
    *,
    color: tuple[int, int, int] | None = None,
    points: bool = False,
) -> Scalars:
    """A :class:`Scalars` item from anything array-like (float64)."""
    return Scalars(
        path, trial, np.asarray(times, dtype=float), np.asarray(values, dtype=float), unit, color=color, points=points
    )
