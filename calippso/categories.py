"""Jamming categories: is a packing locally, collectively or strictly jammed?

The hierarchy of Torquato & Stillinger (J. Phys. Chem. B 105, 11849 (2001)), tested by the
linear programs of Donev, Torquato, Stillinger & Connelly (J. Comput. Phys. 197, 139 (2004))
on the contact network with its rattlers removed:

* **local**: no particle can move while all the others stay put;
* **collective**: no motion of the particles helps, with the box fixed;
* **strict**: none helps even when the box deforms too, at a volume that does not grow.

A motion is the displacements Δr_i of the stable particles and, in the strict test, a
symmetric strain ε of the box (the lattice vectors L → (I + ε) L, the centres r → (I + ε) r
+ Δr). To first order, contact k between i and j (u_k the minimum-image vector from i to j,
n_k = u_k / |u_k|) stays closed or opens when

    n_kᵀ (Δr_j − Δr_i + ε u_k) ≥ 0,

and the box does not grow when −tr ε ≥ 0. A contact with a wall (inward normal e_w) stays
closed when e_wᵀ Δr_i ≥ 0. These rows form a matrix A; the motions allowed to first order are
the cone K = {x : A x ≥ 0}. The packing is jammed in the class when K holds only the trivial
motions (translations along the periodic axes, and the rotation about a cylinder's axis).

The packing is jammed in a class exactly when (Stiemke's theorem of the alternative, and a rank
condition):

1. **no motion opens a contact**: a self-stress f > 0 on every row with Aᵀ f = 0 exists (then
   K is the subspace ker A). The forces f are the certificate; in the strict test the strain
   columns of Aᵀ f = 0 say that the contact stress Σ_k f_k |u_k| n_k n_kᵀ is isotropic, g I,
   with g > 0 the force on the volume row;
2. **no floppy mode**: ker A holds only trivial motions (a floppy mode keeps every contact
   closed to first order; the linear test counts it as unjamming, as Donev et al. do).

How each class is decided (`ClassTest.method`):

* ``"linear programs"`` (the local test, and any class the faster routes cannot settle): the
  opening LP maximises the total opening rate 1ᵀ A x over A x ≥ 0 and the motion box
  |x_c| ≤ 1. A positive optimum is an unjamming motion; a zero optimum proves 1., its duals
  y giving f = 1 + y. Then the floppy LP maximises a random objective (seeded, trivial
  motions projected out) over the same cone: a positive optimum is a floppy mode, a zero one
  proves 2. (an objective orthogonal to a nontrivial ker A has probability zero).
* ``"self-stress"`` (the collective test): f is the network's forces (those of a
  `JammingResult`) or the self-stress nearest to uniform forces (sparse least squares);
  when all its forces are positive, 1. holds, and 2. is read from the stiffness
  AᵀA with one particle pinned: its smallest eigenvalue (shift-invert Lanczos) is zero, up
  to `FLOPPY_EIGENVALUE`, exactly when a floppy mode exists, and its eigenvector is the
  witness. When the least-squares forces are not all positive, the linear programs decide.
* ``"strain"`` (the strict test of a collectively jammed network with a single self-stress
  f₀, such as every isostatic one): every motion of the strict test has Δr fixed by ε up to
  trivial motions, and ε must satisfy σ₀ : ε ≥ 0 and −tr ε ≥ 0, with σ₀ = Σ_k f₀ₖ u_k n_kᵀ.
  The two LPs run on these two rows over the d(d+1)/2 strain entries; an unjamming strain
  is completed by the displacements that solve the contact rows (sparse least squares).
  In a container with a single periodic axis z the strain is ε_zz alone, and any positive
  self-stress f₀ of the collective test decides, however many there are: the volume row
  asks ε_zz ≤ 0, and f₀ with the volume force g = σ₀,zz is a certificate when σ₀,zz > 0
  (every compression along z closes a contact), while the kernel of the strict rows is
  that of the collective ones.

The local test uses the rows of every particle alone (its neighbours fixed, so no motion is
trivial); the collective test sets ε = 0; the strict test adds the strain columns and the
volume row. In a container the walls stay where they are and the strain acts on the periodic
axes only; a container without a periodic axis is refused.

Counting: a strictly jammed network needs d(d+1)/2 − 1 more contacts than an isostatic one,
N_c ≥ d (N_s − 1) + d(d+1)/2, so the strict test of an isostatic network always fails, with a
strain that keeps every contact closed to first order.

The LPs are solved by HiGHS (`scipy.optimize.linprog`): by the dual simplex method, and
when HiGHS fails on such a degenerate cone (it can end with an unknown status), again
without presolve, then by the interior-point method; `calippso.errors.SolverError` (one
line) when all three fail.
"""

from __future__ import annotations

import time
from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp

from .errors import SolverError
from .geometry.neighbors import NeighborSearch
from .geometry.packing import Packing, minimum_image
from .geometry.rattlers import remove_rattlers
from .geometry.sheared_search import sheared_pairs_within
from .geometry.walls import wall_rows_of, wall_rows_within

__all__ = ["jamming_category", "JammingCategory", "ClassTest", "CATEGORIES", "CLASSES",
           "DEFAULT_CONTACT_TOLERANCE", "AMBIGUITY_WINDOW"]

#: The categories, from the weakest to the strongest.
CATEGORIES = ("not jammed", "local", "collective", "strict")
#: The classes tested, in order; the category is the last one that holds.
CLASSES = ("local", "collective", "strict")
#: Pairs of a bare `Packing` with a relative gap |r|/σ − 1 at most this are contacts: the gap
#: of a contact of a `calippso.jam` result is below 1e-12, and the smallest gap of a
#: non-contact in a jammed packing of a few thousand particles is of order 1e-6.
DEFAULT_CONTACT_TOLERANCE = 1e-9
#: A pair whose gap lies between the contact tolerance and this many times it is neither
#: clearly a contact nor clearly open: the packing is refused, unless one of the two is a
#: rattler anyway.
AMBIGUITY_WINDOW = 100.0
#: Bound on every component of a motion in the LPs (displacements in mean diameters, strain
#: entries dimensionless): it only scales the witnesses.
MOTION_BOUND = 1.0
#: An LP optimum above this (opening rates or random objective, per unit of the motion box)
#: is an unjamming motion; below it, round-off.
DECISION_TOLERANCE = 1e-7
#: A witness may close a contact at most at this rate (relative to its largest component).
WITNESS_TOLERANCE = 1e-8
#: HiGHS's primal and dual feasibility tolerances.
LP_TOLERANCE = 1e-10
#: The HiGHS methods tried in turn on an LP of the test, and their options beyond the
#: tolerances: the dual simplex method, the same without presolve, the interior-point method.
LP_ATTEMPTS = (("highs-ds", {}), ("highs-ds", {"presolve": False}), ("highs-ipm", {}))
#: Forces whose net force on every particle is below this times the largest force are a
#: self-stress.
BALANCE_TOLERANCE = 1e-9
#: The pinned stiffness AᵀA has a floppy mode when its smallest eigenvalue is below this
#: times its mean diagonal (a jammed packing of 1024 spheres: about 1e-6).
FLOPPY_EIGENVALUE = 1e-12
#: Up to this many columns the stiffness spectrum is computed densely.
DENSE_COLUMNS = 200


@dataclass(frozen=True)
class ClassTest:
    """The outcome of one class's test.

    Attributes
    ----------
    name : str
        "local", "collective" or "strict".
    jammed : bool
        The packing is jammed in this class.
    method : str
        How it was decided: "linear programs", "self-stress" or "strain" (module docstring).
    seconds : float
        Wall time of the test.
    """

    name: str
    jammed: bool
    method: str
    seconds: float


@dataclass(frozen=True, eq=False)
class JammingCategory:
    """What `jamming_category` found.

    Attributes
    ----------
    category : str
        One of `CATEGORIES`: "not jammed", "local", "collective" or "strict", the strongest
        class that holds.
    tests : tuple of ClassTest
        The classes tested, in order, up to the first that failed.
    displacements : ndarray, shape (N, d), or None
        The witness of the first class that failed: an unjamming motion of the stable
        particles (zeros on rattlers; in mean diameters per unit motion, largest component 1
        with the strain), with the trivial motions projected out; None when the packing is
        strictly jammed (or the test stopped at `up_to`). For the local class only one
        particle moves.
    strain : ndarray, shape (d, d), or None
        The box's symmetric strain in the witness of the strict test (zero outside the
        periodic axes); None when the witness is not from the strict test.
    opens_contacts : bool
        The witness opens at least one contact to first order (False: a floppy mode, which
        keeps every contact closed to first order).
    forces : ndarray, shape (M,), or None
        The certificate of the strongest collective class that holds: contact forces of
        `contacts`, all positive, in balance on every stable particle (with `wall_forces`),
        normalised with the wall forces to mean 1; None when the packing is not collectively
        jammed. From the strict test when the category is "strict".
    wall_forces : ndarray, shape (K,), or None
        The forces of `wall_contacts`, in the units of `forces`.
    pressure : float
        For a strictly jammed packing, the isotropic stress of the certificate:
        Σ_k f_k |u_k| n_k n_kᵀ / V = pressure · I on the periodic axes (units of `forces` per
        length^(d−1)); NaN otherwise.
    balance : float
        max over stable particles of |Σ f n| / mean force of the certificate (round-off);
        NaN without certificate.
    contacts : ndarray, shape (M, 2), int64
        The contacts tested, pairs (i < j) of stable particles.
    wall_contacts : ndarray, shape (K, 2), int64
        Their contacts with walls, (particle, wall) as in `calippso.geometry.walls`.
    rattlers : ndarray, shape (N,), bool
        The particles removed (fewer than d + 1 contacts, recursively).
    contact_tolerance : float or None
        The relative gap under which a pair was taken as a contact; None when the contacts
        were those of a `JammingResult`.
    seed : int
        Seed of the random objectives of the floppy LPs.
    """

    category: str
    tests: tuple[ClassTest, ...]
    displacements: np.ndarray | None
    strain: np.ndarray | None
    opens_contacts: bool
    forces: np.ndarray | None
    wall_forces: np.ndarray | None
    pressure: float
    balance: float
    contacts: np.ndarray
    wall_contacts: np.ndarray
    rattlers: np.ndarray
    contact_tolerance: float | None
    seed: int

    @property
    def failed(self) -> str | None:
        """The class whose test failed (the witness's), or None for a strictly jammed
        packing."""
        return next((test.name for test in self.tests if not test.jammed), None)

    @property
    def seconds(self) -> float:
        """Total wall time of the LPs."""
        return float(sum(test.seconds for test in self.tests))

    def __repr__(self) -> str:
        return (f"JammingCategory({self.category!r}, contacts={len(self.contacts)}, "
                f"rattlers={int(self.rattlers.sum())}, failed={self.failed!r})")


@dataclass(frozen=True)
class _Network:
    """The geometry of the tests: stable particles, contact vectors and normals."""

    n: int
    d: int
    stable: np.ndarray          # (N_s,) indices of the stable particles
    column: np.ndarray          # (N,) first LP column of every stable particle, −1 else
    i: np.ndarray               # (M,) contacts, i < j, both stable
    j: np.ndarray
    vectors: np.ndarray         # (M, d) u_k: minimum image from i to j
    normals: np.ndarray         # (M, d)
    wall_particle: np.ndarray   # (K,)
    wall_normals: np.ndarray    # (K, d) inward
    trivial: np.ndarray         # (N_s d, t) orthonormal trivial motions


@dataclass(frozen=True)
class _Outcome:
    """One class's decision, its witness (LP columns, trivial motions projected out) or its
    certificate (forces on the contact rows, and the volume row's force g)."""

    jammed: bool
    method: str
    motion: np.ndarray | None = None
    opens: bool = False
    forces: np.ndarray | None = None
    volume_force: float = float("nan")


def jamming_category(packing_or_result, *, contact_tolerance: float | None = None,
                     seed: int = 0, up_to: str = "strict") -> JammingCategory:
    """The jamming category of a packing: "not jammed", "local", "collective" or "strict".

    The linear test of Donev, Torquato, Stillinger & Connelly (J. Comput. Phys. 197, 139
    (2004)) on the contact network with its rattlers removed: a class holds when a
    self-stress with every force positive exists (the certificate) and no floppy mode is
    left; otherwise a witness motion is returned (the module's docstring says how each
    class is decided; docs/categories.md).

    Parameters
    ----------
    packing_or_result : Packing or JammingResult
        A periodic packing, or one in a container with at least one periodic axis (the
        strict test strains the periodic axes; the walls stay). A `JammingResult` brings its
        contacts, wall contacts and forces.
    contact_tolerance : float, optional
        Pairs (and particle–wall pairs) with a relative gap at most this are contacts.
        Default: the contacts of a `JammingResult`, `DEFAULT_CONTACT_TOLERANCE` for a
        `Packing`. Gaps between the tolerance and `AMBIGUITY_WINDOW` times it (between
        particles that are not rattlers), or overlaps deeper than it, are refused.
    seed : int
        Seed of the random objectives of the floppy LPs.
    up_to : {"local", "collective", "strict"}
        The strongest class tested (`calippso.jam` asks for "collective" only, which needs
        no periodic axis); a packing jammed in it gets that category.

    Returns
    -------
    JammingCategory

    Raises
    ------
    ValueError
        Not a packing or a result, a container without a periodic axis, a negative
        tolerance, an overlap deeper than the tolerance, or a pair whose gap is ambiguous.
    """
    if up_to not in CLASSES:
        raise ValueError(f"up_to must be one of {', '.join(CLASSES)}, got {up_to!r}")
    classes = CLASSES[:CLASSES.index(up_to) + 1]
    packing, pairs, walls, tolerance = _contacts_of(packing_or_result, contact_tolerance)
    if "strict" in classes and not packing.periodic.any():
        raise ValueError("jamming_category needs a periodic axis: the strict test strains "
                         "the periodic axes and this container has none")
    rattlers, kept = remove_rattlers(packing.n, packing.d, pairs[:, 0], pairs[:, 1],
                                     walls[:, 0])
    wall_kept = ~rattlers[walls[:, 0]]
    given = _given_forces(packing_or_result, tolerance, kept, wall_kept)
    pairs, walls = pairs[kept], walls[wall_kept]
    rng = np.random.default_rng(seed)
    if rattlers.all():   # no backbone: the local test of every particle gives the witness
        every = _network(packing, *_all_contacts(packing_or_result, packing, tolerance),
                         np.zeros(packing.n, dtype=bool))
        return _result(packing, every, [("local", _timed(_local, every, packing, rng))],
                       pairs, walls, rattlers, tolerance, seed)
    network = _network(packing, pairs, walls, rattlers)
    tests = [("local", _timed(_local, network, packing, rng))]
    if tests[-1][1][0].jammed and "collective" in classes:
        tests.append(("collective", _timed(_collective, network, packing, rng, given)))
        collective = tests[-1][1][0]
        if collective.jammed and "strict" in classes:
            tests.append(("strict", _timed(_strict, network, packing, rng, collective)))
    return _result(packing, network, tests, pairs, walls, rattlers, tolerance, seed)


# ------------------------------------------------------------------------------ contacts
def _contacts_of(packing_or_result, contact_tolerance):
    """(packing, pairs (M, 2), wall contacts (K, 2), tolerance or None)."""
    from .result import JammingResult

    if contact_tolerance is not None and not contact_tolerance >= 0:
        raise ValueError(f"contact_tolerance must be >= 0, got {contact_tolerance}")
    if isinstance(packing_or_result, JammingResult):
        packing = packing_or_result.packing
        if contact_tolerance is None:
            return (packing, np.asarray(packing_or_result.contacts, np.int64).reshape(-1, 2),
                    np.asarray(packing_or_result.wall_contacts, np.int64).reshape(-1, 2), None)
    elif isinstance(packing_or_result, Packing):
        packing = packing_or_result
    else:
        raise ValueError(f"jamming_category takes a Packing or a JammingResult, got "
                         f"{type(packing_or_result).__name__}")
    tolerance = DEFAULT_CONTACT_TOLERANCE if contact_tolerance is None else contact_tolerance
    pairs, walls = _contacts_within(packing, tolerance)
    return packing, pairs, walls, float(tolerance)


def _contacts_within(packing: Packing, tolerance: float) -> tuple[np.ndarray, np.ndarray]:
    """Pairs and particle–wall pairs with relative gap ≤ `tolerance`, refusing overlaps
    deeper than it and gaps in (tolerance, AMBIGUITY_WINDOW · tolerance] between particles
    that are not rattlers when every pair within the window is taken as a contact."""
    reach = 1.0 + AMBIGUITY_WINDOW * tolerance
    periodic = None if packing.boundaries.is_periodic else packing.periodic
    if packing.box_matrix is not None:   # a sheared box
        near = sheared_pairs_within(packing.positions, packing.diameters, packing.search_cell,
                                    float(packing.diameters.max()) * reach)
    else:
        search = NeighborSearch(packing.positions, packing.diameters, packing.box, periodic)
        near = search.pairs_within(float(packing.diameters.max()) * reach)
    gaps = near.gaps
    close = gaps <= AMBIGUITY_WINDOW * tolerance
    if periodic is None:
        wall_gaps = np.zeros(0)
        wall_pairs = np.zeros((0, 2), np.int64)
    else:
        rows = wall_rows_within(packing.positions, packing.diameters, packing.box,
                                packing.boundaries, 0.0, reach)
        wall_gaps = rows.gaps
        wall_pairs = np.stack([rows.particle, rows.wall], axis=1)
    every = np.concatenate([gaps[close], wall_gaps])
    if every.size and every.min() < -tolerance:
        raise ValueError(f"the packing overlaps: the deepest relative gap is {every.min():.3e}, "
                         f"beyond the contact tolerance {tolerance:.1e}")
    # a pair that is a contact or not changes nothing when one of its particles is a
    # rattler even if every such pair were a contact (rattlers sit 1e-9 from their cages)
    generous, _ = remove_rattlers(packing.n, packing.d, near.i[close], near.j[close],
                                  wall_pairs[:, 0])
    matters = np.concatenate([~(generous[near.i[close]] | generous[near.j[close]]),
                              ~generous[wall_pairs[:, 0]]])
    unclear = every[(every > tolerance) & matters]
    if unclear.size:
        raise ValueError(f"contacts are ambiguous: {unclear.size} pair(s) have relative gaps "
                         f"between the contact tolerance {tolerance:.1e} and "
                         f"{AMBIGUITY_WINDOW:g} times it (smallest {unclear.min():.3e}); "
                         f"choose contact_tolerance")
    touching = gaps <= tolerance
    pairs = np.stack([near.i[touching], near.j[touching]], axis=1).astype(np.int64)
    return pairs, wall_pairs[wall_gaps <= tolerance].astype(np.int64)


def _all_contacts(packing_or_result, packing, tolerance):
    """Every contact, rattlers included (for the witness of a packing without backbone)."""
    if tolerance is None:
        return (np.asarray(packing_or_result.contacts, np.int64).reshape(-1, 2),
                np.asarray(packing_or_result.wall_contacts, np.int64).reshape(-1, 2))
    return _contacts_within(packing, tolerance)


# ------------------------------------------------------------------------------ geometry
def _network(packing: Packing, pairs: np.ndarray, walls: np.ndarray,
             rattlers: np.ndarray) -> _Network:
    n, d = packing.n, packing.d
    stable = np.flatnonzero(~rattlers)
    column = np.full(n, -1, dtype=np.int64)
    column[stable] = d * np.arange(stable.size)
    i, j = pairs[:, 0], pairs[:, 1]
    periodic = None if packing.boundaries.is_periodic else packing.periodic
    vectors = (packing.minimum_image(packing.positions[j] - packing.positions[i])
               if packing.box_matrix is not None else
               minimum_image(packing.positions[j] - packing.positions[i], packing.box, periodic))
    normals = vectors / np.linalg.norm(vectors, axis=1)[:, None]
    boundaries = packing.boundaries
    rows = wall_rows_of(packing.positions, packing.diameters, packing.box, walls[:, 0],
                        walls[:, 1], boundaries.cylinder_axes)
    return _Network(n, d, stable, column, i, j, vectors, normals, walls[:, 0],
                    rows.normals, _trivial_motions(packing, stable))


def _trivial_motions(packing: Packing, stable: np.ndarray) -> np.ndarray:
    """Orthonormal columns (N_s d, t): the translations along the periodic axes, and the
    rotation about a cylinder's axis."""
    n_s, d = stable.size, packing.d
    modes = []
    for axis in np.flatnonzero(packing.periodic):
        mode = np.zeros((n_s, d))
        mode[:, axis] = 1.0
        modes.append(mode.ravel())
    if packing.boundaries.cylinder_axes:
        a, b = packing.boundaries.cylinder_axes
        offset = packing.positions[stable][:, [a, b]] - 0.5 * packing.box[[a, b]]
        mode = np.zeros((n_s, d))
        mode[:, a], mode[:, b] = -offset[:, 1], offset[:, 0]
        modes.append(mode.ravel())
    if not modes:
        return np.zeros((n_s * d, 0))
    basis, _ = np.linalg.qr(np.stack(modes, axis=1))
    return basis


def _strain_axes(packing: Packing) -> list[tuple[int, int]]:
    """The strain entries (a ≤ b) of the periodic axes: d_p (d_p + 1)/2 columns."""
    axes = np.flatnonzero(packing.periodic)
    return [(int(a), int(b)) for k, a in enumerate(axes) for b in axes[k:]]


def _rows(network: _Network, name: str, packing: Packing) -> tuple[sp.csr_matrix, int]:
    """The matrix A of a class (rows: contacts, then wall contacts, then the volume row of
    the strict test) and its number of contact rows."""
    d, m = network.d, network.i.size
    k = network.wall_particle.size
    n_cols = d * network.stable.size
    axis = np.arange(d)
    col_i = (network.column[network.i][:, None] + axis).ravel()
    col_j = (network.column[network.j][:, None] + axis).ravel()
    col_w = (network.column[network.wall_particle][:, None] + axis).ravel()
    pair_rows = np.repeat(np.arange(m), d)
    if name == "local":   # each particle alone: one row for i, one for j, per contact
        rows = [pair_rows, m + pair_rows, 2 * m + np.repeat(np.arange(k), d)]
        cols = [col_i, col_j, col_w]
        values = [-network.normals.ravel(), network.normals.ravel(),
                  network.wall_normals.ravel()]
        n_rows = 2 * m + k
        return sp.csr_matrix((np.concatenate(values), (np.concatenate(rows),
                                                       np.concatenate(cols))),
                             shape=(n_rows, n_cols)), n_rows
    rows = [pair_rows, pair_rows, m + np.repeat(np.arange(k), d)]
    cols = [col_j, col_i, col_w]
    values = [network.normals.ravel(), -network.normals.ravel(), network.wall_normals.ravel()]
    n_rows = m + k
    if name == "strict":
        strain = _strain_axes(packing)
        u, normal = network.vectors, network.normals
        for s, (a, b) in enumerate(strain):
            coefficient = normal[:, a] * u[:, b] + (normal[:, b] * u[:, a] if a != b else 0.0)
            rows.append(np.arange(m))
            cols.append(np.full(m, n_cols + s))
            values.append(coefficient)
        diagonal = [s for s, (a, b) in enumerate(strain) if a == b]
        rows.append(np.full(len(diagonal), m + k))
        cols.append(n_cols + np.array(diagonal, dtype=np.int64))
        values.append(-np.ones(len(diagonal)))
        n_rows, n_cols = m + k + 1, n_cols + len(strain)
    return sp.csr_matrix((np.concatenate(values), (np.concatenate(rows), np.concatenate(cols))),
                         shape=(n_rows, n_cols)), m + k


# ------------------------------------------------------------------------------ the tests
def _timed(test, *args):
    start = time.perf_counter()
    outcome = test(*args)
    return outcome, time.perf_counter() - start


def _local(network: _Network, packing: Packing, rng) -> _Outcome:
    """Every particle alone: the linear programs on the block-diagonal local rows."""
    matrix, _ = _rows(network, "local", packing)
    jammed, motion, opens, _ = _cone_test(matrix, None, rng)
    if not jammed:
        motion = _one_particle(motion, network.d)
    return _Outcome(jammed, "linear programs", motion, opens)


def _collective(network: _Network, packing: Packing, rng, given) -> _Outcome:
    """The box fixed: a positive self-stress and the stiffness spectrum, or the LPs."""
    matrix, _ = _rows(network, "collective", packing)
    forces = None if packing.boundaries.cylinder_axes else _self_stress(matrix, given)
    if forces is None:
        jammed, motion, opens, duals = _cone_test(matrix, network.trivial, rng)
        return _Outcome(jammed, "linear programs", motion, opens,
                        duals if jammed else None)
    motion = _floppy_mode(matrix, network, packing)
    return _Outcome(motion is None, "self-stress", motion, False, forces)


def _strict(network: _Network, packing: Packing, rng, collective: _Outcome) -> _Outcome:
    """The box deforms too: the strain rows of a single self-stress, or the LPs."""
    matrix, n_rows = _rows(network, "strict", packing)
    n_motion = network.d * network.stable.size
    trivial = np.vstack([network.trivial, np.zeros((matrix.shape[1] - n_motion,
                                                    network.trivial.shape[1]))])
    independent = n_rows - (n_motion - network.trivial.shape[1])   # self-stresses
    contact_rows = matrix[:n_rows].tocsc()
    moves, strains = contact_rows[:, :n_motion], contact_rows[:, n_motion:]
    forces = collective.forces
    single = collective.method == "self-stress" and independent == 1
    one_axis = (int(packing.periodic.sum()) == 1 and forces is not None
                and forces.min() > 0 and _balanced(moves, forces))
    if not (single or one_axis):
        return _strict_by_lps(matrix, n_rows, trivial, rng)
    stress = strains.T @ forces                               # σ₀ : ε per strain entry
    volume = matrix[n_rows, n_motion:].toarray().ravel()      # −tr ε
    jammed, strain, _, duals = _cone_test(sp.csr_matrix(np.stack([stress, volume])), None, rng)
    if jammed:
        return _Outcome(True, "strain", None, False, duals[0] * forces, duals[1])
    if not single:   # one of several self-stresses: its strain is no witness
        return _strict_by_lps(matrix, n_rows, trivial, rng)
    # contact rates along the self-stress (≥ 0) that make the rows solvable for Δr
    rates = float(stress @ strain) / float(forces @ forces) * forces
    displacement = _solve_rows(moves, rates - strains @ strain, network, packing, forces)
    motion = _project(np.concatenate([displacement, strain]), trivial)
    closing = matrix @ motion
    if not _is_witness(closing, motion):   # round-off in the displacements: the LPs decide
        return _strict_by_lps(matrix, n_rows, trivial, rng)
    return _Outcome(False, "strain", motion, bool(closing.max() > DECISION_TOLERANCE))


def _strict_by_lps(matrix: sp.csr_matrix, n_rows: int, trivial: np.ndarray,
                   rng) -> _Outcome:
    """The strict test by the linear programs on the strict rows (contacts, volume)."""
    jammed, motion, opens, duals = _cone_test(matrix, trivial, rng)
    if not jammed:
        return _Outcome(False, "linear programs", motion, opens)
    return _Outcome(True, "linear programs", None, False, duals[:n_rows], duals[n_rows])


def _solve_rows(moves: sp.csc_matrix, target: np.ndarray, network: _Network,
                packing: Packing, forces: np.ndarray) -> np.ndarray:
    """Δr with `moves` Δr = `target`, a consistent system (fᵀ target = 0) of one row more
    than its columns once one particle is pinned along the periodic axes: the square system
    without the row of the largest force, by sparse LU."""
    from scipy.sparse.linalg import splu

    pinned = network.column[network.stable[0]] + np.flatnonzero(packing.periodic)
    free = np.setdiff1d(np.arange(moves.shape[1]), pinned)
    rows = np.delete(np.arange(moves.shape[0]), int(np.argmax(forces)))
    displacement = np.zeros(moves.shape[1])
    square = moves[rows][:, free].tocsc()
    if square.shape[0] != square.shape[1]:
        return _least_squares(moves, target)
    displacement[free] = splu(square).solve(target[rows])
    return displacement


def _given_forces(packing_or_result, tolerance, kept, wall_kept):
    """The forces of a `JammingResult` on the kept contacts (pairs, then walls), or None."""
    if tolerance is not None:
        return None
    forces = np.asarray(packing_or_result.forces, dtype=np.float64)
    wall_forces = np.asarray(packing_or_result.wall_forces, dtype=np.float64)
    if forces.shape != kept.shape or wall_forces.shape != wall_kept.shape:
        return None
    return np.concatenate([forces[kept], wall_forces[wall_kept]])


def _self_stress(matrix: sp.csr_matrix, given: np.ndarray | None) -> np.ndarray | None:
    """Forces f > 0 with Aᵀ f = 0 (mean 1): `given`, or the self-stress nearest to uniform
    forces (the residual of the least-squares solution of A w = 1); None when that one has
    a force ≤ 0."""
    if given is not None and given.size and given.min() > 0 and _balanced(matrix, given):
        return given / given.mean()
    ones = np.ones(matrix.shape[0])
    forces = ones - matrix @ _least_squares(matrix, ones)
    if forces.size and forces.min() > 0 and _balanced(matrix, forces):
        return forces / forces.mean()
    return None


def _balanced(matrix: sp.csr_matrix, forces: np.ndarray) -> bool:
    return bool(np.abs(matrix.T @ forces).max() <= BALANCE_TOLERANCE * np.abs(forces).max())


def _least_squares(matrix, target: np.ndarray) -> np.ndarray:
    """The least-norm least-squares solution of `matrix` x = `target` (sparse LSQR)."""
    from scipy.sparse.linalg import lsqr

    return lsqr(matrix, target, atol=1e-15, btol=1e-15, conlim=1e15,
                iter_lim=20 * sum(matrix.shape))[0]


def _floppy_mode(matrix: sp.csr_matrix, network: _Network,
                 packing: Packing) -> np.ndarray | None:
    """A floppy mode of the contact rows (ker A beyond the translations), or None.

    One stable particle is pinned along the periodic axes (the translations); the smallest
    eigenvalue of the pinned stiffness AᵀA is zero, up to `FLOPPY_EIGENVALUE` × its mean
    diagonal, exactly when a floppy mode exists. Its eigenvector is cleaned of its part off
    ker A (least squares) and of the translations.
    """
    from scipy.sparse.linalg import eigsh

    pinned = network.column[network.stable[0]] + np.flatnonzero(packing.periodic)
    free = np.setdiff1d(np.arange(matrix.shape[1]), pinned)
    stiffness = (matrix[:, free].T @ matrix[:, free]).tocsc()
    scale = float(stiffness.diagonal().mean())
    if free.size <= DENSE_COLUMNS:
        values, vectors = np.linalg.eigh(stiffness.toarray())
    else:
        values, vectors = eigsh(stiffness, k=1, sigma=-1e-3 * FLOPPY_EIGENVALUE * scale,
                                which="LM")
    if values[0] > FLOPPY_EIGENVALUE * scale:
        return None
    mode = np.zeros(matrix.shape[1])
    mode[free] = vectors[:, 0]
    mode -= _least_squares(matrix, matrix @ mode)
    return _project(mode, network.trivial)


def _solve(cost, **constraints):
    """The LP min cost·x over the motion box and `constraints`, by the first of
    `LP_ATTEMPTS` that solves it."""
    from scipy.optimize import linprog

    for method, options in LP_ATTEMPTS:
        answer = linprog(cost, bounds=(-MOTION_BOUND, MOTION_BOUND), method=method,
                         options={"primal_feasibility_tolerance": LP_TOLERANCE,
                                  "dual_feasibility_tolerance": LP_TOLERANCE, **options},
                         **constraints)
        if answer.status == 0:
            return answer
    raise SolverError(f"the jamming test's LP failed by each of the {len(LP_ATTEMPTS)} HiGHS "
                      f"methods tried: {answer.message}")


def _project(motion: np.ndarray, trivial: np.ndarray | None) -> np.ndarray:
    if trivial is None or trivial.shape[1] == 0:
        return motion
    return motion - trivial @ (trivial.T @ motion)


def _cone_test(matrix: sp.csr_matrix, trivial: np.ndarray | None, rng: np.random.Generator
               ) -> tuple[bool, np.ndarray | None, bool, np.ndarray | None]:
    """The two LPs on {x : A x ≥ 0} (module docstring): (jammed, witness, the witness opens
    a contact, the forces f = 1 + y on the rows when no motion opens one)."""
    n_rows, n_cols = matrix.shape
    if n_rows == 0:   # no contact: every motion is floppy
        return False, _project(rng.standard_normal(n_cols), trivial), False, None
    opening_lp = _solve(-(matrix.T @ np.ones(n_rows)), A_ub=-matrix, b_ub=np.zeros(n_rows))
    motion = _project(opening_lp.x, trivial)
    if -opening_lp.fun > DECISION_TOLERANCE and _is_witness(matrix @ motion, motion):
        return False, motion, True, None
    forces = 1.0 - opening_lp.ineqlin.marginals
    objective = _project(rng.standard_normal(n_cols), trivial)
    floppy_lp = _solve(-objective, A_ub=-matrix, b_ub=np.zeros(n_rows))
    motion = _project(floppy_lp.x, trivial)
    if -floppy_lp.fun > DECISION_TOLERANCE and _is_witness(matrix @ motion, motion):
        return False, motion, False, forces
    return True, None, False, forces


def _is_witness(rates: np.ndarray, motion: np.ndarray) -> bool:
    """A nonzero motion that closes no contact faster than round-off."""
    size = float(np.abs(motion).max()) if motion.size else 0.0
    return size > DECISION_TOLERANCE and (rates.size == 0
                                          or rates.min() >= -WITNESS_TOLERANCE * size)


# ------------------------------------------------------------------------------ the result
def _result(packing, network, tests, pairs, walls, rattlers, tolerance, seed):
    records = tuple(ClassTest(name, outcome.jammed, outcome.method, seconds)
                    for name, (outcome, seconds) in tests)
    category = CATEGORIES[sum(test.jammed for test in records)]
    n, d, n_motion = packing.n, packing.d, network.d * network.stable.size
    displacements = strain = None
    last, (outcome, _) = tests[-1]
    if not outcome.jammed:
        motion = outcome.motion
        displacements = np.zeros((n, d))
        displacements[network.stable] = motion[:n_motion].reshape(-1, d)
        if last == "strict":
            strain = np.zeros((d, d))
            for s, (a, b) in enumerate(_strain_axes(packing)):
                strain[a, b] = strain[b, a] = motion[n_motion + s]
        scale = max(float(np.abs(displacements).max()),
                    0.0 if strain is None else float(np.abs(strain).max()))
        displacements /= scale
        if strain is not None:
            strain /= scale
    # the certificate: the strongest of the collective and strict classes that holds
    holding = [(name, outcome) for name, (outcome, _) in tests
               if name != "local" and outcome.jammed]
    forces = wall_forces = None
    pressure = balance = float("nan")
    if holding:
        name, certificate = holding[-1]
        m, k = network.i.size, network.wall_particle.size
        every = certificate.forces[:m + k]
        mean = float(every.mean())
        forces, wall_forces = every[:m] / mean, every[m:] / mean
        balance = _balance(network, forces, wall_forces)
        if name == "strict":
            pressure = float(certificate.volume_force / mean / packing.volume)
    return JammingCategory(category, records, displacements, strain, outcome.opens, forces,
                           wall_forces, pressure, balance, pairs, walls, rattlers, tolerance,
                           seed)


def _one_particle(motion: np.ndarray, d: int) -> np.ndarray:
    """The local witness reduced to the particle that moves most (a motion of its own)."""
    keep = int(np.argmax(np.abs(motion.reshape(-1, d)).max(axis=1)))
    single = np.zeros_like(motion)
    single[d * keep:d * keep + d] = motion[d * keep:d * keep + d]
    return single


def _balance(network: _Network, forces: np.ndarray, wall_forces: np.ndarray) -> float:
    """max over stable particles of |Σ f n| (forces of mean 1)."""
    from .geometry.contacts import net_forces
    from .geometry.walls import wall_net_forces

    # net_forces takes the normal from j to i: −n_k here
    total = net_forces(network.n, network.i, network.j, -network.normals, forces)
    total += wall_net_forces(network.n, network.wall_particle, network.wall_normals,
                             wall_forces)
    total = total[network.stable]
    return float(np.sqrt(np.einsum("nd,nd->n", total, total)).max()) if total.size else 0.0
