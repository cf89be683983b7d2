"""``sfl study``: the study report's maths, and studies of real runs over processes (``--jobs``)."""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
from datetime import datetime
from pathlib import Path

import matplotlib.pyplot as plt
import numpy as np
import psutil
import pytest

from sfl_brain.report.report import write_report
from sfl_brain.report.stats import bootstrap_band
from sfl_brain.report.study import (
    BAND_ALPHA,
    StudySettings,
    curves_figure,
    differ,
    failures_figure,
    group_runs,
    learn_runs,
    moving_success_rate,
    run_metrics,
    short_names,
    varied_keys,
)
from sfl_brain.status import BadInput
from sfl_brain.study.study import TrialCounter, core_slots, first_difference, parse_seeds, parse_vary

from ..conftest import ROOT, SCENARIOS, sfl, wait_for_trials

LEARN = SCENARIOS / "analytic_learn.yaml"


# --------------------------------------------------------------------------- the maths
def test_success_rate_over_a_moving_window_of_trials():
    assert moving_success_rate([1, 0, 1, 1, 0], 2).tolist() == [1.0, 0.5, 0.5, 1.0, 0.5]
    assert moving_success_rate([1, 0, 1], 10).tolist() == pytest.approx([1.0, 0.5, 2 / 3])
    assert len(moving_success_rate([], 5)) == 0


def test_runs_are_grouped_by_what_differs_but_the_seed():
    def scenario(value, seed, kind="sfl"):
        return {
            "name": "s",
            "seed": seed,
            "protocol": {"kind": "learn", "trials": 30, "proposer": {"kind": kind}},
            "modules": {"vigilance": {"params": {"value": value}}, "acc": {"params": {"value": 1}}},
        }

    made = [(0, 0, "sfl"), (0, 1, "sfl"), (0.1, 0, "random")]
    runs = {f"r{i}": scenario(value, seed, kind) for i, (value, seed, kind) in enumerate(made)}
    assert varied_keys(list(runs.values())) == ["protocol.proposer.kind", "modules.vigilance.params.value"]
    assert group_runs(runs) == {"kind=sfl, value=0": ["r0", "r1"], "kind=random, value=0.1": ["r2"]}
    assert group_runs({"a": scenario(0, 0), "b": scenario(0, 1)}) == {"all runs": ["a", "b"]}
    # a key's shortest tail that no other varied key ends with
    assert short_names(["modules.acc.params.value", "modules.vigilance.params.value", "seedless"]) == {
        "modules.acc.params.value": "acc.params.value",
        "modules.vigilance.params.value": "vigilance.params.value",
        "seedless": "seedless",
    }


def test_each_job_gets_its_own_cores():
    assert core_slots([0, 1], 2) == [[0], [1]]
    assert core_slots([0, 1, 2, 3], 2) == [[0, 1], [2, 3]]
    assert core_slots([0, 1, 2], 2) == [[0], [1, 2]]
    assert core_slots([0, 1], 3) == [[0], [1], [0]]  # more jobs than cores: a core each in turn
    assert core_slots([0, 1], 1) == [None]  # one job: every usable core, as sfl run alone
    assert core_slots([], 2) == [None, None]  # no CPU affinity on this OS


def test_bad_study_options_are_named():
    with pytest.raises(BadInput, match=r"^--vary 'x': expected KEY.PATH=V1,V2,...$"):
        parse_vary(["x"])
    with pytest.raises(BadInput, match=r"^--vary a.b: 1 given twice$"):
        parse_vary(["a.b=1,2,1"])
    with pytest.raises(BadInput, match=r"^--seeds '1,x': expected integers separated by commas$"):
        parse_seeds("1,x")
    assert parse_seeds("") == [None] and parse_seeds("0, 2") == [0, 2]


def test_trials_so_far_are_read_from_whole_lines_only(tmp_path):
    path = tmp_path / "records.jsonl"
    counter = TrialCounter(path)
    assert not counter.poll()  # no file yet
    path.write_bytes(b'{"kind":"decision","go":true}\n{"kind":"trial","success":true}\n{"kind":"tri')
    assert counter.poll() and (counter.trials, counter.successes) == (1, 1)
    with open(path, "ab") as f:
        f.write(b'al","success":false}\n')
    assert counter.poll() and (counter.trials, counter.successes) == (2, 1)
    assert not counter.poll()


def test_first_difference_names_the_key_path():
    assert first_difference({"a": {"b": 1, "c": 2}}, {"a": {"b": 1, "c": 3}}) == "a.c"
    assert first_difference({"a": 1}, {"a": 1, "z": 0}) == "z"
    assert first_difference({"a": [1]}, {"a": [1]}) is None


# --------------------------------------------------------------------------- studies of real runs
def _mtimes(out: Path) -> dict[str, int]:
    return {
        str(p.relative_to(out)): p.stat().st_mtime_ns
        for p in out.glob("*/*")
        if p.name in ("summary.json", "records.jsonl", "started", "recording.rrd") and p.parent.name != "report"
    }


def _interval(run_dir: Path) -> tuple[float, float]:
    """When a run started (its ``started`` file) and ended (its summary written), in s since the epoch."""
    started = datetime.fromisoformat((run_dir / "started").read_text().strip()).timestamp()
    return started, (run_dir / "summary.json").stat().st_mtime


def test_study_with_jobs_runs_at_once_reports_the_groups_and_never_runs_a_completed_run_twice(tmp_path):
    out = tmp_path / "study"
    command = (
        "study",
        str(LEARN),
        "--vary",
        "modules.vigilance.params.value=0,-0.3",
        "--seeds",
        "0,1",
        "--set",
        "protocol.trials=30",
        "--out",
        str(out),
        "--jobs",
        "2",
    )
    done = sfl(*command, "--quiet", "--k", "3", timeout=180)
    assert done.returncode == 0, done.stderr
    names = ["value0_seed0", "value0_seed1", "value-0.3_seed0", "value-0.3_seed1"]
    for name in names:
        assert json.loads((out / name / "summary.json").read_text())["status"] == "completed"
        assert (out / name / "records.jsonl").read_bytes().count(b'"kind":"trial"') == 30
    assert "sfl: [4/4] value-0.3_seed1 completed: 30 trials" in done.stderr
    # two runs at a time: some runs overlap in time, never more than two
    spans = [_interval(out / n) for n in names]
    running = [sum(start <= t < end for start, end in spans) for t in sorted(s for s, _ in spans)]
    assert max(running) == 2, spans
    if len(os.sched_getaffinity(0)) >= 2:
        assert "2 runs at once, on core" in done.stdout  # each run on its own cores
    # the report compares the two groups over their two seeds
    page = (out / "report" / "README.md").read_text()
    assert "| group | seeds | failures before first success | failures before K=3 |" in page
    assert "| value=0 | 2 |" in page and "| value=-0.3 | 2 |" in page
    for figure in ("study_learning.png", "study_best_eta.png", "study_failures_before_k.png"):
        assert (out / "report" / figure).stat().st_size > 20_000
    numbers = json.loads((out / "report" / "study_summary.json").read_text())
    assert numbers["groups"]["value=0"]["runs"] == ["value0_seed0", "value0_seed1"]
    assert "| value0_seed0 | completed | learn |" in page  # the run table and the vigilance study are still there
    assert (out / "report" / "success_vs_vigilance_x-y.png").stat().st_size > 10_000
    assert "| -0.30 | 2 | 30 |" in page and "| +0.00 | 2 | 30 |" in page

    # the same command again: nothing runs; a run whose summary is gone (killed) runs again from scratch
    before = _mtimes(out)
    again = sfl(*command, timeout=180)  # with the progress view (not --quiet)
    assert again.returncode == 0, again.stderr
    assert "0 to run" in again.stdout and "4 kept from before" in again.stdout
    assert _mtimes(out) == before
    (out / "value0_seed1" / "summary.json").unlink()  # as a run killed with its study (kill -9) leaves it
    third = sfl(*command, "--quiet", "--k", "2", "--window", "10", timeout=180)  # the report's own K and window
    assert third.returncode == 0, third.stderr
    assert f"value0_seed1 was unfinished: its folder moved to {out / 'attempts' / 'value0_seed1.1'}" in third.stdout
    after = _mtimes(out)
    assert {k: v for k, v in after.items() if not k.startswith("value0_seed1/")} == {
        k: v for k, v in before.items() if not k.startswith("value0_seed1/")
    }
    assert after["value0_seed1/summary.json"] and (out / "attempts" / "value0_seed1.1" / "records.jsonl").exists()
    page = (out / "report" / "README.md").read_text()
    assert "failures before K=2" in page and "success rate, last 10 trials" in page


@pytest.fixture(scope="module")
def proposer_study(tmp_path_factory) -> Path:
    """Issue 22's study, small: success-failure learning against CMA-ES, two seeds each, over processes (the study
    folder; its report written with K = 3). Shared by the tests of what a page says at n = 2."""
    out = tmp_path_factory.mktemp("proposers") / "study"
    done = sfl(
        "study",
        str(LEARN),
        "--vary",
        "protocol.proposer.kind=sfl,cma",
        "--seeds",
        "0,1",
        "--set",
        "protocol.trials=25",
        "--out",
        str(out),
        "--jobs",
        "2",
        "--quiet",
        "--k",
        "3",
        timeout=240,
    )
    assert done.returncode == 0, done.stderr
    return out


RUNS = ("kindsfl_seed0", "kindsfl_seed1", "kindcma_seed0", "kindcma_seed1")


def _groups(study: Path, settings: StudySettings) -> dict[str, list]:
    """The study's groups of completed runs, as its page draws them."""
    scenarios, folders = learn_runs([study / name for name in RUNS])
    return {label: [run_metrics(folders[n], settings) for n in names] for label, names in group_runs(scenarios).items()}


def _summary(study: Path, name: str) -> dict:
    return json.loads((study / name / "summary.json").read_text())


def test_a_study_of_two_proposers_over_two_seeds_compares_them(proposer_study):
    """Each run records its proposer and its safe-learning metrics, and the report compares the two groups."""
    out = proposer_study
    for kind in ("sfl", "cma"):
        for seed in (0, 1):
            summary = json.loads((out / f"kind{kind}_seed{seed}" / "summary.json").read_text())
            assert summary["status"] == "completed" and summary["proposer"] == kind
            assert summary["safe_learning"]["trials"] == 25
            assert (out / f"kind{kind}_seed{seed}" / "proposer.pkl").exists()
    cma = json.loads((out / "kindcma_seed0" / "summary.json").read_text())
    assert cma["decisions"] == 25  # one decision per trial without the gate
    page = (out / "report" / "README.md").read_text()
    assert "| kind=sfl | 2 |" in page and "| kind=cma | 2 |" in page
    assert "failures, all trials" in page


def test_at_two_seeds_every_number_stays_in_its_possible_range_and_says_its_n(proposer_study):
    """Issue 32: "success rate 0.45 +- 4". With two seeds a t half-width is 12.7 standard errors, wider than a rate
    can be; the page and study_summary.json give the mean with the seeds' own values (n shown) and bounds within
    what the values can be."""
    page = (proposer_study / "report" / "README.md").read_text()
    numbers = json.loads((proposer_study / "report" / "study_summary.json").read_text())
    for label in ("kind=sfl", "kind=cma"):
        group = numbers["groups"][label]
        for key in ("success_rate", "success_rate_last_window"):
            rate = group[key]
            assert rate["n"] == 2 and rate["interval"] == "range"
            assert 0.0 <= rate["low"] <= rate["mean"] <= rate["high"] <= 1.0
        failures = group["failures_before_first_success"]
        summaries = [_summary(proposer_study, name) for name in group["runs"]]
        firsts = [x["safe_learning"]["failures_before_first_success"] for x in summaries]
        assert failures["n"] == sum(f is not None for f in firsts)  # the runs that had a first success
        assert failures["n"] < 2 or 0 <= failures["low"] <= failures["mean"] <= failures["high"]
        (row,) = [line for line in page.splitlines() if line.startswith(f"| {label} | 2 |")]
        rates = sorted(x["success_rate"] for x in summaries)
        assert f"(n=2: {rates[0]:.2f}, {rates[1]:.2f})" in row  # the seeds' own values, not a 95 % claim
        assert "±" not in row and "+-" not in row


def test_bands_of_two_seeds_stay_within_them_and_do_not_hide_each_other(proposer_study):
    """Issue 32: with n = 2 a t-band covered the whole plot and the second band hid the first. A bootstrap band lies
    within its seeds' curves, trial by trial; fills are light and every band's dashed edges are drawn above every
    fill."""
    settings = StudySettings(k=3)
    groups = _groups(proposer_study, settings)
    for runs in groups.values():
        curves = [moving_success_rate(r.success, settings.window) for r in runs]
        mean, low, high = bootstrap_band(curves)
        assert np.all(low >= np.min(curves, axis=0) - 1e-12) and np.all(high <= np.max(curves, axis=0) + 1e-12)
        assert np.allclose(low, np.min(curves, axis=0)) and np.allclose(high, np.max(curves, axis=0))  # n=2: envelope
    fig = curves_figure(groups, settings)
    try:
        for ax in fig.axes:
            fills = ax.collections
            edges = [line for line in ax.lines if line.get_linestyle() == "--"]
            assert len(fills) == len(groups) and len(edges) == 2 * len(groups)
            assert all(f.get_alpha() <= BAND_ALPHA for f in fills)
            assert min(e.get_zorder() for e in edges) > max(f.get_zorder() for f in fills)
    finally:
        plt.close(fig)


def test_the_censored_key_cannot_be_read_as_a_run(proposer_study):
    """Issue 32: the censored marker in the legend looked like a data point (a group's colour, inside the axes). The
    key is black, a colour no group has, in a framed box outside the axes."""
    settings = StudySettings(k=1000)  # no run finds 1000 good gaits in 25 trials: every run censored
    groups = _groups(proposer_study, settings)
    fig = failures_figure(groups, settings)
    try:
        (ax,) = fig.axes
        assert ax.get_legend() is None
        (key,) = fig.legends
        (handle,) = key.legend_handles
        colours = {tuple(np.round(c.get_edgecolor()[0], 3)) for c in ax.collections}  # the runs' triangles
        assert len(ax.collections) == len(groups) and (0.0, 0.0, 0.0, 1.0) not in colours
        assert handle.get_color() == "black" and key.get_frame_on()
        fig.canvas.draw()
        assert not key.get_window_extent().overlaps(ax.get_window_extent())
    finally:
        plt.close(fig)


def test_sfl_report_over_runs_of_two_proposers_compares_them_and_names_each_proposer(proposer_study, tmp_path):
    """Issue 32: `sfl report` over a cma run and another proposer's run compared nothing, and a run's page named no
    proposer. Runs that differ by more than the seed are compared as a study's groups; runs of one scenario but for
    the seed, or one run, are not; every page names each learn run's proposer."""
    cma, sfl_run_ = proposer_study / "kindcma_seed0", proposer_study / "kindsfl_seed1"
    from click.testing import CliRunner

    from sfl_brain.cli import main

    done = CliRunner().invoke(main, ["report", str(cma), str(sfl_run_), "--out", str(tmp_path / "two"), "--k", "3"])
    assert done.exit_code == 0, done.output
    page = (tmp_path / "two" / "README.md").read_text()
    assert "## Study: the groups compared" in page and "failures before K=3" in page
    assert "| kind=cma | 1 |" in page and "| kind=sfl | 1 |" in page
    assert (
        "| kindcma_seed0 | completed | learn | cma |" in page and "| kindsfl_seed1 | completed | learn | sfl |" in page
    )
    assert (tmp_path / "two" / "study_learning.png").stat().st_size > 10_000
    assert differ([cma, sfl_run_]) and not differ([cma, proposer_study / "kindcma_seed1"]) and not differ([cma])
    one = write_report([cma], tmp_path / "one").read_text()
    assert "## Study" not in one and "| kindcma_seed0 | completed | learn | cma |" in one


def test_a_killed_run_is_named_and_left_out_of_every_mean_and_the_others_finish(tmp_path):
    out = tmp_path / "study"
    study = subprocess.Popen(
        [sys.executable, "-m", "sfl_brain.cli", "study", str(LEARN), "--vary", "protocol.trials=30,100000"]
        + ["--out", str(out), "--jobs", "2", "--quiet", "--k", "2"],
        cwd=ROOT,
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
    )
    try:
        long_run = out / "trials100000"
        wait_for_trials(long_run, 3, study, timeout=90)
        (child,) = [
            p for p in psutil.Process(study.pid).children() if "run" in p.cmdline() and str(long_run) in p.cmdline()
        ]
        child.kill()
        stdout, stderr = study.communicate(timeout=120)
    finally:
        study.kill()
    assert study.returncode == 1, stderr
    assert "sfl: 1 of 2 runs failed, marked in the report and left out of its means: trials100000" in stderr
    assert "trials100000 failed" in stderr and "`sfl run` was killed by signal 9" in stderr
    assert json.loads((out / "trials30" / "summary.json").read_text())["status"] == "completed"
    page = (out / "report" / "README.md").read_text()
    assert "| trials=30 | 1 |" in page and "| trials=100000 |" not in page
    assert "Left out of every curve, box and mean: 1 runs that did not complete:" in page
    assert (
        "- trials100000: unfinished, no summary.json: the run was killed, or is still running (the study: failed: "
        "`sfl run` was killed by signal 9" in page
    )
    outcome = json.loads((out / "study.json").read_text())["outcomes"]["trials100000"]
    assert outcome["status"] == "failed" and outcome["exit_code"] == -9
    # sfl report on the study folder: into its report/ folder by default, with what the study said of its runs
    (out / "report" / "README.md").unlink()
    report = sfl("report", str(out), "--k", "3")
    assert report.returncode == 0, report.stderr
    assert f"sfl: {out / 'trials100000'} is unfinished" in report.stderr
    page = (out / "report" / "README.md").read_text()
    assert "failures before K=3" in page and "(the study: failed: `sfl run` was killed by signal 9" in page


def test_bad_study_options_exit_2_in_one_line_before_anything_runs(tmp_path):
    from click.testing import CliRunner

    from sfl_brain.cli import main

    out = tmp_path / "study"

    def study(*args: str):
        return CliRunner().invoke(main, ["study", str(LEARN), "--out", str(out), *args])

    done = study("--vary", "modules.vigilance.params.value=0", "--jobs", "0")
    assert done.exit_code == 2 and done.stderr == "sfl: --jobs 0: expected 1 or more runs at once\n"
    done = study("--vary", "a.b=1,1")
    assert done.exit_code == 2 and done.stderr == "sfl: --vary a.b: 1 given twice\n"
    done = study("--jobs", "2", "--cluster", "tcp://127.0.0.1:9")
    assert done.exit_code == 2 and done.stderr.startswith("sfl: --jobs and --cluster: choose one")
    done = study("--window", "0")
    assert done.exit_code == 2 and done.stderr == "sfl: --window 0: expected more than 0\n"
    done = study("--vary", "modules.vigilance.params.valu=0,1")
    assert done.exit_code == 2 and "did you mean `value`" in done.stderr  # every combination checked first
    assert not out.exists()


def test_ctrl_c_stops_every_run_of_the_study_and_says_how_to_resume(tmp_path):
    out = tmp_path / "study"
    study = subprocess.Popen(
        [sys.executable, "-m", "sfl_brain.cli", "study", str(LEARN), "--seeds", "0,1"]
        + ["--set", "protocol.trials=100000", "--out", str(out), "--jobs", "2", "--quiet"],
        cwd=ROOT,
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
    )
    try:
        for name in ("run_seed0", "run_seed1"):
            wait_for_trials(out / name, 2, study, timeout=90)
        family = psutil.Process(study.pid).children(recursive=True)
        assert len(family) >= 2 * 5  # two sfl run, each with acc, vigilance, ofc and a body
        study.send_signal(signal.SIGINT)
        _, stderr = study.communicate(timeout=120)
    finally:
        study.kill()
    assert study.returncode == 130, stderr
    assert "sfl: study interrupted; 0 of 2 runs are done and kept. The same command resumes it" in stderr
    for name in ("run_seed0", "run_seed1"):
        summary = json.loads((out / name / "summary.json").read_text())
        assert summary["status"] == "interrupted", summary
    _, alive = psutil.wait_procs(family, timeout=10)
    assert not alive, [p.cmdline() for p in alive]
