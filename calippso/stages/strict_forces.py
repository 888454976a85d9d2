"""The forces of a deformable box's final network: in balance on every stable particle with
an isotropic stress on the periodic axes, at the final geometry.

`balanced_network` projects the last LP's forces onto those forces (least squares, or an LP
towards the forces whose smallest is largest when the projection has a non-positive one),
and reads the touching pairs instead at a degenerate optimum of a periodic box (a crystal).
`StrictNetwork` holds a network with its forces, the wall contacts' included;
`balance_of` is its force balance. Used by `calippso.stages.strict_finish`.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp

from scipy.optimize import linprog
from scipy.sparse.linalg import lsmr

from ..certification.strict_newton import NEAR_CONTACT
from ..deformable import strain_coefficients, strict_zero_modes
from ..geometry.contact_network import GEOMETRIC_CONTACT_GAP, ContactNetwork
from ..geometry.contacts import force_balance, isostaticity_gap
from ..geometry.packing import Packing
from ..geometry.rattlers import remove_rattlers
from ..geometry.sheared_search import sheared_pairs_within
from ..geometry.walls import wall_equilibrium_columns, wall_rows_of
from ..history import History

__all__ = ["StrictNetwork", "balanced_network", "balance_of"]

#: Tolerances, condition limit (none) and iteration cap of the least-squares projection of
#: the final forces, and its largest number of passes: each pass projects the last one's
#: round-off, the residual does not fall steadily, and the best pass is kept (at N = 1024 in
#: d = 3, one pass leaves a net force of 1e-12 to 2e-12 of the mean force, the best of five
#: 1e-13 to 7e-13).
LSMR_TOLERANCE = 1e-16
LSMR_CONDITION_LIMIT = 1e20
LSMR_ITERATIONS = 100_000
PROJECTION_PASSES = 5
#: The passes stop once the largest residual is below this fraction of the mean force.
PROJECTION_TARGET = 1e-14


@dataclass(frozen=True)
class StrictNetwork:
    """A contact network with its forces: pairs (i, j, forces, shape (M,)), wall contacts
    (`walls` (K, 2) particle, wall; `wall_forces` (K,)) and rattlers (N,), bool."""

    i: np.ndarray
    j: np.ndarray
    forces: np.ndarray
    walls: np.ndarray
    wall_forces: np.ndarray
    rattlers: np.ndarray

    @classmethod
    def of(cls, network: ContactNetwork) -> "StrictNetwork":
        """The network's contacts with its forces scaled to mean 1 (wall forces included)."""
        return cls(network.i, network.j, network.forces,
                   np.stack([network.wall_particle, network.wall], axis=1).astype(np.int64),
                   network.wall_forces, network.rattlers).normalized()

    @property
    def n_contacts(self) -> int:
        """Contacts with particles and walls."""
        return int(self.i.shape[0] + self.walls.shape[0])

    @property
    def every_force(self) -> np.ndarray:
        """The pair forces, then the wall forces, shape (M + K,)."""
        return np.concatenate([self.forces, self.wall_forces])

    def normalized(self) -> "StrictNetwork":
        """The forces scaled to mean 1 (unchanged without a contact)."""
        every = self.every_force
        mean = float(every.mean()) if every.size else 1.0
        return self.with_forces(every / (mean or 1.0))

    def with_forces(self, every: np.ndarray) -> "StrictNetwork":
        """These contacts with the forces `every` (pairs, then walls), shape (M + K,)."""
        m = self.i.shape[0]
        return StrictNetwork(self.i, self.j, every[:m], self.walls, every[m:], self.rattlers)

    def subset(self, kept: np.ndarray, wall_kept: np.ndarray,
               rattlers: np.ndarray) -> "StrictNetwork":
        """The contacts kept (boolean masks over pairs and walls), with new rattlers."""
        return StrictNetwork(self.i[kept], self.j[kept], self.forces[kept], self.walls[wall_kept],
                       self.wall_forces[wall_kept], rattlers)


def balanced_network(packing: Packing, network: StrictNetwork,
                     history: History) -> tuple[StrictNetwork, float]:
    """The contact network and forces at the final geometry.

    The last LP's contacts and forces, projected onto the forces in equilibrium with an
    isotropic stress (on the periodic axes) at the final positions (`_balanced_forces`). At
    a degenerate optimum (a crystal: the vertex puts its duals on too few rows, the network
    looks hypostatic), the touching pairs (h < `GEOMETRIC_CONTACT_GAP`) with the balanced
    forces nearest to uniform replace it, when those are all positive (in a periodic box:
    a container keeps the LP's network).

    Returns
    -------
    (StrictNetwork, float)
        The network with forces of mean 1, and its force balance.
    """
    n, d = packing.n, packing.d
    rattlers, kept = remove_rattlers(n, d, network.i, network.j, network.walls[:, 0])
    network = network.subset(kept, ~rattlers[network.walls[:, 0]], rattlers)
    balanced = _balanced_forces(packing, network)
    n_stable = int(n - rattlers.sum())
    zero_modes = strict_zero_modes(packing.boundaries)
    if packing.boundaries.is_periodic and (
            n_stable == 0 or isostaticity_gap(network.n_contacts, n_stable, d, zero_modes) < 0):
        close = sheared_pairs_within(packing.positions, packing.diameters, packing.search_cell,
                                     float(packing.diameters.max()) * (1.0 + NEAR_CONTACT))
        touching = close.subset(close.gaps < GEOMETRIC_CONTACT_GAP)
        t_rattlers, t_kept = remove_rattlers(n, d, touching.i, touching.j)
        ti, tj = touching.i[t_kept], touching.j[t_kept]
        if (int(n - t_rattlers.sum()), ti.shape[0]) > (n_stable, network.i.shape[0]):
            candidate = StrictNetwork(ti, tj, np.ones(ti.shape[0]), network.walls[:0],
                                network.wall_forces[:0], t_rattlers)
            uniform = _balanced_forces(packing, candidate)
            if uniform is not None:
                history.note(f"contacts taken from the touching pairs (h < "
                             f"{GEOMETRIC_CONTACT_GAP:g}): the LP duals are degenerate here; "
                             f"forces are the balanced, isotropic ones nearest to uniform")
                network, balanced = candidate, uniform
    if balanced is None:
        network = network.normalized()
        balance = balance_of(packing, network)
        if network.n_contacts:
            history.note(f"no positive forces balance the network with an isotropic stress at "
                         f"the final positions: the last LP's forces are kept (force balance "
                         f"{balance:.1e}), no certificate")
        return network, balance
    network = network.with_forces(balanced).normalized()
    return network, balance_of(packing, network)


def _equilibrium(packing: Packing, network: StrictNetwork) -> tuple[sp.csr_matrix, np.ndarray,
                                                                 np.ndarray]:
    """The matrix whose null space holds the forces f (pairs, then walls) in equilibrium on
    every particle with an isotropic stress on the periodic axes: d rows per particle
    (Σ f n, walls' inward normals included), then the deviatoric stress of the periodic
    axes (the strain columns but the trace, `calippso.deformable.strain_coefficients`);
    and the unit normals of the pairs and of the walls."""
    n, d, boundaries = packing.n, packing.d, packing.boundaries
    i, j = network.i, network.j
    vectors = packing.minimum_image(packing.positions[i] - packing.positions[j])
    distances = np.linalg.norm(vectors, axis=1)
    normals = vectors / distances[:, None]
    walls = wall_rows_of(packing.positions, packing.diameters, packing.box, network.walls[:, 0],
                         network.walls[:, 1], boundaries.cylinder_axes)
    m = i.shape[0]
    coordinate = np.arange(d)
    rows = np.concatenate([(i[:, None] * d + coordinate).ravel(),
                           (j[:, None] * d + coordinate).ravel()])
    columns = np.concatenate([np.repeat(np.arange(m), d)] * 2)
    values = np.concatenate([normals.ravel(), -normals.ravel()])
    balance = sp.hstack([sp.csr_matrix((values, (rows, columns)), shape=(n * d, m)),
                         wall_equilibrium_columns(n, walls.particle, walls.normals)])
    deviatoric = strain_coefficients(vectors, distances, boundaries.periodic)[:, :-1].T
    stress_rows = sp.hstack([sp.csr_matrix(deviatoric),
                             sp.csr_matrix((deviatoric.shape[0], len(walls)))])
    return sp.vstack([balance, stress_rows]).tocsr(), normals, walls.normals


def _balanced_forces(packing: Packing, network: StrictNetwork) -> np.ndarray | None:
    """Positive forces (pairs, then walls) in equilibrium with an isotropic stress at the
    packing's geometry: those nearest to the network's (least squares), or, when one of
    those is not positive, the point towards the forces whose smallest is largest (an LP)
    where the smallest force reaches half that largest value; None when no positive such
    forces exist."""
    if not network.n_contacts:
        return None
    matrix, _, _ = _equilibrium(packing, network)
    nearest = _projected(matrix, network.every_force)
    if nearest.min() > 0:
        return nearest
    m = network.n_contacts
    # variables (f, t): maximise t subject to A f = 0, Σ f = m, f ≥ t
    equalities = sp.vstack([sp.hstack([matrix, sp.csr_matrix((matrix.shape[0], 1))]),
                            sp.csr_matrix(np.append(np.ones(m), 0.0)[None, :])]).tocsr()
    answer = linprog(np.append(np.zeros(m), -1.0), A_eq=equalities,
                     b_eq=np.append(np.zeros(matrix.shape[0]), float(m)),
                     A_ub=sp.hstack([-sp.identity(m), np.ones((m, 1))]).tocsr(),
                     b_ub=np.zeros(m), bounds=[(0, None)] * m + [(None, None)],
                     method="highs")
    if answer.status != 0 or not answer.x[-1] > 0:
        return None
    widest, smallest = answer.x[:m], float(answer.x[-1])
    nearest *= m / nearest.sum()
    # the largest share of `nearest` with every force at least half the LP's smallest one
    below = nearest < 0.5 * smallest
    share = np.min((widest[below] - 0.5 * smallest) / (widest[below] - nearest[below]),
                   initial=1.0)
    blended = _projected(matrix, share * nearest + (1.0 - share) * widest)
    return blended if blended.min() > 0 else None


def _projected(matrix: sp.csr_matrix, forces: np.ndarray) -> np.ndarray:
    """`forces` projected onto the null space of `matrix` (least squares, LSMR run to the
    machine's precision): up to `PROJECTION_PASSES` passes, each projecting the last one's
    round-off; the pass with the smallest largest residual |matrix @ forces| relative to the
    mean force is returned (the passes stop once it is below `PROJECTION_TARGET`)."""
    transposed = matrix.T.tocsr()
    best, smallest = forces, float("inf")
    for _ in range(PROJECTION_PASSES):
        correction = lsmr(transposed, forces, atol=LSMR_TOLERANCE, btol=LSMR_TOLERANCE,
                          conlim=LSMR_CONDITION_LIMIT, maxiter=LSMR_ITERATIONS)[0]
        forces = forces - transposed @ correction
        scale = abs(float(forces.mean())) or 1.0
        residual = float(np.abs(matrix @ forces).max(initial=0.0)) / scale
        if residual < smallest:
            best, smallest = forces, residual
        if smallest < PROJECTION_TARGET:
            break
    return best


def balance_of(packing: Packing, network: StrictNetwork) -> float:
    """max over stable particles of |Σ f n| (walls included) / mean force, at the packing's
    geometry."""
    if not network.n_contacts:
        return 0.0
    _, normals, wall_normals = _equilibrium(packing, network)
    return force_balance(packing.n, network.i, network.j, normals, network.forces,
                         ~network.rattlers,
                         (network.walls[:, 0], wall_normals, network.wall_forces))
