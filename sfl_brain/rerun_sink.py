"""The runtime's telemetry sink: typed telemetry items to Rerun columns (one call per item).

The only module besides the supervisor's own log (:mod:`sfl_brain.rrlog`) that imports Rerun.
Each hosted module gets a :class:`RerunTelemetry` on its process's recording stream, prefixed by
the module's entity (``body``, ``controller``, ``acc``).
"""

from __future__ import annotations

import logging

import numpy as np
import rerun as rr

from .telemetry import Arrows2D, Boxes3D, Event, MapSnapshots, Scalars, Strips2D, Telemetry

log = logging.getLogger("sfl.rerun_sink")


def _index(times: np.ndarray, trial: int) -> list:
    return [
        rr.TimeColumn("sim_time", duration=np.asarray(times, dtype=float)),
        rr.TimeColumn("trial", sequence=np.full(len(times), trial, dtype=np.int64)),
    ]


class RerunTelemetry:
    """Send a module's telemetry to a Rerun recording stream under ``entity/``."""

    def __init__(self, recording: rr.RecordingStream, entity: str) -> None:
        self.recording = recording
        self.entity = entity
        self._units_sent: set[str] = set()

    def emit(self, item: Telemetry) -> None:
        send = getattr(self, f"_{type(item).__name__}", None)
        if send is None:
            raise TypeError(f"no Rerun form for telemetry {type(item).__name__}")
        send(item)

    def _path(self, item) -> str:
        return f"{self.entity}/{item.path}"

    def _Scalars(self, item: Scalars) -> None:
        path = self._path(item)
        if item.unit and path not in self._units_sent:  # the unit, once, as the series' name
            self.recording.log(path, rr.SeriesLines(names=f"{item.path.rsplit('/', 1)[-1]} ({item.unit})"), static=True)
            self._units_sent.add(path)
        self.recording.send_columns(path, _index(item.times, item.trial), rr.Scalars.columns(scalars=item.values))

    def _Strips2D(self, item: Strips2D) -> None:
        frames = len(item.times)
        self.recording.send_columns(
            self._path(item),
            _index(item.times, item.trial),
            rr.LineStrips2D.columns(
                strips=item.strips,
                colors=np.tile(item.colors, (frames, 1)),
                radii=np.full(frames * item.per_frame, item.radius, dtype=np.float32),
            ).partition(np.full(frames, item.per_frame)),
        )

    def _Arrows2D(self, item: Arrows2D) -> None:
        n = len(item.times)
        self.recording.send_columns(
            self._path(item),
            _index(item.times, item.trial),
            rr.Arrows2D.columns(
                origins=item.origins, vectors=item.vectors, colors=np.tile(np.array(item.color, np.uint8), (n, 1))
            ),
        )

    def _Boxes3D(self, item: Boxes3D) -> None:
        frames = len(item.times)
        self.recording.send_columns(
            self._path(item),
            _index(item.times, item.trial),
            rr.Boxes3D.columns(
                centers=item.centers,
                half_sizes=np.tile(item.half_sizes, (frames, 1)),
                quaternions=item.quaternions,
                colors=np.tile(item.colors, (frames, 1)),
            ).partition(np.full(frames, item.per_frame)),
        )

    def _Event(self, item: Event) -> None:
        self.recording.send_columns(
            self._path(item),
            _index(np.array([item.time]), item.trial),
            rr.TextLog.columns(text=[item.text], level=[item.level]),
        )

    def _MapSnapshots(self, item: MapSnapshots) -> None:
        k, size, dim = item.weights.shape
        index = [rr.TimeColumn("trial", sequence=np.asarray(item.trials, dtype=np.int64))]
        weights = item.weights.reshape(-1, dim)[:, :3]
        edges = item.edges.reshape(-1, 2, dim)[:, :, :3]
        if dim == 1:  # a 1-D map is drawn on a line
            weights = np.column_stack([weights, np.zeros(len(weights))])
            edges = np.concatenate([edges, np.zeros_like(edges)], axis=2)
        points, strips = (rr.Points3D, rr.LineStrips3D) if weights.shape[1] == 3 else (rr.Points2D, rr.LineStrips2D)
        active = item.active.reshape(-1)
        colour = np.where(active[:, None], item.color, (150, 150, 150)).astype(np.uint8)
        self.recording.send_columns(
            f"{self._path(item)}/neurons",
            index,
            points.columns(positions=weights, colors=colour, radii=np.full(len(weights), 0.008, np.float32)).partition(
                [size] * k
            ),
        )
        per = len(edges) // k if k else 0
        self.recording.send_columns(
            f"{self._path(item)}/edges",
            index,
            strips.columns(
                strips=edges,
                colors=np.tile(np.array(item.color, np.uint8), (len(edges), 1)),
                radii=np.full(len(edges), 0.002, np.float32),
            ).partition([per] * k),
        )
