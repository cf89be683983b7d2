"""What the supervisor logs to Rerun: decisions, trials, vigilance, and the default layout.

Entity paths (every process logs into the same recording id):

* ``decisions/margin`` (d_f - d_s), ``decisions/s_vig``, ``decisions/go`` on the ``decision`` timeline;
* ``trials/*`` (success rate, N_s/N_f, eta, rho, outcome), ``vigilance/*`` (s_vig and band) and
  ``omega/trials`` (the tried point, green success / red failure) on the ``trial`` timeline;
* ``acc/success_map``, ``acc/failure_map``: the maps (logged by the ACC process);
* ``body/...``: the body's motion on ``sim_time`` (logged by the body workers);
* ``controller/...``: neuron activities (logged by the controller).
"""

from __future__ import annotations

import numpy as np
import rerun as rr
import rerun.blueprint as rrb

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
        self.rec = rr.RecordingStream("sfl-brain", recording_id=run_id)
        if viewer:
            self.rec.connect_grpc(viewer)
        else:
            self.rec.save(rrd)
        self.rec.send_blueprint(blueprint())
        self.axes = axes
        self.rec.log("omega", rr.TextDocument("Parameter space axes (unit square): " + ", ".join(axes)), static=True)

    def decisions(self, rows: list[dict]) -> None:
        if not rows:
            return
        index = [rr.TimeColumn("decision", sequence=np.array([r["decision"] for r in rows]))]
        margin = np.array([r["d_failure"] - r["d_success"] for r in rows])
        self.rec.send_columns("decisions/margin", index, rr.Scalars.columns(scalars=margin))
        self.rec.send_columns("decisions/s_vig", index,
                              rr.Scalars.columns(scalars=np.array([r["s_vig"] for r in rows])))
        self.rec.send_columns("decisions/go", index,
                              rr.Scalars.columns(scalars=np.array([float(r["go"]) for r in rows])))

    def trial(self, row: dict) -> None:
        rec = self.rec
        rec.set_time("trial", sequence=int(row["trial"]))
        if row.get("decision") is not None:
            rec.set_time("decision", sequence=int(row["decision"]))
        rec.log("trials/success", rr.Scalars(float(row["success"])))
        rec.log("trials/success_rate", rr.Scalars(float(row["success_rate"])))
        if row.get("quality") is not None:
            rec.log("trials/quality", rr.Scalars(float(row["quality"])))
        if row.get("rho") is not None:
            rec.log("trials/rho", rr.Scalars(float(row["rho"])))
        if row.get("ns_nf") is not None:
            rec.log("trials/ns_nf", rr.Scalars(float(row["ns_nf"])))
        if row.get("s_vig") is not None:
            rec.log("vigilance/s_vig", rr.Scalars(float(row["s_vig"])))
            rec.log("vigilance/band_low", rr.Scalars(float(row["band_low"])))
            rec.log("vigilance/band_high", rr.Scalars(float(row["band_high"])))
        unit = row.get("v_unit")
        if unit is not None and len(unit) >= 2:
            rec.log("omega/trials", rr.Points2D([unit[:2]], colors=[SUCCESS if row["success"] else FAILURE],
                                                radii=0.006))
        rec.log("trials/log", rr.TextLog(
            f"trial {row['trial']}: {'success' if row['success'] else 'failure'}"
            + (f", eta {row['quality']:.4g}" if row.get("quality") is not None else "")
            + (f", rho {row['rho']:.3g}" if row.get("rho") is not None else "")))

    def close(self) -> None:
        self.rec.flush()
        self.rec.disconnect()
