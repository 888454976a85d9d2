"""From LP duals to the contact network: contacts, forces, stress, isostaticity, balance.

`remove_rattlers` lives in `calippso.geometry.rattlers` (the generators use it too); it is imported
here as well, for the modules that take it from this one.
"""

from __future__ import annotations

import numpy as np

from .rattlers import remove_rattlers

__all__ = ["contact_mask", "remove_rattlers", "net_forces", "force_balance",
           "isostaticity_gap", "equilibrium_matrix", "polish_forces", "positive_self_stress",
           "contact_stress", "stress_reading"]

#: `positive_self_stress` takes forces as balanced when the largest net force is below this
#: times the largest force.
SELF_STRESS_TOLERANCE = 1e-10


def contact_mask(duals: np.ndarray, relative_threshold: float) -> np.ndarray:
    """Rows whose dual exceeds `relative_threshold` × the largest dual, shape (M,), bool."""
    if duals.size == 0:
        return np.zeros(0, dtype=bool)
    largest = float(duals.max())
    if largest <= 0:
        return np.zeros(duals.shape, dtype=bool)
    return duals > relative_threshold * largest


def net_forces(n: int, i: np.ndarray, j: np.ndarray, normals: np.ndarray,
               forces: np.ndarray) -> np.ndarray:
    """Net contact force on every particle, shape (N, d).

    The force on i from j is f_ij n_ij with n_ij the unit vector from j to i (repulsion); j
    receives the opposite.
    """
    d = normals.shape[1]
    vectors = forces[:, None] * normals
    total = np.zeros((n, d))
    for axis in range(d):
        total[:, axis] = (np.bincount(i, vectors[:, axis], minlength=n)
                          - np.bincount(j, vectors[:, axis], minlength=n))
    return total


def force_balance(n: int, i: np.ndarray, j: np.ndarray, normals: np.ndarray,
                  forces: np.ndarray, stable: np.ndarray,
                  walls: tuple[np.ndarray, np.ndarray, np.ndarray] | None = None) -> float:
    """max over stable particles of |Σ_j f_ij n_ij| / mean force (0 when there is no force).

    `walls`, when given, is (particle, inward normals (K, d), forces) of the wall contacts
    (`calippso.geometry.walls`): their forces enter the net force and the mean.
    """
    all_forces = forces if walls is None else np.concatenate([forces, walls[2]])
    if all_forces.size == 0 or not stable.any():
        return 0.0
    mean = float(all_forces.mean())
    if mean <= 0:
        return 0.0
    total = net_forces(n, i, j, normals, forces)
    if walls is not None:
        from .walls import wall_net_forces

        total += wall_net_forces(n, *walls)
    total = total[stable]
    return float(np.sqrt(np.einsum("nd,nd->n", total, total)).max() / mean)


def isostaticity_gap(n_contacts: int, n_stable: int, d: int,
                     zero_modes: int | None = None) -> int:
    """N_c − (d N_s + 1 − zero modes): zero for an isostatic packing (N_c itself when nothing
    is stable).

    In a periodic box the zero modes are the d translations, and the count is the familiar
    N_c − d (N_s − 1) − 1. With walls (`calippso.geometry.boundaries.Boundaries.zero_modes`) only the
    translations along periodic axes are left, and N_c counts the wall contacts too.
    """
    if n_stable == 0:
        return n_contacts
    zero_modes = d if zero_modes is None else zero_modes
    return n_contacts - d * n_stable - 1 + zero_modes


def equilibrium_matrix(n: int, i: np.ndarray, j: np.ndarray, normals: np.ndarray):
    """The (n·d, M) sparse matrix mapping contact forces to the net force on each particle.

    Column k holds +n_k in the rows of particle i_k and −n_k in those of j_k, so that the
    product with the forces f is Σ_j f_ij n_ij for every particle (flattened, particle-major).
    """
    from scipy.sparse import csr_matrix

    m, d = normals.shape
    contact = np.arange(m)
    rows = np.concatenate([(i[:, None] * d + np.arange(d)).ravel(),
                           (j[:, None] * d + np.arange(d)).ravel()])
    cols = np.concatenate([np.repeat(contact, d), np.repeat(contact, d)])
    values = np.concatenate([normals.ravel(), -normals.ravel()])
    return csr_matrix((values, (rows, cols)), shape=(n * d, m))


def polish_forces(n: int, i: np.ndarray, j: np.ndarray, normals: np.ndarray,
                  weights: np.ndarray, forces: np.ndarray, extra=None) -> np.ndarray:
    """Refine contact forces so that every particle is in balance to round-off.

    Solves, by sparse least squares started from `forces`, the equilibrium equations
    Σ_j f_ij n_ij = 0 for every particle together with the normalisation Σ weights·f = 1.
    For an isostatic network the solution is the unique self-stress; interior-point duals
    (balanced only to the solver tolerance) converge to it in a few iterations.

    Parameters
    ----------
    n : int
        Number of particles.
    i, j : ndarray, shape (M,)
        Contacts.
    normals : ndarray, shape (M, d)
        Unit vectors n_ij from j to i.
    weights : ndarray, shape (M,)
        Coefficients of the normalisation (2σ_ij²/(2|r_ij|) for f = μ/2).
    forces : ndarray, shape (M,)
        Starting forces (e.g. the duals / 2).
    extra : scipy.sparse matrix, shape (n·d, K), optional
        Further columns of the equilibrium matrix (the wall contacts,
        `calippso.geometry.walls.wall_equilibrium_columns`); `weights` and `forces` then have
        M + K entries, the pairs' first.

    Returns
    -------
    ndarray, shape (M,) or (M + K,)
        Polished forces, scaled so that weights·f = 1.
    """
    from scipy.sparse import csr_matrix, hstack, vstack
    from scipy.sparse.linalg import lsqr

    m = forces.shape[0]
    equilibrium = equilibrium_matrix(n, i, j, normals)
    if extra is not None:
        equilibrium = hstack([equilibrium, extra])
    system = vstack([equilibrium, csr_matrix(weights[None, :])]).tocsr()
    target = np.zeros(system.shape[0])
    target[-1] = 1.0
    start = forces / float(weights @ forces)
    correction = lsqr(system, target - system @ start, atol=1e-16, btol=1e-16,
                      iter_lim=20 * m)[0]
    polished = start + correction
    return polished / float(weights @ polished)


def positive_self_stress(n: int, i: np.ndarray, j: np.ndarray, normals: np.ndarray,
                         weights: np.ndarray, extra=None) -> np.ndarray | None:
    """A self-stress of the network with every force positive, as close to uniform as found.

    A hyperstatic network (more contacts than the isostatic count) has a space of
    self-stresses. The one nearest to uniform forces (least squares) is returned when all its
    forces are positive. Otherwise the self-stress whose smallest force is largest is found
    by an LP (scipy's HiGHS), and the returned forces are the point on the segment from the
    least-squares self-stress to it where the smallest force first reaches half that largest
    value: as uniform as this segment allows, with every contact carrying force. (If the
    least-squares forces are not balanced, the network has no self-stress near uniform and
    the LP's self-stress is returned as it is.)

    Parameters
    ----------
    n : int
        Number of particles.
    i, j : ndarray, shape (M,)
        Contacts.
    normals : ndarray, shape (M, d)
        Unit vectors n_ij from j to i.
    weights : ndarray, shape (M,) or (M + K,)
        Coefficients of the normalisation Σ weights·f = 1.
    extra : scipy.sparse matrix, shape (n·d, K), optional
        Further columns of the equilibrium matrix (wall contacts, as in `polish_forces`).

    Returns
    -------
    ndarray, shape (M,) or (M + K,), or None
        Forces in balance on every particle, normalised so that weights·f = 1; None when the
        network has no self-stress with all forces positive.
    """
    from scipy.optimize import linprog
    from scipy.sparse import csr_matrix, hstack, identity, vstack

    m = weights.shape[0]
    equilibrium = equilibrium_matrix(n, i, j, normals)
    if extra is not None:
        equilibrium = hstack([equilibrium, extra]).tocsr()
    uniform = polish_forces(n, i, j, normals, weights, np.ones(m), extra)
    balanced = np.abs(equilibrium @ uniform).max() <= SELF_STRESS_TOLERANCE * np.abs(uniform).max()
    if balanced and uniform.min() > 0:
        return uniform
    # variables (f, t): maximise t subject to A f = 0, weights·f = 1, f ≥ t
    equalities = vstack([hstack([equilibrium, csr_matrix((equilibrium.shape[0], 1))]),
                         csr_matrix(np.append(weights, 0.0)[None, :])])
    right_hand = np.zeros(equalities.shape[0])
    right_hand[-1] = 1.0
    floors = hstack([-identity(m), csr_matrix(np.ones((m, 1)))])
    cost = np.zeros(m + 1)
    cost[-1] = -1.0
    solution = linprog(cost, A_ub=floors.tocsr(), b_ub=np.zeros(m), A_eq=equalities.tocsr(),
                       b_eq=right_hand, bounds=[(0, None)] * m + [(None, None)],
                       method="highs", options={"primal_feasibility_tolerance": 1e-10,
                                                "dual_feasibility_tolerance": 1e-10})
    if solution.status != 0 or solution.x[-1] <= 0:
        return None
    widest = polish_forces(n, i, j, normals, weights, solution.x[:-1], extra)
    floor = 0.5 * float(widest.min())
    if floor <= 0:
        return None
    if not balanced:
        return widest
    low = uniform < floor
    mix = float(np.max((floor - uniform[low]) / (widest[low] - uniform[low])))
    return uniform + min(mix, 1.0) * (widest - uniform)


def contact_stress(vectors: np.ndarray, forces: np.ndarray, volume: float) -> np.ndarray:
    """The contact stress tensor Σ_k f_k |r_k| n_k n_kᵀ / V, shape (d, d), symmetric.

    Parameters
    ----------
    vectors : ndarray, shape (M, d)
        Contact vectors r_k (length units).
    forces : ndarray, shape (M,)
        Contact forces f_k (any force unit).
    volume : float
        Box volume V (length units^d); 1 gives the stress's sum unscaled.
    """
    distances = np.linalg.norm(vectors, axis=1)
    stress = np.einsum("k,ka,kb->ab", forces / distances, vectors, vectors) / volume
    return 0.5 * (stress + stress.T)


def stress_reading(stress: np.ndarray, periodic: np.ndarray) -> tuple[float, float]:
    """The pressure p = tr/d_p of the periodic block of `stress` (shape (d, d); `periodic`
    (d,), bool) and that block's anisotropy max |stress − p I| / p (NaN when p ≤ 0)."""
    block = stress[np.ix_(periodic, periodic)]
    pressure = float(np.trace(block)) / block.shape[0]
    if not pressure > 0:
        return pressure, float("nan")
    return pressure, float(np.abs(block - pressure * np.eye(block.shape[0])).max()) / pressure
