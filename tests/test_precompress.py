"""`calippso.protocols.precompress`: LS compression of a loose input, before `jam`."""

import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from configurations import random_sequential_addition

from calippso import Packing, jam
from calippso.geometry.neighbors import NeighborSearch
from calippso.protocols import precompress, precompress_checkpoint, precompress_note


@pytest.fixture(scope="module")
def loose_bidisperse():
    """A loose (φ = 0.3) bidisperse start in d = 3: far below jamming."""
    sizes = np.where(np.arange(96) % 2 == 0, 1.0, 1.4)
    return random_sequential_addition(96, 3, 0.3, seed=4, diameters=sizes)


@pytest.fixture(scope="module")
def compressed(loose_bidisperse):
    return precompress(loose_bidisperse, 1e5)


@pytest.fixture(scope="module")
def precompressed(compressed):
    return jam(compressed.packing)


def test_precompressed_jam_is_a_certified_jammed_packing(loose_bidisperse, precompressed):
    result = precompressed
    assert result.converged and result.isostatic and result.force_balance < 1e-12
    jammed = result.packing
    search = NeighborSearch(jammed.positions, jammed.diameters, jammed.box)
    close = search.pairs_within(float(jammed.diameters.max()) * 1.01)
    assert close.gaps.min() > -1e-12          # no overlap, relative to the contact diameter
    assert jammed.phi > 0.6 > 2 * loose_bidisperse.phi / 1.5


def test_precompression_keeps_particles_box_and_size_ratios(loose_bidisperse, precompressed):
    jammed = precompressed.packing
    assert jammed.n == loose_bidisperse.n
    np.testing.assert_allclose(jammed.box, loose_bidisperse.box, rtol=1e-14)
    ratio = jammed.diameters / loose_bidisperse.diameters
    np.testing.assert_allclose(ratio, ratio[0], rtol=1e-12)


def test_the_note_says_the_input_was_compressed(loose_bidisperse, compressed):
    assert compressed.reduced_pressure >= 1e5
    note = precompress_note(loose_bidisperse, compressed)
    assert "compressed by Lubachevsky-Stillinger" in note
    assert f"phi {loose_bidisperse.phi:.6f} -> {compressed.packing.phi:.6f}" in note


def test_overlapping_input_is_refused_before_compression():
    start = random_sequential_addition(32, 3, 0.2, seed=9)
    positions = start.positions.copy()
    positions[1] = positions[0] + np.array([0.5, 0.0, 0.0])
    with pytest.raises(ValueError, match="overlapping particles"):
        precompress(Packing(positions, start.diameters, start.box), 1e5)
    positions[1] = positions[0]
    with pytest.raises(ValueError, match="duplicated particles in the input: particles 0 and 1"):
        precompress(Packing(positions, start.diameters, start.box), 1e5)


@pytest.mark.parametrize("pressure", [0.0, -1e5, float("nan")])
def test_bad_pressure_is_refused(pressure):
    start = random_sequential_addition(16, 2, 0.2, seed=1)
    with pytest.raises(ValueError, match="pressure must be a finite number > 0"):
        precompress(start, pressure)


def test_checkpointed_run_resumes_both_stages(tmp_path):
    start = random_sequential_addition(48, 2, 0.3, seed=2,
                                       diameters=np.where(np.arange(48) < 24, 1.0, 1.4))
    state = tmp_path / "run.npz"

    def run():
        compressed = precompress(start, 1e5, checkpoint=precompress_checkpoint(state))
        return jam(compressed.packing, checkpoint=state)

    first = run()
    assert state.exists() and precompress_checkpoint(state) == tmp_path / "run.precompress.npz"
    assert precompress_checkpoint(state).exists()
    again = run()
    np.testing.assert_array_equal(first.packing.positions, again.packing.positions)
    np.testing.assert_array_equal(first.contacts, again.contacts)
    assert first.converged and first.isostatic


def test_plain_jam_does_not_load_the_generators():
    code = ("import calippso, sys; from configurations import random_sequential_addition; "
            "calippso.jam(random_sequential_addition(16, 2, 0.5, seed=0)); "
            "print('numba' in sys.modules, 'generators' in sys.modules)")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                         check=True, cwd=Path(__file__).parent).stdout
    assert out.split()[-2:] == ["False", "False"]
