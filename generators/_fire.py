"""Numba kernels of the soft-sphere quench: harmonic forces, FIRE 2.0 at fixed pressure,
spatial sorting.

Harmonic spheres, V_ij = ε/2 (1 − r_ij/σ_ij)² for r_ij < σ_ij, with ε = 1 and unit masses;
lengths in mean diameters of the nominal sizes s_i, current diameters σ_i = a s_i (a: the
diameter scale). Each Verlet pair is evaluated once; the force loop runs in parallel over
blocks of particles, each thread writing only its own rows (`harmonic_forces`).

Along an axis closed by flat walls at 0 and L_μ (`periodic[μ]` False) pairs meet without the
minimum image, and a particle at distance δ < σ_i/2 from a wall overlaps it by σ_i/2 − δ:
it has the energy of a pair with that overlap, V = ε/2 ((σ_i/2 − δ)/σ_i)², and the force
(σ_i/2 − δ)/σ_i² along the wall's inward normal. Its virial term is that force × δ, so that
the pressure stays −∂E/∂ ln V under an affine compression of the box, walls included.

In a cylinder (two axes a, b with equal sides L, `cylinder` = (a, b); no minimum image along
either) a particle whose centre is ρ_i from the cylinder's axis (the line through
(L/2, L/2)) overlaps the curved wall by δ = ρ_i + σ_i/2 − L/2 when positive: the energy
ε/2 (δ/σ_i)², the force δ/σ_i² along −ρ̂ in the circle's plane, and the virial term that
force × (L/2 − ρ_i), the centre's distance to the wall along the radius. That is
∂E/∂ ln a at fixed centres (E depends on (ρ_i − L/2)/σ_i), as for a flat wall, so the
enthalpy's gradient in ln a stays exact. The volume of the box is then the cylinder's,
π L²/4 × the periodic sides (`container_volume`).

FIRE 2.0 (Guénolé et al., Comput. Mater. Sci. 175, 109584 (2020)): semi-implicit Euler
steps, velocity mixing v ← (1 − α) v + α |v| F̂, a backstep x ← x − Δt v / 2 with v ← 0 when
the power F·v turns non-positive, and no Δt decrease during the first `N_DELAY` steps.
"""

from __future__ import annotations

import numpy as np
from numba import njit, prange

from .periodic import NO_CYLINDER, has_walls, image_component, inverse_sides

__all__ = ["cell_order", "pair_lists", "harmonic_forces", "fire_run", "converged", "contact_pairs",
           "box_volume", "container_volume", "NO_CYLINDER", "CONVERGED", "REBUILD",
           "OUT_OF_STEPS"]

#: FIRE parameters of Bitzek et al., PRL 97, 170201 (2006): steps of positive power before Δt
#: may grow (also the initial delay of FIRE 2.0), growth and cut factors of Δt, initial
#: mixing α and its decay per step.
N_DELAY = 5
F_INC = 1.1
F_DEC = 0.5
ALPHA_START = 0.1
F_ALPHA = 0.99
#: Smallest Δt, relative to Δt0 (FIRE 2.0's default, 0.02): the backstep never stalls.
DT_MIN_FRACTION = 0.02

#: Mass of λ = ln a (the log of the diameter scale) in `fire_run`, per degree of freedom of
#: the particles.
SCALE_MASS = 1.0

#: Return codes of `fire_run`.
CONVERGED, REBUILD, OUT_OF_STEPS = 0, 1, 2


@njit(cache=True)
def cell_order(x: np.ndarray, box: np.ndarray, width: float) -> np.ndarray:
    """Particle order sorted by cell (lexicographic, last axis slowest), stable within a cell.

    Parameters
    ----------
    x : ndarray, shape (N, d)
        Positions, wrapped into [0, L).
    box : ndarray, shape (d,)
        Box sides (length units).
    width : float
        Smallest cell width (length units); the cell grid has max(1, floor(L/width)) cells
        per direction.

    Returns
    -------
    ndarray of int64, shape (N,)
        `order[k]` is the particle that goes to slot k.
    """
    n, d = x.shape
    n_cells = np.empty(d, dtype=np.int64)
    stride = np.empty(d, dtype=np.int64)
    total = 1
    for mu in range(d):
        n_cells[mu] = max(1, int(box[mu] / width))
        stride[mu] = total
        total *= n_cells[mu]
    cell = np.empty(n, dtype=np.int64)
    counts = np.zeros(total + 1, dtype=np.int64)
    for i in range(n):
        c = 0
        for mu in range(d):
            k = min(max(int(x[i, mu] / box[mu] * n_cells[mu]), 0), n_cells[mu] - 1)
            c += k * stride[mu]
        cell[i] = c
        counts[c + 1] += 1
    for c in range(total):
        counts[c + 1] += counts[c]
    order = np.empty(n, dtype=np.int64)
    for i in range(n):
        order[counts[cell[i]]] = i
        counts[cell[i]] += 1
    return order


#: Particles per block of the force loop. Each block sums its share of the reductions in a
#: fixed order and the blocks are added in a fixed order, so that the results do not depend
#: on the number of threads or their scheduling (runs are reproducible bit for bit).
BLOCK = 128
#: Reductions of `harmonic_forces`, one column each in the per-block work array.
N_SUMS = 8
#: Floor of r² in the force loop, so that two particles at the same place give no NaN.
TINY = 1e-300


@njit(cache=True)
def work_array(n: int) -> np.ndarray:
    """Per-block work array of `harmonic_forces` for N particles, shape (blocks, N_SUMS)."""
    return np.zeros(((n + BLOCK - 1) // BLOCK, N_SUMS))


@njit(cache=True)
def pair_lists(start: np.ndarray, neighbours: np.ndarray):
    """Each pair once, from full CSR Verlet lists, with the index lists of both its ends.

    Parameters
    ----------
    start, neighbours : ndarray of int64
        Full CSR lists (`generators.cells.verlet_lists`: every pair in both rows).

    Returns
    -------
    first : ndarray of int64, shape (N + 1,)
        Pairs k in ``first[i]:first[i + 1]`` have i as their lower particle.
    second : ndarray of int64, shape (M,)
        The higher particle j > i of pair k.
    incoming_start : ndarray of int64, shape (N + 1,)
    incoming : ndarray of int64, shape (M,)
        ``incoming[incoming_start[j]:incoming_start[j + 1]]``: the pairs whose higher particle
        is j.
    """
    n = start.shape[0] - 1
    first = np.zeros(n + 1, dtype=np.int64)
    incoming_start = np.zeros(n + 1, dtype=np.int64)
    for i in range(n):
        for k in range(start[i], start[i + 1]):
            j = neighbours[k]
            if j > i:
                first[i + 1] += 1
                incoming_start[j + 1] += 1
    for i in range(n):
        first[i + 1] += first[i]
        incoming_start[i + 1] += incoming_start[i]
    second = np.empty(first[n], dtype=np.int64)
    incoming = np.empty(first[n], dtype=np.int64)
    fill = incoming_start[:-1].copy()
    m = 0
    for i in range(n):
        for k in range(start[i], start[i + 1]):
            j = neighbours[k]
            if j > i:
                second[m] = j
                incoming[fill[j]] = m
                fill[j] += 1
                m += 1
    return first, second, incoming_start, incoming


@njit(cache=True)
def _pairs(x: np.ndarray, s: np.ndarray, scale: float, box: np.ndarray, inv: np.ndarray,
           first: np.ndarray, second: np.ndarray, pair_force: np.ndarray, f: np.ndarray,
           lo: int, hi: int, sums: np.ndarray) -> None:
    """Pass 1 of `harmonic_forces` for particles lo ≤ i < hi, any d.

    Each pair k of row i: pair_force[k] = its force on i; f[i] = the sum over the row;
    sums[4:8] = Σ f_ij, Σ f_ij r_ij, the number of overlapping pairs of these rows and their
    energy Σ (1 − r_ij/σ_ij)² / 2. `inv`: `periodic.inverse_sides` of the box.
    """
    d = x.shape[1]
    r_ij = np.empty(d)
    f_i = np.empty(d)
    force_sum = virial = overlaps = energy = 0.0
    for i in range(lo, hi):
        f_i[:] = 0.0
        for k in range(first[i], first[i + 1]):
            j = second[k]
            r2 = 0.0
            for mu in range(d):
                dx = image_component(x[i, mu] - x[j, mu], box[mu], inv[mu])
                r_ij[mu] = dx
                r2 += dx * dx
            # Branch-free: about half the listed pairs overlap, in no predictable order,
            # and a mispredicted branch costs more than the square root.
            sigma = 0.5 * scale * (s[i] + s[j])
            r = np.sqrt(max(r2, TINY))
            magnitude = max(sigma - r, 0.0) / (sigma * sigma)
            factor = magnitude / r
            for mu in range(d):
                pair_force[k, mu] = factor * r_ij[mu]
                f_i[mu] += factor * r_ij[mu]
            force_sum += magnitude
            virial += magnitude * r
            overlaps += 1.0 if r < sigma else 0.0
            energy += (magnitude * sigma) ** 2
        for mu in range(d):
            f[i, mu] = f_i[mu]
    sums[4], sums[5], sums[6], sums[7] = force_sum, virial, overlaps, 0.5 * energy


@njit(cache=True)
def _pairs_3d(x: np.ndarray, s: np.ndarray, scale: float, box: np.ndarray, inv: np.ndarray,
              first: np.ndarray, second: np.ndarray, pair_force: np.ndarray, f: np.ndarray,
              lo: int, hi: int, sums: np.ndarray) -> None:
    """`_pairs` written out for d = 3, so that the pair vectors stay in registers."""
    box0, box1, box2 = box[0], box[1], box[2]
    inv0, inv1, inv2 = inv[0], inv[1], inv[2]
    force_sum = virial = overlaps = energy = 0.0
    for i in range(lo, hi):
        x0, x1, x2 = x[i, 0], x[i, 1], x[i, 2]
        f0 = f1 = f2 = 0.0
        for k in range(first[i], first[i + 1]):
            j = second[k]
            dx0 = image_component(x0 - x[j, 0], box0, inv0)
            dx1 = image_component(x1 - x[j, 1], box1, inv1)
            dx2 = image_component(x2 - x[j, 2], box2, inv2)
            sigma = 0.5 * scale * (s[i] + s[j])
            r = np.sqrt(max(dx0 * dx0 + dx1 * dx1 + dx2 * dx2, TINY))
            magnitude = max(sigma - r, 0.0) / (sigma * sigma)
            factor = magnitude / r
            pair_force[k, 0] = factor * dx0
            pair_force[k, 1] = factor * dx1
            pair_force[k, 2] = factor * dx2
            f0 += factor * dx0
            f1 += factor * dx1
            f2 += factor * dx2
            force_sum += magnitude
            virial += magnitude * r
            overlaps += 1.0 if r < sigma else 0.0
            energy += (magnitude * sigma) ** 2
        f[i, 0], f[i, 1], f[i, 2] = f0, f1, f2
    sums[4], sums[5], sums[6], sums[7] = force_sum, virial, overlaps, 0.5 * energy


@njit(cache=True)
def _walls(x: np.ndarray, s: np.ndarray, scale: float, box: np.ndarray,
           periodic: np.ndarray, cylinder: tuple[int, int], f: np.ndarray, lo: int, hi: int,
           sums: np.ndarray) -> None:
    """Flat-wall terms of pass 1 for particles lo ≤ i < hi, after `_pairs`: each particle
    closer than its radius to a wall (along an axis that is neither periodic nor one of the
    `cylinder`'s) gets the wall's force in f[i], and sums[4:8] gain the force, its virial
    (force × distance to the wall), the overlap count and the energy, as a pair would."""
    d = x.shape[1]
    force_sum = virial = overlaps = energy = 0.0
    for i in range(lo, hi):
        sigma = scale * s[i]
        radius = 0.5 * sigma
        for mu in range(d):
            if periodic[mu] or mu == cylinder[0] or mu == cylinder[1]:
                continue
            for side in range(2):          # the wall at 0 (normal +e_μ), then at L_μ
                distance = x[i, mu] if side == 0 else box[mu] - x[i, mu]
                normal = 1.0 - 2.0 * side
                if distance < radius:
                    magnitude = (radius - distance) / (sigma * sigma)
                    f[i, mu] += normal * magnitude
                    force_sum += magnitude
                    virial += magnitude * distance
                    overlaps += 1.0
                    energy += (magnitude * sigma) ** 2
    sums[4] += force_sum
    sums[5] += virial
    sums[6] += overlaps
    sums[7] += 0.5 * energy


@njit(cache=True)
def _cylinder(x: np.ndarray, s: np.ndarray, scale: float, box: np.ndarray,
              cylinder: tuple[int, int], f: np.ndarray, lo: int, hi: int,
              sums: np.ndarray) -> None:
    """Cylinder terms of pass 1 for particles lo ≤ i < hi, after `_pairs`: a particle whose
    centre is ρ from the axis of the cylinder (axes a, b = `cylinder`, diameter L = box[a])
    overlaps it by δ = ρ + σ_i/2 − L/2 when positive, and gets the force δ/σ_i² along −ρ̂ in
    f[i]; sums[4:8] gain the force, its virial (force × (L/2 − ρ)), the overlap count and the
    energy (δ/σ_i)²/2."""
    a, b = cylinder
    half = 0.5 * box[a]
    force_sum = virial = overlaps = energy = 0.0
    for i in range(lo, hi):
        sigma = scale * s[i]
        offset_a = x[i, a] - half
        offset_b = x[i, b] - half
        rho = np.sqrt(offset_a * offset_a + offset_b * offset_b)
        overlap = rho + 0.5 * sigma - half
        if overlap > 0.0:          # then ρ > (L − σ_i)/2 > 0: ρ̂ is defined
            magnitude = overlap / (sigma * sigma)
            factor = magnitude / rho
            f[i, a] -= factor * offset_a
            f[i, b] -= factor * offset_b
            force_sum += magnitude
            virial += magnitude * (half - rho)
            overlaps += 1.0
            energy += (magnitude * sigma) ** 2
    sums[4] += force_sum
    sums[5] += virial
    sums[6] += overlaps
    sums[7] += 0.5 * energy


@njit(cache=True)
def _gather(v: np.ndarray, incoming_start: np.ndarray, incoming: np.ndarray,
            pair_force: np.ndarray, f: np.ndarray, lo: int, hi: int, sums: np.ndarray) -> None:
    """Pass 2 of `harmonic_forces` for particles lo ≤ j < hi, any d.

    f[j] −= the forces of the pairs whose higher particle is j; sums[0:4] = F·v, |F|², |v|²
    and max |F_j|² over these particles.
    """
    d = v.shape[1]
    power = force2 = speed2 = largest2 = 0.0
    for j in range(lo, hi):
        for q in range(incoming_start[j], incoming_start[j + 1]):
            k = incoming[q]
            for mu in range(d):
                f[j, mu] -= pair_force[k, mu]
        ff = 0.0
        for mu in range(d):
            power += f[j, mu] * v[j, mu]
            ff += f[j, mu] * f[j, mu]
            speed2 += v[j, mu] * v[j, mu]
        force2 += ff
        largest2 = max(largest2, ff)
    sums[0], sums[1], sums[2], sums[3] = power, force2, speed2, largest2


@njit(cache=True)
def _gather_3d(v: np.ndarray, incoming_start: np.ndarray, incoming: np.ndarray,
               pair_force: np.ndarray, f: np.ndarray, lo: int, hi: int,
               sums: np.ndarray) -> None:
    """`_gather` written out for d = 3."""
    power = force2 = speed2 = largest2 = 0.0
    for j in range(lo, hi):
        f0, f1, f2 = f[j, 0], f[j, 1], f[j, 2]
        for q in range(incoming_start[j], incoming_start[j + 1]):
            k = incoming[q]
            f0 -= pair_force[k, 0]
            f1 -= pair_force[k, 1]
            f2 -= pair_force[k, 2]
        f[j, 0], f[j, 1], f[j, 2] = f0, f1, f2
        ff = f0 * f0 + f1 * f1 + f2 * f2
        power += f0 * v[j, 0] + f1 * v[j, 1] + f2 * v[j, 2]
        speed2 += v[j, 0] * v[j, 0] + v[j, 1] * v[j, 1] + v[j, 2] * v[j, 2]
        force2 += ff
        largest2 = max(largest2, ff)
    sums[0], sums[1], sums[2], sums[3] = power, force2, speed2, largest2


@njit(parallel=True, cache=True)
def harmonic_forces(x: np.ndarray, v: np.ndarray, s: np.ndarray, scale: float, box: np.ndarray,
                    first: np.ndarray, second: np.ndarray, incoming_start: np.ndarray,
                    incoming: np.ndarray, pair_force: np.ndarray, f: np.ndarray,
                    partial: np.ndarray, periodic: np.ndarray,
                    cylinder: tuple[int, int] = NO_CYLINDER):
    """Harmonic forces into `f` (in place) and the sums FIRE and the pressure need.

    Two parallel passes over blocks of particles: the first computes each pair once (as the
    row of its lower particle, which takes the force) and stores it; the second subtracts the
    stored forces of the pairs where a particle is the higher one. Every thread writes only
    its own rows, and each pair costs one evaluation. d = 3 has its own loops (`_pairs_3d`,
    `_gather_3d`); other dimensions share `_pairs` and `_gather`. With walls, the first pass
    adds the wall forces (`_walls`, and `_cylinder` in a cylinder); a periodic box skips
    these loops.

    Parameters
    ----------
    x, v : ndarray, shape (N, d)
        Positions and velocities.
    s : ndarray, shape (N,)
        Nominal diameters (mean 1); the diameters are `scale` · s.
    scale : float
        Diameter scale a.
    box : ndarray, shape (d,)
    first, second, incoming_start, incoming : ndarray of int64
        Pair lists (`pair_lists`).
    pair_force : ndarray, shape (M, d)
        Work array: force of pair k on its lower particle.
    f : ndarray, shape (N, d)
        Output: force on each particle, Σ_j (1 − r_ij/σ_ij)/σ_ij r̂_ij (ε = 1).
    partial : ndarray, shape (blocks, N_SUMS)
        Work array (`work_array`).
    periodic : ndarray, shape (d,), bool
        Periodic axes; along the others the box is closed by flat walls at 0 and L_μ, or by
        the cylinder.
    cylinder : tuple of int, optional
        The two axes (a, b) of a cylinder (not periodic, box[a] = box[b]), or `NO_CYLINDER`.

    Returns
    -------
    power, force2, speed2 : float
        F·v, |F|², |v|² over all particles.
    largest2 : float
        max_i |F_i|².
    force_sum, virial : float
        Σ over overlapping pairs (and particle–wall overlaps) of f_ij and of f_ij r_ij (for
        a flat wall: the force × the centre's distance to the wall; for the cylinder: the
        force × (L/2 − ρ)).
    overlaps : int
        Number of overlapping pairs and particle–wall overlaps.
    energy : float
        Harmonic energy E = Σ (1 − r_ij/σ_ij)² / 2 (ε = 1), wall terms included.
    """
    n, d = x.shape
    blocks = partial.shape[0]
    inv = inverse_sides(box, periodic)
    walled = has_walls(periodic)
    for b in prange(blocks):
        lo, hi = b * BLOCK, min(n, (b + 1) * BLOCK)
        if d == 3:
            _pairs_3d(x, s, scale, box, inv, first, second, pair_force, f, lo, hi, partial[b])
        else:
            _pairs(x, s, scale, box, inv, first, second, pair_force, f, lo, hi, partial[b])
        if walled:
            _walls(x, s, scale, box, periodic, cylinder, f, lo, hi, partial[b])
            if cylinder[0] >= 0:
                _cylinder(x, s, scale, box, cylinder, f, lo, hi, partial[b])
    for b in prange(blocks):
        lo, hi = b * BLOCK, min(n, (b + 1) * BLOCK)
        if d == 3:
            _gather_3d(v, incoming_start, incoming, pair_force, f, lo, hi, partial[b])
        else:
            _gather(v, incoming_start, incoming, pair_force, f, lo, hi, partial[b])
    sums = partial[0].copy()
    for b in range(1, blocks):
        for q in range(N_SUMS):
            sums[q] = max(sums[q], partial[b, q]) if q == 3 else sums[q] + partial[b, q]
    return (sums[0], sums[1], sums[2], sums[3], sums[4], sums[5], int(sums[6] + 0.5),
            sums[7])


@njit(parallel=True, cache=True)
def _move(x: np.ndarray, v: np.ndarray, f: np.ndarray, x_built: np.ndarray, dt: float,
          keep: float, push: float, backstep: bool) -> float:
    """One FIRE 2.0 integration step in place; return the largest squared drift since the build.

    With `backstep`, first x ← x − Δt v/2 and v ← 0; then v ← v + Δt F,
    v ← keep · v + push · F (keep = 1 − α, push = α |v|/|F|), x ← x + Δt v.
    """
    n, d = x.shape
    drift2 = 0.0
    for i in prange(n):
        moved = 0.0
        for mu in range(d):
            vi = v[i, mu]
            if backstep:
                x[i, mu] -= 0.5 * dt * vi
                vi = 0.0
            vi = keep * (vi + dt * f[i, mu]) + push * f[i, mu]
            v[i, mu] = vi
            x[i, mu] += dt * vi
            delta = x[i, mu] - x_built[i, mu]
            moved += delta * delta
        drift2 = max(drift2, moved)
    return drift2


@njit(cache=True)
def box_volume(box: np.ndarray) -> float:
    """Product of the box sides, left to right (a plain loop: inside a parallel=True caller
    np.prod may become a threaded reduction, whose rounding depends on the threads)."""
    volume = 1.0
    for side in box:
        volume *= side
    return volume


@njit(cache=True)
def container_volume(box: np.ndarray, cylinder: tuple[int, int]) -> float:
    """Volume of the container: `box_volume`, times π/4 in a cylinder (its circle of
    diameter L instead of the square L², `calippso.geometry.boundaries.Boundaries.volume`)."""
    volume = box_volume(box)
    if cylinder[0] >= 0:
        volume *= np.pi / 4.0
    return volume


# fire_run calls the parallel `harmonic_forces`. Compiled with parallel=True itself (it has
# no prange), it loads safely from Numba's on-disk cache even when a new argument type makes
# it compile anew; a cached serial caller of a parallel function crashes (numba issue #8578).
@njit(cache=True)
def converged(overlaps: int, largest2: float, mean_force: float, pressure: float,
              target: float, tolerance: float, force_floor: float) -> bool:
    """The convergence test of every minimiser of the enthalpy (FIRE, L-BFGS, Newton): some
    pair overlaps, max_i |F_i|² (`largest2`) ≤ max(tolerance × the mean pair force,
    `force_floor`)², and |p − p*| ≤ tolerance × p* (p* = `target`)."""
    return (overlaps > 0 and largest2 <= max(tolerance * mean_force, force_floor) ** 2
            and abs(pressure - target) <= tolerance * target)


@njit(parallel=True, cache=True)
def fire_run(x: np.ndarray, v: np.ndarray, f: np.ndarray, s: np.ndarray, box: np.ndarray,
             first: np.ndarray, second: np.ndarray, incoming_start: np.ndarray,
             incoming: np.ndarray, x_built: np.ndarray, skin: float, scale_built: float,
             state: np.ndarray, dt_max: float, dt_min: float, tolerance: float,
             force_floor: float, target: float, max_steps: int, periodic: np.ndarray,
             cylinder: tuple[int, int]):
    """FIRE 2.0 minimisation of the enthalpy H = E + p* Ṽ at pressure p* = `target`, until
    converged, a list rebuild or the step limit.

    The degrees of freedom are the positions (unit masses) and λ = ln a, the logarithm of
    the diameter scale. Ṽ = V / a^d is the box volume in units of the mean diameter, and
    −∂H/∂λ = d Ṽ (p* − p) drives λ; λ has the mass `SCALE_MASS` × N d, which gives it a
    frequency of order one (∂²E/∂λ² ≈ N_c ≈ N d near jamming). Growing the diameters at fixed
    positions is the same as shrinking the box affinely at fixed diameters.

    Parameters
    ----------
    x, v : ndarray, shape (N, d)
        Positions and velocities, updated in place (positions are not wrapped).
    f : ndarray, shape (N, d)
        Work array; holds the forces at the returned positions.
    s, box, first, second, incoming_start, incoming
        As in `harmonic_forces`; the lists hold every pair within σ + `skin` at the build.
    x_built : ndarray, shape (N, d)
        Positions at the last list build.
    skin : float
        Verlet skin at the build: a rebuild is due when 2 × the largest drift plus the growth
        of the largest diameter since the build exceeds it.
    scale_built : float
        Diameter scale at the last list build.
    state : ndarray, shape (6,)
        Δt, α, steps of positive power in a row, steps since the minimisation began, λ and
        its velocity (in units of √mass); carried across rebuilds, updated in place.
    dt_max, dt_min : float
        Bounds on Δt.
    tolerance, force_floor : float
        Converged when max_i |F_i| ≤ max(tolerance × the mean force of the overlapping pairs,
        force_floor) and |p − p*| ≤ tolerance × p*.
    target : float
        p*, in units of ε / (mean diameter)^d.
    max_steps : int
        Steps allowed in this call.
    periodic : ndarray, shape (d,), bool
        Periodic axes; flat walls at 0 and L_μ along the others (`harmonic_forces`), or the
        cylinder.
    cylinder : tuple of int
        The cylinder's two axes, or `NO_CYLINDER`; V is then the cylinder's volume
        (`container_volume`).

    Returns
    -------
    code : int
        CONVERGED, REBUILD (positions and scale moved; rebuild the lists and call again) or
        OUT_OF_STEPS.
    steps : int
        FIRE steps taken in this call.
    pressure : float
        Pressure at the returned positions (before a rebuild: at the previous step's).
    drift : float
        Largest distance a particle moved since the list build.
    """
    n, d = x.shape
    volume = container_volume(box, cylinder)
    root_mass = np.sqrt(SCALE_MASS * n * d)
    largest = s.max()
    partial = work_array(n)
    pair_force = np.empty((second.shape[0], d))
    dt, alpha, positive, age = state[0], state[1], state[2], state[3]
    log_scale, v_scale = state[4], state[5]
    scale = np.exp(log_scale)
    power, force2, speed2, largest2, force_sum, virial, overlaps, _ = harmonic_forces(
        x, v, s, scale, box, first, second, incoming_start, incoming, pair_force, f, partial,
        periodic, cylinder)
    steps = 0
    drift2 = 0.0
    code = OUT_OF_STEPS
    while True:
        pressure = virial * scale**d / (d * volume)
        f_scale = d * volume / scale**d * (target - pressure) / root_mass
        mean_force = force_sum / overlaps if overlaps > 0 else 0.0
        if converged(overlaps, largest2, mean_force, pressure, target, tolerance, force_floor):
            code = CONVERGED
            break
        if steps >= max_steps:
            break
        power += f_scale * v_scale
        force2 += f_scale * f_scale
        speed2 += v_scale * v_scale
        backstep = power <= 0.0
        if backstep:
            positive = 0.0
            if age >= N_DELAY:
                dt = max(dt * F_DEC, dt_min)
                alpha = ALPHA_START
            speed2 = (dt * dt) * force2
            log_scale -= 0.5 * dt * v_scale / root_mass
            v_scale = 0.0
        else:
            positive += 1.0
            if positive > N_DELAY:
                dt = min(dt * F_INC, dt_max)
                alpha *= F_ALPHA
            speed2 = speed2 + 2.0 * dt * power + dt * dt * force2
        push = alpha * np.sqrt(speed2 / force2) if force2 > 0.0 else 0.0
        v_scale = (1.0 - alpha) * (v_scale + dt * f_scale) + push * f_scale
        log_scale += dt * v_scale / root_mass
        scale = np.exp(log_scale)
        drift2 = _move(x, v, f, x_built, dt, 1.0 - alpha, push, backstep)
        steps += 1
        age += 1.0
        if 2.0 * np.sqrt(drift2) + largest * max(scale - scale_built, 0.0) > skin:
            code = REBUILD
            break
        power, force2, speed2, largest2, force_sum, virial, overlaps, _ = harmonic_forces(
            x, v, s, scale, box, first, second, incoming_start, incoming, pair_force, f,
            partial, periodic, cylinder)
    state[0], state[1], state[2], state[3] = dt, alpha, positive, age
    state[4], state[5] = log_scale, v_scale
    return code, steps, pressure, np.sqrt(drift2)


@njit(cache=True)
def contact_pairs(x: np.ndarray, s: np.ndarray, scale: float, box: np.ndarray,
                  first: np.ndarray, second: np.ndarray, largest_gap: float,
                  periodic: np.ndarray):
    """Every listed pair (i < j in slot order) with relative gap h = |r|/σ − 1 < `largest_gap`
    (the minimum image along the `periodic` axes only).

    Returns
    -------
    i, j : ndarray of int64, shape (M,)
    gaps : ndarray, shape (M,)
    """
    n, d = x.shape
    inv = inverse_sides(box, periodic)
    lower = np.empty(second.shape[0], dtype=np.int64)
    upper = np.empty(second.shape[0], dtype=np.int64)
    gaps = np.empty(second.shape[0])
    m = 0
    for i in range(n):
        for k in range(first[i], first[i + 1]):
            j = second[k]
            r2 = 0.0
            for mu in range(d):
                dx = image_component(x[i, mu] - x[j, mu], box[mu], inv[mu])
                r2 += dx * dx
            sigma = 0.5 * scale * (s[i] + s[j])
            gap = np.sqrt(r2) / sigma - 1.0
            if gap < largest_gap:
                lower[m], upper[m], gaps[m] = i, j, gap
                m += 1
    return lower[:m], upper[:m], gaps[:m]
