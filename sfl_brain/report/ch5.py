"""``sfl report`` for chapter 5's learn runs on the humanoid (thesis §5.6-5.7): QARL, vigilance, maps per slope.

A chapter-5 run learns the humanoid's (MN gain pitch, MN gain roll, sigma_s) (scenarios/e5_learn.yaml and its
variants). Runs are told apart by what their scenario sets: QARL on or off (``modules.ofc.params.enabled``), the
vigilance (fixed at a value, or adaptive), the terrain (``conditions.body.slope_deg``); every setting over its seeds.

* one table row per run: its setting, status, successes, the success rate after 200 trials (L1707), N_s/N_f after 100
  trials and at the end (Fig. 5.11, 5.13), the best parameters (L1584), the success map's highest and lowest learnt
  efficiency, and the share of the unit cube the maps call success (closer to the success map than to the failure
  map, each counting its neurons that won a trial: the "success region", Fig. 5.12);
* E5.1 (L1689-1707): with against without QARL on the same seed, flat ground, fixed vigilance: the ratio of the
  highest-efficiency success neuron (thesis +60%), of the lowest (+40%), of the number of successful trials (+16%);
* E5.2 (L1726, L1755): N_s/N_f against the trial index, adaptive against fixed vigilance, flat and uphill;
* E5.3 (L1739): the success region per terrain (the thesis: larger downhill than uphill);
* per run, figures: eta of every trial against its index; the success map after 4 successes and at the end, each
  neuron coloured by the efficiency it learnt, the successful trials as dots sized by their reward rho (Fig. 5.9).

A neuron's efficiency is what it learnt (acc.npz ``success_reward``: the eta of the successes that pulled it, weighted
as (5.1) pulled it), not a re-run of its parameters. Only completed runs enter a mean.
"""

from __future__ import annotations

import math
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402
import pyarrow.parquet as pq  # noqa: E402
import yaml  # noqa: E402

from ..recording.records import read_records, run_status  # noqa: E402

THESIS_E51 = {"highest": 0.60, "lowest": 0.40, "successes": 0.16}  # L1689-1691, L1770


def is_ch5_run(scenario: dict) -> bool:
    """A learn run of chapter 5's space by success-failure learning (another proposer's run is a baseline's, compared
    in the study section, not in the thesis's terms)."""
    axes = {a.get("name") for a in scenario.get("space", [])}
    protocol = scenario.get("protocol", {})
    proposer = (protocol.get("proposer") or {}).get("kind", "sfl")
    return protocol.get("kind") == "learn" and {"gain_pitch", "gain_roll", "sigma_s"} <= axes and proposer == "sfl"


def setting(scenario: dict) -> dict:
    """What tells a chapter-5 run apart: QARL, the vigilance, the terrain."""
    modules = scenario.get("modules", {})
    ofc = modules.get("ofc", {}).get("params", {})
    vig = modules.get("vigilance", {}).get("params", {})
    mode = vig.get("mode", "fixed")
    slope = float(scenario.get("conditions", {}).get("body.slope_deg", 0.0))
    terrain = "flat" if slope == 0 else ("uphill" if slope > 0 else "downhill") + f" {abs(slope):g} deg"
    return {
        "qarl": bool(ofc.get("enabled", True)) if "ofc" in modules else False,
        "vigilance": f"fixed {vig.get('value', 0.0):g}" if mode == "fixed" else mode,
        "terrain": terrain,
        "slope": slope,
    }


def success_region(maps: dict, points: int = 21) -> float:
    """Share of a points^3 grid over the unit cube nearer the learnt success map than the learnt failure map: each
    map's active neurons that won at least one trial of their kind (an untrained map, spread over the cube by its
    initialisation, is no region; a run without a success has none, one without a failure covers the cube)."""
    axis = np.linspace(0.0, 1.0, points)
    grid = np.stack(np.meshgrid(axis, axis, axis, indexing="ij"), axis=-1).reshape(-1, 3)

    def nearest(name: str) -> np.ndarray:
        learnt = maps[f"{name}_active"] & (maps[f"{name}_wins"] > 0)
        if not learnt.any():
            return np.full(len(grid), np.inf)
        w = maps[f"{name}_weights"][learnt]
        return np.min(np.linalg.norm(grid[:, None, :] - w[None, :, :], axis=2), axis=1)

    return float(np.mean(nearest("success") < nearest("failure")))


class Run:
    """One chapter-5 run: its scenario, setting, status, trial rows, maps."""

    def __init__(self, run_dir: Path) -> None:
        self.dir = Path(run_dir)
        self.scenario = yaml.safe_load((self.dir / "scenario.yaml").read_text())
        self.setting = setting(self.scenario)
        self.seed = self.scenario.get("seed", 0)
        self.status, self.why = run_status(self.dir)
        self.trials = [r for r in read_records(self.dir) if r.get("kind") == "trial"]
        self.trials.sort(key=lambda r: r["trial"])
        self.maps = dict(np.load(self.dir / "acc.npz")) if (self.dir / "acc.npz").exists() else None
        try:
            import json

            self.best = json.loads((self.dir / "summary.json").read_text()).get("best")
        except (OSError, ValueError):
            self.best = None

    @property
    def completed(self) -> bool:
        return self.status == "completed"

    @property
    def successes(self) -> int:
        return sum(1 for r in self.trials if r.get("success"))

    def rate_after(self, n: int) -> float | None:
        first = self.trials[:n]
        return sum(1 for r in first if r.get("success")) / len(first) if len(first) == n else None

    def ns_nf(self, n: int | None = None) -> float | None:
        rows = self.trials[:n] if n else self.trials
        if not rows:
            return None
        return rows[-1].get("ns_nf")

    def neuron_eta(self) -> tuple[float, float] | None:
        """(highest, lowest) efficiency the active success neurons learnt."""
        if self.maps is None or "success_reward" not in self.maps:
            return None
        reward = self.maps["success_reward"][self.maps["success_active"]]
        reward = reward[np.isfinite(reward)]
        return (float(reward.max()), float(reward.min())) if len(reward) else None

    def label(self) -> str:
        s = self.setting
        return f"{s['terrain']}, {'QARL' if s['qarl'] else 'no QARL'}, {s['vigilance']}, seed {self.seed}"


def _fmt(x, spec: str = ".3g") -> str:
    return "-" if x is None or (isinstance(x, float) and math.isnan(x)) else format(x, spec)


def ch5_sections(run_dirs: list[Path], out: Path) -> list[str]:
    runs = [Run(d) for d in run_dirs]
    lines = ["## Chapter 5: learning on the humanoid", ""]
    lines += [
        "| run | terrain | QARL | vigilance | seed | status | trials | successes | success rate, first 200 | "
        "N_s/N_f at 100 | N_s/N_f at end | best eta (trial) | best neuron (gain pitch, gain roll, sigma_s) | "
        "neuron eta highest / lowest | success region |",
        "|" + "---|" * 15,
    ]
    for run in runs:
        s, best, eta = run.setting, run.best or {}, run.neuron_eta()
        point = best.get("neuron_point") or {}
        neuron = ", ".join(_fmt(point.get(k)) for k in ("gain_pitch", "gain_roll", "sigma_s")) if point else "-"
        region = success_region(run.maps) if run.maps is not None else None
        status = run.status if run.completed else f"**{run.status}**"
        lines.append(
            f"| {run.dir.name} | {s['terrain']} | {'on' if s['qarl'] else 'off'} | {s['vigilance']} | {run.seed} | "
            f"{status} | {len(run.trials)} | {run.successes} | {_fmt(run.rate_after(200), '.0%')} | "
            f"{_fmt(run.ns_nf(100), '.2f')} | {_fmt(run.ns_nf(), '.2f')} | "
            f"{_fmt(best.get('trial_eta'), '.4g')} ({best.get('trial', '-')}) | {neuron} | "
            f"{_fmt(eta[0] if eta else None, '.4g')} / {_fmt(eta[1] if eta else None, '.4g')} | {_fmt(region, '.0%')} |"
        )
    lines.append("")
    done = [r for r in runs if r.completed]
    lines += _e51(done) + _e52(done, out) + _e53(done)
    for run in runs:
        lines += [f"### {run.label()} ({run.dir.name})", ""]
        lines += [f"![]({_eta_figure(run, out)})", ""]
        figure = _maps_figure(run, out)
        if figure:
            lines += [f"![]({figure})", ""]
    return lines


def _e51(runs: list[Run]) -> list[str]:
    """QARL against no QARL, same seed, flat ground, the same fixed vigilance."""
    pairs = []
    for run in runs:
        s = run.setting
        if s["qarl"] and s["terrain"] == "flat" and s["vigilance"].startswith("fixed"):
            other = next(
                (
                    o
                    for o in runs
                    if not o.setting["qarl"]
                    and o.seed == run.seed
                    and o.setting["terrain"] == "flat"
                    and o.setting["vigilance"] == s["vigilance"]
                ),
                None,
            )
            if other is not None:
                pairs.append((run, other))
    if not pairs:
        return []
    lines = [
        "### E5.1: with against without QARL (flat ground, fixed vigilance, same seed)",
        "",
        "| seed | highest neuron eta, QARL / without | ratio | lowest neuron eta, QARL / without | ratio | "
        "successful trials, QARL / without | ratio | success rate after 200, QARL / without |",
        "|---|---|---|---|---|---|---|---|",
    ]
    ratios: dict[str, list[float]] = {"highest": [], "lowest": [], "successes": []}
    for qarl, plain in pairs:
        a, b = qarl.neuron_eta(), plain.neuron_eta()
        high = a[0] / b[0] if a and b else math.nan
        low = a[1] / b[1] if a and b and b[1] > 0 else math.nan
        count = qarl.successes / plain.successes if plain.successes else math.nan
        for key, value in (("highest", high), ("lowest", low), ("successes", count)):
            if not math.isnan(value):
                ratios[key].append(value)
        lines.append(
            f"| {qarl.seed} | {_fmt(a[0] if a else None, '.4g')} / {_fmt(b[0] if b else None, '.4g')} | "
            f"{high - 1:+.0%} | {_fmt(a[1] if a else None, '.4g')} / {_fmt(b[1] if b else None, '.4g')} | "
            f"{low - 1:+.0%} | {qarl.successes} / {plain.successes} | {count - 1:+.0%} | "
            f"{_fmt(qarl.rate_after(200), '.0%')} / {_fmt(plain.rate_after(200), '.0%')} |"
        )
    lines += ["", "| | thesis (one run) | ours: mean over seeds (each seed) |", "|---|---|---|"]
    for key, what in (
        ("highest", "highest-efficiency success neuron"),
        ("lowest", "lowest-efficiency success neuron"),
        ("successes", "successful trials"),
    ):
        values = ratios[key]
        mean = f"{np.mean(values) - 1:+.0%} ({', '.join(f'{v - 1:+.0%}' for v in values)})" if values else "-"
        lines.append(f"| {what}, QARL / without | {THESIS_E51[key]:+.0%} | {mean} |")
    return lines + [""]


def _e52(runs: list[Run], out: Path) -> list[str]:
    """N_s/N_f against the trial index, adaptive against fixed vigilance, per terrain."""
    terrains = sorted({r.setting["terrain"] for r in runs if r.setting["qarl"]})
    panels = [t for t in terrains if len({r.setting["vigilance"] for r in runs if r.setting["terrain"] == t}) > 1]
    if not panels:
        return []
    fig, axes = plt.subplots(1, len(panels), figsize=(6 * len(panels), 4.2), squeeze=False)
    lines = [
        "### E5.2: N_s/N_f against the trial index, adaptive against fixed vigilance",
        "",
        "| terrain | vigilance | seed | N_s/N_f at 100 | at 200 | at the end | s_vig at the end |",
        "|---|---|---|---|---|---|---|",
    ]
    colours = {"adaptive": "tab:blue"}
    for ax, terrain in zip(axes[0], panels, strict=True):
        for run in (r for r in runs if r.setting["terrain"] == terrain and r.setting["qarl"]):
            vig = run.setting["vigilance"]
            x = [r["trial"] + 1 for r in run.trials if r.get("ns_nf") is not None]
            y = [r["ns_nf"] for r in run.trials if r.get("ns_nf") is not None]
            ax.plot(x, y, lw=1, color=colours.get(vig, "tab:orange"), label=f"{vig}, seed {run.seed}")
            last = run.trials[-1].get("s_vig") if run.trials else None
            lines.append(
                f"| {terrain} | {vig} | {run.seed} | {_fmt(run.ns_nf(100), '.2f')} | {_fmt(run.ns_nf(200), '.2f')} | "
                f"{_fmt(run.ns_nf(), '.2f')} | {_fmt(last, '.3f')} |"
            )
        ax.axhline(1.0, color="k", lw=0.8, ls="--")
        ax.set_yscale("log")
        ax.set_xlabel("trial", fontsize=11)
        ax.set_ylabel("N_s / N_f", fontsize=11)
        ax.set_title(terrain, fontsize=11)
        ax.legend(fontsize=7)
        ax.grid(alpha=0.3)
    fig.tight_layout()
    name = "e5_2_ns_nf.png"
    fig.savefig(out / name, dpi=110)
    plt.close(fig)
    return lines + ["", f"![]({name})", ""]


def _e53(runs: list[Run]) -> list[str]:
    """The success region per terrain (adaptive vigilance, QARL)."""
    chosen = [r for r in runs if r.setting["qarl"] and r.setting["vigilance"] == "adaptive" and r.maps is not None]
    terrains = sorted({r.setting["terrain"] for r in chosen})
    if len(terrains) < 2:
        return []
    lines = [
        "### E5.3: the success region per terrain (adaptive vigilance, QARL)",
        "",
        "The share of the unit cube (a 21^3 grid) nearer the learnt success map than the learnt failure map "
        "(each map's neurons that won at least one trial of their kind).",
        "",
        "| terrain | success region per seed | mean | successes per seed |",
        "|---|---|---|---|",
    ]
    for terrain in terrains:
        mine = [r for r in chosen if r.setting["terrain"] == terrain]
        regions = [success_region(r.maps) for r in mine]
        lines.append(
            f"| {terrain} | {', '.join(f'{v:.0%}' for v in regions)} | {np.mean(regions):.0%} | "
            f"{', '.join(str(r.successes) for r in mine)} |"
        )
    return lines + [""]


def _eta_figure(run: Run, out: Path) -> str:
    fig, (top, bottom) = plt.subplots(2, 1, figsize=(8, 5.2), sharex=True)
    x = np.array([r["trial"] for r in run.trials])
    ok = np.array([bool(r.get("success")) for r in run.trials])
    eta = np.array([r.get("quality") or 0.0 for r in run.trials])
    top.plot(x[ok], eta[ok], ".", ms=4, color="tab:green", label="success: eta (5.8)")
    top.plot(x[~ok], np.zeros((~ok).sum()), "|", ms=6, color="tab:red", label="failure")
    top.set_ylabel("eta", fontsize=11)
    top.legend(fontsize=8)
    top.grid(alpha=0.3)
    top.set_title(run.label(), fontsize=11)
    vig = [r.get("s_vig") for r in run.trials]
    bottom.plot(x, vig, lw=1, color="tab:purple", label="s_vig")
    rate = np.cumsum(ok) / np.arange(1, len(ok) + 1)
    bottom.plot(x, rate, lw=1, color="tab:green", label="success rate so far")
    bottom.set_xlabel("trial", fontsize=11)
    bottom.legend(fontsize=8)
    bottom.grid(alpha=0.3)
    fig.tight_layout()
    name = f"{run.dir.name}_eta.png"
    fig.savefig(out / name, dpi=100)
    plt.close(fig)
    return name


def _maps_figure(run: Run, out: Path) -> str:
    """Fig. 5.9: the success map after 4 successes and at the end (3-D, unit cube), neurons coloured by the efficiency
    they learnt (at the end), the successful trials so far as dots sized by their reward rho."""
    table = run.dir / "maps.parquet"
    if run.maps is None or not table.exists():
        return ""
    snapshots = pq.read_table(table, columns=["map", "final", "trial", "neuron", "weights"]).to_pydict()
    columns = {key: np.asarray(values, dtype=object) for key, values in snapshots.items()}
    successes = [r for r in run.trials if r.get("success")]
    if len(successes) < 4:
        return ""
    fourth = successes[3]["trial"] + 1  # the snapshot after the 4th success learnt
    fig = plt.figure(figsize=(11, 5))
    for k, (title, trial, final) in enumerate((("after 4 successes", fourth, False), ("at the end", None, True))):
        ax = fig.add_subplot(1, 2, k + 1, projection="3d")
        keep = (columns["map"] == "success") & (columns["final"] == final)
        if trial is not None:
            keep &= columns["trial"] == trial
        if not keep.any():
            continue
        order = np.argsort(columns["neuron"][keep].astype(int), kind="stable")
        weights = np.array(columns["weights"][keep][order].tolist(), dtype=float)
        reward = run.maps["success_reward"] if final else None
        colours = reward if reward is not None and np.isfinite(reward).any() else "tab:green"
        cmap = "viridis" if not isinstance(colours, str) else None
        points = ax.scatter(*weights.T, c=colours, cmap=cmap, s=25, depthshade=False)
        seen = [r for r in successes if trial is None or r["trial"] < trial]
        v = np.array([r["v_unit"] for r in seen])
        rho = np.array([r.get("rho") or 1.0 for r in seen])
        ax.scatter(*v.T, s=18 * rho, c="tab:red", alpha=0.5, label="successful trials, size = rho")
        ax.set_xlim(0, 1)
        ax.set_ylim(0, 1)
        ax.set_zlim(0, 1)
        ax.legend(fontsize=7, loc="upper left")
        ax.set_xlabel("gain pitch (unit)")
        ax.set_ylabel("gain roll (unit)")
        ax.set_zlabel("sigma_s (unit)")
        ax.set_title(f"success map {title}", fontsize=10)
        if final and not isinstance(colours, str):
            fig.colorbar(points, ax=ax, shrink=0.6, label="eta the neuron learnt")
    fig.tight_layout()
    name = f"{run.dir.name}_maps.png"
    fig.savefig(out / name, dpi=100)
    plt.close(fig)
    return name
