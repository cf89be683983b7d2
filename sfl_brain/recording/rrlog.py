"""What the supervisor logs to Rerun: decisions, trials, vigilance, and the default layout.

Entity paths (every process logs into the same recording id; ``docs/recording.md`` shows the layout):

* ``decisions/d_success``, ``decisions/d_failure`` (3.1)-(3.2), ``decisions/margin`` (d_f - d_s),
  ``decisions/s_vig``, ``decisions/go`` (1 go, 0 no-go: the early warning (3.3)) and
  ``decisions/v_unit/<axis>``, ``decisions/v/<axis>``: one row per decision (per sample drawn), on
  the ``decision`` timeline, on ``trial`` (the trial it was drawn for: a no-go's is the next trial)
  and on ``sim_time`` (that trial's start);
* ``trials/*`` (success, success rate, N_s, N_f, N_s/N_f, eta, rho, v per axis, each map's winning neuron's
  index: ``success_winner``, ``failure_winner``), ``trials/log`` (a
  line per trial, green success / red failure), ``vigilance/*`` (s_vig and its band) and
  ``omega/trials`` (the tried point, green success / red failure) on ``trial`` and ``sim_time``;
* ``acc/success_map``, ``acc/failure_map``: the maps (the ACC process's telemetry);
* ``body/...``: the body's motion, joint angles, motors, trial start/end markers on ``sim_time``
  (the body workers' telemetry), ``controller/neurons/...``: neuron activities.

On ``sim_time`` trial k starts at ``k * trial_seconds`` (the body's ``duration``), so scrubbing it
shows a trial's walker beside the decision that chose it and the maps that decided. The default layout depends on
the run (:func:`layout_of`): the planar walkers' (:func:`walker_layout`) or the humanoid's (:func:`humanoid_layout`).
"""

from __future__ import annotations

import logging
import os
import sys
import time

import numpy as np
import rerun as rr
import rerun.blueprint as rrb

from ..telemetry import FAILURE, SUCCESS
from .rerun_sink import attach_sinks

log = logging.getLogger("sfl.rrlog")

#: what the decisions panel shows, with the series' names and colours
#: s a process waits for its recording to reach the disk when it closes (seconds on a healthy disk; a full disk
#: stops rerun's writer thread and an unbounded flush would wait for ever)
RERUN_FLUSH_TIMEOUT = 30.0


#: recordings whose writer a full disk has stuck: kept alive so that no garbage collection drops them (rerun's
#: ``disconnect`` and a dropped stream both wait for that writer for ever); a process holding any leaves with
#: :func:`exit_process`
STUCK: list[rr.RecordingStream] = []


def close_recording(rec: rr.RecordingStream, timeout: float = RERUN_FLUSH_TIMEOUT) -> RuntimeError | None:
    """Flush ``rec`` for up to ``timeout`` s, then disconnect it; returns the flush's error instead of raising. When the
    flush fails (a full disk stops rerun's writer thread), the stream is neither disconnected nor dropped (seen: a run
    hung in ``disconnect``, and in the stream's ``__del__``, after its disk filled up): it is kept in ``STUCK``."""
    try:
        rec.flush(timeout_sec=timeout)
    except RuntimeError as exc:
        STUCK.append(rec)
        return exc
    rec.disconnect()
    return None


def exit_process(code: int) -> None:
    """``sys.exit(code)``, or, when a recording is stuck (``STUCK``), leave at once without the interpreter's clean-up
    (which would drop the stream and wait for its writer for ever); everything else is written and closed by then."""
    if STUCK:
        logging.shutdown()
        sys.stdout.flush()
        sys.stderr.flush()
        os._exit(code)
    sys.exit(code)


DECISION_SERIES = {
    "d_success": ("d_s", SUCCESS),
    "d_failure": ("d_f", FAILURE),
    "margin": ("d_f - d_s", (120, 120, 120)),
    "s_vig": ("s_vig", (60, 110, 220)),
    "go": ("go (1) / no-go (0)", (230, 150, 30)),
}


#: the default layouts: the planar walkers' (chapters 3-4) and the humanoid's (chapter 5, the humanoid's ch. 4 runs)
LAYOUTS = ("walker", "humanoid")


def layout_of(plan) -> dict:
    """The default layout's arguments for a run's :class:`~sfl_brain.scenario.Plan`: ``body`` from its body class's
    ``LAYOUT`` ("walker" when it names none), ``learning`` when its protocol learns (maps, eta, rho, s_vig, winners)."""
    body = next((i.cls for i in plan.instances if i.spec_name == plan.body_spec), None)
    return {
        "body": getattr(body, "LAYOUT", "walker"),
        "learning": plan.scenario.protocol.kind == "learn",
    }


def blueprint(timeline: str | None = None, body: str = "walker", learning: bool = True) -> rrb.Blueprint:
    """The default layout of a run whose body is drawn as ``body`` (one of ``LAYOUTS``), with the learning's panels
    when ``learning``; ``timeline`` is the one shown first (default: ``trial`` for a learning run, else ``sim_time``).
    "walker": :func:`walker_layout`; "humanoid": :func:`humanoid_layout`."""
    if body not in LAYOUTS:
        raise ValueError(f"blueprint body: expected one of {list(LAYOUTS)}; got {body!r}")
    timeline = timeline or ("trial" if learning else "sim_time")
    if body == "humanoid":
        return humanoid_layout(timeline, learning)
    return walker_layout(timeline)


def _so_far() -> list:
    """Every row up to the time cursor, on either timeline (the tried points so far)."""
    return [
        rrb.VisibleTimeRange(t, start=rrb.TimeRangeBoundary.infinite(), end=rrb.TimeRangeBoundary.cursor_relative())
        for t in ("trial", "sim_time")
    ]


def _unit_square() -> rrb.EyeControls3D:
    """Omega's unit square (cube) seen along z, its second axis up."""
    return rrb.EyeControls3D(
        kind="Orbital", position=(0.5, 0.5, 1.3), look_target=(0.5, 0.5, 0.0), eye_up=(0.0, 1.0, 0.0)
    )


def _around(before: float, after: float) -> rrb.VisibleTimeRange:
    """On ``sim_time``, ``before`` s before the cursor to ``after`` s after it (a logged trial's series)."""
    return rrb.VisibleTimeRange(
        "sim_time",
        start=rrb.TimeRangeBoundary.cursor_relative(seconds=-before),
        end=rrb.TimeRangeBoundary.cursor_relative(seconds=after),
    )


def _maps_views() -> rrb.Horizontal:
    return rrb.Horizontal(
        rrb.Spatial3DView(
            name="maps: success (by learnt reward), failure (red); winners",
            origin="/",
            contents=["/acc/**", "/omega/axes"],
            eye_controls=_unit_square(),
        ),
        rrb.Spatial3DView(
            name="tried points so far",
            origin="/",
            contents=["/omega/**"],
            eye_controls=_unit_square(),
            time_ranges=_so_far(),
        ),
    )


#: the terrain switch over the torso pitch: the series' names and colours (the controller's are orange)
TORSO_SERIES = {
    "/body/torso/pitch": rr.SeriesLines(names="torso pitch (deg)", colors=[(60, 110, 220)]),
    "/controller/terrain_switch/band_low": rr.SeriesPoints(
        names="switch threshold, low (deg)", colors=[(240, 140, 20)], marker_sizes=1.5
    ),
    "/controller/terrain_switch/band_high": rr.SeriesPoints(
        names="switch threshold, high (deg)", colors=[(240, 140, 20)], marker_sizes=1.5
    ),
    "/controller/terrain_switch/at": rr.SeriesPoints(
        names="switch", colors=[(240, 140, 20)], markers="diamond", marker_sizes=8.0
    ),
}


#: the ankle adaptation and the foot detector (issue 29): each foot's sensed slope, each ankle's centre shift, the
#: foot_slope detector's band and the switch (orange), in degrees
TERRAIN_SERIES = {
    "/controller/terrain/slope_l": rr.SeriesLines(names="sensed slope, left foot (deg)", colors=[(40, 110, 220)]),
    "/controller/terrain/slope_r": rr.SeriesLines(names="sensed slope, right foot (deg)", colors=[(230, 140, 30)]),
    "/controller/terrain/ankle_centre_l": rr.SeriesLines(
        names="left ankle's centre shift (deg)", colors=[(110, 170, 240)]
    ),
    "/controller/terrain/ankle_centre_r": rr.SeriesLines(
        names="right ankle's centre shift (deg)", colors=[(240, 190, 120)]
    ),
    "/controller/terrain/band_low": rr.SeriesPoints(
        names="detector band, low (deg)", colors=[(240, 140, 20)], marker_sizes=1.5
    ),
    "/controller/terrain/band_high": rr.SeriesPoints(
        names="detector band, high (deg)", colors=[(240, 140, 20)], marker_sizes=1.5
    ),
    "/controller/terrain/switch": rr.SeriesPoints(
        names="switch", colors=[(240, 140, 20)], markers="diamond", marker_sizes=8.0
    ),
}


def humanoid_layout(timeline: str, learning: bool) -> rrb.Blueprint:
    """The humanoid's layout (chapter 5). Left, a logged trial on ``sim_time``: the walk (every NAO link as a box, the
    ground, seen from the side by a camera that follows the robot along x), the torso pitch with the terrain switch's
    threshold and the switch marked, the slope each foot senses with each ankle's centre and the foot detector's band
    (issue 29), the torso's distance. Right, when ``learning``, per trial: both maps (the success
    map coloured by each neuron's learnt reward, each trial's winning neurons labelled) and the tried points, eta
    (5.8), rho (5.2), s_vig with its band and N_s/N_f, the winning neurons' indices; without learning (a
    conditions run), each trial's outcome; then the events."""
    walk = rrb.Spatial3DView(  # seen from /body/follow, which moves along x with the robot (z up)
        name="walk (z up, sim_time)",
        origin="/body/follow",
        contents=["/body/robot", "/body/ground"],
        line_grid=rrb.LineGrid3D(visible=True, spacing=0.25, plane=rr.components.Plane3D.XY),
        eye_controls=rrb.EyeControls3D(
            kind="Orbital", position=(0.35, -1.3, 0.55), look_target=(0.0, 0.0, 0.25), eye_up=(0.0, 0.0, 1.0)
        ),
    )
    trial_range = _around(30.0, 10.0)  # most of a logged trial (30-40 s) before the cursor
    left = rrb.Vertical(
        walk,
        rrb.TimeSeriesView(
            name="torso pitch (deg), the terrain switch's threshold and the switch",
            contents=list(TORSO_SERIES),
            overrides=TORSO_SERIES,
            time_ranges=trial_range,
        ),
        rrb.TimeSeriesView(
            name="the slope each foot senses, each ankle's centre, the foot detector's band and the switch (deg)",
            contents=list(TERRAIN_SERIES),
            overrides=TERRAIN_SERIES,
            time_ranges=trial_range,
        ),
        rrb.TimeSeriesView(name="torso's distance x (m)", contents=["/body/path/x"], time_ranges=trial_range),
        row_shares=[4, 3, 3, 2],
    )
    events = rrb.TextLogView(
        name="events (terrain switches, trials)",
        contents=["/controller/events/**", "/trials/log", "/body/trial/events", "/body/events/**"],
    )
    if learning:
        run = _so_far()  # per trial: every trial up to the cursor, on sim_time too (each at its start)
        right = rrb.Vertical(
            _maps_views(),
            rrb.TimeSeriesView(
                name="per trial: eta (5.8), the quality of a success (0: a failure)",
                contents=["/trials/quality"],
                overrides={"/trials/quality": rr.SeriesPoints(names="eta", colors=[SUCCESS], marker_sizes=3.0)},
                plot_legend=rrb.PlotLegend(visible=False),
                time_ranges=run,
            ),
            rrb.TimeSeriesView(
                name="per trial: rho (5.2), the reward a success teaches",
                contents=["/trials/rho"],
                overrides={"/trials/rho": rr.SeriesPoints(names="rho", colors=[(60, 110, 220)], marker_sizes=3.0)},
                plot_legend=rrb.PlotLegend(visible=False),
                time_ranges=run,
            ),
            rrb.TimeSeriesView(
                name="per trial: s_vig and its band, N_s/N_f",
                contents=["/vigilance/s_vig", "/vigilance/band_low", "/vigilance/band_high", "/trials/ns_nf"],
                overrides={
                    "/vigilance/s_vig": rr.SeriesLines(names="s_vig", colors=[(60, 110, 220)]),
                    "/vigilance/band_low": rr.SeriesLines(names="band low", colors=[(150, 150, 150)]),
                    "/vigilance/band_high": rr.SeriesLines(names="band high", colors=[(150, 150, 150)]),
                    "/trials/ns_nf": rr.SeriesLines(names="N_s/N_f", colors=[(230, 150, 30)]),
                },
                time_ranges=run,
            ),
            rrb.TimeSeriesView(
                name="per trial: the winning neuron of each map (index)",
                contents=["/trials/success_winner", "/trials/failure_winner"],
                overrides={
                    "/trials/success_winner": rr.SeriesPoints(
                        names="success winner", colors=[SUCCESS], marker_sizes=3.0
                    ),
                    "/trials/failure_winner": rr.SeriesPoints(
                        names="failure winner", colors=[FAILURE], marker_sizes=3.0
                    ),
                },
                time_ranges=run,
            ),
            events,
            row_shares=[5, 2, 2, 2, 2, 2],
        )
    else:
        right = rrb.Vertical(
            rrb.TimeSeriesView(
                name="trials: outcome; start/end markers",
                contents=["/trials/success", "/trials/survived", "/body/trial/success", "/body/trial/failure"],
                overrides={
                    "/trials/success": rr.SeriesPoints(names="success (1) / failure (0)", marker_sizes=3.0),
                    "/trials/survived": rr.SeriesPoints(names="survived (1) / fell (0)", marker_sizes=2.0),
                },
            ),
            events,
            row_shares=[2, 3],
        )
    return rrb.Blueprint(
        rrb.Horizontal(left, right, column_shares=[3, 2]),
        rrb.TimePanel(state="collapsed", timeline=timeline, play_state="following"),
        collapse_panels=True,
    )


def walker_layout(timeline: str = "trial") -> rrb.Blueprint:
    """The planar walkers' layout: the body on the left (a y-up 3-D view of the walker and its ground, joint
    angles in degrees, motor voltages, neuron activities), the brain on the right (both maps with the
    tried points, the ACC's decisions, the trials with start/end markers, the events). Every panel
    has data on both the ``trial`` and the ``sim_time`` timelines; ``timeline`` is the one shown first."""
    walker = rrb.Spatial3DView(  # seen from /body/follow, which moves with the walker: the camera follows it
        name="walker (y up, sim_time)",
        origin="/body/follow",
        contents=["/body/**"],  # pictures only: series and logs have no 3-D form
        line_grid=rrb.LineGrid3D(visible=True, spacing=0.1, plane=rr.components.Plane3D.XY),
        eye_controls=rrb.EyeControls3D(
            kind="Orbital", position=(0.0, 0.15, 0.65), look_target=(0.0, 0.15, 0.0), eye_up=(0.0, 1.0, 0.0)
        ),
    )
    # on sim_time a body's series show the trial at the cursor (20 s around it), on trial the whole run
    around = rrb.VisibleTimeRange(
        "sim_time",
        start=rrb.TimeRangeBoundary.cursor_relative(seconds=-10.0),
        end=rrb.TimeRangeBoundary.cursor_relative(seconds=10.0),
    )
    body = rrb.Vertical(
        walker,
        rrb.TimeSeriesView(name="joint angles (deg)", contents=["/body/joints/**"], time_ranges=around),
        rrb.TimeSeriesView(name="motor voltages (V)", contents=["/body/motors/**"], time_ranges=around),
        rrb.TimeSeriesView(name="neuron activities", contents=["/controller/neurons/**"], time_ranges=around),
        row_shares=[3, 2, 2, 2],
    )

    brain = rrb.Vertical(
        _maps_views(),
        rrb.TimeSeriesView(
            name="ACC decisions: go iff d_f - d_s > s_vig",
            contents=[f"/decisions/{k}" for k in DECISION_SERIES] + ["/vigilance/band_low", "/vigilance/band_high"],
            overrides={  # one marker per decision: a trial's decisions stack on the trial and sim_time timelines
                f"/decisions/{k}": rr.SeriesPoints(names=name, colors=[colour], marker_sizes=2.5)
                for k, (name, colour) in DECISION_SERIES.items()
            },
        ),
        rrb.TimeSeriesView(
            name="trials: outcome, success rate; start/end markers",
            contents=["/trials/success", "/trials/success_rate", "/body/trial/success", "/body/trial/failure"],
            overrides={
                "/trials/success": rr.SeriesPoints(names="success (1) / failure (0)", marker_sizes=2.5),
                "/trials/success_rate": rr.SeriesLines(names="success rate", colors=[SUCCESS]),
            },
        ),
        rrb.TextLogView(
            name="events", contents=["/trials/log", "/body/trial/events", "/body/events/**", "/controller/events/**"]
        ),
        row_shares=[3, 2, 2, 2],
    )
    return rrb.Blueprint(
        rrb.Horizontal(body, brain),
        rrb.TimePanel(state="collapsed", timeline=timeline, play_state="following"),
        collapse_panels=True,
    )


class RerunLog:
    """The supervisor's own recording stream (same recording id as every module's).

    ``trial_seconds``: simulated seconds between trial starts (the body's ``duration``,
    ``Plan.trial_seconds``). None: the supervisor's rows stay off ``sim_time``.
    """

    def __init__(
        self,
        run_id: str,
        rrd: str | None,
        viewer: str | None,
        axes: list[str],
        trial_seconds: float | None = None,
        layout: dict | None = None,
        first_trial: int = 0,
    ) -> None:
        self.rec = rr.RecordingStream("sfl-brain", recording_id=run_id)
        attach_sinks(self.rec, rrd, viewer)
        # the default layout for this run (``layout``: :func:`blueprint`'s arguments, :func:`layout_of`), not forced
        # on a viewer that has one of its own (a user's changes, a layout file opened with the recording)
        self.rec.send_blueprint(blueprint(**(layout or {})), make_active=False, make_default=True)
        self.axes = axes
        self.trial_seconds = trial_seconds
        self._decisions: list[dict] = []
        self._trials: list[dict] = []
        self._next_trial = first_trial  # the trial the next no-go decision is drawn for (a resumed run: after its own)
        self._flushed = time.monotonic()
        self.live = bool(viewer)
        self.broken = False  # the sink failed: stop sending, say so once
        self.rec.log("omega", rr.TextDocument("Parameter space axes (unit square): " + ", ".join(axes)), static=True)
        self.rec.log("omega", rr.ViewCoordinates.RIGHT_HAND_Y_UP, static=True)
        ends = np.eye(3)[: min(len(axes), 3)] * 1.04  # each axis's name at its end of the unit square
        if len(ends):
            self.rec.log("omega/axes", rr.Points3D(ends, labels=list(axes[:3]), radii=0.004), static=True)

    #: rows are buffered and sent as columns (one call per series) when this many wait, at least every
    #: FLUSH_SECONDS while a viewer watches, and at close (a file gets fewer, larger chunks)
    FLUSH_ROWS = 256
    FLUSH_SECONDS = 2.0

    def decisions(self, rows: list[dict]) -> None:
        self._decisions.extend(rows)
        self._maybe_flush()

    def trial(self, row: dict) -> None:
        self._trials.append(row)
        self._maybe_flush()

    def _maybe_flush(self) -> None:
        if (
            len(self._decisions) >= self.FLUSH_ROWS
            or len(self._trials) >= self.FLUSH_ROWS
            or (self.live and time.monotonic() - self._flushed > self.FLUSH_SECONDS)
        ):
            self.flush()

    def flush(self) -> None:
        self._flushed = time.monotonic()
        decisions, self._decisions = self._decisions, []
        trials, self._trials = self._trials, []
        if self.broken:
            return
        try:
            if decisions:
                self._send_decisions(decisions)
            if trials:
                self._send_trials(trials)
        except RuntimeError as exc:  # the recording's sink died (a full disk): the records still hold it all
            self._broke(exc)

    def _broke(self, exc: Exception) -> None:
        if not self.broken:
            log.warning("the Rerun recording stopped (%s); records.jsonl keeps every row", exc)
        self.broken = True

    def _trial_index(self, trials: np.ndarray, decisions: np.ndarray | None = None) -> list:
        """Time columns: ``trial`` (and ``decision``), and ``sim_time`` at each trial's start when known."""
        index = [rr.TimeColumn("trial", sequence=trials)]
        if decisions is not None:
            index.append(rr.TimeColumn("decision", sequence=decisions))
        if self.trial_seconds:
            index.append(rr.TimeColumn("sim_time", duration=trials * self.trial_seconds))
        return index

    def _send_decisions(self, rows: list[dict]) -> None:
        drawn_for = []  # a go decision starts its trial; a no-go was drawn for the next trial to start
        for r in rows:
            if r.get("trial") is not None:
                drawn_for.append(int(r["trial"]))
                self._next_trial = int(r["trial"]) + 1
            else:
                drawn_for.append(self._next_trial)
        index = self._trial_index(np.array(drawn_for), np.array([r["decision"] for r in rows]))
        columns = {
            "decisions/margin": [r["d_failure"] - r["d_success"] for r in rows],
            "decisions/d_success": [r["d_success"] for r in rows],
            "decisions/d_failure": [r["d_failure"] for r in rows],
            "decisions/s_vig": [r["s_vig"] for r in rows],
            "decisions/go": [float(r["go"]) for r in rows],
        }
        for j, axis in enumerate(self.axes):  # v, in the unit space and in the axis's own units
            columns[f"decisions/v_unit/{axis}"] = [r["v_unit"][j] for r in rows]
            if all(axis in r for r in rows):
                columns[f"decisions/v/{axis}"] = [r[axis] for r in rows]
        for path, values in columns.items():
            self.rec.send_columns(path, index, rr.Scalars.columns(scalars=np.array(values, dtype=float)))

    def _series(self, path: str, rows: list[dict], key: str) -> None:
        """One scalar series on the trial (and decision, sim_time) timelines, rows where ``key`` has a value."""
        kept = [r for r in rows if r.get(key) is not None]
        if not kept:
            return
        self.rec.send_columns(
            path, self._index(kept), rr.Scalars.columns(scalars=np.array([float(r[key]) for r in kept]))
        )

    def _index(self, rows: list[dict]) -> list:
        trials = np.array([int(r["trial"]) for r in rows])
        with_decision = all(r.get("decision") is not None for r in rows)
        return self._trial_index(trials, np.array([int(r["decision"]) for r in rows]) if with_decision else None)

    def _send_trials(self, rows: list[dict]) -> None:
        for path, key in (
            ("trials/success", "success"),
            ("trials/success_rate", "success_rate"),
            ("trials/quality", "quality"),
            ("trials/rho", "rho"),
            ("trials/ns_nf", "ns_nf"),
            ("trials/n_success", "n_success"),
            ("trials/n_failure", "n_failure"),
            ("trials/survived", "survived"),
            ("trials/success_winner", "success_winner"),  # the neuron of each map that judged the trial's point
            ("trials/failure_winner", "failure_winner"),
            *((f"trials/v/{axis}", axis) for axis in self.axes),
            ("vigilance/s_vig", "s_vig"),
            ("vigilance/band_low", "band_low"),
            ("vigilance/band_high", "band_high"),
        ):
            self._series(path, rows, key)
        placed = [r for r in rows if r.get("v_unit") is not None and len(r["v_unit"]) >= 2]
        if placed:
            self.rec.send_columns(
                "omega/trials",
                self._index(placed),
                rr.Points3D.columns(  # in the y-up space of the maps (z = 0 for two axes)
                    positions=np.array([(list(r["v_unit"][:3]) + [0.0, 0.0])[:3] for r in placed], dtype=float),
                    colors=np.array([SUCCESS if r["success"] else FAILURE for r in placed], dtype=np.uint8),
                    radii=np.full(len(placed), 0.006, dtype=np.float32),
                ),
            )
        self.rec.send_columns(
            "trials/log",
            self._index(rows),
            rr.TextLog.columns(
                text=[
                    f"trial {r['trial']}{_case(r)}: {'success' if r['success'] else 'failure'}"
                    + (f" ({'survived' if r['survived'] else 'fell'})" if "survived" in r else "")
                    + (f", eta {r['quality']:.4g}" if r.get("quality") is not None else "")
                    + (f", rho {r['rho']:.3g}" if r.get("rho") is not None else "")
                    for r in rows
                ],
                level=["INFO" if r["success"] else "WARN" for r in rows],
                color=np.array([SUCCESS if r["success"] else FAILURE for r in rows], dtype=np.uint8),
            ),
        )

    def close(self, timeout: float = RERUN_FLUSH_TIMEOUT) -> None:
        """Send what is left and close the recording, waiting up to ``timeout`` s for it to reach the disk."""
        self.flush()
        problem = close_recording(self.rec, timeout)
        if problem is not None:
            self._broke(problem)


def _case(row: dict) -> str:
    """A conditions protocol's trial as text: its condition, trial parameters and repeat (empty for other rows)."""
    if "condition" not in row:
        return ""
    params = ", ".join(
        f"{k.partition('.')[2]} {v:g}" if isinstance(v, float) else f"{k.partition('.')[2]} {v}"
        for k, v in row.items()
        if k.startswith(("body.", "controller."))
    )
    return f" ({row['condition']}{', ' + params if params else ''}, repeat {row['repeat']})"
