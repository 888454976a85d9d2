"""Every public call in every container: `jam` (each route, each box), `jamming_category`
(each class), `generators.relax` and `calippso.protocols.precompress`, `calippso report`,
`calippso render`, and `write`/`read` in each format, for a periodic box, flat walls on one
and on two axes and a cylinder, in d = 2 and 3. Each call returns an answer, checked here,
or refuses in one line naming what is unsupported (`_refusal`); none raises a solver's or
numpy's error."""

from __future__ import annotations

import functools
import traceback
from pathlib import Path

import numpy as np
import pytest

import calippso
import generators
from configurations import container_gaps
from calippso import Boundaries, Packing
from calippso.cli import main
from calippso.errors import JammingError, SolverError
from calippso.io import SUFFIXES, read_result
from calippso.protocols import precompress

#: Particles per packing: small, so that the whole matrix runs in seconds.
N = 40
#: The containers, by name, for a dimension d.
CONTAINERS = {
    "periodic": lambda d: Boundaries.all_periodic(d),
    "walls x": lambda d: Boundaries.walls(d, ["x"]),
    "walls x, y": lambda d: Boundaries.walls(d, ["x", "y"]),
    "cylinder x, y": lambda d: Boundaries.cylinder(d, ["x", "y"]),
}
CASES = [(name, d) for name in CONTAINERS for d in (2, 3)]
#: The diameters of the jam inputs are this fraction of the quench's, so that the LP loop
#: runs (the quench's own network would be certified with no LP).
LOOSE = 0.98
#: Overlaps and crossings of a wall, relative to the diameters, allowed in an answer.
OVERLAP = 1e-12
#: Net force on a stable particle (mean force 1) allowed in a certificate.
BALANCE = 1e-9
#: A witness closes no contact faster than this (relative to its largest component).
WITNESS = 1e-8
#: Relative distance between written and read positions, diameters and box.
ROUND_TRIP = 1e-12
#: The reduced pressure of the LS precompression (low: the start is near jamming already).
PRECOMPRESS_PRESSURE = 1e3
#: The errors a refusal may raise (one line each).
REFUSAL_TYPES = (ValueError, JammingError, SolverError)


def _refusal(call: str, boundaries: Boundaries, d: int, box: str = "fixed",
             route: str = "lp", extension: str = "") -> str | None:
    """The words of the one-line refusal that `call` may give in this container, or None
    when it must answer."""
    periodic = boundaries.is_periodic
    if call == "jam" and box == "deformable":
        if route != "lp":
            return "takes the LP route"
        return None if boundaries.periodic.any() else "needs a periodic axis"
    if call == "strict" and not boundaries.periodic.any():
        return "needs a periodic axis"
    if call == "write":
        if extension == ".dat" and not periodic:
            return "Skoge-Donev files hold periodic packings"
        if extension == ".xyz" and boundaries.cylinder_axes:
            return "cannot hold a cylinder"
        if extension == ".xyzd":
            if d != 3:
                return "d = 3 only"
            if not (periodic or boundaries.cylinder_axes
                    or tuple(boundaries.wall_axes) == (0, 1)):
                return "PackingGeneration holds periodic boxes, cylinders in x, y and rectangles"
    return None


def _answer(call, refusal: str | None):
    """What `call()` returns, or None when it refused with `refusal` in one line of a
    calippso error raised by calippso's (or the generators') own code."""
    try:
        return call()
    except Exception as error:   # every error is checked below
        message = str(error)
        assert refusal is not None, f"{type(error).__name__}: {message}"
        assert isinstance(error, REFUSAL_TYPES), f"{type(error).__name__}: {message}"
        assert refusal in message and "\n" not in message, message
        raised_in = Path(traceback.extract_tb(error.__traceback__)[-1].filename).parts
        assert "calippso" in raised_in or "generators" in raised_in, raised_in
        return None


# ------------------------------------------------------------------------------ inputs
@functools.cache
def _quenched(name: str, d: int) -> Packing:
    """A soft quench of N particles in the container (discs: the 50:50 mixture of diameter
    ratio 1.4)."""
    sizes = (generators.diameters.bidisperse(N, 1.4) if d == 2
             else generators.diameters.monodisperse(N))
    return generators.soft_quench(sizes, d, seed=1, boundaries=CONTAINERS[name](d)).packing


@functools.cache
def _loose(name: str, d: int) -> Packing:
    packing = _quenched(name, d)
    return Packing(packing.positions, LOOSE * packing.diameters, packing.box,
                   packing.boundaries)


@functools.cache
def _jammed(name: str, d: int) -> calippso.JammingResult:
    return calippso.jam(_loose(name, d))


def assert_jammed_in_its_container(result, start: Packing) -> None:
    """Converged in the container of its input, overlap-free and inside it, with positive
    forces in balance on a rigid network."""
    packing = result.packing
    assert result.converged, result.status
    assert packing.boundaries == start.boundaries
    pairs, walls = container_gaps(packing)
    assert pairs.min() >= -OVERLAP and walls.min(initial=0.0) >= -OVERLAP
    assert np.all(result.forces > 0) and np.all(result.wall_forces > 0)
    assert result.force_balance <= BALANCE
    assert result.isostaticity_gap >= 0 and result.n_stable > packing.d + 1
    assert (result.n_wall_contacts > 0) == (not packing.boundaries.is_periodic)


def assert_strict_witness(packing: Packing, category) -> None:
    """The strict test's witness strains the periodic axes only, does not grow the volume,
    and closes no contact, with a particle or a wall, to first order."""
    strain, motion = category.strain, category.displacements
    fixed = ~packing.boundaries.periodic
    size = max(np.abs(strain).max(), np.abs(motion).max())
    assert np.all(strain[fixed] == 0) and np.all(strain[:, fixed] == 0)
    assert np.trace(strain) <= WITNESS * size
    i, j = category.contacts.T
    u = packing.minimum_image(packing.positions[j] - packing.positions[i])
    normals = u / np.linalg.norm(u, axis=1)[:, None]
    rates = np.einsum("md,md->m", normals, motion[j] - motion[i] + u @ strain.T)
    particle, wall = category.wall_contacts.T
    inward = np.zeros((particle.size, packing.d))
    flat = wall < 2 * packing.d
    inward[flat, wall[flat] // 2] = np.where(wall[flat] % 2 == 0, 1.0, -1.0)
    if packing.boundaries.cylinder_axes:
        axes = list(packing.boundaries.cylinder_axes)
        offset = 0.5 * packing.box[axes] - packing.positions[particle[~flat]][:, axes]
        inward[np.ix_(~flat, axes)] = offset / np.linalg.norm(offset, axis=1)[:, None]
    wall_rates = np.einsum("kd,kd->k", inward, motion[particle])
    assert min(rates.min(), wall_rates.min(initial=0.0)) >= -WITNESS * size


# ------------------------------------------------------------------------------ the calls
@pytest.mark.parametrize("route", ["lp", "relaxed", "auto"])
@pytest.mark.parametrize("box", ["fixed", "deformable"])
@pytest.mark.parametrize("name, d", CASES)
def test_jam_answers_by_every_route_and_box(name, d, route, box):
    start = _loose(name, d)
    result = _answer(lambda: calippso.jam(start, route=route, box=box),
                     _refusal("jam", start.boundaries, d, box=box, route=route))
    if result is not None:
        assert_jammed_in_its_container(result, start)
        if box == "deformable":
            assert result.category == "strict"


@pytest.mark.parametrize("up_to", ["local", "collective", "strict"])
@pytest.mark.parametrize("name, d", CASES)
def test_jamming_category_answers_for_every_class(name, d, up_to):
    """On the result (its contacts and forces) and on its bare packing (contacts from the
    gaps): a jammed result is collectively jammed; the strict test answers where the
    container has a periodic axis, with a certificate or a witness on the periodic axes."""
    result = _jammed(name, d)
    boundaries = result.packing.boundaries
    for tested in (result, result.packing):
        category = _answer(lambda: calippso.jamming_category(tested, up_to=up_to),
                           _refusal(up_to, boundaries, d))
        if category is None:
            continue
        assert category.category == up_to or (up_to, category.category) == ("strict",
                                                                             "collective")
        if category.category in ("collective", "strict"):
            assert category.forces.min() > 0 and category.balance <= BALANCE
        if category.failed == "strict":
            assert_strict_witness(result.packing, category)
        if up_to == "strict" and int(boundaries.periodic.sum()) == 1:
            # a compression along the single periodic axis closes a contact
            assert category.category == "strict" and category.pressure > 0


@pytest.mark.parametrize("name, d", CASES)
def test_relax_and_precompress_answer(name, d):
    """The soft-sphere relaxation and the LS precompression keep the container, with no
    overlap and no particle across a wall."""
    start = _loose(name, d)
    for moved in (generators.relax(start).packing,
                  precompress(start, PRECOMPRESS_PRESSURE).packing):
        assert moved.boundaries == start.boundaries and moved.n == start.n
        pairs, walls = container_gaps(moved)
        assert pairs.min() >= -OVERLAP and walls.min(initial=0.0) >= -OVERLAP


@pytest.mark.parametrize("name, d", CASES)
def test_report_and_render_answer(name, d, tmp_path, capsys):
    result = _jammed(name, d)
    source = calippso.write(result, tmp_path / "jammed.npz")
    assert main(["report", str(source), "-o", str(tmp_path / "report")]) == 0, \
        capsys.readouterr().err
    page = (tmp_path / "report" / "report.md").read_text()
    assert ("cylinder" in page) == bool(result.packing.boundaries.cylinder_axes)
    assert main(["render", str(source), "-o", str(tmp_path / "jammed.png"),
                 "--backend", "matplotlib", "--size", "200"]) == 0, capsys.readouterr().err
    assert (tmp_path / "jammed.png").stat().st_size > 0


def _same_packing(back: Packing, packing: Packing) -> None:
    """Equal up to the order of the particles (Skoge–Donev files group them by size)."""
    def ordered(p: Packing) -> np.ndarray:
        table = np.column_stack([p.diameters, p.positions])
        return table[np.lexsort(table.T[::-1])]
    assert back.boundaries == packing.boundaries
    np.testing.assert_allclose(back.box, packing.box, rtol=ROUND_TRIP)
    np.testing.assert_allclose(ordered(back), ordered(packing), rtol=0,
                               atol=ROUND_TRIP * float(packing.box.max()))


@pytest.mark.parametrize("extension", sorted(set(SUFFIXES) - {".extxyz", ".hdf5", ".txt"}))
@pytest.mark.parametrize("name, d", CASES)
def test_write_and_read_answer_in_every_format(name, d, extension, tmp_path):
    """Each format holds the packing (a result in full for .npz and .h5) and reads it back,
    or refuses it in one line naming the formats that hold it, and those do."""
    result = _jammed(name, d)
    packing = result.packing.wrapped()
    refusal = _refusal("write", packing.boundaries, d, extension=extension)
    for kind, written in (("result", result), ("packing", result.packing)):
        path = tmp_path / f"{kind}{extension}"
        try:
            calippso.write(written, path)
        except ValueError as error:
            assert refusal is not None and refusal in str(error), str(error)
            assert "\n" not in str(error)
            others = [word.strip(",") for word in str(error).split(": ")[-1].split()
                      if word.strip(",").startswith(".")]
            for other in others:   # the formats it names hold the packing
                _same_packing(calippso.read(calippso.write(written, path.with_suffix(other))),
                              packing)
            continue
        assert refusal is None, f"{extension} wrote a packing it should refuse"
        _same_packing(calippso.read(path).wrapped(), packing)
        if kind == "result" and extension in (".npz", ".h5"):
            back = calippso.load_result(path) if extension == ".npz" else \
                read_result(path)
            np.testing.assert_array_equal(back.forces, result.forces)
            np.testing.assert_array_equal(back.wall_contacts, result.wall_contacts)
