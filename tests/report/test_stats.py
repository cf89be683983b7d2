"""The statistics of a study page (issue 33): intervals that respect bounds, log-scale tests, Holm, Kaplan-Meier."""

from __future__ import annotations

import math

import numpy as np
import pytest
from scipy import stats as scipy_stats

from sfl_brain.report import stats


def test_a_bootstrap_interval_of_a_count_never_goes_below_zero_and_is_seeded():
    counts = [0, 0, 1, 3, 40]  # skewed: a t-interval's lower bound is far below 0
    mean, half, _ = 8.8, scipy_stats.t.ppf(0.975, 4) * np.std(counts, ddof=1) / math.sqrt(5), None
    assert mean - half < 0
    interval = stats.bootstrap_mean(counts)
    assert interval.estimate == pytest.approx(8.8)
    assert 0 <= interval.low < interval.estimate < interval.high <= 40
    assert stats.bootstrap_mean(counts) == interval
    assert stats.bootstrap_mean([3, 3, 3]).low == 3 and math.isnan(stats.bootstrap_mean([4]).low)


def test_at_three_values_or_fewer_a_bootstrap_interval_is_their_range_and_a_page_lists_them():
    """Why a page lists the values at n <= FEW: the percentile interval is then exactly their range, not 95 %."""
    from sfl_brain.report.study import bounded_cell

    for values in ([0.2, 0.9], [0.1, 0.5, 0.7]):
        interval = stats.bootstrap_mean(values)
        assert (interval.low, interval.high) == pytest.approx((min(values), max(values)))
    four = stats.bootstrap_mean([0.1, 0.5, 0.7, 0.9])
    assert 0.1 < four.low and four.high < 0.9  # from four values on, narrower than the range
    assert bounded_cell([0.9, 0.2], ".2f") == "0.55 (n=2: 0.20, 0.90)" and bounded_cell([4], ".1f") == "4.0 (n=1)"
    assert bounded_cell([0.1, 0.5, 0.7, 0.9], ".2f") == f"0.55 [{four.low:.2f}, {four.high:.2f}]"


def test_a_bootstrap_band_lies_within_its_curves_trial_by_trial_and_skips_missing_values():
    rng = np.random.default_rng(5)
    curves = [rng.uniform(0, 1, 40) for _ in range(5)]
    mean, low, high = stats.bootstrap_band(curves)
    assert mean == pytest.approx(np.mean(curves, axis=0))
    assert np.all(np.min(curves, axis=0) <= low) and np.all(low <= mean) and np.all(mean <= high)
    assert np.all(high <= np.max(curves, axis=0))
    for t in (0, 17, 39):  # each trial's band is that trial's bootstrap interval of the mean
        interval = stats.bootstrap_mean([c[t] for c in curves])
        assert (low[t], high[t]) == pytest.approx((interval.low, interval.high), abs=0.03)
    # the trials every curve has; a nan (no value yet) left out of that trial; one value: no band
    mean, low, high = stats.bootstrap_band([np.array([np.nan, 1.0, 2.0, 9.0]), np.array([0.0, 3.0, 4.0])])
    assert len(mean) == 3 and mean[0] == 0.0 and np.isnan(low[0]) and np.isnan(high[0])
    assert (mean[1], low[1], high[1]) == (2.0, 1.0, 3.0)  # two values: their range


def test_the_paired_log_t_test_is_scipy_s_on_the_log_scale_and_its_ratio_is_positive():
    plain = [40, 61, 22, 35, 55]
    gated = [10, 14, 7, 9, 12]
    test = stats.paired_log_t(gated, plain)
    reference = scipy_stats.ttest_rel(np.log1p(gated), np.log1p(plain))
    assert test.p == pytest.approx(reference.pvalue, rel=1e-12)
    assert test.p < 0.001
    ratio = np.exp(np.mean(np.log1p(gated) - np.log1p(plain)))
    assert test.effect.estimate == pytest.approx(ratio)
    assert 0 < test.effect.low < ratio < test.effect.high < 1
    assert stats.paired_log_t(plain, plain).p == 1.0
    with pytest.raises(ValueError, match="different sizes"):
        stats.paired_log_t([1, 2], [1, 2, 3])


def test_welch_s_log_t_test_is_scipy_s_and_a_non_difference_is_not_significant():
    a, b = [18, 20, 15, 22, 19], [41, 30, 77, 25, 52]
    test = stats.welch_log_t(a, b)
    reference = scipy_stats.ttest_ind(np.log1p(a), np.log1p(b), equal_var=False)
    assert test.p == pytest.approx(reference.pvalue, rel=1e-10)
    assert test.effect.high < 1
    rng = np.random.default_rng(3)
    same = [stats.welch_log_t(rng.poisson(20, 5), rng.poisson(20, 5)).p for _ in range(400)]
    assert 0.02 < np.mean(np.array(same) < 0.05) < 0.09  # about its nominal rate under the null
    with pytest.raises(ValueError, match="counts or positive"):
        stats.welch_log_t([-1, 2], [1, 2])


def test_holm_adjusts_step_down_monotone_and_capped():
    adjusted = stats.holm({"a": 0.01, "b": 0.04, "c": 0.03, "d": 0.005})
    assert adjusted == pytest.approx({"a": 0.03, "b": 0.06, "c": 0.06, "d": 0.02})
    assert list(adjusted) == ["a", "b", "c", "d"]  # the claims in the order given
    assert stats.holm({"x": 0.6, "y": 0.7}) == {"x": 1.0, "y": 1.0}
    assert stats.holm({}) == {}
    with pytest.raises(ValueError, match="must be in"):
        stats.holm({"x": 1.5})


def test_kaplan_meier_median_with_and_without_censoring():
    assert stats.kaplan_meier_median([1, 2, 3, 4], [False] * 4) == 2
    # 5: 4/5 left; 8 censored; 10: 4/5 * 2/3 = 0.53; 12 censored; 20: 0
    assert stats.kaplan_meier_median([5, 8, 10, 12, 20], [False, True, False, True, False]) == 20
    assert (
        stats.kaplan_meier_median([5, 9, 12, 14, 20], [False, True, True, True, True]) is None
    )  # most never got there


def test_a_censored_rank_test_takes_censored_runs_against_the_claim():
    low, high = [3, 4, 5, 6, 7], [10, 12, 14, 16, 18]
    assert stats.censored_rank_test(low, [False] * 5, high, [False] * 5).p == pytest.approx(2 / 252)
    # high's censored runs (lower bounds) still lie above: the claim stands
    assert stats.censored_rank_test(low, [False] * 5, high, [True] * 5).p == pytest.approx(2 / 252)
    # low's runs that never got there might lie anywhere above: the claim cannot stand
    assert stats.censored_rank_test(low, [True, True, True, False, False], high, [False] * 5).p > 0.3


def test_the_sign_test_of_five_seeds_cannot_go_below_one_in_sixteen():
    assert stats.sign_test([1, 2, 3, 4, 5]).p == pytest.approx(1 / 16)
    assert stats.sign_test([1, -2, 3, 0, 5]).n == (4,)
    assert stats.sign_test([0, 0]).p == 1.0


def test_a_ratio_of_positive_values_is_tested_on_log_x():
    gated, plain = [0.0102, 0.0104, 0.0099, 0.0105, 0.0101], [0.0105, 0.0106, 0.0104, 0.0105, 0.0103]
    test = stats.paired_log_t(gated, plain, shift=0.0)
    assert test.name == "paired t, log x"
    assert test.p == pytest.approx(scipy_stats.ttest_rel(np.log(gated), np.log(plain)).pvalue, rel=1e-12)
    assert test.effect.estimate == pytest.approx(np.exp(np.mean(np.log(gated) - np.log(plain))))
    with pytest.raises(ValueError, match="positive"):
        stats.paired_log_t([0.0, 1.0], [1.0, 1.0], shift=0.0)


def test_a_page_s_claims_are_holm_adjusted_and_a_failed_one_is_not_shown(tmp_path):
    from sfl_brain.report.study import Claim, bounded_cell, censored_cell, claims_table, tradeoff_figure

    strong = stats.paired_log_t([10, 14, 7, 9, 12], [40, 61, 22, 35, 55])
    weak = stats.welch_log_t([18, 25, 15, 22, 19], [20, 30, 17, 25, 52])
    lines, adjusted = claims_table(
        [Claim("a", "gated fails less", strong, "ratio"), Claim("b", "gated fails less than sfl", weak, "ratio")]
    )
    assert adjusted["a"] == pytest.approx(2 * strong.p) and adjusted["a"] < 0.05 <= adjusted["b"]
    assert "**holds**" in lines[2] and "not shown" in lines[3] and "Holm p (over 2)" in lines[0]
    assert bounded_cell([0, 0, 1, 3, 40], ".1f").startswith("8.8 [0.") and bounded_cell([]) == "-"
    assert censored_cell([3, 5, 8], [False] * 3).endswith("(all 3)")
    assert censored_cell([3, 20, 30], [False, True, True]) == "1 of 3 reach it; no median (under half reach it)"
    tradeoff_figure({"planar": {"cma": [(40, 0.0105), (61, 0.0104)], "cma + gate": [(10, 0.0105)]}}, tmp_path / "t.png")
    assert (tmp_path / "t.png").stat().st_size > 10_000
