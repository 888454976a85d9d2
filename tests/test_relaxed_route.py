"""The relaxed route: a configuration relaxed as soft spheres in its own box
(`generators.relax`), then jammed from its overlap network (`jam(route="relaxed")`).

Inputs are LS states compressed at a constant rate to p = 1e5, which are not jamming points.
Every relaxed result is certified (positive forces, no overlap, isostatic, balance 1e-12),
keeps the input's box, boundaries and diameter ratios, and says how far it lies from the
input."""

from __future__ import annotations

import numpy as np
import pytest

import calippso
import generators
from calippso import Boundaries, JammingError
from calippso.geometry.periodic import displacements
from calippso.routes import DEFAULT_MAX_DISPLACEMENT, lp_route_slow
from generators import diameters as dist
from generators.soft_quench import PAUSE_STEPS

from conftest import assert_jammed
from test_cylinder import assert_jammed_in_a_cylinder
from test_walls import assert_jammed_between_walls

#: Reduced pressure of the constant-rate LS inputs.
LS_PRESSURE = 1e5


def ls_state(sizes: np.ndarray, d: int, seed: int,
             boundaries: Boundaries | None = None) -> calippso.Packing:
    """An LS state compressed at the default constant rate to `LS_PRESSURE`."""
    return generators.lubachevsky_stillinger(sizes, d, target_pressure=LS_PRESSURE, seed=seed,
                                             boundaries=boundaries).packing


@pytest.fixture(scope="module")
def spheres(computed_once) -> calippso.Packing:
    """Equal spheres, N = 256, d = 3."""
    return computed_once("relaxed_route_spheres",
                         lambda: ls_state(dist.monodisperse(256), 3, seed=1))


@pytest.fixture(scope="module")
def relaxed_route(spheres, computed_once) -> calippso.JammingResult:
    """`spheres` jammed by the relaxed route."""
    return computed_once("relaxed_route_result",
                         lambda: calippso.jam(spheres, route="relaxed"))


def assert_same_container(result: calippso.JammingResult, start: calippso.Packing) -> None:
    """The box and boundaries of `start`, its diameters times one factor."""
    packing = result.packing
    np.testing.assert_array_equal(packing.box, start.box)
    assert packing.boundaries == start.boundaries
    ratio = packing.diameters / start.diameters
    assert np.ptp(ratio) <= 1e-14 * ratio.mean()


def assert_distance_recorded(result: calippso.JammingResult, start: calippso.Packing,
                             route: str) -> None:
    """The route and the distance from `start`, recomputed from the two geometries."""
    assert result.route == route
    lengths, _ = displacements(start.positions, result.packing.positions, start.box,
                               start.periodic)
    lengths /= start.mean_diameter
    assert result.displacement_max == pytest.approx(lengths.max(), rel=1e-12)
    assert result.displacement_median == pytest.approx(np.median(lengths), rel=1e-12)
    assert result.phi_input == pytest.approx(start.phi, rel=1e-15)
    assert result.phi_change == pytest.approx(result.phi - start.phi, abs=1e-15)


def test_relax_keeps_the_container_and_its_network_is_certified(spheres):
    relaxed = generators.relax(spheres)
    assert_same_container(relaxed, spheres)
    assert 0 < relaxed.extra["median_displacement"] <= relaxed.extra["max_displacement"] \
        < DEFAULT_MAX_DISPLACEMENT
    result = calippso.jam(relaxed.packing, network=relaxed.contacts, network_first="require")
    assert_jammed(result)
    assert result.iterations == 0


def test_the_relaxed_route_is_certified_and_says_how_far_it_moved(spheres, relaxed_route):
    result = relaxed_route
    assert_jammed(result)
    assert_same_container(result, spheres)
    assert_distance_recorded(result, spheres, "relaxed")
    assert 0 < result.displacement_median < result.displacement_max < DEFAULT_MAX_DISPLACEMENT
    assert result.phi_change > 0
    assert "Relaxed route" in result.status and "from the input" in result.status
    assert result.iterations == 0


def test_the_route_is_saved_and_loaded(relaxed_route, tmp_path):
    result = relaxed_route
    back = calippso.load_result(result.save(tmp_path / "relaxed"))
    assert back.route == "relaxed"
    for name in ("phi_input", "displacement_max", "displacement_median"):
        assert getattr(back, name) == getattr(result, name)


def test_the_lp_route_is_todays_loop(spheres):
    plain = calippso.jam(spheres, network_first="off", max_iters=2)
    explicit = calippso.jam(spheres, route="lp", network_first="off", max_iters=2)
    np.testing.assert_array_equal(plain.packing.positions, explicit.packing.positions)
    assert plain.phi == explicit.phi and plain.status == explicit.status
    assert_distance_recorded(explicit, spheres, "lp")


def test_auto_keeps_a_small_input_on_the_lp_route(spheres):
    assert lp_route_slow(spheres) is None
    result = calippso.jam(spheres, route="auto", network_first="off", max_iters=1)
    assert result.route == "lp" and not any("route" in note for note in result.notes)


def test_a_relaxation_that_moves_too_far_stops_at_once(spheres):
    relaxed = generators.relax(spheres, max_displacement=1e-4)
    assert relaxed.extra["halted"] and relaxed.extra["max_displacement"] > 1e-4
    # stopped at the first pause of the first of its four minimisations
    assert len(relaxed.history) == 1 and len(relaxed.extra["rungs"]) == 4
    assert relaxed.steps <= PAUSE_STEPS
    assert f"particle {relaxed.extra['farthest']} lies" in relaxed.status


def test_a_route_that_moves_too_far_is_refused_before_the_ladder_ends(spheres):
    with pytest.raises(JammingError, match=r"more than max_displacement = 0\.0001 \(the "
                       r"relaxation stopped there, at pressure 1e-04, rung 1 of 4\)") as caught:
        calippso.jam(spheres, route="relaxed", max_displacement=1e-4)
    assert "\n" not in str(caught.value)


def test_a_stopped_relaxation_continues_from_its_checkpoint(spheres, tmp_path):
    path = tmp_path / "relax.npz"
    assert generators.relax(spheres, checkpoint=path, max_displacement=1e-4).extra["halted"]
    resumed = generators.relax(spheres, checkpoint=path)
    whole = generators.relax(spheres)
    assert resumed.extra["resumed"] and not resumed.extra["halted"]
    np.testing.assert_array_equal(resumed.packing.positions, whole.packing.positions)
    np.testing.assert_array_equal(resumed.packing.diameters, whole.packing.diameters)


@pytest.mark.parametrize("route, options, message", [
    ("fast", {}, "unknown route 'fast'"),
    ("relaxed", {"max_displacement": 0.0}, "max_displacement must be > 0"),
    ("relaxed", {"network": np.array([[0, 1]])}, "makes its own contact network"),
])
def test_bad_route_options_are_named(spheres, route, options, message):
    with pytest.raises(ValueError, match=message):
        calippso.jam(spheres, route=route, **options)


def test_the_ladder_goes_down_in_equal_factors_no_smaller_than_asked(spheres):
    from generators.relax import pressure_ladder

    ladder = pressure_ladder(1e-4, 5e-8, 0.01)         # 2000 = 100^1.65: two factors
    np.testing.assert_allclose(ladder, [1e-4, np.sqrt(1e-4 * 5e-8), 5e-8], rtol=1e-12)
    assert pressure_ladder(1e-4, 5e-7, 0.1).size == 4  # the quench's factor: three
    np.testing.assert_array_equal(pressure_ladder(1e-6, 1e-5, 0.01), [1e-5])
    with pytest.raises(ValueError, match="pressure_reduction must lie in"):
        generators.relax(spheres, pressure_reduction=1.0)


@pytest.mark.parametrize("d, sizes", [
    (2, dist.bidisperse(256, 1.4)),     # 1:1.4 discs do not crystallise
    pytest.param(5, dist.monodisperse(256), marks=pytest.mark.slow),    # ~30 s
])
def test_discs_and_five_dimensions(d, sizes):
    start = ls_state(sizes, d, seed=2)
    result = calippso.jam(start, route="relaxed")
    assert_jammed(result)
    assert_same_container(result, start)
    assert_distance_recorded(result, start, "relaxed")


def test_between_walls_and_in_a_cylinder():
    for d, boundaries, check in (
            (2, Boundaries.walls(2, ["x"]), assert_jammed_between_walls),
            (3, Boundaries.cylinder(3, ["x", "y"]), assert_jammed_in_a_cylinder)):
        sizes = dist.bidisperse(128, 1.4) if d == 2 else dist.monodisperse(128)
        start = ls_state(sizes, d, seed=3, boundaries=boundaries)
        result = calippso.jam(start, route="relaxed")
        check(result)
        assert_same_container(result, start)
        assert_distance_recorded(result, start, "relaxed")


def test_the_cli_takes_a_route(spheres, tmp_path):
    from calippso.cli import main

    source, output = tmp_path / "ls.npz", tmp_path / "jammed.npz"
    calippso.write(spheres, source)
    assert main(["jam", str(source), "-o", str(output), "--route", "relaxed",
                 "--max-displacement", "0.1"]) == 0
    result = calippso.load_result(output)
    assert result.route == "relaxed" and result.converged
    assert result.displacement_max < 0.1


def test_auto_predicts_a_slow_lp_route_from_the_gaps():
    """From N = 1024 on: a crystal at contact has all its gaps at round-off (LP route); the
    same crystal with gaps holds no rigid network near contact (relaxed route)."""
    from lattices import fcc

    assert fcc(7).n >= 1024                   # 4 × 7³ = 1372 spheres
    assert lp_route_slow(fcc(7)) is None
    assert "hypostatic" in lp_route_slow(fcc(7, fill=0.99))
