"""What the supervisor logs to Rerun: decisions, trials, vigilance, and the default layout.

Entity paths (every process logs into the same recording id):

* ``decisions/margin`` (d_f - d_s), ``decisions/d_success``, ``decisions/d_failure``, ``decisions/s_vig``,
  ``decisions/go`` and ``decisions/v_unit/<axis>``, ``decisions/v/<axis>`` on the ``decision`` timeline;
* ``trials/*`` (success rate, N_s, N_f, N_s/N_f, eta, rho, outcome, v per axis), ``vigilance/*`` (s_vig
  and band) and
  ``omega/trials`` (the tried point, green success / red failure) on the ``trial`` timeline;
* ``acc/success_map``, ``acc/failure_map``: the maps (logged by the ACC process);
* ``body/...``: the body's motion on ``sim_time`` (logged by the body workers);
* ``controller/...``: neuron activities (logged by the controller).
"""

from __future__ import annotations

import logging
import time

import numpy as np
import rerun as rr
import rerun.blueprint as rrb

log = logging.getLogger("sfl.rrlog")

SUCCESS = (40, 170, 60)
FAILURE = (210, 50, 50)


def blueprint() -> rrb.Blueprint:
    return rrb.Blueprint(
        rrb.Horizontal(
            rrb.Vertical(
                rrb.Spatial2DView(name="success and failure maps", origin="/", contents=["/acc/**", "/omega/**"]),
                rrb.Spatial2DView(name="body", origin="/body"),
            ),
            rrb.Vertical(
                rrb.TimeSeriesView(name="trials", origin="/trials"),
                rrb.TimeSeriesView(name="vigilance", origin="/vigilance"),
                rrb.TimeSeriesView(name="decisions", origin="/decisions"),
                rrb.TimeSeriesView(name="joints and neurons", contents=["/body/joints/**", "/controller/**"]),
            ),
        ),
        collapse_panels=True,
    )


class RerunLog:
    """The supervisor's own recording stream (same recording id as every module's)."""

    def __init__(self, run_id: str, rrd: str | None, viewer: str | None, axes: list[str]) -> None:
        from .host import attach_sinks

        self.rec = rr.RecordingStream("sfl-brain", recording_id=run_id)
        attach_sinks(self.rec, rrd, viewer)
        self.rec.send_blueprint(blueprint())
        self.axes = axes
        self._decisions: list[dict] = []
        self._trials: list[dict] = []
        self._flushed = time.monotonic()
        self.broken = False  # the sink failed: stop sending, say so once
        self.rec.log("omega", rr.TextDocument("Parameter space axes (unit square): " + ", ".join(axes)), static=True)

    #: rows are buffered and sent as columns (one call per series) at most this often, and at close
    FLUSH_ROWS = 64
    FLUSH_SECONDS = 0.5

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
            or time.monotonic() - self._flushed > self.FLUSH_SECONDS
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

    def _send_decisions(self, rows: list[dict]) -> None:
        index = [rr.TimeColumn("decision", sequence=np.array([r["decision"] for r in rows]))]
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
        """One scalar series on the trial (and decision) timelines, rows where ``key`` has a value."""
        kept = [r for r in rows if r.get(key) is not None]
        if not kept:
            return
        self.rec.send_columns(
            path, self._index(kept), rr.Scalars.columns(scalars=np.array([float(r[key]) for r in kept]))
        )

    @staticmethod
    def _index(rows: list[dict]) -> list:
        index = [rr.TimeColumn("trial", sequence=np.array([int(r["trial"]) for r in rows]))]
        if all(r.get("decision") is not None for r in rows):
            index.append(rr.TimeColumn("decision", sequence=np.array([int(r["decision"]) for r in rows])))
        return index

    def _send_trials(self, rows: list[dict]) -> None:
        for path, key in (
            ("trials/success", "success"),
            ("trials/success_rate", "success_rate"),
            ("trials/quality", "quality"),
            ("trials/rho", "rho"),
            ("trials/ns_nf", "ns_nf"),
            ("trials/n_success", "n_success"),
            ("trials/n_failure", "n_failure"),
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
                rr.Points2D.columns(
                    positions=np.array([r["v_unit"][:2] for r in placed], dtype=float),
                    colors=np.array([SUCCESS if r["success"] else FAILURE for r in placed], dtype=np.uint8),
                    radii=np.full(len(placed), 0.006, dtype=np.float32),
                ),
            )
        self.rec.send_columns(
            "trials/log",
            self._index(rows),
            rr.TextLog.columns(
                text=[
                    f"trial {r['trial']}: {'success' if r['success'] else 'failure'}"
                    + (f", eta {r['quality']:.4g}" if r.get("quality") is not None else "")
                    + (f", rho {r['rho']:.3g}" if r.get("rho") is not None else "")
                    for r in rows
                ]
            ),
        )

    def close(self) -> None:
        self.flush()
        try:
            self.rec.flush()
        except RuntimeError as exc:
            self._broke(exc)
        self.rec.disconnect()
