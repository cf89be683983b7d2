"""Issue 34's goals on this machine: a busy machine makes a run slower, never fails it.

    python docs/experiments/busy_machine.py [--out runs/busy_machine] [--seeds 10] [--stops 5] [--stop-seconds 10]
                                           [--page docs/results/busy_machine.md]

Two sets of runs, each compared with a quiet run of the same scenario and seed (``sfl run`` alone, nothing added):

* **busy**: ``--seeds`` learn runs of the planar walker (``scenarios/quickstart.yaml``, 20 trials of 5 s) and as many
  of the 8-link walker on its CPG (``scenarios/e4_2_learn.yaml``, 10 trials of 5 s, a fixed vigilance of -0.3 instead
  of E4.2's scheduled band, whose first trials take 10^4-10^5 no-go decisions: here every decision is a go, and the
  run's time is its walks'), seeds 0, 1, ..., each run at ``nice -n 10`` beside more busy processes than cores (one
  spinning process per usable core and one more, at ``nice -n 5``: above the run's priority, below other users'
  work);
* **stopped**: ``--stops`` runs of the planar walker whose controller is stopped (SIGSTOP) for ``--stop-seconds`` s
  mid-trial (once the run has recorded 3 trials and the supervisor says it waits on the stopped controller), then
  continued (SIGCONT).

A run meets the goal when it ends ``completed`` with the records of its quiet run, every row equal but for the
wall-clock fields (``wall_ms``, ``worker``), and no trial retried. Results: ``OUT/results.json`` and the page
``--page``; the script exits 1 if any run missed the goal. A run folder that already holds a run's result
(``goal.json``) is kept: running the script again goes on where it stopped.
"""

from __future__ import annotations

import argparse
import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]
sys.path.insert(0, str(ROOT))

from sfl_brain.recording.provenance import made_here  # noqa: E402
from sfl_brain.recording.records import read_records  # noqa: E402
from sfl_brain.runtime.placement import usable_cpus  # noqa: E402

#: the learn runs: scenario and overrides of each body
BODIES = {
    "planar": ("scenarios/quickstart.yaml", ["protocol.trials=20", "modules.body.params.duration=5"]),
    "cpg": (
        "scenarios/e4_2_learn.yaml",
        [
            "protocol.trials=10",
            "modules.body.params.duration=5",
            "modules.vigilance.params.mode=fixed",
            "modules.vigilance.params.value=-0.3",
        ],
    ),
}
RECORD = ["record.body_every=5"]
WALL = {"wall_ms", "worker", "cpu_body_s", "cpu_controller_s"}
SPIN = [sys.executable, "-c", "while True: pass"]


def sfl_run(scenario: str, sets: list[str], seed: int, out: Path, nice: int = 0) -> subprocess.Popen:
    command = [sys.executable, "-m", "sfl_brain.cli", "run", str(ROOT / scenario), "--seed", str(seed)]
    command += [a for s in [*sets, *RECORD] for a in ("--set", s)] + ["--out", str(out), "--quiet"]
    return subprocess.Popen(
        command,
        cwd=ROOT,
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
        preexec_fn=(lambda: os.nice(nice)) if nice else None,
    )


def finish(proc: subprocess.Popen) -> tuple[int, str]:
    _, stderr = proc.communicate()
    return proc.returncode, stderr


def trials_in(run_dir: Path) -> int:
    path = run_dir / "records.jsonl"
    return path.read_bytes().count(b'"kind":"trial"') if path.exists() else 0


def module_pid(run: subprocess.Popen, name: str) -> int:
    """The process hosting module ``name`` (``python -m sfl_brain.runtime.host --name NAME``), a child of ``run``."""
    for entry in os.listdir("/proc"):
        if not entry.isdigit():
            continue
        try:
            stat = Path(f"/proc/{entry}/stat").read_text()
            cmd = Path(f"/proc/{entry}/cmdline").read_bytes().split(b"\0")
        except OSError:
            continue
        parent = int(stat[stat.rindex(")") + 2 :].split()[1])
        if parent == run.pid and b"--name" in cmd and cmd[cmd.index(b"--name") + 1] == name.encode():
            return int(entry)
    raise RuntimeError(f"no process for {name}")


def median_trial_ms(run_dir: Path) -> float | None:
    walls = sorted(r["wall_ms"] for r in read_records(run_dir) if r["kind"] == "trial")
    return round(walls[len(walls) // 2], 1) if walls else None


def compare(run_dir: Path, quiet_dir: Path) -> dict:
    """How a run ended and whether its records are its quiet run's (but for the wall clock)."""
    summary = json.loads((run_dir / "summary.json").read_text())
    rows, quiet = read_records(run_dir), read_records(quiet_dir)
    retries = [r for r in rows if r["kind"] == "retry"]
    same = [{k: v for k, v in r.items() if k not in WALL} for r in rows] == [
        {k: v for k, v in r.items() if k not in WALL} for r in quiet
    ]
    trials = [r for r in rows if r["kind"] == "trial"]
    return {
        "status": summary["status"],
        "trials": len(trials),
        "retries": len(retries),
        "records_equal_quiet": same,
        "wall_s": round(summary["wall_time_s"], 1),
        "median_trial_ms": median_trial_ms(run_dir),
        "met": summary["status"] == "completed" and same and not retries,
    }


def quiet_run(out: Path, body: str, seed: int) -> Path:
    run_dir = out / "quiet" / f"{body}_s{seed}"
    if not (run_dir / "summary.json").exists():
        scenario, sets = BODIES[body]
        code, stderr = finish(sfl_run(scenario, sets, seed, run_dir))
        if code != 0:
            raise SystemExit(f"the quiet run {run_dir} failed: {stderr[-2000:]}")
    return run_dir


def kept(run_dir: Path) -> dict | None:
    """The result of a run this script made before (``goal.json`` in its folder), or None."""
    try:
        return json.loads((run_dir / "goal.json").read_text())
    except (OSError, ValueError):
        return None


def keep(run_dir: Path, result: dict) -> dict:
    (run_dir / "goal.json").write_text(json.dumps(result, indent=1) + "\n")
    return result


def busy_run(out: Path, body: str, seed: int) -> dict:
    quiet = quiet_run(out, body, seed)
    run_dir = out / "busy" / f"{body}_s{seed}"
    if (result := kept(run_dir)) is not None:
        return result
    scenario, sets = BODIES[body]
    spinners = [
        subprocess.Popen(SPIN, preexec_fn=lambda: os.nice(5)) for _ in range(len(usable_cpus()) + 1)
    ]  # more busy processes than cores
    try:
        code, stderr = finish(sfl_run(scenario, sets, seed, run_dir, nice=10))
    finally:
        for proc in spinners:
            proc.kill()
            proc.wait()
    result = {"run": str(run_dir), "exit_code": code, **compare(run_dir, quiet)}
    if code != 0:
        result["stderr"] = stderr[-1500:]
    return keep(run_dir, result)


def stopped_run(out: Path, seed: int, seconds: float) -> dict:
    quiet = quiet_run(out, "planar", seed)
    run_dir = out / "stopped" / f"planar_s{seed}"
    if (result := kept(run_dir)) is not None:
        return result
    scenario, sets = BODIES["planar"]
    run = sfl_run(scenario, sets, seed, run_dir)
    said = []
    while trials_in(run_dir) < 3 and run.poll() is None:
        time.sleep(0.05)  # nothing announces a trial but the records file
    pid = module_pid(run, "controller")
    os.kill(pid, signal.SIGSTOP)
    stopped_at = time.monotonic()
    for line in run.stderr:  # the supervisor says when it waits on the stopped controller (a trial is in flight)
        said.append(line)
        if "module `controller` is stopped" in line:
            break
    time.sleep(max(0.0, seconds - (time.monotonic() - stopped_at)))  # the stop itself: nothing to wait for
    waited = time.monotonic() - stopped_at
    os.kill(pid, signal.SIGCONT)
    _, rest = run.communicate()
    said.append(rest)
    text = "".join(said)
    result = {
        "run": str(run_dir),
        "exit_code": run.returncode,
        "stopped_s": round(waited, 1),
        "said_it_waited": "module `controller` is stopped" in text and "module `controller` runs again" in text,
        **compare(run_dir, quiet),
    }
    result["met"] = result["met"] and result["said_it_waited"]
    if run.returncode != 0:
        result["stderr"] = text[-1500:]
    return keep(run_dir, result)


def page(results: dict, command: str) -> str:
    busy, stopped = results["busy"], results["stopped"]
    lines = [
        "# A busy machine never kills a healthy run (issue 34)",
        "",
        made_here(),
        "",
        f"`{command}`: {len(busy)} learn runs at `nice -n 10` beside {results['spinners']} processes spinning at "
        f"`nice -n 5` on {results['cores']} cores, and {len(stopped)} runs whose controller was stopped (SIGSTOP) for "
        f"{results['stop_seconds']:g} s mid-trial and continued; each compared with a quiet run of the same scenario "
        "and seed (docs/experiments/busy_machine.py says how). Load average before and after: "
        f"{results['load_before']} / {results['load_after']}.",
        "",
        f"**{sum(r['met'] for r in busy + stopped)} of {len(busy) + len(stopped)} runs met the goal** (completed, the "
        "quiet run's records but for `wall_ms` and `worker`, no trial retried); "
        f"{sum(not r['met'] for r in busy + stopped)} did not.",
        "",
        "| run | status | trials | retried | records = quiet run's | median trial, ms | quiet run's, ms | wall, s |",
        "|---|---|---|---|---|---|---|---|",
    ]
    for r in busy + stopped:
        name = "/".join(Path(r["run"]).parts[-2:])
        same = "yes" if r["records_equal_quiet"] else "**no**"
        lines.append(
            f"| {name} | {r['status']} | {r['trials']} | {r['retries']} | {same} | {r['median_trial_ms']} | "
            f"{r.get('quiet_median_trial_ms')} | {r['wall_s']} |"
        )
    lines.append("")
    return "\n".join(lines)


def load() -> str:
    return " ".join(f"{x:.2f}" for x in os.getloadavg())


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--out", type=Path, default=ROOT / "runs" / "busy_machine")
    parser.add_argument("--seeds", type=int, default=10, help="seeds per body (busy runs: 2 x seeds)")
    parser.add_argument("--stops", type=int, default=5)
    parser.add_argument("--stop-seconds", type=float, default=10.0)
    parser.add_argument("--page", type=Path, default=ROOT / "docs" / "results" / "busy_machine.md")
    args = parser.parse_args()
    command = "python docs/experiments/busy_machine.py" + (
        f" --seeds {args.seeds} --stops {args.stops} --stop-seconds {args.stop_seconds:g}"
        if (args.seeds, args.stops, args.stop_seconds) != (10, 5, 10.0)
        else ""
    )
    results = {
        "cores": len(usable_cpus()),
        "spinners": len(usable_cpus()) + 1,
        "stop_seconds": args.stop_seconds,
        "load_before": load(),
        "busy": [],
        "stopped": [],
    }
    for seed in range(args.seeds):
        for body in BODIES:
            result = busy_run(args.out, body, seed)
            result["quiet_median_trial_ms"] = median_trial_ms(args.out / "quiet" / f"{body}_s{seed}")
            results["busy"].append(result)
            print(json.dumps({k: v for k, v in result.items() if k != "stderr"}), flush=True)
    for seed in range(args.stops):
        result = stopped_run(args.out, seed, args.stop_seconds)
        result["quiet_median_trial_ms"] = median_trial_ms(args.out / "quiet" / f"planar_s{seed}")
        results["stopped"].append(result)
        print(json.dumps({k: v for k, v in result.items() if k != "stderr"}), flush=True)
    results["load_after"] = load()
    args.out.mkdir(parents=True, exist_ok=True)
    (args.out / "results.json").write_text(json.dumps(results, indent=1) + "\n")
    args.page.write_text(page(results, command))
    missed = [r["run"] for r in results["busy"] + results["stopped"] if not r["met"]]
    print(f"{len(missed)} runs missed the goal{': ' + ', '.join(missed) if missed else ''}; page: {args.page}")
    sys.exit(1 if missed else 0)


if __name__ == "__main__":
    main()
