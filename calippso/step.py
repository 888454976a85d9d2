"""What one solved LP says: its contacts, rattlers and forces, its largest displacements, and
whether the bound on the displacements held it back.

`analyse` reads an LP's answer into a `Step`; the LP stage (`calippso.stages.lp_step`)
decides from it whether the packing has converged, and `calippso.ilp.next_step_bound` how
the bound adapts.
Lengths are in the loop's units (mean input diameter = 1).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from .complementarity import read_complementarity
from .geometry.contacts import contact_mask, force_balance, isostaticity_gap
from .lp import LinearProgram
from .geometry.contact_network import ContactNetwork
from .geometry.rattlers import remove_rattlers
from .settings import JamSettings
from .solvers import LPSolution

__all__ = ["Step", "analyse", "at_bound", "held_by_bound", "AT_BOUND_TOLERANCE",
           "BINDING_REDUCED_COST"]

#: A displacement within this fraction of the bound sits at the bound (the solver's
#: round-off).
AT_BOUND_TOLERANCE = 1e-6
#: A displacement at the bound limits Γ when its reduced cost |(Aᵀμ)_k| exceeds this fraction
#: of the largest dual (far above the solver's dual feasibility tolerance, far below the
#: reduced cost of a particle that the bound really holds back).
BINDING_REDUCED_COST = 1e-6


@dataclass(frozen=True, eq=False)
class Step:
    """One solved LP and what its duals say.

    Attributes
    ----------
    lp : LinearProgram
        The LP that was solved.
    solution : LPSolution
        Its accepted answer.
    contact_rows : ndarray, shape (M_c,), int
        Rows of `lp` that are contacts between stable particles.
    rattlers : ndarray, shape (N,), bool
        Particles left with fewer than d + 1 contacts (recursively).
    forces : ndarray, shape (M_c,)
        Contact forces f = μ/2 of `contact_rows`, not normalised.
    balance : float
        Largest net force on a stable particle / mean force, at the LP's own geometry.
    max_displacement : float
        Largest |s_iμ| over non-rattlers (mean diameters).
    max_contacting : float
        Largest |s_iμ| over particles with at least one contact, before rattler removal
        (mean diameters).
    stable_fraction : float
        Fraction of the particles that are not rattlers.
    held_by_bound : bool
        Relaxing the bound would increase Γ (`held_by_bound`).
    offered_warm_start : bool
        The LP was given the previous LP's basis.
    wall_rows : ndarray, shape (K_c,), int
        Rows of `lp.walls` that are contacts of a stable particle with a wall.
    wall_forces : ndarray, shape (K_c,)
        Their forces f = μ/2, in the units of `forces`.
    """

    lp: LinearProgram
    solution: LPSolution
    contact_rows: np.ndarray
    rattlers: np.ndarray
    forces: np.ndarray
    balance: float
    max_displacement: float
    max_contacting: float
    stable_fraction: float
    held_by_bound: bool
    offered_warm_start: bool = False
    wall_rows: np.ndarray = field(default_factory=lambda: np.zeros(0, np.int64))
    wall_forces: np.ndarray = field(default_factory=lambda: np.zeros(0))

    @property
    def displacements(self) -> np.ndarray:
        """The LP's displacements s*, shape (N, d) (mean diameters)."""
        return self.solution.x[:-1].reshape(self.lp.n, self.lp.d)

    @property
    def n_contacts(self) -> int:
        """Contacts of stable particles: with each other and with walls."""
        return int(self.contact_rows.shape[0] + self.wall_rows.shape[0])

    @property
    def hypostatic(self) -> bool:
        """Fewer contacts than d N_s + 1 − zero modes, or no stable particle at all."""
        n_stable = int(self.rattlers.size - self.rattlers.sum())
        return n_stable == 0 or isostaticity_gap(self.n_contacts, n_stable, self.lp.d,
                                                 self.lp.zero_modes) < 0

    @property
    def needs_cold_resolve(self) -> bool:
        """A warm-started vertex with a hypostatic network, not held back by the bound.

        Such a vertex is solved again from scratch (`SolverPolicy.cold_resolve`): at a
        degenerate optimum the simplex can stop at a vertex whose duals leave contacts out.
        When the bound holds a particle back (`held_by_bound`), the bound stands in for the
        missing contact instead, and the cold solve ends with the same deficit.
        """
        return self.solution.warm_started and self.hypostatic and not self.held_by_bound

    @property
    def normalization(self) -> float:
        """Σ μ σ² / (2 |r|) over the rows (wall rows included): 1 at an exact optimum."""
        return float(self.solution.duals @ self.lp.gamma_coefficients)

    def network(self) -> ContactNetwork:
        """The LP's contact network, with the forces of its duals."""
        pairs, rows = self.lp.pairs, self.contact_rows
        walls = self.lp.walls.subset(self.wall_rows)
        return ContactNetwork(pairs.i[rows], pairs.j[rows], self.forces, self.rattlers,
                              self.normalization, self.solution.solver, from_lp=True,
                              wall_particle=walls.particle, wall=walls.wall,
                              wall_forces=self.wall_forces)


def analyse(lp: LinearProgram, solution: LPSolution, settings: JamSettings,
            stable: np.ndarray | None = None, offered_warm_start: bool = False) -> Step:
    """Read an LP's answer: contacts, rattlers, forces and their balance, the largest
    displacements.

    The contacts of a vertex are the rows whose duals exceed `contact_threshold` × the
    largest; those of an interior solution, with ``crossover="off"``, the rows that strict
    complementarity reads as contacts (`calippso.complementarity`); of any other interior
    solution, the duals above `interior_contact_threshold` × the largest.

    Parameters
    ----------
    lp : LinearProgram
        The LP that was solved (N particles in d dimensions).
    solution : LPSolution
        Its answer.
    settings : JamSettings
        `contact_threshold` for a vertex solution, `interior_contact_threshold` otherwise.
    stable : ndarray, shape (N,), bool, optional
        Particles known to be stable; the others count as rattlers (the force clean-up LP).
    offered_warm_start : bool
        The LP was given the previous LP's basis (kept on the `Step`).

    Returns
    -------
    Step
    """
    n, d = lp.n, lp.d
    if not solution.vertex and settings.crossover == "off":
        every = np.flatnonzero(read_complementarity(lp, solution).contacts)
    else:
        threshold = (settings.contact_threshold if solution.vertex
                     else settings.interior_contact_threshold)
        every = np.flatnonzero(contact_mask(solution.duals, threshold))
    pairs, m = lp.pairs, len(lp.pairs)
    rows, wall_rows = every[every < m], every[every >= m] - m
    wall_particle = lp.walls.particle[wall_rows]
    contacting = np.zeros(n, dtype=bool)
    contacting[pairs.i[rows]] = contacting[pairs.j[rows]] = True
    contacting[wall_particle] = True
    rattlers, kept = remove_rattlers(n, d, pairs.i[rows], pairs.j[rows],
                                     wall_particle if len(lp.walls) else None)
    if stable is not None:
        rattlers |= ~stable
    rows = rows[kept]
    wall_rows = wall_rows[~rattlers[wall_particle]]
    forces = 0.5 * solution.duals[rows]
    wall_forces = 0.5 * solution.duals[m + wall_rows]
    normals = pairs.vectors[rows] / pairs.distances[rows, None]
    walls = (lp.walls.particle[wall_rows], lp.walls.normals[wall_rows], wall_forces)
    balance = force_balance(n, pairs.i[rows], pairs.j[rows], normals, forces, ~rattlers,
                            walls if len(lp.walls) else None)
    s = solution.x[:-1].reshape(n, d)
    free = (lp.col_upper[:-1].reshape(n, d) > 0).any(axis=1)
    max_contacting = float(np.abs(s[contacting & free]).max(initial=0.0))
    # with no stable particle at all, the steps of particles with a contact count: a run is
    # not converged just because rattler removal emptied its network
    max_displacement = (float(np.abs(s[~rattlers & free]).max(initial=0.0))
                        if (~rattlers).any() else max_contacting)
    return Step(lp, solution, rows, rattlers, forces, balance, max_displacement,
                max_contacting, float(np.count_nonzero(~rattlers)) / n,
                held_by_bound(lp, solution), offered_warm_start, wall_rows, wall_forces)


def at_bound(displacement: float | np.ndarray, bound: float) -> bool | np.ndarray:
    """Whether a displacement (float or array) equals the bound, up to the solver's round-off
    (`AT_BOUND_TOLERANCE`)."""
    return displacement >= bound * (1.0 - AT_BOUND_TOLERANCE)


def held_by_bound(lp: LinearProgram, solution: LPSolution) -> bool:
    """Whether the bound on the displacements limited Γ in this LP.

    At the optimum, a displacement s_k strictly inside its bound has a zero reduced cost
    (Aᵀμ)_k: the forces on that particle balance along k. A non-zero one at the bound is the
    bound's own multiplier, the rate at which Γ would grow if the bound were relaxed.
    """
    if solution.duals.size == 0:
        return False
    largest = float(solution.duals.max())
    if largest <= 0:
        return False
    s = solution.x[:-1]
    free = lp.col_upper[:-1] > 0
    pressed = free & at_bound(np.abs(s), lp.step_bound)
    if not pressed.any():
        return False
    reduced = (lp.matrix.T @ solution.duals)[:-1]
    return bool(np.any(np.abs(reduced[pressed]) > BINDING_REDUCED_COST * largest))
