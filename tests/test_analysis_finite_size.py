"""Exponents across sizes: fits on synthetic power laws with cut-offs, the extrapolation to
N → ∞ on planted finite-size trends, the gap cut-off h_min(N), and the per-size analysis of
jammed packings."""

from __future__ import annotations

import numpy as np
import pytest

import calippso
import generators
from calippso.analysis import PooledSample, critical_exponents, exponent_from_sample
from calippso.analysis.collapse import collapsed_cumulative, gap_cutoff
from calippso.analysis.extrapolation import OMEGA_AT_BOUND, OMEGA_RANGE, extrapolate
from calippso.analysis.finite_size import finite_size_analysis, packings_needed

GAMMA, THETA_E = 0.41269, 0.42311


def _grouped(values: np.ndarray, groups: int) -> PooledSample:
    """`values` split into `groups` packings of equal size, each normalised by its count."""
    return PooledSample.concatenate([(part, part.size) for part in np.array_split(values, groups)])


# --- fits on synthetic samples ---------------------------------------------------------------

#: Synthetic samples per sample size in the coverage tests, and how many intervals must
#: hold the planted exponent (16 of 20: a 95 % interval misses it more than 4 times with
#: probability 1.6 %).
SAMPLES, COVERED = 20, 16


def _recovers(name: str, exponent: float, draw, size: int, seed: int, **options) -> None:
    """`SAMPLES` synthetic samples of `size` values in 20 packings: at least `COVERED`
    intervals hold `exponent`, and the mean estimate lies within three standard errors."""
    rng = np.random.default_rng(seed)
    values, covered = [], 0
    for k in range(SAMPLES):
        fitted = exponent_from_sample(name, _grouped(draw(rng, size), 20), n_bootstrap=200,
                                      seed=k, **options)
        assert fitted.fit.resampling == "packings"
        values.append(fitted.value)
        covered += fitted.interval[0] < exponent < fitted.interval[1]
    assert covered >= COVERED, (size, covered)
    assert abs(np.mean(values) - exponent) < 3 * np.std(values) / np.sqrt(SAMPLES)


@pytest.mark.parametrize("size", [5_000, 20_000, 100_000])
def test_cutoff_fit_recovers_theta_of_a_power_law_with_cutoff(size):
    """Forces with density f^θ e^(−(1+θ) f) (mean 1), the cut-off model over f ≤ 0.3."""
    _recovers("theta_e", THETA_E, lambda rng, k: rng.gamma(1 + THETA_E, 1 / (1 + THETA_E), k),
              size, seed=size, model="cutoff")


@pytest.mark.parametrize("size", [5_000, 20_000, 100_000])
def test_gap_fit_recovers_gamma_of_a_power_law_with_cutoff(size):
    """Gaps with density h^−γ e^(−h) (a cut-off two decades above the window top 1e-2), the
    pure power law over h ≤ 1e-2."""
    _recovers("gamma", GAMMA, lambda rng, k: rng.gamma(1 - GAMMA, 1.0, k), size,
              seed=size + 1)


def test_a_floor_above_a_depletion_recovers_gamma():
    """Gaps with density h^−γ (1 − e^(−√(h/h₀))), h₀ = 1e-6 (a depletion of the smallest
    gaps, as in a finite packing): from the 10th smallest value the fit is biased low, from
    `lower` = 100 h₀ it recovers γ."""
    def depleted(rng, size):
        h = rng.gamma(1 - GAMMA, 1.0, size)
        return h[rng.random(h.size) < 1 - np.exp(-np.sqrt(h / 1e-6))]

    _recovers("gamma", GAMMA, depleted, 200_000, seed=12, lower=1e-4)
    rng = np.random.default_rng(13)
    ranked = [exponent_from_sample("gamma", _grouped(depleted(rng, 200_000), 20),
                                   n_bootstrap=0).value for _ in range(SAMPLES)]
    assert np.mean(ranked) < GAMMA - 3 * np.std(ranked) / np.sqrt(SAMPLES)


# --- extrapolation ---------------------------------------------------------------------------

def _trend(sizes, limit, amplitude, omega, sigma, rng):
    n = np.asarray(sizes, dtype=float)
    x = limit + amplitude * n ** -omega + rng.normal(0, sigma, n.size)
    return n, x, np.c_[x - 1.96 * sigma, x + 1.96 * sigma]


def test_fitted_omega_recovers_a_planted_limit():
    """x(N) = 0.41269 − 0.8 N^−0.5 at six sizes: "auto" fits ω and its interval holds the
    planted limit; the one-sided assumption 1/N would miss it."""
    n, x, intervals = _trend([512, 1024, 2048, 4096, 8192, 16384], GAMMA, -0.8, 0.5, 0.003,
                             np.random.default_rng(2))
    result = extrapolate(n, x, intervals)
    assert result.chosen.form == "power" and result.chosen.omega_fitted
    assert result.interval[0] < GAMMA < result.interval[1]
    assert set(result.candidates) == {"constant", "inverse_n", "power"}
    assert extrapolate(n, x, intervals, form="power", omega=0.5).interval[0] < GAMMA


def test_fitted_omega_covers_the_limit_at_its_level():
    """Four sizes (1024–8192), trends with ω = 0.3, 0.5, 1 and none: the 95 % interval of
    the fitted ω covers the planted limit in at least 90 % of 60 samples each."""
    rng = np.random.default_rng(3)
    for amplitude, omega in ((-0.3, 0.3), (-0.8, 0.5), (-20.0, 1.0), (0.0, 1.0)):
        covered = 0
        for seed in range(60):
            n, x, intervals = _trend([1024, 2048, 4096, 8192], GAMMA, amplitude, omega, 0.005,
                                     rng)
            low, high = extrapolate(n, x, intervals, n_draws=400, seed=seed).interval
            covered += low < GAMMA < high
        assert covered >= 54, (omega, covered)


def test_a_known_form_recovers_its_limit_with_a_narrower_interval():
    n, x, intervals = _trend([1024, 2048, 4096, 8192], THETA_E, -30.0, 1.0, 0.005,
                             np.random.default_rng(4))
    known = extrapolate(n, x, intervals, form="inverse_n")
    fitted = extrapolate(n, x, intervals)
    assert known.interval[0] < THETA_E < known.interval[1]
    assert np.diff(known.interval)[0] < np.diff(fitted.interval)[0]
    assert known.chosen.amplitude == pytest.approx(-30.0, rel=0.5)


def test_a_fitted_omega_at_its_lower_bound_says_no_trend_is_resolved():
    """Four sizes with no trend, the last one high (θ_e of the d = 3 study): ω runs to the
    lower end of its range, and the reason says so beside the constant form's fit; a
    resolved trend says nothing of the kind."""
    sizes = [1024, 2048, 4096, 8192]
    values = [0.407, 0.393, 0.416, 0.425]
    intervals = [[0.367, 0.444], [0.352, 0.431], [0.382, 0.447], [0.398, 0.455]]
    flat = extrapolate(sizes, values, intervals, n_draws=400)
    assert flat.chosen.omega == pytest.approx(OMEGA_RANGE[0], rel=OMEGA_AT_BOUND)
    constant = flat.candidates["constant"]
    assert "lower bound" in flat.reason and f"{constant.value:.4g}" in flat.reason
    assert constant.value == pytest.approx(0.413, abs=0.002)
    n, x, trend_intervals = _trend(sizes, GAMMA, -20.0, 1.0, 0.002, np.random.default_rng(5))
    resolved = extrapolate(n, x, trend_intervals, n_draws=400)
    assert resolved.chosen.omega > OMEGA_RANGE[0] * 2 and "lower bound" not in resolved.reason


def test_few_sizes_assume_one_over_n():
    n, x, intervals = _trend([1024, 2048, 4096], GAMMA, -20.0, 1.0, 0.002,
                             np.random.default_rng(5))
    result = extrapolate(n, x, intervals)
    assert result.chosen.form == "inverse_n" and "1/N assumed" in result.reason
    assert result.interval[0] < GAMMA < result.interval[1]
    two = extrapolate(n[:2], x[:2], intervals[:2])
    assert two.chosen.form == "inverse_n" and two.chosen.dof == 0


def test_extrapolation_refuses_bad_input():
    intervals = [[0.3, 0.4], [0.35, 0.45]]
    with pytest.raises(ValueError, match="two or more sizes"):
        extrapolate([1024], [0.4], [[0.3, 0.5]])
    with pytest.raises(ValueError, match="distinct"):
        extrapolate([1024, 1024], [0.35, 0.4], intervals)
    with pytest.raises(ValueError, match="positive, finite width"):
        extrapolate([1024, 2048], [0.35, 0.4], [[0.3, 0.3], [0.35, 0.45]])
    with pytest.raises(ValueError, match="form must be"):
        extrapolate([1024, 2048], [0.35, 0.4], intervals, form="log")
    with pytest.raises(ValueError, match="more parameters than there are sizes"):
        extrapolate([1024, 2048], [0.35, 0.4], intervals, form="power")


# --- the gap cut-off -------------------------------------------------------------------------

def test_gap_cutoff_scales_as_n_to_minus_one_over_one_minus_gamma():
    PACKINGS = 100
    """Packings of N particles with 0.3 N gaps of cumulative ∝ h^(1−γ) below 0.1: their
    smallest gap falls as N^(−1/(1−γ)), and γ read off the slope holds the planted one."""
    rng = np.random.default_rng(6)
    by_size = {}
    for n in (1024, 2048, 4096, 8192):
        parts = [(0.1 * rng.random(int(0.3 * n)) ** (1 / (1 - GAMMA)), 0.5 * n)
                 for _ in range(PACKINGS)]
        by_size[n] = PooledSample.concatenate(parts)
    cutoff = gap_cutoff(by_size)
    assert cutoff.gamma_interval[0] < GAMMA < cutoff.gamma_interval[1]
    low, high = cutoff.slope_interval
    assert low < -1 / (1 - GAMMA) < high and high - low < 1.5
    assert np.all(np.diff(cutoff.h_min) < 0) and cutoff.packings.tolist() == [PACKINGS] * 4
    line = cutoff.scaling_line(cutoff.sizes, GAMMA)
    assert np.all(np.abs(np.log(line / cutoff.h_min)) < 0.5)
    # on the scaled axes the cumulatives of the smallest and largest size coincide
    x_small, y_small = collapsed_cumulative(by_size[1024], 1024, GAMMA)
    x_large, y_large = collapsed_cumulative(by_size[8192], 8192, GAMMA)
    probe = np.geomspace(1, 100, 5)
    assert np.interp(probe, x_small, y_small) == pytest.approx(
        np.interp(probe, x_large, y_large), rel=0.2)   # unscaled they differ 8-fold


def test_a_size_without_gaps_is_left_out_of_the_cutoff_slope():
    """A size whose packings hold no gap (all beyond the pooling's largest: an empty sample)
    has h_min nan and no packings; the slope is that of the other sizes."""
    rng = np.random.default_rng(7)
    by_size = {n: PooledSample.concatenate(
        [(0.1 * rng.random(int(0.3 * n)) ** (1 / (1 - GAMMA)), 0.5 * n) for _ in range(20)])
        for n in (1024, 4096)}
    both = gap_cutoff(by_size)
    by_size[32] = PooledSample.concatenate([(np.zeros(0), 16.0)])
    with_empty = gap_cutoff(by_size)
    assert np.isnan(with_empty.h_min[0]) and with_empty.packings[0] == 0
    assert with_empty.slope == pytest.approx(both.slope, rel=1e-12)


# --- samples and sizes -----------------------------------------------------------------------

def test_select_and_minima_of_a_pooled_sample():
    sample = PooledSample.concatenate([(np.array([0.3, 0.1]), 2.0), (np.array([0.2]), 1.0),
                                       (np.array([0.05, 0.4]), 4.0)])
    picked = sample.select([2, 0])
    assert picked.n_groups == 2 and picked.normalization == 6.0
    assert picked.values.tolist() == [0.05, 0.1, 0.3, 0.4]
    assert picked.groups.tolist() == [0, 1, 1, 0]
    assert sample.minima().tolist() == [0.1, 0.2, 0.05]
    with pytest.raises(ValueError, match="distinct indices"):
        sample.select([0, 0])


def test_packings_needed_scales_with_the_square_of_the_width():
    assert packings_needed((0.38, 0.42), 20, 0.02) == 20
    assert packings_needed((0.36, 0.44), 20, 0.02) == 80
    with pytest.raises(ValueError):
        packings_needed((0.3, 0.4), 10, 0.0)


@pytest.fixture(scope="module")
def two_sizes():
    """Soft-quench packings of N = 64 and 128 in d = 3 (three seeds each), jammed with their
    networks."""
    results = []
    for n in (128, 64):
        for seed in (1, 2, 3):
            q = generators.soft_quench(generators.diameters.monodisperse(n), 3, seed=seed)
            results.append(calippso.jam(q.packing, network=q.contacts))
    return results


def test_finite_size_analysis_fits_each_size_as_on_its_own(two_sizes):
    analysis = finite_size_analysis(two_sizes, n_bootstrap=50)
    assert analysis.sizes == (64, 128) and analysis.d == 3
    small = [r for r in two_sizes if r.packing.n == 64]
    alone = critical_exponents(small, n_bootstrap=50)
    for name, exponent in analysis.by_size[0].exponents.items():
        assert exponent.value == pytest.approx(alone[name].value, abs=1e-12)
        assert exponent.interval == pytest.approx(alone[name].interval, abs=1e-12)
    summary = analysis.to_dict()
    assert summary["by_size"]["64"]["packings"] == 3
    assert set(summary["by_size"]["128"]) == {"packings", "gamma", "theta_e", "theta_l",
                                              "theta"}
    for name, entry in summary["extrapolated"].items():
        assert entry["form"] == "inverse_n" and len(entry["interval"]) == 2
    assert summary["gap_cutoff"]["sizes"] == [64, 128]


def test_gap_floor_starts_each_gamma_window_at_its_cutoff(two_sizes):
    analysis = finite_size_analysis(two_sizes, n_bootstrap=20, gap_floor="cutoff")
    for k, size in enumerate(analysis.by_size):
        if "gamma" in size.exponents:
            assert size.exponents["gamma"].fit.lower >= analysis.gap_cutoff.h_min[k]
    assert analysis.to_dict()["gap_floor"] == "cutoff"
    with pytest.raises(ValueError, match="gap_floor"):
        finite_size_analysis(two_sizes, gap_floor="lowest")


def test_finite_size_analysis_needs_two_sizes(two_sizes):
    with pytest.raises(ValueError, match="two sizes or more"):
        finite_size_analysis([r for r in two_sizes if r.packing.n == 64])
