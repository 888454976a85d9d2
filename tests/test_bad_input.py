"""Bad input: every kind gives an error that names the problem (API, readers, generators, CLI).

Each case is one parametrised test: the call, the exception type and a regular expression
that the message must match (the words a user needs to fix the input).
"""

from __future__ import annotations

from pathlib import Path

import itertools

import numpy as np
import pytest

import calippso
import generators
from calippso import Packing, jam

from configurations import random_sequential_addition

GOOD = random_sequential_addition(16, 3, 0.2, seed=1)
POS, DIAM, BOX = GOOD.positions, GOOD.diameters, GOOD.box


def _with(array: np.ndarray, index, value) -> np.ndarray:
    out = np.array(array, dtype=float)
    out[index] = value
    return out


def _duplicated() -> np.ndarray:
    positions = POS.copy()
    positions[5] = positions[2]
    return positions


def _duplicated_by_a_period() -> np.ndarray:
    positions = POS.copy()
    positions[5] = positions[2] + BOX  # the same point one period away
    return positions


#: (id, arguments of Packing / jam, exception, message pattern)
ARRAY_CASES = [
    ("nan-position", (_with(POS, (0, 1), np.nan), DIAM, BOX), ValueError, r"positions contains 1 non-finite"),
    ("inf-position", (_with(POS, (3, 0), np.inf), DIAM, BOX), ValueError, r"positions contains 1 non-finite"),
    ("nan-diameter", (POS, _with(DIAM, 2, np.nan), BOX), ValueError, r"diameters contains 1 non-finite"),
    ("inf-box", (POS, DIAM, _with(BOX, 1, np.inf)), ValueError, r"box contains 1 non-finite"),
    ("positions-1d", (POS[:, 0], DIAM, BOX), ValueError, r"positions must have shape \(N, d\)"),
    ("positions-3d", (POS[None], DIAM, BOX), ValueError, r"positions must have shape \(N, d\)"),
    ("diameters-2d", (POS, DIAM[:, None], BOX), ValueError, r"diameters must have shape a 1-d array"),
    ("dimension-1", (POS[:, :1], DIAM, BOX[0]), ValueError, r"dimension d must be at least 2, got d = 1"),
    ("zero-diameter", (POS, _with(DIAM, 4, 0.0), BOX), ValueError, r"diameters must be > 0"),
    ("negative-diameter", (POS, _with(DIAM, 4, -1.0), BOX), ValueError, r"diameters must be > 0.*smallest -1"),
    ("zero-box", (POS, DIAM, _with(BOX, 0, 0.0)), ValueError, r"box sides must be > 0"),
    ("negative-box", (POS, DIAM, -BOX), ValueError, r"box sides must be > 0"),
    ("particle-wider-than-half-box", (POS, _with(DIAM, 0, 0.6 * BOX[0]), BOX), ValueError,
     r"box too small: the largest diameter .* half the smallest box side"),
    ("empty", (np.zeros((0, 3)), np.zeros(0), BOX), ValueError, r"the packing is empty"),
    ("mismatched-lengths", (POS, DIAM[:-1], BOX), ValueError, r"diameters has 15 entries but positions has 16"),
    ("box-sides-vs-dimension", (POS, DIAM, BOX[:2]), ValueError, r"box has 2 sides but positions are 3-dimensional"),
    ("non-numeric-array", ([["a", "b", "c"]] * 16, DIAM, BOX), ValueError, r"positions must be numeric"),
]


@pytest.mark.parametrize("args, error, pattern", [c[1:] for c in ARRAY_CASES],
                         ids=[c[0] for c in ARRAY_CASES])
def test_packing_refuses(args, error, pattern):
    with pytest.raises(error, match=pattern):
        Packing(*args)


@pytest.mark.parametrize("args, error, pattern", [c[1:] for c in ARRAY_CASES],
                         ids=[c[0] for c in ARRAY_CASES])
def test_jam_refuses_before_any_lp(args, error, pattern):
    with pytest.raises(error, match=pattern):
        jam(*args)


def _overlapping(amount: float) -> Packing:
    """Eight unit spheres on a cubic grid of spacing 2 in a box of side 4, with sphere 1 moved
    next to sphere 0 so that they overlap by `amount` σ (the only overlap)."""
    positions = np.array(list(itertools.product([1.0, 3.0], repeat=3)))
    positions[1] = [2.0 - amount, 1.0, 1.0]
    return Packing(positions, np.ones(8), np.full(3, 4.0))


DUPLICATE = r"duplicated particles in the input: particles 2 and 5 sit at the same position"


@pytest.mark.parametrize("call, error, pattern", [
    (lambda: jam(_overlapping(1e-3)), ValueError,
     r"overlapping particles in the input: 1 pair\(s\) overlap beyond round-off \(h < -1e-10\), "
     r"the worst is \(0, 1\) with gap h = .*-1\.000e-03; shrink every diameter"),
    (lambda: jam(_duplicated(), DIAM, BOX), ValueError, DUPLICATE),
    (lambda: jam(_duplicated_by_a_period(), DIAM, BOX), ValueError, DUPLICATE),
    (lambda: jam(GOOD, solver="gurobi"), ValueError, r"unknown solver 'gurobi': choose one of highs, clarabel, cvxpy"),
    (lambda: jam(GOOD, tol_gammma=1e-9), TypeError, r"unknown jam option\(s\) \['tol_gammma'\]"),
    (lambda: jam(GOOD, precompress_pressure=1e5), TypeError,
     r"precompress_pressure option was removed: call calippso\.protocols\.precompress"),
    (lambda: jam(GOOD, max_iters=0), ValueError, r"max_iters must be a positive integer"),
    (lambda: jam(GOOD, tol_gamma=-1.0), ValueError, r"tol_gamma must be > 0"),
    (lambda: jam(GOOD, GOOD.diameters, GOOD.box), TypeError, r"either a Packing, or positions"),
    (lambda: jam(GOOD.positions), TypeError, r"diameters and box are required"),
], ids=["real-overlap", "duplicated-particles", "duplicated-one-period-away", "unknown-solver", "unknown-option", "removed-option", "max-iters-zero", "negative-tolerance",
        "packing-and-arrays", "positions-only"])
def test_jam_refuses_bad_arguments(call, error, pattern):
    with pytest.raises(error, match=pattern):
        call()


# ----------------------------------------------------------------------------- files

SKOGE_HEADER = "3\n4 1\n4\n0.5\n3 0 0 0 3 0 0 0 3\nT T T\n"


def _write(tmp: Path, name: str, content: str | bytes) -> Path:
    path = tmp / name
    if isinstance(content, bytes):
        path.write_bytes(content)
    else:
        path.write_text(content)
    return path


FILE_CASES = [
    ("missing-file", "absent.dat", None, FileNotFoundError, r"no such file"),
    ("unknown-format", "packing.foo", "1 2 3\n", ValueError, r"unknown file format '.foo'"),
    ("empty-file", "empty.dat", "", ValueError, r"too short for Skoge-Donev"),
    ("non-numeric-dimension", "word.dat", "three\n4 1\n4\n0.5\n", ValueError, r"line 1: expected the dimension"),
    ("dimension-1-file", "d1.dat", "1\n4 1\n4\n0.5\n", ValueError, r"line 1: expected the dimension \(an integer ≥ 2\)"),
    ("non-numeric-header", "hdr.dat", "3\nfour 1\n4\n0.5\n", ValueError, r"line 2: expected numbers"),
    ("non-numeric-coordinates", "coords.dat",
     SKOGE_HEADER + "0 0 0\n1 1 1\n2 x 2\n0.5 2.5 1\n", ValueError, r"non-numeric coordinates"),
    ("truncated-file", "short.dat", SKOGE_HEADER + "0 0 0\n1 1 1\n", ValueError,
     r"truncated, 2 coordinate lines where N = 4"),
    ("short-coordinate-line", "cols.dat", SKOGE_HEADER + "0 0 0\n1 1\n2 2 2\n0.5 2.5 1\n",
     ValueError, r"every coordinate line needs 3 numbers"),
    ("species-mismatch", "species.dat", "3\n4 1\n3\n0.5\n3 0 0 0 3 0 0 0 3\nT T T\n", ValueError,
     r"species counts \[3\] .* do not match N = 4"),
    ("sheared-box", "shear.dat", "3\n4 1\n4\n0.5\n3 0.1 0 0 3 0 0 0 3\nT T T\n", ValueError,
     r"only rectangular \(diagonal\) boxes"),
    ("binary-as-text", "binary.dat", bytes(range(256)) * 4, ValueError, r"not a text file"),
    ("nan-in-file", "nan.dat", SKOGE_HEADER + "0 0 0\n1 1 1\nnan 2 2\n0.5 2.5 1\n", ValueError,
     r"positions contains 1 non-finite"),
    ("negative-diameter-file", "neg.dat", "3\n4 1\n4\n-0.5\n3 0 0 0 3 0 0 0 3\nT T T\n"
     "0 0 0\n1 1 1\n2 2 2\n0.5 2.5 1\n", ValueError, r"diameters must be > 0"),
    ("garbage-npz", "garbage.npz", b"PK\x03\x04 this is not a zip archive", ValueError, r"unreadable \.npz"),
    ("truncated-xyzd", "packing.xyzd", b"\x00" * 40, ValueError, r"not a whole number of \(x, y, z, d\) records"),
]


@pytest.mark.parametrize("name, content, error, pattern", [c[1:] for c in FILE_CASES],
                         ids=[c[0] for c in FILE_CASES])
def test_read_refuses(tmp_path, name, content, error, pattern):
    path = tmp_path / name if content is None else _write(tmp_path, name, content)
    if name.endswith(".xyzd"):
        _write(tmp_path, "generation.conf", "Particles count: 1\nPacking size: 3 3 3\n")
        _write(tmp_path, "packing.nfo", "Theoretical Porosity: 0.5\nFinal Porosity: 0.5\n")
    with pytest.raises(error, match=pattern):
        calippso.read(path)


def _packing_generation_folder(tmp: Path, boundaries_line: str) -> Path:
    """GOOD written as a PackingGeneration folder, `boundaries_line` in place of its conf's
    own "Boundaries mode: 1"."""
    folder = tmp / "pg"
    calippso.write(GOOD, folder / "packing.xyzd")
    conf = folder / "generation.conf"
    conf.write_text(conf.read_text().replace("Boundaries mode: 1", boundaries_line))
    return folder


@pytest.mark.parametrize("line, pattern", [
    ("Boundaries mode: 4", r"boundaries mode 4 \(periodic in z inside a trapezoid in xy\) is "
                           r"not supported; calippso reads periodic packings \(mode 1\), "
                           r"cylinders \(mode 2\) and rectangles \(mode 3\)$"),
    ("Boundaries mode: 7", r"unknown boundaries mode 7; PackingGeneration's modes are 1, 2, 3, "
                           r"4$"),
    ("Boundaries mode: cylinder", r"'Boundaries mode:' is not an integer: 'cylinder'$"),
], ids=["trapezoid", "unknown-mode", "non-numeric-mode"])
def test_packing_generation_containers_are_refused(tmp_path, line, pattern):
    """A container packing is never read as a periodic one: one line naming the file."""
    folder = _packing_generation_folder(tmp_path, line)
    with pytest.raises(ValueError, match=pattern) as refused:
        calippso.read(folder)
    message = str(refused.value)
    assert message.startswith(f"{folder / 'generation.conf'}: ") and "\n" not in message


def test_packing_generation_periodic_mode_is_read(tmp_path):
    """Mode 1, as in PackingGeneration's own files, reads as the file without the line."""
    packing = calippso.read(_packing_generation_folder(tmp_path, "Boundaries mode: 1"))
    np.testing.assert_array_equal(packing.box, GOOD.box)
    np.testing.assert_allclose(packing.positions, GOOD.wrapped().positions, rtol=0, atol=0)
    np.testing.assert_allclose(packing.diameters, GOOD.diameters, rtol=1e-15)


def test_npz_without_packing_keys_is_refused(tmp_path):
    path = tmp_path / "other.npz"
    np.savez(path, weights=np.ones(3))
    with pytest.raises(ValueError, match=r"missing keys \['positions', 'diameters', 'box'\]"):
        calippso.read(path)


# ----------------------------------------------------------------------------- generators

@pytest.mark.parametrize("call, pattern", [
    (lambda: generators.lubachevsky_stillinger(np.ones(8), d=1), r"dimension d must be an integer >= 2"),
    (lambda: generators.lubachevsky_stillinger(np.ones(8)), r"dimension d must be an integer >= 2, got d = None"),
    (lambda: generators.lubachevsky_stillinger([1.0, np.nan], d=3), r"diameters contain NaN or inf"),
    (lambda: generators.lubachevsky_stillinger([1.0, -1.0], d=3), r"diameters must be > 0"),
    (lambda: generators.lubachevsky_stillinger([], d=3), r"non-empty 1-d array"),
    (lambda: generators.lubachevsky_stillinger(np.ones(64), d=3, growth_rate=-1), r"growth_rate must be a finite number > 0"),
    (lambda: generators.lubachevsky_stillinger(np.ones(64), d=3, target_pressure=np.nan), r"target_pressure must be a finite number > 0"),
    (lambda: generators.lubachevsky_stillinger(d=2, start=GOOD), r"d = 2 contradicts the start's dimension 3"),
    (lambda: generators.poisson(np.ones(4), 3, phi=0.5), r"too few particles for phi = 0.5"),
    (lambda: generators.poisson(np.ones(4), 3, phi=1.5), r"phi must lie in \(0, 1\)"),
    (lambda: generators.closest_jamming(np.ones(8)), r"dimension d must be an integer >= 2, got d = None"),
    (lambda: generators.lubachevsky_stillinger(start=Packing(_duplicated(), DIAM, BOX)),
     r"duplicated particles in the input: particles 2 and 5"),
    (lambda: generators.closest_jamming(start=Packing(_duplicated_by_a_period(), DIAM, BOX)),
     r"duplicated particles in the input: particles 2 and 5"),
    (lambda: generators.closest_jamming(start=GOOD, initial_rate=1e-5, final_rate=1e-3), r"final_rate 0.001 exceeds initial_rate 1e-05"),
], ids=["ls-d1", "ls-no-d", "ls-nan", "ls-negative", "ls-empty", "ls-rate", "ls-pressure",
        "ls-dimension-clash", "poisson-box", "poisson-phi", "mls-no-d", "ls-duplicates",
        "mls-duplicates", "mls-rates"])
def test_generators_refuse(call, pattern):
    with pytest.raises(ValueError, match=pattern):
        call()


# ----------------------------------------------------------------------------- CLI


@pytest.mark.parametrize("make, pattern", [
    (lambda tmp: tmp / "absent.dat", r"no such file|does not exist"),
    (lambda tmp: _write(tmp, "packing.foo", "1 2 3\n"), r"unknown file format"),
    (lambda tmp: _write(tmp, "short.dat", SKOGE_HEADER + "0 0 0\n"), r"truncated"),
    (lambda tmp: _write(tmp, "coords.dat", SKOGE_HEADER + "0 0 0\n1 1 1\n2 x 2\n0.5 2.5 1\n"),
     r"non-numeric coordinates"),
    (lambda tmp: _write(tmp, "nan.dat", SKOGE_HEADER + "0 0 0\n1 1 1\nnan 2 2\n0.5 2.5 1\n"),
     r"non-finite"),
    (lambda tmp: _write(tmp, "garbage.npz", b"PK\x03\x04 not a zip"), r"unreadable \.npz"),
    (lambda tmp: _packing_generation_folder(tmp, "Boundaries mode: 4"),
     r"generation\.conf: boundaries mode 4 .* is not supported"),
    (lambda tmp: _packing_generation_folder(tmp, "Boundaries mode: 2"),
     r"packing\.xyzd: .* outside the container or overlapping its wall \(the cylinder"),
], ids=["missing", "unknown-format", "truncated", "non-numeric", "nan", "garbage-npz",
        "packing-generation-trapezoid", "packing-generation-outside-cylinder"])
def test_cli_reports_bad_files(tmp_path, make, pattern, capfd):
    """The command's `main`, in this process: ``python -m calippso`` runs the same function
    (tests/test_cli.py runs it so, on a missing file)."""
    from calippso.cli import main

    path = make(tmp_path)
    code = main(["jam", str(path), "-o", str(tmp_path / "out.npz")])
    err = capfd.readouterr().err
    assert code in (1, 2), err
    assert "Traceback" not in err
    message = err.strip().splitlines()[-1]
    assert message.startswith("error: ")
    assert __import__("re").search(pattern, message), message
