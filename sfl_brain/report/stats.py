"""Statistics for comparing groups of runs (seeds) that hold with few seeds, skewed counts and censored runs.

What a study page uses (``docs/results/baselines.md``, :mod:`sfl_brain.report.study`):

- **intervals that respect bounds**: :func:`bootstrap_mean` (a percentile bootstrap interval of the mean: never
  outside the values' range, so never below 0 for a count or above 1 for a rate), :func:`bootstrap_band` (the same,
  trial by trial, for learning curves) and :func:`ratio_interval` (a ratio of two groups on the log scale: always
  positive); with :data:`FEW` values or fewer a bootstrap interval is only the values' range, and a page lists the
  values instead of calling it 95 %;
- **tests**: :func:`paired_log_t` (a paired t-test on log(x + 1), where the seeds pair: the same seed's runs share
  their starting state), :func:`welch_log_t` (Welch's t-test on log(x + 1) otherwise), :func:`censored_rank_test`
  (Mann-Whitney's U where some runs never got there, each censored run taken at the bound least favourable to the
  claim) and :func:`sign_test` (exact, for "in every seed");
- **a family of claims**: :func:`holm` (Holm's step-down adjustment of the p-values of every claim a page makes);
  a claim whose adjusted p is not below ``alpha`` is not made;
- **time to an event with censoring**: :func:`kaplan_meier_median` (the median failures before K good gaits when
  some runs never found K).

Why on the log scale: the counts are skewed and bounded at 0, the effects are ratios ("the gate cuts failures to
0.25x"), and a mean difference of counts with five seeds gives intervals with negative lower bounds. ``+ 1`` keeps a
run with no failure finite. With five seeds an exact rank test cannot reach p < 0.0625 paired or 0.0079 unpaired
(two-sided): too coarse for a family of claims, hence t-tests on the log scale, and ten seeds where a claim hinges on
a rank test.

Plain numpy and scipy; every function takes sequences of numbers (None or nan are not accepted unless said).
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass

import numpy as np

#: resamples of a bootstrap interval; its generator's seed (the same page from the same runs)
BOOTSTRAP_RESAMPLES = 10_000
BOOTSTRAP_SEED = 0
#: at most this many values, a 95 % percentile bootstrap interval of the mean is their range (min, max): each extreme
#: mean, all draws of one value, has probability n**-n, above 2.5 % for n <= 3
FEW = 3


@dataclass(frozen=True)
class Interval:
    """An estimate and its two-sided interval at ``confidence``."""

    estimate: float
    low: float
    high: float
    confidence: float = 0.95

    def text(self, digits: str = ".3g") -> str:
        if math.isnan(self.low):
            return f"{self.estimate:{digits}}"
        return f"{self.estimate:{digits}} [{self.low:{digits}}, {self.high:{digits}}]"


@dataclass(frozen=True)
class Test:
    """A test's outcome: its name, the p-value (two-sided) and the effect it measured (an :class:`Interval`)."""

    name: str
    p: float
    effect: Interval
    n: tuple[int, ...]


def _finite(values: Sequence[float]) -> np.ndarray:
    a = np.asarray(list(values), dtype=float)
    if a.size and not np.all(np.isfinite(a)):
        raise ValueError(f"expected finite numbers, got {list(values)}")
    return a


def bootstrap_mean(
    values: Sequence[float],
    confidence: float = 0.95,
    resamples: int = BOOTSTRAP_RESAMPLES,
    seed: int = BOOTSTRAP_SEED,
) -> Interval:
    """The mean and its percentile bootstrap interval. The interval lies within the values' range (a count's never
    below 0). With n = 5 it covers less than ``confidence`` (the bootstrap knows only the five values): a
    description of the spread, not a test. One value: no interval (nan)."""
    a = _finite(values)
    if a.size == 0:
        return Interval(math.nan, math.nan, math.nan, confidence)
    if a.size == 1 or np.all(a == a[0]):
        return Interval(
            float(a.mean()),
            float(a.min()) if a.size > 1 else math.nan,
            float(a.max()) if a.size > 1 else math.nan,
            confidence,
        )
    rng = np.random.default_rng(seed)
    means = a[rng.integers(0, a.size, size=(resamples, a.size))].mean(axis=1)
    low, high = np.quantile(means, [(1 - confidence) / 2, (1 + confidence) / 2])
    return Interval(float(a.mean()), float(low), float(high), confidence)


def bootstrap_band(
    curves: Sequence[Sequence[float]],
    confidence: float = 0.95,
    resamples: int = BOOTSTRAP_RESAMPLES,
    seed: int = BOOTSTRAP_SEED,
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Mean and percentile bootstrap band, trial by trial, of ``curves`` (one per seed) over the trials they all
    have. A resample draws whole seeds, the same draw at every trial; a nan (no value yet at that trial) is left out
    of that trial's mean. Every resampled mean is a weighted mean of the seeds' values, so the band lies within the
    seeds' range at every trial (at :data:`FEW` seeds or fewer it is that range): never outside what a curve can
    reach. A trial with one value has no band (nan)."""
    length = min(len(c) for c in curves)
    a = np.array([np.asarray(c[:length], dtype=float) for c in curves]).reshape(len(curves), length)
    has = np.isfinite(a)
    n = has.sum(axis=0)
    mean = np.where(n > 0, np.where(has, a, 0.0).sum(axis=0) / np.maximum(n, 1), np.nan)
    draws = np.random.default_rng(seed).multinomial(len(curves), np.full(len(curves), 1 / len(curves)), resamples)
    with np.errstate(invalid="ignore", divide="ignore"):
        means = (draws @ np.where(has, a, 0.0)) / (draws @ has)  # (resamples, trials); nan: no seed drawn has one
    if not means.size:
        return mean, mean.copy(), mean.copy()
    valid = np.isfinite(means)  # nan where no seed drawn has a value (0 / 0); never inf
    low, high = np.full(length, np.nan), np.full(length, np.nan)
    enough = (n > 1) & valid.any(axis=0)
    if enough.any():
        tails = [(1 - confidence) / 2, (1 + confidence) / 2]
        low[enough], high[enough] = np.nanquantile(means[:, enough], tails, axis=0)
    return mean, low, high


def _log(values: Sequence[float], shift: float = 1.0) -> np.ndarray:
    a = _finite(values) + shift
    if a.size and np.any(a <= 0):
        raise ValueError(f"a log-scale test takes counts or positive values, got {list(values)}")
    return np.log(a)


def _scale(shift: float) -> str:
    return "log x" if shift == 0 else f"log(x+{shift:g})"


def paired_log_t(a: Sequence[float], b: Sequence[float], confidence: float = 0.95, shift: float = 1.0) -> Test:
    """Paired t-test of log(a + shift) - log(b + shift), seed by seed (``a[i]`` and ``b[i]`` the same seed): the
    effect is the geometric mean ratio (a + shift) / (b + shift) with its t-interval, back from the log scale (always
    positive). ``shift`` 1 for counts (a run without a failure stays finite), 0 for positive values (eta)."""
    from scipy import stats  # here: scipy.stats costs about 0.75 s to import

    x, y = _log(a, shift), _log(b, shift)
    if x.size != y.size:
        raise ValueError(f"paired samples of different sizes: {x.size} and {y.size}")
    d = x - y
    n = d.size
    if n < 2:
        raise ValueError("a paired t-test needs two pairs or more")
    mean, sd = float(d.mean()), float(d.std(ddof=1))
    if sd == 0.0:
        p = 1.0 if mean == 0.0 else 0.0
        exact = Interval(math.exp(mean), math.exp(mean), math.exp(mean), confidence)
        return Test(f"paired t, {_scale(shift)}", p, exact, (n,))
    se = sd / math.sqrt(n)
    p = float(2 * stats.t.sf(abs(mean) / se, n - 1))
    half = float(stats.t.ppf((1 + confidence) / 2, n - 1) * se)
    return Test(
        f"paired t, {_scale(shift)}",
        p,
        Interval(math.exp(mean), math.exp(mean - half), math.exp(mean + half), confidence),
        (n,),
    )


def welch_log_t(a: Sequence[float], b: Sequence[float], confidence: float = 0.95, shift: float = 1.0) -> Test:
    """Welch's t-test of log(a + shift) against log(b + shift) (unpaired, unequal variances): the effect is the ratio
    of the geometric means of (a + shift) and (b + shift) with its Welch interval, back from the log scale."""
    from scipy import stats  # here: scipy.stats costs about 0.75 s to import

    x, y = _log(a, shift), _log(b, shift)
    if x.size < 2 or y.size < 2:
        raise ValueError("Welch's test needs two values or more in each group")
    diff = float(x.mean() - y.mean())
    vx, vy = x.var(ddof=1) / x.size, y.var(ddof=1) / y.size
    se = math.sqrt(vx + vy)
    if se == 0.0:
        p = 1.0 if diff == 0.0 else 0.0
        return Test(
            f"Welch t, {_scale(shift)}",
            p,
            Interval(math.exp(diff), math.exp(diff), math.exp(diff), confidence),
            (x.size, y.size),
        )
    df = (vx + vy) ** 2 / (vx**2 / (x.size - 1) + vy**2 / (y.size - 1))
    p = float(2 * stats.t.sf(abs(diff) / se, df))
    half = float(stats.t.ppf((1 + confidence) / 2, df) * se)
    effect = Interval(math.exp(diff), math.exp(diff - half), math.exp(diff + half), confidence)
    return Test(f"Welch t, {_scale(shift)}", p, effect, (x.size, y.size))


def ratio_interval(a: Sequence[float], b: Sequence[float], paired: bool, confidence: float = 0.95) -> Interval:
    """(a + 1) / (b + 1) as a geometric-mean ratio with its interval (log scale; paired by seed or not)."""
    return (paired_log_t if paired else welch_log_t)(a, b, confidence).effect


def censored_rank_test(
    a: Sequence[float], a_censored: Sequence[bool], b: Sequence[float], b_censored: Sequence[bool]
) -> Test:
    """Is ``a`` lower than ``b`` when some runs never got there (a censored run's value is a lower bound)?
    Mann-Whitney's U (exact when there are no ties, two-sided), each censored value taken where it hurts the claim
    "a < b" most: a censored run of ``a`` at +infinity, one of ``b`` at its lower bound. A small p supports the
    claim whatever the censored runs would have given; the effect is the difference of the medians so taken."""
    from scipy import stats  # here: scipy.stats costs about 0.75 s to import

    x = np.where(np.asarray(a_censored, dtype=bool), np.inf, _finite(a))
    y = _finite(b)
    if x.size < 1 or y.size < 1:
        raise ValueError("each group needs a value")
    del b_censored  # taken at their lower bounds: y as given
    result = stats.mannwhitneyu(x, y, alternative="two-sided", method="auto")
    effect = float(np.median(x) - np.median(y)) if np.isfinite(np.median(x)) else math.inf
    return Test(
        "Mann-Whitney U, censored runs against the claim",
        float(result.pvalue),
        Interval(effect, math.nan, math.nan),
        (x.size, y.size),
    )


def sign_test(differences: Sequence[float]) -> Test:
    """Exact two-sided sign test that the differences (e.g. gated minus plain, seed by seed) are as often above 0 as
    below (zeros dropped); the effect is the share of non-zero differences above 0."""
    from scipy import stats  # here: scipy.stats costs about 0.75 s to import

    d = _finite(differences)
    d = d[d != 0]
    if d.size == 0:
        return Test("exact sign test", 1.0, Interval(math.nan, math.nan, math.nan), (0,))
    above = int(np.sum(d > 0))
    p = float(stats.binomtest(above, d.size, 0.5).pvalue)
    return Test("exact sign test", p, Interval(above / d.size, math.nan, math.nan), (int(d.size),))


def holm(pvalues: Mapping[str, float]) -> dict[str, float]:
    """Holm's step-down adjusted p-values of a family of tests (claim -> p): the i-th smallest of m is multiplied by
    (m - i + 1), made monotone and capped at 1. A claim holds at level alpha when its adjusted p is below alpha; the
    family's chance of any false claim is then at most alpha, whatever the dependence between the tests."""
    items = sorted(pvalues.items(), key=lambda kv: kv[1])
    m = len(items)
    adjusted: dict[str, float] = {}
    running = 0.0
    for i, (name, p) in enumerate(items):
        if not 0.0 <= p <= 1.0 or math.isnan(p):
            raise ValueError(f"{name}: a p-value must be in [0, 1], got {p}")
        running = max(running, min(1.0, (m - i) * p))
        adjusted[name] = running
    return {name: adjusted[name] for name in pvalues}


def kaplan_meier_median(values: Sequence[float], censored: Sequence[bool]) -> float | None:
    """The Kaplan-Meier median of values to an event (e.g. failures before K good gaits) when the runs with
    ``censored`` True never got there (their value, e.g. total failures, a lower bound): the smallest value at
    which the estimated share still waiting falls to 0.5 or below; None when it never does."""
    t = _finite(values)
    c = np.asarray(censored, dtype=bool)
    if t.size != c.size:
        raise ValueError("a value and a censored flag per run")
    surviving = 1.0
    for time in np.unique(t[~c]):
        at_risk = int(np.sum(t >= time))
        events = int(np.sum((t == time) & ~c))
        surviving *= 1.0 - events / at_risk
        if surviving <= 0.5:
            return float(time)
    return None
