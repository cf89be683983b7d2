"""The runtime's telemetry sink: typed telemetry items to Rerun columns (one call per item).

The only module besides the supervisor's own log (:mod:`sfl_brain.recording.rrlog`) that imports Rerun.
Each hosted module gets a :class:`RerunTelemetry` on its process's recording stream, prefixed by
the module's entity (``body``, ``controller``, ``acc``).

How the items look (the default layout is :func:`sfl_brain.recording.rrlog.blueprint`):

* :class:`~sfl_brain.telemetry.Scalars`: a time series named ``<last path part> (<unit>)``, drawn as
  a line, or as markers when ``points``; on ``sim_time`` and ``trial``;
* :class:`~sfl_brain.telemetry.Strips2D` and :class:`~sfl_brain.telemetry.Arrows2D`: 3-D strips and
  arrows in the plane z = 0 of a y-up space (``ViewCoordinates.RIGHT_HAND_Y_UP`` at the module's
  entity), so that a 3-D view shows a walker upright (Rerun's 2-D views are y-down); colours and
  radii, the same for every frame, are sent once (static), each frame only its points. A picture
  with ``follow`` also moves ``<entity>/follow`` (a translation along x to the picture's middle):
  the body's view has it as origin, so its camera walks with the walker;
* :class:`~sfl_brain.telemetry.MapSnapshots`: points and grid edges in the same y-up space (a 2-D
  map in the plane z = 0, so that the second axis of Omega points up) on ``trial`` and, when the
  run's trial length is known, on ``sim_time`` at ``trial x trial_seconds`` (the maps that chose
  trial k are shown while trial k runs);
* :class:`~sfl_brain.telemetry.MapWinners`: each trial's winning neuron as a larger labelled point at
  ``<map>/winner``, in the same space and on the same timelines as the map's snapshot it won in.
"""

from __future__ import annotations

import logging
import time
from collections.abc import Callable

import numpy as np
import rerun as rr

from ..telemetry import Arrows2D, Boxes3D, Event, MapSnapshots, MapWinners, Rates, Scalars, Strips2D, Telemetry

log = logging.getLogger("sfl.rerun_sink")

_GREY = (150, 150, 150)


def _index(times: np.ndarray, trial: int) -> list:
    return [
        rr.TimeColumn("sim_time", duration=np.asarray(times, dtype=float)),
        rr.TimeColumn("trial", sequence=np.full(len(times), trial, dtype=np.int64)),
    ]


def _z0(xy: np.ndarray) -> np.ndarray:
    """(n, 2) points of the y-up plane as (n, 3) points at z = 0."""
    xy = np.asarray(xy, dtype=np.float32).reshape(-1, 2)
    return np.column_stack([xy, np.zeros(len(xy), dtype=np.float32)])


#: the entity (under a module's) that moves with a followed picture: the origin of the body's view
FOLLOW = "follow"


def _frames(item: Strips2D):
    """The strips of each frame of a picture."""
    n = item.per_frame
    return (item.strips[i * n : (i + 1) * n] for i in range(len(item.times)))


def _strips3d(strips) -> np.ndarray | list[np.ndarray]:
    """2-D strips as 3-D strips at z = 0: one (strips, points, 3) array when they all have as many
    points (Rerun's fast path), else a list."""
    if len(strips) and len({len(s) for s in strips}) == 1:
        flat = np.asarray(strips, dtype=np.float32)
        return np.concatenate([flat, np.zeros((*flat.shape[:2], 1), dtype=np.float32)], axis=2)
    return [_z0(s) for s in strips]


def _reward_colours(values: np.ndarray, active: np.ndarray, colour: np.ndarray) -> np.ndarray:
    """One snapshot's neurons with a learnt reward coloured on viridis from the map's lowest (dark) to its highest
    (yellow); the others keep ``colour``."""
    import matplotlib

    known = active & np.isfinite(values)
    if not known.any():
        return colour
    low, high = float(values[known].min()), float(values[known].max())
    share = (values[known] - low) / (high - low) if high > low else np.ones(int(known.sum()))
    out = colour.copy()
    out[known] = (np.asarray(matplotlib.colormaps["viridis"](share))[:, :3] * 255).astype(np.uint8)
    return out


class RerunTelemetry:
    """Send a module's telemetry to a Rerun recording stream under ``entity/``.

    ``trial_seconds``: simulated seconds from one trial's start to the next (or a function that
    finds it, called once when first needed); None: map snapshots only on the ``trial`` timeline.
    ``batch_seconds``: send queued series at least this often (a live viewer); None: only when a
    path holds ``BATCH_ROWS`` rows and at :meth:`close` (a file: fewer, larger chunks whatever the
    machine's speed).
    """

    #: scalar series and pictures are sent in chunks of several trials, when a path holds this many
    #: rows (a chunk costs its own schema and index in the file)
    BATCH_ROWS = 4096

    def __init__(
        self,
        recording: rr.RecordingStream,
        entity: str,
        rates: Rates | None = None,
        trial_seconds: float | Callable[[], float | None] | None = None,
        batch_seconds: float | None = None,
    ) -> None:
        self.recording = recording
        self.batch_seconds = batch_seconds
        self.entity = entity
        self.rates = rates or Rates()
        self._trial_seconds = trial_seconds
        self._styled: set[str] = set()  # paths whose static style (name, colours, radii) is sent
        self._y_up = False
        # path -> (kind, per_frame, [times], [trials], [data], rows) not yet sent
        self._pending: dict[str, list] = {}
        self._oldest: float | None = None

    def emit(self, item: Telemetry) -> None:
        send = getattr(self, f"_{type(item).__name__}", None)
        if send is None:
            raise TypeError(f"no Rerun form for telemetry {type(item).__name__}")
        send(item)

    def _queue(self, path: str, kind: str, times, trial: int, data, per_frame: int = 1) -> None:
        pending = self._pending.get(path)
        if pending is None:
            pending = self._pending[path] = [kind, per_frame, [], [], [], 0]
        pending[2].append(np.asarray(times, dtype=float))
        pending[3].append(np.full(len(times), trial, dtype=np.int64))
        pending[4].append(data)
        pending[5] += len(times)
        now = time.monotonic()
        if self._oldest is None:
            self._oldest = now
        late = self.batch_seconds is not None and now - self._oldest > self.batch_seconds
        if pending[5] >= self.BATCH_ROWS or late:
            self.flush()

    def flush(self) -> None:
        """Send every queued series and picture (at most one call per path)."""
        pending, self._pending, self._oldest = self._pending, {}, None
        for path, (kind, per_frame, times, trials, data, rows) in pending.items():
            index = [
                rr.TimeColumn("sim_time", duration=np.concatenate(times)),
                rr.TimeColumn("trial", sequence=np.concatenate(trials)),
            ]
            if kind == "scalars":
                self.recording.send_columns(path, index, rr.Scalars.columns(scalars=np.concatenate(data)))
            elif kind == "events":  # (text, level, colour) each
                colors = None
                if all(c is not None for _, _, c in data):
                    colors = np.array([c for _, _, c in data], dtype=np.uint8)
                self.recording.send_columns(
                    path,
                    index,
                    rr.TextLog.columns(text=[t for t, _, _ in data], level=[lv for _, lv, _ in data], color=colors),
                )
            elif kind == "follow":  # x of the followed picture
                x = np.concatenate(data)
                translation = np.column_stack([x, np.zeros(len(x)), np.zeros(len(x))])
                self.recording.send_columns(path, index, rr.Transform3D.columns(translation=translation))
            else:  # pictures: per_frame strips a row
                strips = [s for piece in data for s in piece]
                if all(isinstance(piece, np.ndarray) for piece in data) and len({p.shape[1:] for p in data}) == 1:
                    strips = np.concatenate(data)
                self.recording.send_columns(
                    path, index, rr.LineStrips3D.columns(strips=strips).partition(np.full(rows, per_frame))
                )

    def close(self) -> None:
        self.flush()

    @property
    def trial_seconds(self) -> float | None:
        if callable(self._trial_seconds):
            self._trial_seconds = self._trial_seconds()
        return self._trial_seconds

    def _path(self, item) -> str:
        return f"{self.entity}/{item.path}"

    def _style_once(self, path: str, *archetypes) -> None:
        if path not in self._styled:
            self._styled.add(path)
            for archetype in archetypes:
                self.recording.log(path, archetype, static=True)

    def _plane(self) -> None:
        """The module's pictures are in a y-up space (x forward, y up, z toward the viewer)."""
        if not self._y_up:
            self._y_up = True
            self.recording.log(self.entity, rr.ViewCoordinates.RIGHT_HAND_Y_UP, static=True)

    def _Scalars(self, item: Scalars) -> None:
        path = self._path(item)
        leaf = item.path.rsplit("/", 1)[-1]
        name = f"{leaf} ({item.unit})" if item.unit else leaf
        colors = [item.color] if item.color is not None else None
        if item.points:
            style = rr.SeriesPoints(names=name, colors=colors, markers="circle", marker_sizes=4.0)
        else:
            style = rr.SeriesLines(names=name, colors=colors)
        self._style_once(path, style)
        self._queue(path, "scalars", item.times, item.trial, np.asarray(item.values, dtype=float))

    def _Strips2D(self, item: Strips2D) -> None:
        path = self._path(item)
        self._plane()
        self._style_once(
            path,
            rr.LineStrips3D.from_fields(
                colors=np.asarray(item.colors, dtype=np.uint8).reshape(-1, 3),
                radii=np.full(item.per_frame, item.radius, dtype=np.float32),
            ),
        )
        strips = _strips3d(item.strips)
        self._queue(path, "strips", item.times, item.trial, strips, item.per_frame)
        if item.follow:  # a frame that moves along x with the picture: the view of the body has it as origin
            xs = [float(np.mean(np.concatenate([np.asarray(s)[:, 0] for s in frame]))) for frame in _frames(item)]
            self._queue(f"{self.entity}/{FOLLOW}", "follow", item.times, item.trial, np.array(xs))

    def _Arrows2D(self, item: Arrows2D) -> None:
        path = self._path(item)
        self._plane()
        self._style_once(path, rr.Arrows3D.from_fields(colors=np.array([item.color], dtype=np.uint8)))
        self.recording.send_columns(
            path,
            _index(item.times, item.trial),
            rr.Arrows3D.columns(origins=_z0(item.origins), vectors=_z0(item.vectors)),
        )

    def _Boxes3D(self, item: Boxes3D) -> None:
        path = self._path(item)
        self._style_once(
            path,
            rr.Boxes3D.from_fields(half_sizes=item.half_sizes, colors=np.asarray(item.colors, dtype=np.uint8)),
        )
        frames = len(item.times)
        self.recording.send_columns(
            path,
            _index(item.times, item.trial),
            rr.Boxes3D.columns(centers=item.centers, quaternions=item.quaternions).partition(
                np.full(frames, item.per_frame)
            ),
        )
        if item.follow:  # as a followed picture's: the view of the body has <entity>/follow as origin
            xs = np.asarray(item.centers, dtype=float)[:, 0].reshape(frames, item.per_frame).mean(axis=1)
            self._queue(f"{self.entity}/{FOLLOW}", "follow", item.times, item.trial, xs)

    def _Event(self, item: Event) -> None:
        self._queue(self._path(item), "events", [item.time], item.trial, (item.text, item.level, item.color))

    def _MapWinners(self, item: MapWinners) -> None:
        """Each trial's winning neuron, a larger point labelled with its index over the map's snapshot of that
        trial (``<map>/winner``), on ``trial`` and, when known, ``sim_time`` at the trial's start."""
        trials = np.asarray(item.trials, dtype=np.int64)
        index = [rr.TimeColumn("trial", sequence=trials)]
        if self.trial_seconds:
            index.append(rr.TimeColumn("sim_time", duration=trials * self.trial_seconds))
        positions = np.asarray(item.positions, dtype=float)[:, :3]
        if positions.shape[1] < 3:
            positions = np.column_stack([positions, np.zeros((len(positions), 3 - positions.shape[1]))])
        self._plane()
        path = f"{self._path(item)}/winner"
        self._style_once(
            path, rr.Points3D.from_fields(radii=[0.02], colors=np.array([item.color], dtype=np.uint8), show_labels=True)
        )
        labels = [f"{item.path.removesuffix('_map')} winner {int(n)}" for n in item.neurons]
        self.recording.send_columns(path, index, rr.Points3D.columns(positions=positions, labels=labels))

    def _MapSnapshots(self, item: MapSnapshots) -> None:
        k, size, dim = item.weights.shape
        trials = np.asarray(item.trials, dtype=np.int64)
        index = [rr.TimeColumn("trial", sequence=trials)]
        if self.trial_seconds:
            index.append(rr.TimeColumn("sim_time", duration=trials * self.trial_seconds))
        weights = item.weights.reshape(-1, dim)[:, :3]
        edges = item.edges.reshape(-1, 2, dim)[:, :, :3]
        if dim < 3:  # a 1-D map on the x axis, a 2-D map in the plane z = 0 of the y-up space
            weights = np.column_stack([weights, np.zeros((len(weights), 3 - dim))])
            edges = np.concatenate([edges, np.zeros((*edges.shape[:2], 3 - dim))], axis=2)
        self._plane()
        points, strips = rr.Points3D, rr.LineStrips3D
        active = item.active.reshape(-1)
        colour = np.where(active[:, None], item.color, _GREY).astype(np.uint8)  # switched-off neurons in grey
        if item.values is not None:  # the success map coloured by the reward each neuron learnt (QARL, Fig. 5.9)
            values = np.asarray(item.values, dtype=float).reshape(k, size)
            colour = np.concatenate(
                [
                    _reward_colours(values[i], active[i * size : (i + 1) * size], colour[i * size : (i + 1) * size])
                    for i in range(k)
                ]
            )
        neurons, grid = f"{self._path(item)}/neurons", f"{self._path(item)}/edges"
        self._style_once(neurons, points.from_fields(radii=np.full(size, 0.008, np.float32)))
        self.recording.send_columns(
            neurons, index, points.columns(positions=weights, colors=colour).partition([size] * k)
        )
        per = len(edges) // k if k else 0
        self._style_once(
            grid,
            strips.from_fields(
                colors=np.tile(np.array(item.color, np.uint8), (per, 1)), radii=np.full(per, 0.002, np.float32)
            ),
        )
        self.recording.send_columns(grid, index, strips.columns(strips=edges).partition([per] * k))


def attach_sinks(rec, rrd: str | None, viewer: str | None) -> None:
    """Send a recording to the run folder's file, to a live viewer, or to both at once."""
    if viewer and rrd:
        rec.set_sinks(rr.GrpcSink(viewer), rr.FileSink(rrd))
    elif viewer:
        rec.connect_grpc(viewer)
    else:
        rec.save(rrd)
