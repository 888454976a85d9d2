import numpy as np
import pytest

from calippso import Packing
from calippso.geometry.packing import ball_volume, minimum_image, wrap


def test_phi_of_known_configuration():
    packing = Packing(np.zeros((1, 3)) + 0.5, [1.0], [4.0, 4.0, 4.0])
    assert packing.phi == pytest.approx(np.pi / 6 / 64)
    assert packing.n == 1 and packing.d == 3


@pytest.mark.parametrize("d, expected", [(2, np.pi), (3, 4 * np.pi / 3), (4, np.pi**2 / 2),
                                         (5, 8 * np.pi**2 / 15)])
def test_ball_volume_unit_radius(d, expected):
    assert ball_volume(d, 1.0) == pytest.approx(expected, rel=1e-14)


def test_wrap_never_returns_box_side():
    box = np.array([1.0, 1.0])
    wrapped = wrap(np.array([[-1e-18, 0.3], [1.0, 2.5]]), box)
    assert np.all(wrapped >= 0) and np.all(wrapped < box)


def test_minimum_image_rectangular():
    box = np.array([2.0, 5.0])
    delta = minimum_image(np.array([[1.9, -4.0]]), box)
    np.testing.assert_allclose(delta, [[-0.1, 1.0]])


def test_scalar_box_means_cubic():
    packing = Packing(np.zeros((2, 4)), [0.1, 0.2], 3.0)
    np.testing.assert_array_equal(packing.box, [3.0] * 4)


def test_scaled_to_phi():
    rng = np.random.default_rng(0)
    packing = Packing(rng.random((20, 3)) * 10, rng.random(20) + 0.5, 10.0).scaled_to_phi(0.3)
    assert packing.phi == pytest.approx(0.3, rel=1e-13)


@pytest.mark.parametrize(
    "positions, diameters, box, message",
    [
        (np.zeros((3, 3)), np.ones(2), 10.0, "diameters has 2 entries"),
        (np.zeros(3), np.ones(3), 10.0, "shape"),
        (np.zeros((3, 1)), np.ones(3), 10.0, "at least 2"),
        (np.full((3, 3), np.nan), np.ones(3), 10.0, "non-finite"),
        (np.zeros((3, 3)), [1.0, -1.0, 1.0], 10.0, "> 0"),
        (np.zeros((3, 3)), np.ones(3), [10.0, 0.0, 10.0], "box sides must be > 0"),
        (np.zeros((3, 3)), np.ones(3), [10.0, 10.0], "box has 2 sides"),
        (np.zeros((3, 3)), [1.0, 6.0, 1.0], 10.0, "box too small"),
        (np.zeros((0, 3)), np.ones(0), 10.0, "empty"),
        (np.zeros((3, 3)), ["a", "b", "c"], 10.0, "numeric"),
    ],
)
def test_invalid_input_names_the_problem(positions, diameters, box, message):
    with pytest.raises(ValueError, match=message):
        Packing(positions, diameters, box)


def test_arrays_are_read_only():
    packing = Packing(np.zeros((2, 2)), np.ones(2) * 0.1, 1.0)
    with pytest.raises(ValueError):
        packing.positions[0, 0] = 1.0
