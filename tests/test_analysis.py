"""calippso.analysis: contact statistics, gaps, bucklers, force split and power-law fits."""

from __future__ import annotations

import json
from importlib.resources import files

import numpy as np
import pytest

import calippso
from calippso import Packing
from calippso.analysis import (PooledSample, analyze, bucklers, contact_statistics,
                               exponent_from_sample, fit_cumulative_power_law, gaps,
                               localized_contacts, normalized_forces, pooled_forces, pooled_gaps,
                               window_scan)
from calippso.analysis.exponents import MODEL, resolve_models
from calippso.analysis.forces import RESPONSE_THRESHOLD, split_forces
from calippso.analysis.response import opening_response
from calippso.geometry.packing import minimum_image
from calippso.result import JammingResult


@pytest.fixture(scope="module")
def jammed() -> JammingResult:
    """The built-in LS packing (N = 512, d = 3) jammed once for the module (~5 s)."""
    start = calippso.read(str(files("calippso") / "data" / "example_d3_n512_ls.npz"))
    return calippso.jam(start)


# --- contact statistics -------------------------------------------------------------------

def test_contact_statistics_of_one_packing(jammed):
    stats = contact_statistics(jammed)
    stable = ~jammed.rattlers
    assert stats.n_stable == stable.sum()
    assert stats.mean_z == pytest.approx(2 * jammed.n_contacts / jammed.n_stable)
    assert stats.contact_numbers.min() >= jammed.d + 1          # rattlers removed recursively
    assert stats.contact_numbers.sum() == 2 * jammed.n_contacts
    assert stats.isostaticity_gaps.tolist() == [0] and stats.n_isostatic == 1
    # isostatic: N_c = d (N_s - 1) + 1, so z = 2d - 2(d - 1)/N_s
    assert stats.mean_z == pytest.approx(2 * 3 - 2 * 2 / jammed.n_stable)
    z, fraction = stats.histogram()
    assert fraction.sum() == pytest.approx(1.0) and z.min() >= jammed.d + 1


def test_pooling_adds_counts(jammed):
    one, two = contact_statistics(jammed), contact_statistics([jammed, jammed])
    assert two.n_packings == 2 and two.n_contacts == 2 * one.n_contacts
    assert two.mean_z == pytest.approx(one.mean_z)
    assert two.rattler_fraction == pytest.approx(one.rattler_fraction)
    assert len(pooled_gaps([jammed, jammed])) == 2 * len(pooled_gaps(jammed))


def _square_result() -> JammingResult:
    """A 2-d result (4 disks on a square lattice) built by hand, for input checks."""
    positions = np.array([[1.0, 1.0], [3.0, 1.0], [1.0, 3.0], [3.0, 3.0]])
    packing = Packing(positions, np.ones(4), np.array([4.0, 4.0]))
    return JammingResult(packing, np.zeros((0, 2), dtype=np.int64), np.zeros(0),
                         np.ones(4, dtype=bool), False, "hand-made", 0)


def test_bad_input_is_named(jammed):
    with pytest.raises(ValueError, match="empty"):
        contact_statistics([])
    with pytest.raises(ValueError, match="different dimensions"):
        analyze([jammed, _square_result()])
    with pytest.raises(TypeError, match=r"results\[1\].*JammingResult"):
        pooled_gaps([jammed, jammed.packing])
    with pytest.raises(ValueError, match="max_gap"):
        gaps(jammed, max_gap=0.0)
    with pytest.raises(ValueError, match="rule"):
        localized_contacts(jammed, rule="strongest")
    with pytest.raises(ValueError, match="kind"):
        pooled_forces(jammed, kind="weak")


# --- gaps ----------------------------------------------------------------------------------

def _gaps_by_brute_force(result: JammingResult, max_gap: float) -> np.ndarray:
    """Every pair of stable non-contact particles with h ≤ max_gap, one row at a time."""
    p = result.packing
    contacts = {tuple(c) for c in result.contacts.tolist()}
    found = []
    for i in np.flatnonzero(~result.rattlers):
        j = np.arange(i + 1, p.n)
        j = j[~result.rattlers[j]]
        r = minimum_image(p.positions[i] - p.positions[j], p.box)
        h = np.linalg.norm(r, axis=1) / (0.5 * (p.diameters[i] + p.diameters[j])) - 1
        found += [hk for jk, hk in zip(j, h) if hk <= max_gap and (i, jk) not in contacts]
    return np.sort(found)


def test_gaps_are_the_non_contact_pairs_of_stable_particles(jammed):
    h = gaps(jammed, max_gap=0.05)
    np.testing.assert_allclose(h, _gaps_by_brute_force(jammed, 0.05), rtol=0, atol=1e-13)
    # contacts are touching (|h| ~ round-off); the gap list holds none of them
    assert h.min() > 1e-9 and h.max() <= 0.05
    assert np.all(np.diff(h) >= 0)


def test_touching_pairs_without_force_are_not_gaps(jammed):
    """A pair at contact distance that is not in the contact list is left out of the gaps."""
    import dataclasses

    dropped = dataclasses.replace(jammed, contacts=jammed.contacts[1:],
                                  forces=jammed.forces[1:])
    np.testing.assert_array_equal(gaps(dropped, 0.05), gaps(jammed, 0.05))


def test_pooled_gap_cumulative_is_per_stable_particle(jammed):
    sample = pooled_gaps(jammed, max_gap=0.1)
    x, c = sample.cumulative()
    assert c[-1] == pytest.approx(2 * len(sample) / jammed.n_stable)
    centres, density = sample.density(bins_per_decade=4)
    assert np.all(density > 0) and np.all(np.diff(centres) > 0)


# --- forces and bucklers --------------------------------------------------------------------

def test_every_force_is_positive_and_normalised(jammed):
    f = normalized_forces(jammed)
    assert f.shape == (jammed.n_contacts,)
    assert np.all(f > 0) and f.mean() == pytest.approx(1.0, abs=1e-12)
    assert len(pooled_forces(jammed)) == jammed.n_contacts


def test_bucklers_have_d_plus_one_contacts(jammed):
    b = bucklers(jammed)
    assert b.any()
    assert np.all(jammed.contact_numbers[b] == jammed.d + 1)
    assert not np.any(b & jammed.rattlers)
    others = ~b & ~jammed.rattlers
    assert np.all(jammed.contact_numbers[others] > jammed.d + 1)


def test_buckler_forces_follow_cramers_rule(jammed):
    """Force balance on a buckler: f_k ∝ |det of the other d contact normals|."""
    normals = jammed.contact_vectors / np.linalg.norm(jammed.contact_vectors, axis=1)[:, None]
    for particle in np.flatnonzero(bucklers(jammed)):
        edges = np.flatnonzero((jammed.contacts == particle).any(axis=1))
        sign = np.where(jammed.contacts[edges, 0] == particle, 1.0, -1.0)
        n = sign[:, None] * normals[edges]
        minors = np.array([abs(np.linalg.det(np.delete(n, k, axis=0)))
                           for k in range(len(edges))])
        f = jammed.forces[edges]
        np.testing.assert_allclose(f / f.max(), minors / minors.max(), atol=1e-8)
        assert np.argmin(f) == np.argmin(minors)


def test_localized_forces_are_the_forces_on_bucklers(jammed):
    """Default rule: every contact with a buckler at either end is localised."""
    b = np.flatnonzero(bucklers(jammed))
    localized = localized_contacts(jammed)
    touches_buckler = np.isin(jammed.contacts, b).any(axis=1)
    np.testing.assert_array_equal(localized, touches_buckler)
    np.testing.assert_array_equal(localized_contacts(jammed, "bucklers"), localized)
    np.testing.assert_array_equal(localized_contacts(jammed, "all"), localized)  # former name
    local, extended = pooled_forces(jammed, "localized"), pooled_forces(jammed, "extended")
    assert len(local) == localized.sum()
    assert len(local) + len(extended) == jammed.n_contacts
    np.testing.assert_allclose(np.sort(np.concatenate([local.values, extended.values])),
                               np.sort(normalized_forces(jammed)))
    assert analyze(jammed, n_bootstrap=0).rule == "bucklers"


def test_weakest_rule_keeps_the_weakest_force_of_each_buckler(jammed):
    weakest = localized_contacts(jammed, "weakest")
    everything = localized_contacts(jammed, "bucklers")
    assert np.all(everything[weakest])                 # "bucklers" contains "weakest"
    b = np.flatnonzero(bucklers(jammed))
    assert b.size >= weakest.sum() >= b.size / 2        # a contact may be weakest of both ends
    for particle in b:
        edges = np.flatnonzero((jammed.contacts == particle).any(axis=1))
        assert weakest[edges[np.argmin(jammed.forces[edges])]]
        assert everything[edges].all()
    local = pooled_forces(jammed, "localized", rule="weakest")
    extended = pooled_forces(jammed, "extended", rule="weakest")
    assert len(local) == weakest.sum()
    assert len(local) + len(extended) == jammed.n_contacts


def _openings_by_least_squares(result: JammingResult, contacts: list[int]) -> np.ndarray:
    """Displacements, shape (len(contacts), N_s, d), of the minimum-norm responses to opening
    each of `contacts` by 1, from a QR factorisation of the compatibility matrix's transpose
    (independent of the LU that `opening_response` uses)."""
    from scipy.linalg import solve_triangular

    from calippso.geometry.contacts import equilibrium_matrix

    stable = ~result.rattlers
    index = np.cumsum(stable) - 1
    i, j = index[result.contacts[:, 0]], index[result.contacts[:, 1]]
    normals = result.contact_vectors / np.linalg.norm(result.contact_vectors, axis=1)[:, None]
    sigma = 0.5 * result.packing.diameters[result.contacts].sum(axis=1)
    compatibility = equilibrium_matrix(int(stable.sum()), i, j, normals).T.toarray()
    matrix = np.column_stack([compatibility, -sigma])      # (M, N_s d + 1), full row rank
    openings = np.zeros((result.n_contacts, len(contacts)))
    openings[contacts, np.arange(len(contacts))] = 1.0
    q, r = np.linalg.qr(matrix.T)                          # matrix = rᵀ qᵀ
    solutions = q @ solve_triangular(r, openings, trans="T")   # x = q r⁻ᵀ b, minimum norm
    return solutions[:-1].T.reshape(len(contacts), -1, result.d)


@pytest.fixture(scope="module")
def response(jammed):
    """The opening response of `jammed` (dense LU), computed once for the module."""
    return opening_response(jammed)


def test_opening_response_matches_least_squares_and_carries_the_forces(jammed, response):
    m = jammed.n_contacts
    assert response.share.shape == response.mover.shape == response.inflation.shape == (m,)
    assert np.all((response.share > 0) & (response.share <= 1 + 1e-12))
    # The inflation per unit opening is -f_k / sum(f sigma): the force is what opening costs.
    sigma = 0.5 * jammed.packing.diameters[jammed.contacts].sum(axis=1)
    np.testing.assert_allclose(-response.inflation * np.sum(jammed.forces * sigma),
                               jammed.forces, rtol=1e-8)
    stable = np.flatnonzero(~jammed.rattlers)
    checked = [0, m // 2, int(np.argmax(response.share)), int(np.argmin(response.share))]
    for contact, moves in zip(checked, _openings_by_least_squares(jammed, checked)):
        squared = (moves ** 2).sum(axis=1)
        assert response.share[contact] == pytest.approx(squared.max() / squared.sum(), rel=1e-6)
        assert response.mover[contact] == stable[np.argmax(squared)]
    assert response.reciprocal_condition > 1e3 * response.share.size * np.finfo(float).eps
    sparse = opening_response(jammed, factorization="sparse")
    np.testing.assert_allclose(sparse.share, response.share, rtol=1e-8, atol=1e-12)
    np.testing.assert_allclose(sparse.inflation, response.inflation, rtol=1e-8)
    assert np.isnan(sparse.reciprocal_condition)


def test_localised_responses_move_a_particle_next_to_the_opened_contact(jammed, response):
    """Opening a localised contact moves mostly one of its own ends, most often a buckler."""
    localized = localized_contacts(jammed, "response")
    np.testing.assert_array_equal(localized, response.localized(RESPONSE_THRESHOLD))
    assert 0 < localized.sum() < jammed.n_contacts / 10
    movers = response.mover[localized]
    ends = jammed.contacts[localized]
    is_end = (movers == ends[:, 0]) | (movers == ends[:, 1])
    assert is_end.mean() >= 0.75
    for mover, (a, b) in zip(movers[~is_end], ends[~is_end]):  # else a neighbour of an end
        touching = jammed.contacts[(jammed.contacts == mover).any(axis=1)].ravel()
        assert a in touching or b in touching
    assert np.mean(bucklers(jammed)[movers]) > 0.5
    # localised forces are weak ones
    assert np.median(jammed.forces[localized]) < 0.5 * np.median(jammed.forces)
    split = split_forces(jammed, "response")
    assert len(split["localized"]) == localized.sum()
    assert len(split["localized"]) + len(split["extended"]) == len(split["all"])


def test_opening_response_needs_an_isostatic_rigid_packing(jammed, response):
    from dataclasses import replace

    hypostatic = replace(jammed, contacts=jammed.contacts[1:], forces=jammed.forces[1:])
    with pytest.raises(ValueError, match="isostatic"):
        opening_response(hypostatic)
    contacts = jammed.contacts.copy()
    contacts[0] = contacts[1]                  # right count, one direction left unconstrained
    with pytest.raises(ValueError, match="floppy mode"):
        opening_response(replace(jammed, contacts=contacts))
    with pytest.raises(ValueError, match="threshold"):
        response.localized(1.5)
    with pytest.raises(ValueError, match="factorization"):
        opening_response(jammed, factorization="qr")


# --- fits ------------------------------------------------------------------------------------

@pytest.mark.parametrize("slope", [0.58731, 1.42311, 1.17])
def test_fit_recovers_the_slope_of_synthetic_power_law_data(slope):
    rng = np.random.default_rng(7)
    x = rng.random(40000) ** (1.0 / slope)              # C(x) = x^slope on [0, 1]
    fit = fit_cumulative_power_law(x, upper=0.3, n_bootstrap=200, seed=1)
    assert fit.slope == pytest.approx(slope, abs=0.05)
    assert fit.interval[0] < slope < fit.interval[1]
    assert fit.interval[1] - fit.interval[0] < 0.15
    assert fit.amplitude == pytest.approx(1.0, rel=0.15)
    assert fit.resampling == "values" and fit.upper == 0.3
    assert fit.lower == pytest.approx(np.sort(x)[9])     # window starts at the 10th value


def test_fit_resamples_packings_when_many_are_pooled():
    rng = np.random.default_rng(3)
    parts = [(rng.random(2000) ** (1 / 0.6), 1000.0) for _ in range(10)]
    sample = PooledSample.concatenate(parts)
    fit = fit_cumulative_power_law(sample, upper=0.1, n_bootstrap=100)
    assert fit.resampling == "packings" and sample.n_groups == 10
    assert fit.slope == pytest.approx(0.6, abs=0.04)
    assert fit.amplitude == pytest.approx(2.0, rel=0.2)   # 2000 values per 1000 normalisation
    assert fit.interval[0] < 0.6 < fit.interval[1]


def test_exponents_from_slopes():
    rng = np.random.default_rng(5)
    gaps_like = PooledSample.from_values(rng.random(40000) ** (1 / (1 - 0.41269)))
    forces_like = PooledSample.from_values(rng.random(40000) ** (1 / 1.42311))
    gamma = exponent_from_sample("gamma", gaps_like, upper=0.1, n_bootstrap=100)
    theta = exponent_from_sample("theta_e", forces_like, upper=0.3, n_bootstrap=100)
    assert gamma.value == pytest.approx(0.41269, abs=0.03)
    assert gamma.interval[0] < gamma.value < gamma.interval[1]
    assert theta.value == pytest.approx(0.42311, abs=0.05)
    assert theta.interval[0] < 0.42311 < theta.interval[1]
    assert abs(theta.deviation) < 0.05 and theta.reference == 0.42311


def test_fit_needs_enough_points():
    with pytest.raises(ValueError, match="sample points"):
        fit_cumulative_power_law(np.linspace(0.5, 1, 100), upper=0.1)
    with pytest.raises(ValueError, match="upper"):
        fit_cumulative_power_law(np.linspace(0.5, 1, 100), upper=0.0)


def test_an_exponent_fitted_on_few_values_carries_a_warning():
    from calippso.analysis.fits import MIN_RELIABLE_POINTS

    rng = np.random.default_rng(3)
    small, large = (exponent_from_sample("theta_l", PooledSample.from_values(
        rng.random(n) ** (1 / 1.17)), n_bootstrap=0) for n in (150, 5000))  # G(f) = f^1.17
    assert small.fit.n_points < MIN_RELIABLE_POINTS <= large.fit.n_points
    assert small.warning.startswith(f"θ_ℓ = {small.value:.3g} rests on only "
                                    f"{small.fit.n_points} values in its fit window")
    assert f"fewer than {MIN_RELIABLE_POINTS}" in small.warning
    assert small.to_dict()["warning"] == small.warning
    assert large.warning is None and large.to_dict()["warning"] is None


@pytest.mark.parametrize("method", ["mle", "lsq"])
def test_both_estimators_recover_the_slope(method):
    rng = np.random.default_rng(11)
    x = rng.random(20000) ** (1.0 / 1.42311)
    fit = fit_cumulative_power_law(x, upper=0.2, method=method, n_bootstrap=100)
    assert fit.method == method
    assert fit.slope == pytest.approx(1.42311, abs=0.06)
    assert fit.interval[0] < 1.42311 < fit.interval[1]


def test_likelihood_fit_ignores_what_lies_below_the_window():
    """A deficit of values below the window biases least squares on log C, not the MLE."""
    rng = np.random.default_rng(2)
    x = rng.random(200000) ** (1.0 / 0.6)
    keep = (x > 1e-3) | (rng.random(x.size) < 0.2)     # 80 % of the values below 1e-3 removed
    sample = PooledSample.from_values(x[keep])
    mle = fit_cumulative_power_law(sample, upper=1e-1, min_count=int((x[keep] <= 1e-3).sum()),
                                   n_bootstrap=50)
    assert mle.lower == pytest.approx(1e-3, rel=0.05)
    assert mle.slope == pytest.approx(0.6, abs=0.02)
    assert mle.interval[0] < 0.6 < mle.interval[1]
    with pytest.raises(ValueError, match="method"):
        fit_cumulative_power_law(sample, upper=0.1, method="chi2")


def _gamma_sample(theta: float, n: int, seed: int) -> np.ndarray:
    """Density ∝ f^θ e^(−(1 + θ) f) (mean 1): a power law only as f → 0."""
    return np.random.default_rng(seed).gamma(1.0 + theta, 1.0 / (1.0 + theta), n)


def test_cutoff_model_recovers_the_exponent_that_a_pure_power_law_misses():
    forces = _gamma_sample(0.42311, 100000, seed=3)
    pure = fit_cumulative_power_law(forces, upper=0.3, model="power_law", n_bootstrap=0)
    cutoff = fit_cumulative_power_law(forces, upper=0.3, model="cutoff", n_bootstrap=100)
    assert pure.slope < 1.42311 - 0.1                      # the drift of the pure law
    assert cutoff.slope == pytest.approx(1.42311, abs=0.05)
    assert cutoff.interval[0] < 1.42311 < cutoff.interval[1]
    assert 0.5 < cutoff.cutoff < 3.0          # λ of the gamma density is 1.42, loosely fixed
    auto = fit_cumulative_power_law(forces, upper=0.3, n_bootstrap=0)
    assert auto.model == "cutoff" and auto.p_value < 1e-6
    assert auto.slope == cutoff.slope
    # the fitted cumulative follows the empirical one across the window
    x, c = PooledSample.from_values(forces).cumulative()
    for point in (0.03, 0.1, 0.3):
        k = np.searchsorted(x, point)
        assert auto(np.array([x[k]]))[0] == pytest.approx(c[k], rel=0.03)


def test_likelihoods_of_the_two_models_agree_where_they_coincide():
    """The closed-form pure power law equals the cut-off model's quadrature at λ = 0."""
    from scipy.integrate import quad

    from calippso.analysis.fits import _cutoff_mle, _power_law_loglik, window_mle

    x = np.sort(np.random.default_rng(9).random(5000) ** (1.0 / 1.42311))
    a, b = float(x[9]), 0.3
    inside = x[9:][x[9:] <= b]
    mean_log, la, span = float(np.mean(np.log(inside))), np.log(a), np.log(b / a)
    alpha = window_mle(inside, a, b)
    norm = quad(lambda t: t ** (alpha - 1.0), a, b, epsabs=0, epsrel=1e-12)[0]
    direct = (alpha - 1.0) * mean_log - np.log(norm)
    assert _power_law_loglik(mean_log, alpha, la, span) == pytest.approx(direct, abs=1e-6)
    _, _, best = _cutoff_mle(mean_log, float(np.mean(inside)), a, b, start=alpha)
    assert best >= _power_law_loglik(mean_log, alpha, la, span) - 1e-12   # nested models
    # continuous through α = 0, where the closed form switches to its expansion
    for tiny in (1e-9, -1e-9):
        assert _power_law_loglik(mean_log, tiny, la, span) == pytest.approx(
            _power_law_loglik(mean_log, 1e-5 * np.sign(tiny), la, span), abs=1e-4)


def test_auto_model_keeps_a_pure_power_law():
    rng = np.random.default_rng(8)
    x = rng.random(40000) ** (1.0 / 1.42311)
    fit = fit_cumulative_power_law(x, upper=0.3, n_bootstrap=0)
    assert fit.model == "power_law" and fit.cutoff == 0.0 and fit.p_value > 0.05
    both = fit_cumulative_power_law(x, upper=0.3, model="cutoff", n_bootstrap=0)
    assert both.slope == pytest.approx(1.42311, abs=0.1)
    assert abs(both.cutoff * 0.3) < 1.0                   # λ b compatible with 0


def test_bad_model_is_named():
    x = np.random.default_rng(0).random(1000)
    with pytest.raises(ValueError, match="model must be one of"):
        fit_cumulative_power_law(x, upper=0.5, model="exponential")
    with pytest.raises(ValueError, match="needs method"):
        fit_cumulative_power_law(x, upper=0.5, model="cutoff", method="lsq")
    assert fit_cumulative_power_law(x, upper=0.5, method="lsq",
                                    n_bootstrap=0).model == "power_law"


def test_fit_models_by_exponent():
    assert resolve_models(None) == MODEL
    assert MODEL["gamma"] == "power_law" and MODEL["theta_e"] == "auto"
    assert set(resolve_models("cutoff").values()) == {"cutoff"}
    assert resolve_models({"gamma": "auto"}) == {**MODEL, "gamma": "auto"}
    with pytest.raises(ValueError, match="model must be one of"):
        resolve_models("exponential")
    with pytest.raises(ValueError, match="unknown exponent"):
        resolve_models({"theta_x": "auto"})


def test_window_scan_is_flat_on_a_pure_power_law():
    rng = np.random.default_rng(4)
    sample = PooledSample.from_values(rng.random(100000) ** (1.0 / 1.42311))
    rows = window_scan("theta_e", sample, upper=0.1)
    assert [row["upper"] for row in rows] == sorted(row["upper"] for row in rows)
    assert rows[-1]["upper"] == pytest.approx(1.0)
    big = [row for row in rows if row["points"] > 2000]
    assert len(big) >= 5
    for row in big:
        assert row["power_law"] == pytest.approx(0.42311, abs=0.05)
        assert row["cutoff"] == pytest.approx(0.42311, abs=0.08)
        assert 0 <= row["p_value"] <= 1
    assert all(row["upper"] <= 0.05 * 1.0001 for row in window_scan("gamma", sample,
                                                                    largest=0.05))


# --- everything at once ------------------------------------------------------------------------

def test_analyze_one_packing(jammed):
    analysis = analyze(jammed, n_bootstrap=50)
    summary = json.loads(json.dumps(analysis.to_dict()))
    assert summary["d"] == 3 and summary["packings"] == 1
    assert summary["isostatic_packings"] == 1
    assert summary["bucklers"] == int(bucklers(jammed).sum())
    assert summary["localized_forces"] + summary["extended_forces"] == jammed.n_contacts
    assert set(summary["exponents"]) | set(summary["exponent_errors"]) == {
        "gamma", "theta_e", "theta_l", "theta"}
    for e in analysis.exponents.values():
        assert e.interval[0] <= e.value <= e.interval[1]
    for name, e in summary["exponents"].items():
        assert e["model"] in ("power_law", "cutoff")
        assert MODEL[name] == "auto" or e["model"] == MODEL[name]
        assert e["model"] == "power_law" or e["power_law_p_value"] < 0.05
    least_squares = analyze(jammed, method="lsq", n_bootstrap=0)
    assert all(e.fit.model == "power_law" for e in least_squares.exponents.values())


def test_theta_is_fitted_on_all_forces(jammed):
    """θ uses every contact force, extended and localised together, whatever the rule."""
    analysis = analyze(jammed, n_bootstrap=20)
    assert "theta" in analysis.exponents, analysis.exponent_errors.get("theta")
    fit = analysis.exponents["theta"].fit
    forces = analysis.forces["all"].values
    assert len(forces) == jammed.n_contacts
    assert fit.n_points == np.count_nonzero((forces >= fit.lower) & (forces <= fit.upper))
    assert analysis.exponents["theta"].value == pytest.approx(fit.slope - 1.0)
    weakest = analyze(jammed, rule="weakest", n_bootstrap=20).exponents["theta"]
    assert weakest.value == pytest.approx(analysis.exponents["theta"].value, abs=1e-12)
