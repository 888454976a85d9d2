"""Numba L-BFGS for the soft-sphere quench: the enthalpy of harmonic spheres at fixed pressure.

The same function and degrees of freedom as `_fire.fire_run`: positions x (shape (N, d)) and
λ = ln a, the logarithm of the diameter scale, here as u = √(N d) λ so that its curvature is
of order one like that of a particle (∂²E/∂λ² ≈ N_c ≈ N d near jamming). The enthalpy is
H = E + p* Ṽ, Ṽ = V / a^d, with the gradient −F on x and (Σ f_ij r_ij − d Ṽ p*) / √(N d) on u.

L-BFGS (Nocedal, Math. Comp. 35, 773 (1980)): the two-loop recursion over the last
`HISTORY` steps (Nocedal & Wright, Numerical Optimization, Alg. 7.4), and a line search
for the strong Wolfe conditions (sufficient decrease and curvature), its trial steps
chosen by the secant of the directional derivative: along a line the enthalpy of harmonic
spheres is piecewise quadratic, so the secant is exact between two changes of the overlap
set. The sufficient-decrease test allows for the round-off of H, below which
the decrease of a step near a minimum falls. No particle moves by more than
`MOVE_FRACTION` × the Verlet skin in one step, so that a step never outruns the lists.
"""

from __future__ import annotations

import numpy as np
from numba import njit

from ._fire import (CONVERGED, OUT_OF_STEPS, REBUILD, container_volume, converged,
                    harmonic_forces, work_array)

__all__ = ["HISTORY", "STATE_SIZE", "lbfgs_run", "new_state"]

#: Steps kept for the inverse-Hessian estimate.
HISTORY = 8
#: Wolfe constants: sufficient decrease c1 and (strong) curvature c2 of Nocedal & Wright.
ARMIJO = 1e-4
CURVATURE = 0.9
#: Force evaluations allowed to one line search before it gives up (`lbfgs_run`).
LINE_SEARCH_EVALUATIONS = 12
#: Largest move of a particle (and growth of the largest diameter) in one step, × the skin.
MOVE_FRACTION = 0.25
#: Round-off of the enthalpy, × machine epsilon × (E + p* Ṽ): decreases below it are not
#: resolved, and the sufficient-decrease test accepts them.
ENERGY_ROUNDOFF = 100.0
#: Trial steps of the line search stay this fraction of the bracket away from its ends.
BRACKET_MARGIN = 0.1
#: Longest extrapolation of a too-short step, as a factor on it.
EXTRAPOLATION = 4.0
#: Layout of the state array: λ, pairs stored, slot of the newest, force evaluations.
LOG_SCALE, STORED, NEWEST, EVALUATIONS = 0, 1, 2, 3
STATE_SIZE = 4


def new_state(log_scale: float) -> np.ndarray:
    """State array of a minimisation that starts at λ = `log_scale` with no history."""
    state = np.zeros(STATE_SIZE)
    state[LOG_SCALE] = log_scale
    return state


@njit
def _enthalpy(x, still, s, scale, box, first, second, incoming_start, incoming, pair_force, f,
              partial, target, root_mass, periodic, cylinder):
    """Forces into `f`; H, ∂H/∂u, max |F_i|², Σ f_ij over overlaps, pressure, overlaps.

    `still` is a zero array of the shape of x (the velocities `harmonic_forces` reads);
    `periodic` the periodic axes (walls along the others), `cylinder` the cylinder's axes
    or `_fire.NO_CYLINDER`."""
    d = x.shape[1]
    volume = container_volume(box, cylinder) / scale**d
    _, _, _, largest2, force_sum, virial, overlaps, energy = harmonic_forces(
        x, still, s, scale, box, first, second, incoming_start, incoming, pair_force, f,
        partial, periodic, cylinder)
    enthalpy = energy + target * volume
    gradient_u = (virial - d * volume * target) / root_mass
    pressure = virial / (d * volume)
    return enthalpy, gradient_u, largest2, force_sum, pressure, overlaps


@njit(cache=True, fastmath=True)
def _direction(f, gradient_u, memory_x, memory_u, stored, newest, p):
    """p ← −H̃ ∇H by the two-loop recursion over the `stored` newest pairs (s, y); returns
    its u component.

    memory_x[0, k], memory_x[1, k]: s and y of pair k (positions, flattened to N d);
    memory_u[0, k],
    memory_u[1, k]: their u components, memory_u[2, k] = 1/(s·y), memory_u[3, k] = s·y/(y·y).
    Each pass over the vectors updates with one pair and takes the dot product of the next
    (flat loops, so that they vectorise).
    """
    m = memory_x.shape[1]
    size = f.size
    flat = memory_x
    q = p.reshape(size)
    q[:] = f.reshape(size)
    q_u = -gradient_u
    coefficients = np.empty(m)
    if stored == 0:
        return q_u
    k = newest
    dot = q_u * memory_u[0, k]
    for i in range(size):
        dot += flat[0, k, i] * q[i]
    for back in range(stored):
        k = (newest - back) % m
        a = memory_u[2, k] * dot
        coefficients[k] = a
        q_u -= a * memory_u[1, k]
        if back + 1 < stored:
            following = (k - 1) % m
            dot = q_u * memory_u[0, following]
            for i in range(size):
                q[i] -= a * flat[1, k, i]
                dot += flat[0, following, i] * q[i]
        else:
            gamma = memory_u[3, newest]
            oldest = following = k
            dot = 0.0
            for i in range(size):
                q[i] = gamma * (q[i] - a * flat[1, k, i])
                dot += flat[1, oldest, i] * q[i]
            q_u *= gamma
            dot += q_u * memory_u[1, oldest]
    for forward in range(stored):
        k = (newest - stored + 1 + forward) % m
        b = coefficients[k] - memory_u[2, k] * dot
        q_u += b * memory_u[0, k]
        if forward + 1 < stored:
            following = (k + 1) % m
            dot = 0.0
            for i in range(size):
                q[i] += b * flat[0, k, i]
                dot += flat[1, following, i] * q[i]
            dot += q_u * memory_u[1, following]
        else:
            for i in range(size):
                q[i] += b * flat[0, k, i]
    return q_u


@njit(cache=True)
def _place(x, x0, p, alpha, x_built):
    """x ← x0 + α p; return the largest squared distance from the list build."""
    n, d = x.shape
    drift2 = 0.0
    for i in range(n):
        moved = 0.0
        for mu in range(d):
            x[i, mu] = x0[i, mu] + alpha * p[i, mu]
            delta = x[i, mu] - x_built[i, mu]
            moved += delta * delta
        drift2 = max(drift2, moved)
    return drift2


@njit(cache=True, fastmath=True)
def _memorise(memory_x, memory_u, k, alpha, p, p_u, f0, f, change_u):
    """Store the step s = α (p, p_u) and the gradient change y = (f0 − f, change_u) in slot
    k of the history, with 1/(s·y) and s·y/(y·y); return False unless s·y > 0, the
    curvature that keeps the inverse-Hessian estimate positive definite (slot k is then
    overwritten but not to be used)."""
    size = p.size
    step, before, after = p.reshape(size), f0.reshape(size), f.reshape(size)
    sy = alpha * p_u * change_u
    yy = change_u * change_u
    for i in range(size):
        memory_x[0, k, i] = alpha * step[i]
        memory_x[1, k, i] = before[i] - after[i]
        sy += memory_x[0, k, i] * memory_x[1, k, i]
        yy += memory_x[1, k, i] * memory_x[1, k, i]
    if not sy > 0.0:
        return False
    memory_u[0, k], memory_u[1, k] = alpha * p_u, change_u
    memory_u[2, k], memory_u[3, k] = 1.0 / sy, sy / yy
    return True


@njit(cache=True)
def _copy(target, source):
    """target ← source, arrays of the same shape (a serial loop: in the parallel `lbfgs_run`
    an array assignment becomes a threaded loop, whose start costs more than the copy)."""
    flat_target, flat_source = target.reshape(target.size), source.reshape(source.size)
    for i in range(flat_target.size):
        flat_target[i] = flat_source[i]


@njit(cache=True, fastmath=True)
def _slope(f, gradient_u, p, p_u):
    """Directional derivative ∇H · (p, p_u) with ∇_x H = −F."""
    n, d = f.shape
    slope = gradient_u * p_u
    for i in range(n):
        for mu in range(d):
            slope -= f[i, mu] * p[i, mu]
    return slope


# lbfgs_run calls the parallel `_fire.harmonic_forces` (through `_enthalpy`, compiled into it).
# Compiled with parallel=True itself (as `_fire.fire_run`), it loads safely from Numba's
# on-disk cache; a cached serial caller of a parallel function crashes (numba issue #8578).
# It holds no array expression whose rounding a threaded reduction could change.
@njit(parallel=True, cache=True)
def lbfgs_run(x, f, s, box, first, second, incoming_start, incoming, x_built, skin,
              scale_built, state, memory_x, memory_u, tolerance, force_floor, target,
              max_steps, periodic, cylinder):
    """L-BFGS minimisation of H = E + p* Ṽ at p* = `target`, until converged, a list rebuild
    or the force-evaluation limit.

    Parameters
    ----------
    x : ndarray, shape (N, d)
        Positions, updated in place (not wrapped).
    f : ndarray, shape (N, d)
        Work array; holds the forces at the returned positions.
    s, box, first, second, incoming_start, incoming
        As in `_fire.harmonic_forces`; the lists hold every pair within σ + `skin` at the
        build.
    x_built : ndarray, shape (N, d)
        Positions at the last list build.
    skin : float
        Verlet skin at the build: a step that would make 2 × the largest drift plus the
        growth of the largest diameter since the build exceed it is not taken (REBUILD).
    scale_built : float
        Diameter scale at the last list build.
    state : ndarray, shape (STATE_SIZE,)
        λ, pairs stored, slot of the newest pair, force evaluations since the minimisation
        began (`new_state`); updated in place.
    memory_x : ndarray, shape (2, HISTORY, N d)
        s and y (position components, particle i at i d … i d + d − 1) of the stored pairs,
        updated in place; they follow the particles (permute them with the positions at a
        re-sort).
    memory_u : ndarray, shape (4, HISTORY)
        u components of s and y, 1/(s·y) and s·y/(y·y), updated in place.
    tolerance, force_floor : float
        Converged when max_i |F_i| ≤ max(tolerance × the mean force of the overlapping pairs,
        force_floor) and |p − p*| ≤ tolerance × p*.
    target : float
        p*, in units of ε / (mean diameter)^d.
    max_steps : int
        Force evaluations allowed in this call (a step in progress finishes its line search).
    periodic : ndarray, shape (d,), bool
        Periodic axes; flat walls at 0 and L_μ along the others (`_fire.harmonic_forces`),
        or the cylinder.
    cylinder : tuple of int
        The cylinder's two axes, or `_fire.NO_CYLINDER` (`_fire.fire_run`).

    Returns
    -------
    code : int
        CONVERGED, REBUILD (rebuild the lists and call again) or OUT_OF_STEPS.
    steps : int
        Force evaluations in this call.
    pressure : float
        Pressure at the returned positions.
    drift : float
        Largest distance a particle moved since the list build.
    """
    n, d = x.shape
    m = memory_x.shape[1]
    root_mass = np.sqrt(n * d)
    largest = s.max()
    partial = work_array(n)
    pair_force = np.empty((second.shape[0], d))
    still = np.zeros((n, d))
    x0 = np.empty((n, d))
    f0 = np.empty((n, d))
    p = np.empty((n, d))
    log_scale = state[LOG_SCALE]
    stored, newest = int(state[STORED]), int(state[NEWEST])
    scale = np.exp(log_scale)
    enthalpy, gradient_u, largest2, force_sum, pressure, overlaps = _enthalpy(
        x, still, s, scale, box, first, second, incoming_start, incoming, pair_force, f,
        partial, target, root_mass, periodic, cylinder)
    # Only a fresh minimisation counts this evaluation: after a pause or a rebuild it repeats
    # the last one, and the counts do not depend on where the pauses fall.
    steps = 1 if state[EVALUATIONS] == 0.0 else 0
    drift2 = 0.0
    for i in range(n):
        moved = 0.0
        for mu in range(d):
            moved += (x[i, mu] - x_built[i, mu]) ** 2
        drift2 = max(drift2, moved)
    code = OUT_OF_STEPS
    while True:
        mean_force = force_sum / overlaps if overlaps > 0 else 0.0
        if converged(overlaps, largest2, mean_force, pressure, target, tolerance, force_floor):
            code = CONVERGED
            break
        if steps >= max_steps:
            break
        p_u = _direction(f, gradient_u, memory_x, memory_u, stored, newest, p)
        slope0 = _slope(f, gradient_u, p, p_u)
        if slope0 >= 0.0:               # not a descent direction: forget the history
            stored = 0
            p_u = _direction(f, gradient_u, memory_x, memory_u, stored, newest, p)
            slope0 = _slope(f, gradient_u, p, p_u)
        move2 = 0.0
        for i in range(n):
            moved = 0.0
            for mu in range(d):
                moved += p[i, mu] * p[i, mu]
            move2 = max(move2, moved)
        growth = largest * scale * abs(p_u) / root_mass
        reach = max(np.sqrt(move2), growth)
        alpha_max = MOVE_FRACTION * skin / reach if reach > 0.0 else 1.0
        _copy(x0, x)
        _copy(f0, f)
        log_scale0, gradient_u0, enthalpy0, pressure0 = log_scale, gradient_u, enthalpy, pressure
        roundoff = ENERGY_ROUNDOFF * np.finfo(np.float64).eps * enthalpy0
        alpha = min(1.0, alpha_max)
        low, slope_low, high = 0.0, slope0, np.inf
        accepted = outrun = False
        for _ in range(LINE_SEARCH_EVALUATIONS):
            moved2 = _place(x, x0, p, alpha, x_built)
            trial_log_scale = log_scale0 + alpha * p_u / root_mass
            trial_scale = np.exp(trial_log_scale)
            if 2.0 * np.sqrt(moved2) + largest * max(trial_scale - scale_built, 0.0) > skin:
                outrun = True
                break
            drift2 = moved2
            log_scale, scale = trial_log_scale, trial_scale
            enthalpy, gradient_u, largest2, force_sum, pressure, overlaps = _enthalpy(
                x, still, s, scale, box, first, second, incoming_start, incoming, pair_force,
                f, partial, target, root_mass, periodic, cylinder)
            steps += 1
            slope = _slope(f, gradient_u, p, p_u)
            decrease = enthalpy <= enthalpy0 + ARMIJO * alpha * slope0 + roundoff
            if decrease and abs(slope) <= CURVATURE * abs(slope0):
                accepted = True
                break
            if not decrease or slope > 0.0:
                high = alpha
                if slope > 0.0 and slope_low < 0.0:
                    guess = low + (alpha - low) * slope_low / (slope_low - slope)
                else:
                    guess = 0.5 * (low + alpha)
                margin = BRACKET_MARGIN * (high - low)
                alpha = min(max(guess, low + margin), high - margin)
            else:
                if alpha >= alpha_max:
                    accepted = True
                    break
                previous, slope_previous = low, slope_low
                low, slope_low = alpha, slope
                if np.isfinite(high):
                    margin = BRACKET_MARGIN * (high - low)
                    alpha = min(max(0.5 * (low + high), low + margin), high - margin)
                else:
                    guess = EXTRAPOLATION * alpha
                    if slope > slope_previous:
                        guess = min(guess, previous + (alpha - previous) * slope_previous
                                    / (slope_previous - slope))
                    alpha = min(max(guess, alpha), alpha_max)
        if outrun:                      # back to the start of the step, rebuild first
            _copy(x, x0)
            _copy(f, f0)
            log_scale = log_scale0
            pressure = pressure0
            code = REBUILD
            break
        if not accepted and stored > 0:  # no acceptable step: forget the history, retry
            _copy(x, x0)
            log_scale = log_scale0
            scale = np.exp(log_scale)
            enthalpy, gradient_u, largest2, force_sum, pressure, overlaps = _enthalpy(
                x, still, s, scale, box, first, second, incoming_start, incoming, pair_force,
                f, partial, target, root_mass, periodic, cylinder)
            steps += 1
            stored = 0
            continue
        k = (newest + 1) % m
        if _memorise(memory_x, memory_u, k, alpha, p, p_u, f0, f, gradient_u - gradient_u0):
            newest, stored = k, min(stored + 1, m)
        else:                           # slot k (the oldest pair when full) was overwritten
            stored = min(stored, m - 1)
    state[LOG_SCALE], state[STORED], state[NEWEST] = log_scale, stored, newest
    state[EVALUATIONS] += steps
    return code, steps, pressure, np.sqrt(drift2)
