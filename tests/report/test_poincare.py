"""E4.5 as a scenario: the Poincaré analysis (sfl_brain/report/poincare.py) on a known map, and on a real run read
back from its recording by sfl report (sfl_brain/recording/recorded.py)."""

from __future__ import annotations

import numpy as np
import pytest

from sfl_brain.recording.recorded import read_series
from sfl_brain.report.poincare import analyse, fit_return_map, section_returns

from ..conftest import SCENARIOS, sfl, sfl_run


def test_the_section_and_the_fit_recover_a_known_contracting_map():
    # maxima r_n of a 1-Hz oscillation following r_{n+1} = 0.05 + 0.6 r_n: fixed point 0.125, slope 0.6
    r = [0.3]
    for _ in range(40):
        r.append(0.05 + 0.6 * r[-1])
    t = np.arange(0, 40, 0.001)
    amplitude = np.interp(t, np.arange(41), r)  # slow change between the maxima at whole seconds
    pitch = amplitude * np.cos(2 * np.pi * t)
    rate = np.gradient(pitch, t)
    times, returns = section_returns(t, pitch, rate)
    assert len(returns) == 39 and np.allclose(times, np.arange(1, 40), atol=0.01)
    assert np.allclose(returns, r[1:40], atol=2e-3)
    fit = fit_return_map(returns)
    assert fit.slope == pytest.approx(0.6, abs=0.01) and fit.fixed_point == pytest.approx(0.125, abs=0.002)
    assert fit.stable
    assert analyse(t, pitch, rate)["steady_mean"] == pytest.approx(0.125, abs=0.005)
    assert analyse(t[:1500], pitch[:1500], rate[:1500]) is None  # fewer than 3 returns


def test_e4_5_runs_as_a_scenario_and_its_report_reads_the_recording(tmp_path):
    out = tmp_path / "run"
    sets = ("modules.body.params.duration=12", "protocol.repeats=1", "protocol.grid.body.start_noise=[0.02]")
    done = sfl_run(SCENARIOS / "e4_5_poincare.yaml", out, *sets)
    assert done.returncode == 0, done.stderr
    pitch = read_series(out / "recording.rrd", ["body/torso/pitch", "body/torso/pitch_rate"])
    series = pitch["body/torso/pitch"][0]
    assert len(series.times) == 1200 and np.allclose(np.diff(series.times), 0.01)  # every 10-ms tick
    assert 0 < np.mean(series.values) < 20  # degrees, leaning forward as it walks
    report = sfl("report", str(out), "--out", str(tmp_path / "report"))
    assert report.returncode == 0, report.stderr
    page = (tmp_path / "report" / "e4_5_poincare.md").read_text()
    assert "### Poincaré return maps of the torso pitch (E4.5)" in page
    row = next(line for line in page.splitlines() if line.startswith("| 0 | gait, start_noise 0.02, repeat 0 |"))
    returns = int(row.split("|")[5])
    # the section's rate on the 250-s walk of docs/results/chapter4/e4_5_poincare.md: 901 returns (3.6 a second: the
    # 1.5-Hz gait's two steps a cycle and a few double-humped steps); 12 s give 43, within 15 %
    assert abs(returns - 901 / 250 * 12) <= 0.15 * 901 / 250 * 12, returns
    assert (tmp_path / "report" / "e4_5_poincare_poincare.png").stat().st_size > 30_000
