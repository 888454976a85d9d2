"""Damped Newton (Levenberg–Marquardt) minimisation of the soft-sphere enthalpy.

The same function, degrees of freedom and convergence test as `_fire.fire_run` and
`_lbfgs.lbfgs_run`: positions x (shape (N, d)) and u = √(N d) λ, λ = ln a the logarithm of
the diameter scale, the enthalpy H = E + p* Ṽ with Ṽ = V / a^d.

Every term of the energy (a pair, a particle against a flat wall or against the cylinder) is
E_t = ½ h_t² where its overlap h_t > 0, and each overlap has the form h = c + e^{−λ} w(x)/s:

- a pair: c = 1, w = −|r_ij|, s = (s_i + s_j)/2 (h = 1 − r/σ);
- a flat wall: c = ½, w = −δ (the centre's distance to the wall), s = s_i;
- the cylinder: c = ½, w = ρ − L/2 (ρ the centre's distance from its axis), s = s_i.

Hence ∂h/∂λ = c − h, ∂²h/∂λ² = h − c and ∂²h/∂x∂λ = −∂h/∂x, and the Hessian of E is
Σ (∇h ∇hᵀ + h ∇²h) over the overlapping terms, in vectorised numpy from the listed pairs:
sparse (d × d blocks) in x, with one dense row and column for u.

Each iteration solves (∇²H + μ I) δ = −∇H: the x block is factorised once (SuperLU in
symmetric mode) and u eliminated by its Schur complement (two solves). The enthalpy itself is
the merit. Along the damped step a line search looks for sufficient decrease (Armijo), its
trial steps the secants of the slope (H is piecewise quadratic along a line while the overlap
set does not change); once found, μ follows the ratio ρ of the actual to the predicted
decrease of H (Nielsen's rule: μ ← μ max(1/3, 1 − (2ρ − 1)³)), and when none is found
μ ← ν μ, ν ← 2 ν (Madsen, Nielsen & Tingleff, Methods for non-linear least squares problems
(2004), sec. 3.2). H is C¹ and piecewise smooth (pairs enter and leave the overlap set),
which a plain Newton step ignores; the line search and the damping globalise it, and the
damping handles the zero modes (rattlers, translations) since K + μ I is non-singular.

The factorised matrix is the Gauss–Newton part Σ ∇h ∇hᵀ (positive semi-definite; exact as
p → 0). The exact Hessian (`hessian(exact=True)`) adds the stress term h ∇²h, negative along
the floppy directions of a contact, which can leave the damped matrix indefinite
(docs/notes/soft-quench-protocol.md, Damped Newton).
The actual decrease is
(E₁ − E₀) + p* Ṽ₀ expm1(−d Δλ), free of the round-off of p* Ṽ; when the predicted decrease
is within the round-off of E, a step is taken when it does not increase |∇H|.

No particle moves by more than `MOVE_FRACTION` × the Verlet skin in one step (nor does the
largest diameter grow by more), and the lists are rebuilt before a step could outrun them.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp
from scipy.sparse.linalg import splu

from ._fire import CONVERGED, OUT_OF_STEPS, REBUILD, converged, container_volume

__all__ = ["LOG_SCALE", "STATE_SIZE", "Terms", "evaluate", "gradient", "hessian", "new_state",
           "newton_run"]

#: Largest move of a particle (and growth of the largest diameter) in one step, × the skin.
MOVE_FRACTION = 0.25
#: Starting damping μ of a minimisation (units of ε/σ²: a contact's stiffness is ~1).
MU_START = 1e-3
#: Smallest damping: far below the softest non-zero mode near jamming (~p), large enough to
#: keep K + μ I non-singular along the zero modes.
MU_MIN = 1e-14
#: Nielsen's rule: smallest factor on μ after a successful step, and the initial ν.
MU_SHRINK = 1.0 / 3.0
NU_START = 2.0
#: Round-off of the energy change, × machine epsilon × Σ h of the overlapping terms (each h
#: carries the round-off ~ε of |r|/σ): a predicted decrease below it is not resolved.
ENERGY_ROUNDOFF = 100.0
#: Sufficient decrease of a step (Armijo's c1), evaluations allowed to its line search, and
#: how far its trial steps stay from the ends of the bracket (fraction of it).
ARMIJO = 1e-4
LINE_SEARCH_EVALUATIONS = 8
BRACKET_MARGIN = 0.1
#: Layout of the state array: λ, μ, ν, solves since the minimisation began.
LOG_SCALE, MU, NU, SOLVES = 0, 1, 2, 3
STATE_SIZE = 4


def new_state(log_scale: float) -> np.ndarray:
    """State array of a minimisation that starts at λ = `log_scale`, shape (STATE_SIZE,)."""
    state = np.zeros(STATE_SIZE)
    state[LOG_SCALE], state[MU], state[NU] = log_scale, MU_START, NU_START
    return state


@dataclass
class Terms:
    """The overlapping terms of the energy at one configuration.

    Attributes
    ----------
    particle : ndarray of int64, shape (K,)
        The particle of each term (the lower one of a pair).
    partner : ndarray of int64, shape (K,)
        The other particle of a pair, −1 for a wall or the cylinder.
    h : ndarray, shape (K,)
        Overlaps h > 0 (relative).
    offset : ndarray, shape (K,)
        c of each term (1 for a pair, ½ for a wall).
    sigma : ndarray, shape (K,)
        σ of each term (pair: (σ_i + σ_j)/2; wall: σ_i), mean diameters.
    grad : ndarray, shape (K, d)
        ∂h/∂x of `particle` (a pair's `partner` has −grad).
    curvature : ndarray, shape (K, d, d)
        ∂²h/∂x² of `particle` (a pair: also of `partner`, and −this across the two).
    energy : float
        E = Σ h²/2.
    """

    particle: np.ndarray
    partner: np.ndarray
    h: np.ndarray
    offset: np.ndarray
    sigma: np.ndarray
    grad: np.ndarray
    curvature: np.ndarray
    energy: float


def evaluate(x: np.ndarray, s: np.ndarray, scale: float, box: np.ndarray,
             first: np.ndarray, second: np.ndarray, periodic: np.ndarray,
             cylinder: tuple[int, int]) -> Terms:
    """The overlapping terms at positions x and diameter scale a.

    Parameters
    ----------
    x : ndarray, shape (N, d)
        Positions (mean diameters).
    s : ndarray, shape (N,)
        Nominal diameters; the diameters are `scale` · s.
    scale : float
        Diameter scale a.
    box : ndarray, shape (d,)
    first, second : ndarray of int64
        Pair lists (`_fire.pair_lists`): pairs k in ``first[i]:first[i + 1]`` are (i,
        second[k]).
    periodic : ndarray, shape (d,), bool
        Periodic axes (minimum image); flat walls at 0 and L_μ along the others, except the
        cylinder's.
    cylinder : tuple of int
        The cylinder's two axes, or `_fire.NO_CYLINDER`.
    """
    n, d = x.shape
    i = np.repeat(np.arange(n, dtype=np.int64), np.diff(first))
    j = second
    r_vec = x[i] - x[j]
    for mu in np.flatnonzero(periodic):
        r_vec[:, mu] -= box[mu] * np.rint(r_vec[:, mu] * (1.0 / box[mu]))
    r = np.sqrt(np.einsum("kd,kd->k", r_vec, r_vec))
    sigma = 0.5 * scale * (s[i] + s[j])
    h = 1.0 - r / sigma
    on = h > 0.0
    i, j, r_vec, r, sigma, h = i[on], j[on], r_vec[on], r[on], sigma[on], h[on]
    unit = r_vec / r[:, None]
    eye = np.eye(d)
    projector = eye[None] - unit[:, :, None] * unit[:, None, :]
    parts = [(i, j, h, np.ones_like(h), sigma, -unit / sigma[:, None],
              -projector / (sigma * r)[:, None, None])]
    sizes = scale * s
    flat = ~np.asarray(periodic, dtype=bool)
    if cylinder[0] >= 0:
        flat[list(cylinder)] = False
    for mu in np.flatnonzero(flat):
        for side, distance in enumerate((x[:, mu], box[mu] - x[:, mu])):
            overlap = 0.5 - distance / sizes
            hit = np.flatnonzero(overlap > 0.0)
            grad = np.zeros((hit.size, d))
            grad[:, mu] = (2 * side - 1) / sizes[hit]        # wall at 0: −e_μ/σ
            parts.append((hit, np.full(hit.size, -1), overlap[hit], np.full(hit.size, 0.5),
                          sizes[hit], grad, np.zeros((hit.size, d, d))))
    if cylinder[0] >= 0:
        axes = list(cylinder)
        half = 0.5 * box[cylinder[0]]
        offset = x[:, axes] - half
        rho = np.sqrt(np.einsum("nk,nk->n", offset, offset))
        overlap = 0.5 + (rho - half) / sizes
        hit = np.flatnonzero(overlap > 0.0)
        radial = offset[hit] / rho[hit, None]
        grad = np.zeros((hit.size, d))
        grad[:, axes] = radial / sizes[hit, None]
        curvature = np.zeros((hit.size, d, d))
        plane = np.eye(2)[None] - radial[:, :, None] * radial[:, None, :]
        curvature[np.ix_(np.arange(hit.size), axes, axes)] = (
            plane / (sizes[hit] * rho[hit])[:, None, None])
        parts.append((hit, np.full(hit.size, -1), overlap[hit], np.full(hit.size, 0.5),
                      sizes[hit], grad, curvature))
    fields = [np.concatenate(column) for column in zip(*parts)]
    return Terms(*fields, energy=0.5 * float(np.sum(fields[2] ** 2)))


def gradient(terms: Terms, n: int) -> tuple[np.ndarray, float]:
    """∂E/∂x (shape (N, d)) and ∂E/∂λ = Σ h (c − h) (the virial Σ f r)."""
    d = terms.grad.shape[1]
    weighted = terms.h[:, None] * terms.grad
    pair = terms.partner >= 0
    grad_x = np.zeros((n, d))
    for mu in range(d):
        grad_x[:, mu] = (np.bincount(terms.particle, weighted[:, mu], minlength=n)
                         - np.bincount(terms.partner[pair], weighted[pair, mu], minlength=n))
    return grad_x, float(np.sum(terms.h * (terms.offset - terms.h)))


def hessian(terms: Terms, n: int, exact: bool = True
            ) -> tuple[sp.csr_matrix, np.ndarray, float]:
    """The Hessian of E in (x, λ): the x block (sparse, shape (N d, N d)), the mixed
    derivatives ∂²E/∂x∂λ (shape (N d,)) and ∂²E/∂λ²; with `exact` False its Gauss–Newton
    part Σ ∇h ∇hᵀ (positive semi-definite)."""
    d = terms.grad.shape[1]
    weight = 1.0 if exact else 0.0
    block = (terms.grad[:, :, None] * terms.grad[:, None, :]
             + weight * terms.h[:, None, None] * terms.curvature)
    pair = terms.partner >= 0
    axis = np.arange(d)

    def entries(rows: np.ndarray, cols: np.ndarray, values: np.ndarray):
        return ((d * rows[:, None, None] + axis[None, :, None]).repeat(d, 2).ravel(),
                (d * cols[:, None, None] + axis[None, None, :]).repeat(d, 1).ravel(),
                values.ravel())

    i, j, paired = terms.particle, terms.partner[pair], block[pair]
    pieces = [entries(i, i, block), entries(j, j, paired),
              entries(i[pair], j, -paired), entries(j, i[pair], -paired)]
    rows, cols, values = (np.concatenate(column) for column in zip(*pieces))
    matrix = sp.csr_matrix((values, (rows, cols)), shape=(n * d, n * d))
    mixed_terms = (terms.offset - (1.0 + weight) * terms.h)[:, None] * terms.grad
    mixed = np.zeros((n, d))
    for mu in range(d):
        mixed[:, mu] = (np.bincount(i, mixed_terms[:, mu], minlength=n)
                        - np.bincount(j, mixed_terms[pair, mu], minlength=n))
    second = float(np.sum((terms.offset - terms.h) * (terms.offset - (1.0 + weight) * terms.h)))
    return matrix, mixed.ravel(), second


def _solve(matrix: sp.csr_matrix, mixed: np.ndarray, second: float, mu: float,
           grad_x: np.ndarray, grad_u: float) -> tuple[np.ndarray, float] | None:
    """The damped Newton step (δx, δu) of the system [[K + μ I, b], [bᵀ, k + μ]] δ = −g
    (u components already scaled), or None when the damped matrix is not positive definite
    (or singular)."""
    damped = (matrix + mu * sp.identity(matrix.shape[0], format="csr")).tocsc()
    try:
        factors = splu(damped, permc_spec="MMD_AT_PLUS_A", diag_pivot_thresh=0.0,
                       options={"SymmetricMode": True})
    except RuntimeError:            # exactly singular
        return None
    z = factors.solve(np.stack([grad_x, mixed], axis=1))
    if not np.all(np.isfinite(z)):
        return None
    schur = second + mu - mixed @ z[:, 1]
    if not schur > 0.0:
        return None
    step_u = (mixed @ z[:, 0] - grad_u) / schur
    return -z[:, 0] - z[:, 1] * step_u, step_u


def newton_run(x: np.ndarray, f: np.ndarray, s: np.ndarray, box: np.ndarray,
               first: np.ndarray, second: np.ndarray, x_built: np.ndarray, skin: float,
               scale_built: float, state: np.ndarray, tolerance: float, force_floor: float,
               target: float, max_steps: int, periodic: np.ndarray,
               cylinder: tuple[int, int]) -> tuple[int, int, float, float]:
    """Damped Newton minimisation of H = E + p* Ṽ at p* = `target`, until converged, a list
    rebuild is due, or `max_steps` solves.

    Parameters
    ----------
    x : ndarray, shape (N, d)
        Positions (mean diameters), updated in place (not wrapped).
    f : ndarray, shape (N, d)
        Work array; holds the forces −∂E/∂x at the returned positions.
    s, box, first, second
        As in `evaluate`; the lists hold every pair within σ + `skin` at the build.
    x_built : ndarray, shape (N, d)
        Positions at the last list build.
    skin : float
        Verlet skin at the build (mean diameters).
    scale_built : float
        Diameter scale at the last list build.
    state : ndarray, shape (STATE_SIZE,)
        λ, μ, ν and the solves since the minimisation began (`new_state`); updated in
        place. With x, it is all that the next iteration needs: a call continues where the
        last one returned.
    tolerance, force_floor : float
        Converged when max_i |F_i| ≤ max(tolerance × the mean force of the overlapping
        terms, force_floor) and |p − p*| ≤ tolerance × p* (as `_fire.fire_run`).
    target : float
        p*, in units of ε / (mean diameter)^d.
    max_steps : int
        Solves (factorisations) allowed in this call.
    periodic : ndarray, shape (d,), bool
        Periodic axes; flat walls at 0 and L_μ along the others, or the cylinder.
    cylinder : tuple of int
        The cylinder's two axes, or `_fire.NO_CYLINDER`; V is then the cylinder's volume.

    Returns
    -------
    code : int
        CONVERGED, REBUILD (the next step might outrun the lists: rebuild them and call
        again) or OUT_OF_STEPS.
    steps : int
        Solves in this call.
    pressure : float
        Pressure at the returned positions.
    drift : float
        Largest distance a particle moved since the list build.
    """
    n, d = x.shape
    root_mass = np.sqrt(n * d)
    volume = container_volume(box, cylinder)
    largest = float(s.max())
    log_scale, mu, nu = state[LOG_SCALE], state[MU], state[NU]

    def measure(positions: np.ndarray, log_a: float
                ) -> tuple[Terms, np.ndarray, float, float]:
        """The overlapping terms at (positions, λ = log_a), ∂E/∂x, ∂H/∂u and the
        pressure."""
        terms = evaluate(positions, s, float(np.exp(log_a)), box, first, second, periodic,
                         cylinder)
        grad_x, virial = gradient(terms, n)
        reduced = volume * np.exp(-d * log_a)
        return terms, grad_x, (virial - d * reduced * target) / root_mass, virial / (d * reduced)

    terms, grad_x, grad_u, pressure = measure(x, log_scale)
    matrix = None
    steps = 0
    code = OUT_OF_STEPS
    while True:
        f[:] = -grad_x
        drift2 = float(np.max(np.sum((x - x_built) ** 2, axis=1)))
        overlaps = int(np.count_nonzero(terms.h))
        mean_force = float(np.sum(terms.h / terms.sigma)) / overlaps if overlaps else 0.0
        largest2 = float(np.max(np.sum(grad_x ** 2, axis=1)))
        if converged(overlaps, largest2, mean_force, pressure, target, tolerance, force_floor):
            code = CONVERGED
            break
        if steps >= max_steps:
            break
        scale = np.exp(log_scale)
        reach = 2.0 * np.sqrt(drift2) + largest * max(scale - scale_built, 0.0)
        if reach > (1.0 - 3.0 * MOVE_FRACTION) * skin:
            code = REBUILD
            break
        if matrix is None:
            matrix, mixed, second_lambda = hessian(terms, n, exact=False)
            mixed = mixed / root_mass
            reduced = volume * np.exp(-d * log_scale)
            second_u = (second_lambda + d * d * reduced * target) / root_mass ** 2
        flat_grad = grad_x.ravel()
        step = _solve(matrix, mixed, second_u, mu, flat_grad, grad_u)
        steps += 1
        if step is None:
            mu, nu = mu * nu, 2.0 * nu
            continue
        step_x, step_u = step
        curved = matrix @ step_x + mixed * step_u
        slope = flat_grad @ step_x + grad_u * step_u
        quadratic = step_x @ curved + step_u * (mixed @ step_x + second_u * step_u)
        move = np.sqrt(np.max(np.sum(step_x.reshape(n, d) ** 2, axis=1)))
        growth = largest * scale * abs(np.expm1(step_u / root_mass))
        fraction = min(1.0, MOVE_FRACTION * skin / max(move, growth, np.finfo(float).tiny))
        roundoff = ENERGY_ROUNDOFF * np.finfo(np.float64).eps * float(np.sum(terms.h))
        reduced = volume * np.exp(-d * log_scale)
        low, slope_low = 0.0, slope
        accepted = None
        for _ in range(LINE_SEARCH_EVALUATIONS):
            trial_x = x + fraction * step_x.reshape(n, d)
            trial_log_scale = log_scale + fraction * step_u / root_mass
            trial = measure(trial_x, trial_log_scale)
            predicted = -(fraction * slope + 0.5 * fraction ** 2 * quadratic)
            actual = -((trial[0].energy - terms.energy) + target * reduced
                       * np.expm1(-d * (trial_log_scale - log_scale)))
            if not predicted > 0.0:
                break
            if predicted <= roundoff:
                size_before = flat_grad @ flat_grad + grad_u ** 2
                size_after = float(np.sum(trial[1] ** 2)) + trial[2] ** 2
                if size_after <= size_before:
                    accepted = 1.0
                break
            if actual >= -ARMIJO * fraction * slope:
                accepted = actual / predicted
                break
            trial_slope = float(trial[1].ravel() @ step_x) + trial[2] * step_u
            if trial_slope > slope_low:
                guess = low + (fraction - low) * slope_low / (slope_low - trial_slope)
            else:
                guess = 0.5 * (low + fraction)
            margin = BRACKET_MARGIN * (fraction - low)
            fraction = min(max(guess, low + margin), fraction - margin)
        if accepted is not None:
            x[:] = trial_x
            log_scale = trial_log_scale
            terms, grad_x, grad_u, pressure = trial
            matrix = None
            mu = max(mu * max(MU_SHRINK, 1.0 - (2.0 * min(accepted, 1.0) - 1.0) ** 3), MU_MIN)
            nu = NU_START
        else:
            mu, nu = mu * nu, 2.0 * nu
    state[LOG_SCALE], state[MU], state[NU] = log_scale, mu, nu
    state[SOLVES] += steps
    return code, steps, pressure, np.sqrt(drift2)
