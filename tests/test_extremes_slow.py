"""The extreme matrix, slow part (run with ``pytest -m slow tests/test_extremes_slow.py``).

Real p = 1e12 packings from ../shared/data (case 1), larger random starts far from jamming
in d = 3, 4, 5 (case 2), a small d = 5 box whose default cutoff would
exceed half the box (case 5), LS p = 1e12 inputs in d = 4, 5, and the N = 10000 input with
round-off overlaps (case 7), as docs/stability.md lists them. Every backend on
the slow inputs (case 9): tests/test_backends.py.
"""

from __future__ import annotations

import pytest

import calippso
from calippso import jam, protocols
from calippso.geometry.neighbors import min_gap

from configurations import ls_packing, phi_j, random_sequential_addition
from conftest import assert_jammed

pytestmark = pytest.mark.slow


def test_packing_generation_p1e12_folder(shared_data):
    start = calippso.read(shared_data / "mono_N1000_fba1e-3_then_ls1e-2_seed11")
    result = jam(start)
    assert_jammed(result)
    assert result.phi >= start.phi


def test_polydisperse_p1e12_folder(shared_data):
    start = calippso.read(shared_data / "lognormal0.2_N1000_fba1e-3_then_ls1e-2_seed13")
    result = jam(start)
    assert_jammed(result)


def test_roundoff_overlaps_in_a_real_n10000_input(shared_data):
    start = calippso.read(shared_data / "mono_N10000_fba1e-3_then_ls1e-2_seed21")
    gap, overlapping = min_gap(start.positions, start.diameters, start.box)
    assert overlapping > 0 and gap > -1e-13
    result = jam(start)
    assert_jammed(result)


@pytest.mark.parametrize("d, n", [(3, 512), (4, 256), (5, 128)])
def test_far_from_jamming_larger(d, n):
    start = random_sequential_addition(n, d, 0.3 * phi_j(d), seed=10 + d)
    result = jam(start)
    assert_jammed(result)
    assert 0.9 * phi_j(d) < result.phi < 1.05 * phi_j(d)


def test_small_box_in_five_dimensions():
    """d = 5, N = 256: the box side (~2.7 σ at jamming) is below twice the reference cutoff
    4R = 2σ, so pairs must come from the step bound, not from a fixed cutoff."""
    start = random_sequential_addition(256, 5, 0.3 * phi_j(5), seed=5)
    result = jam(start)
    assert_jammed(result)
    sigma = result.packing.diameters.max()
    assert 2 * sigma > 0.5 * result.packing.box.min()   # the reference cutoff would not fit


@pytest.mark.parametrize("d, n", [(4, 256), (5, 256)])
def test_ls_p1e12_in_high_dimension(d, n):
    start = ls_packing(n, d, seed=d)
    result = jam(start)
    assert_jammed(result)
    assert result.phi >= start.phi


def test_ls_state_whose_bound_held_particles_back():
    """LS at p = 1e5 from Poisson points (N = 1000, seed 3; the generator validation's
    hardest start). The loop once ran 1000 LPs on it without converging, and with
    step_margin=2 stalled at the smallest bound, where spheres with d or fewer contacts were
    pressed against it. Measured since the bound is kept while it limits Gamma: 52 LPs."""
    import generators

    points = generators.poisson(generators.diameters.monodisperse(1000), 3, phi=0.3, seed=3)
    gap, _ = min_gap(points.positions, points.diameters, points.box)
    start = calippso.Packing(points.positions, points.diameters * (1 + gap) * (1 - 1e-9),
                             points.box)
    result = jam(protocols.precompress(start, 1e5).packing, max_iters=200)
    assert_jammed(result)
    assert 0.64 < result.phi < 0.647
