"""A singular network (`calippso.certification.pivots`, the repair of a singular network): isostatic by
count, singular by rank.

The inputs are made from a jammed packing: a particle p with d + 1 contacts keeps only d − 1
of them, so that it can roll on them (a floppy mode, with Γ fixed), and two near pairs
elsewhere join the network, one more than the rest of it can hold (a self-stress). The count
is isostatic, N_c = d (N_s − 1) + 1, the Jacobian singular: Newton refuses the network, and
the pivot path used to stop there. The repair opens a redundant contact, closes p's floppy
mode with the ratio test, and the ordinary pivots go on to a certified jamming point: from
the packing's own positions (the source, or a jamming point next to it), from a singular
vertex (every contact closed, Γ growing from it), and from that vertex handed in as a
Newton point. A regular network that Newton cannot solve is not repaired, and network first
hands a network that Newton refuses to the pivots.
"""

from __future__ import annotations

import itertools

import numpy as np
import pytest
import scipy.sparse as sp

from calippso import Packing
from calippso.geometry.neighbors import NeighborSearch
from calippso.certification.newton import Refinement, network_jacobian, refine_isostatic
from calippso.geometry.packing import minimum_image
from calippso.certification.pivots import describe_path, pivot_to_jamming, singular_vectors

from conftest import BALANCE_TOLERANCE, assert_jammed
from test_pivots import certified_again, in_mean_diameters, same_network, vertex_touching

#: Relative round-off of the singular vectors: |J t| and |Jᵀ s| against |J| |t| and |Jᵀ| |s|.
ROUND_OFF = 1e-12
#: The smallest singular value of a singular Jacobian, relative to the largest, is round-off;
#: the next one is not (the rank lacks exactly one).
SINGULAR = 1e-13
REGULAR = 1e-6
#: Jamming points that agree in φ to this relative precision are the same.
SAME_PHI = 1e-9
#: Two jamming points of the source packing lie this close in φ (relative).
NEIGHBOURING_PHI = 1e-7
#: A start this far (mean diameters, per coordinate) from its jamming point is too far for
#: Newton: its first correction exceeds `newton.MAX_CORRECTION`.
FAR_MOVE = 0.05


@pytest.fixture(scope="module")
def source(ls_jammed):
    """An LS packing at p = 1e7 (d = 3, N = 64) jammed by the LP path."""
    return ls_jammed


def floppy_particle(result) -> tuple[int, np.ndarray]:
    """The first stable particle with exactly d + 1 contacts, and the rows of its contacts."""
    contacts, d = result.contacts, result.packing.d
    counts = np.bincount(contacts.ravel(), minlength=result.packing.n)
    candidates = np.flatnonzero((counts == d + 1) & ~result.rattlers)
    assert candidates.size, "the source packing has no particle with d + 1 contacts"
    p = int(candidates[0])
    return p, np.flatnonzero((contacts[:, 0] == p) | (contacts[:, 1] == p))


def near_pairs_apart_from(positions, diameters, box, network: np.ndarray, p: int,
                          rattlers: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The pairs of stable particles outside `network` and away from particle p, nearest
    first: (pairs (P, 2), relative gaps (P,))."""
    n = positions.shape[0]
    search = NeighborSearch(positions, diameters, box)
    close = search.pairs_within(1.2 * diameters.max())
    outside = (~np.isin(close.i * n + close.j, network[:, 0] * n + network[:, 1])
               & (close.i != p) & (close.j != p) & ~rattlers[close.i] & ~rattlers[close.j])
    order = np.flatnonzero(outside)[np.argsort(close.gaps[outside], kind="stable")]
    return np.column_stack([close.i[order], close.j[order]]), close.gaps[order]


def singular_network(result, dropped: tuple[int, int]) -> tuple[np.ndarray, int]:
    """The source's network with two of p's contacts (`dropped`, indices among them) left
    out and the two near pairs nearest to contact away from p added: isostatic by count,
    p floppy on its d − 1 contacts, the rest redundant by one. Shape (M, 2), and p."""
    positions, diameters, box = in_mean_diameters(result.packing)
    p, own = floppy_particle(result)
    keep = np.ones(result.contacts.shape[0], dtype=bool)
    keep[own[list(dropped)]] = False
    added, _ = near_pairs_apart_from(positions, diameters, box, result.contacts, p,
                                     result.rattlers)
    return np.concatenate([result.contacts[keep], added[:2]]), p


def jacobian_of(positions, diameters, box, network, rattlers):
    vectors = minimum_image(positions[network[:, 0]] - positions[network[:, 1]], box)
    sigma = 0.5 * (diameters[network[:, 0]] + diameters[network[:, 1]])
    return network_jacobian(vectors, sigma, network[:, 0], network[:, 1], ~rattlers)


def test_the_network_is_isostatic_by_count_and_singular_by_rank(source):
    """The bordered LU finds the floppy mode (p rolling on its d − 1 contacts, Γ fixed) and
    the self-stress (on the redundant rest, none on p's contacts, Σ s = 0 for Γ's column);
    Newton refuses the network."""
    positions, diameters, box = in_mean_diameters(source.packing)
    d = source.packing.d
    network, p = singular_network(source, (0, 1))
    n_stable = int(np.count_nonzero(~source.rattlers))
    assert network.shape[0] == d * (n_stable - 1) + 1
    jacobian = jacobian_of(positions, diameters, box, network, source.rattlers)
    values = np.linalg.svd(jacobian.toarray(), compute_uv=False)
    assert values[-1] < SINGULAR * values[0] and values[-2] > REGULAR * values[0]

    null, stress = singular_vectors(jacobian)
    magnitudes = abs(jacobian)
    assert np.abs(jacobian @ null).max() <= ROUND_OFF * (magnitudes @ np.abs(null)).max()
    assert np.abs(jacobian.T @ stress).max() <= ROUND_OFF * (
        magnitudes.T @ np.abs(stress)).max()
    columns = np.flatnonzero(~source.rattlers)[1:]   # the first stable particle is pinned
    mode = np.zeros((source.packing.n, d))
    mode[columns] = null[:-1].reshape(-1, d)
    moving = np.flatnonzero(np.abs(mode).max(axis=1) > ROUND_OFF)
    assert moving.tolist() == [p] and abs(null[-1]) <= ROUND_OFF
    on_p = (network[:, 0] == p) | (network[:, 1] == p)
    assert np.abs(stress[on_p]).max() <= ROUND_OFF and abs(stress.sum()) <= ROUND_OFF
    assert refine_isostatic(positions, diameters, box, network[:, 0], network[:, 1],
                            ~source.rattlers) is None


@pytest.mark.parametrize("dropped", list(itertools.combinations(range(4), 2)))
def test_a_singular_start_is_repaired_and_the_path_ends_certified(source, dropped):
    """The repair opens a redundant contact of the rest and closes p's floppy mode with a
    pair of p; the pivots then end at a jamming point that `jam` certifies by itself.

    The end is the source packing, or the jamming point next to it: closing the two added
    pairs (relative gaps 5e-5 and 3e-4) moves the repaired vertex ~4e-4 mean diameters from
    the source, farther than the gaps of its near pairs, and this packing holds another
    jamming point 4.7e-8 below it in φ there; the pivots, which only climb from the vertex,
    reach that one (the LP loop from the same vertex returns to the source), as they may
    from the swapped networks of `test_pivots`."""
    positions, diameters, box = in_mean_diameters(source.packing)
    network, p = singular_network(source, dropped)
    path, failure = pivot_to_jamming(positions, diameters, box, network[:, 0], network[:, 1],
                                     source.rattlers)
    assert path is not None and path.jammed, failure
    repair = path.swaps[0]
    assert repair.repaired and path.repairs == 1
    assert "singular Jacobian (1 of them opened a redundant contact" in describe_path(path)
    assert repair.released in {tuple(pair) for pair in network.tolist()}
    assert p not in repair.released and p in repair.closed
    assert all(swap.growth >= 0 for swap in path.swaps)   # Γ never decreases
    assert path.refinement.positive
    assert certified_again(path, box)
    phi = Packing(positions, diameters, box).phi
    change = Packing(path.refinement.positions, path.refinement.diameters, box).phi / phi - 1.0
    if same_network(np.column_stack([path.i, path.j]), source.contacts):
        assert abs(change) < SAME_PHI
    else:
        assert abs(change) < NEIGHBOURING_PHI


@pytest.fixture(scope="module")
def returning_source():
    """Another LS packing at p = 1e7 (d = 3, N = 64, seed 15) jammed by the LP path: from
    its singular networks the path climbs back to it."""
    import generators
    from calippso import jam

    sizes = generators.diameters.monodisperse(64)
    start = generators.lubachevsky_stillinger(sizes, d=3, target_pressure=1e7,
                                              seed=15).packing
    return jam(start, network_first="off")


@pytest.mark.parametrize("dropped", list(itertools.combinations(range(4), 2)))
def test_a_repaired_path_returns_to_the_source(returning_source, dropped):
    """The same singular networks of another packing (added pairs at relative gaps 3e-4 and
    1e-3): the repair and the pivots end at the source packing itself, its network and its
    φ_J to `SAME_PHI`."""
    source = returning_source
    assert_jammed(source)
    positions, diameters, box = in_mean_diameters(source.packing)
    network, p = singular_network(source, dropped)
    path, failure = pivot_to_jamming(positions, diameters, box, network[:, 0], network[:, 1],
                                     source.rattlers)
    assert path is not None and path.jammed, failure
    assert path.swaps[0].repaired and p in path.swaps[0].closed
    assert all(swap.growth >= 0 for swap in path.swaps)
    assert same_network(np.column_stack([path.i, path.j]), source.contacts)
    np.testing.assert_array_equal(path.rattlers, source.rattlers)
    phi = Packing(positions, diameters, box).phi
    assert abs(Packing(path.refinement.positions, path.refinement.diameters, box).phi
               - phi) < SAME_PHI * phi
    assert certified_again(path, box)


def singular_vertex(result) -> tuple[np.ndarray, np.ndarray, np.ndarray, int]:
    """A configuration where every contact of a singular network closes: p held by d
    contacts and one near pair added (an isostatic network), one particle grown until a
    second near pair touches at its Newton point, then one of p's contacts swapped for that
    pair. The first such vertex at which no other pair overlaps: positions (N, d),
    diameters (N,), the network (M, 2) and p."""
    positions, diameters, box = in_mean_diameters(result.packing)
    p, own = floppy_particle(result)
    added, _ = near_pairs_apart_from(positions, diameters, box, result.contacts, p,
                                     result.rattlers)
    for first, second in itertools.permutations(own, 2):
        keep = np.ones(result.contacts.shape[0], dtype=bool)
        keep[first] = False
        held = np.concatenate([result.contacts[keep], added[:1]])   # p held by d contacts
        vertex = refine_isostatic(positions, diameters, box, held[:, 0], held[:, 1],
                                  ~result.rattlers)
        if vertex is None:
            continue
        moved, _ = near_pairs_apart_from(vertex.positions, vertex.diameters, box, held, p,
                                         result.rattlers)
        start = vertex_touching(positions, diameters, box, held, result.rattlers,
                                tuple(moved[0]))
        if start is None:
            continue
        network = np.concatenate([held[np.any(held != result.contacts[second], axis=1)],
                                  moved[:1]])
        _, gaps = near_pairs_apart_from(start.positions, start.diameters, box, network, -1,
                                        result.rattlers)
        if np.all(gaps >= -ROUND_OFF):   # a feasible vertex
            return start.positions, start.diameters, network, p
    pytest.fail("no singular vertex without overlap was made")


def test_a_singular_vertex_is_repaired_with_gamma_growing(source):
    """A start where every contact of the singular network closes (a singular vertex): the
    repair's Γ does not decrease from it, and the path ends certified above it."""
    _, _, box = in_mean_diameters(source.packing)
    positions, diameters, network, p = singular_vertex(source)
    path, failure = pivot_to_jamming(positions, diameters, box, network[:, 0], network[:, 1],
                                     source.rattlers)
    assert path is not None and path.jammed, failure
    assert path.swaps[0].repaired and p in path.swaps[0].closed
    assert all(swap.growth >= 0 for swap in path.swaps)
    assert path.refinement.sqrt_gamma_minus_1 >= 0   # measured from the singular vertex
    assert certified_again(path, box)


def test_a_singular_vertex_solved_as_if_regular_is_repaired(source):
    """The same vertex handed to the pivots as a Newton point, with forces that solve
    Jᵀ f = −e_Γ but are not unique (f + α s for any α: what Newton gives on factors with
    perturbed pivots), one of them negative. Every release leaves a singular network (the
    floppy cluster is still there), so the vertex is repaired, and the path ends certified."""
    _, _, box = in_mean_diameters(source.packing)
    positions, diameters, network, p = singular_vertex(source)
    jacobian = jacobian_of(positions, diameters, box, network, source.rattlers).toarray()
    target = np.zeros(jacobian.shape[0])
    target[-1] = -1.0
    forces, *_ = np.linalg.lstsq(jacobian.T, target, rcond=None)
    assert np.abs(jacobian.T @ forces - target).max() <= ROUND_OFF   # Γ flat: consistent
    _, stress = singular_vectors(sp.csr_matrix(jacobian))
    up = stress > 0
    forces = forces - 2.0 * max(float(np.max(forces[up] / stress[up])), 0.0) * stress
    assert forces.min() < 0
    vertex = Refinement(positions=positions, diameters=diameters, forces=forces, iterations=0,
                        factorizations=0, sqrt_gamma_minus_1=0.0, max_displacement=0.0,
                        residual=0.0)
    path, failure = pivot_to_jamming(positions, diameters, box, network[:, 0], network[:, 1],
                                     source.rattlers, refined=vertex)
    assert path is not None and path.jammed, failure
    assert path.repairs == 1 and p in next(swap.closed for swap in path.swaps
                                           if swap.repaired)
    assert all(swap.growth >= 0 for swap in path.swaps)
    assert certified_again(path, box)


def test_a_network_newton_cannot_solve_for_another_reason_is_not_repaired(source):
    """A regular network from a start too far from its jamming point: Newton fails, the
    Jacobian is not singular, and the path is refused as before."""
    positions, diameters, box = in_mean_diameters(source.packing)
    rng = np.random.default_rng(0)
    far = positions + FAR_MOVE * rng.standard_normal(positions.shape)
    network = source.contacts
    assert refine_isostatic(far, diameters, box, network[:, 0], network[:, 1],
                            ~source.rattlers) is None
    path, failure = pivot_to_jamming(far, diameters, box, network[:, 0], network[:, 1],
                                     source.rattlers)
    assert path is None and "not singular" in failure


def test_network_first_hands_a_network_newton_refuses_to_the_pivots(source, monkeypatch):
    """Network first gives the pivots a network whose Newton solve it cannot make (singular,
    simulated: its own Newton refuses every network), and they end certified with no LP.
    A real singular network of network first keeps every particle on d + 1 contacts or more
    (fewer make it a rattler there), which needs a floppy cluster of four particles in
    d = 3, rare in packings this small: the repair itself is tested above, from the pivots."""
    from calippso import StopReason, jam
    from calippso.certification import network_first
    from test_pivots import swapped_networks

    positions, diameters, box = in_mean_diameters(source.packing)
    network = swapped_networks(source, 1, wanted=1)[0]
    vertex = refine_isostatic(positions, diameters, box, network[:, 0], network[:, 1],
                              ~source.rattlers)
    start = Packing(vertex.positions, vertex.diameters, box)
    monkeypatch.setattr(network_first, "refine_isostatic", lambda *args, **kwargs: None)
    result = jam(start, network=network, network_first="require")
    assert result.stop_reason is StopReason.CERTIFIED_PIVOTS and result.iterations == 0
    assert_jammed(result)
    assert result.force_balance <= BALANCE_TOLERANCE
