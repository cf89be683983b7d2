"""``sfl study --cluster``: a study on a real Dask cluster, started the way Dask is started on machines
(``dask scheduler`` and two ``dask worker`` processes), all on loopback."""

from __future__ import annotations

import json
import time

import pytest

from ..conftest import SCENARIOS, sfl

pytest.importorskip("distributed", reason="sfl study --cluster needs sfl-brain[cluster]")

from sfl_brain.study.cluster import loopback_cluster  # noqa: E402


def test_a_study_on_a_dask_cluster_brings_every_run_folder_back(tmp_path):
    out = tmp_path / "study"
    with loopback_cluster(tmp_path) as scheduler_file:
        command = (
            "study",
            str(SCENARIOS / "analytic_learn.yaml"),
            "--vary",
            "modules.vigilance.params.value=0,-0.3",
            "--seeds",
            "0",
            "--set",
            "protocol.trials=30",
            "--out",
            str(out),
            "--cluster",
            str(scheduler_file),
            "--quiet",
            "--k",
            "3",
        )
        done = sfl(*command, timeout=240)
        assert done.returncode == 0, done.stderr
        assert "2 workers, 2 threads" in done.stdout
        for name in ("value0_seed0", "value-0.3_seed0"):  # one run for each of the two workers
            assert json.loads((out / name / "summary.json").read_text())["status"] == "completed"
            assert (out / name / "records.jsonl").read_bytes().count(b'"kind":"trial"') == 30
            assert (out / name / "recording.rrd").stat().st_size > 10_000
            assert f"{name} started on " in done.stderr and " tcp://127.0.0.1:" in done.stderr
        page = (out / "report" / "README.md").read_text()
        assert "| value=0 | 1 |" in page and "| value=-0.3 | 1 |" in page
        # again: every run is kept, nothing is sent to the cluster
        before = {p: p.stat().st_mtime_ns for p in out.glob("value*/summary.json")}
        again = sfl(*command, timeout=120)
        assert again.returncode == 0, again.stderr
        assert "0 to run" in again.stdout and "started on" not in again.stderr
        assert {p: p.stat().st_mtime_ns for p in out.glob("value*/summary.json")} == before


def test_an_address_where_no_scheduler_answers_is_bad_input_within_seconds(tmp_path):
    started = time.monotonic()
    done = sfl(
        "study",
        str(SCENARIOS / "analytic_learn.yaml"),
        "--out",
        str(tmp_path / "study"),
        "--cluster",
        "tcp://127.0.0.1:9",  # the discard port: nobody listens
        timeout=60,
    )
    assert done.returncode == 2
    assert done.stderr.startswith("sfl: --cluster tcp://127.0.0.1:9: no Dask scheduler answered within 5 s")
    assert len(done.stderr.splitlines()) == 1
    assert time.monotonic() - started < 20  # 5 s of trying, plus starting Python on a busy machine
    assert not (tmp_path / "study").exists()
