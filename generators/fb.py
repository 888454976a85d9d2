"""Force-biased (FB) generation: push overlapping spheres apart while their nominal size shrinks."""

from __future__ import annotations

import time

import numpy as np
from numba import njit

from calippso.geometry.boundaries import CYLINDER, PERIODIC, WALLS, Boundaries
from calippso.geometry.packing import Packing

from ._checks import (check_boundaries, check_diameters, check_dimension, check_phi,
                      check_positive, phi_estimate, remove_roundoff_overlap)
from ._progress import Progress
from .cells import verlet_lists
from .periodic import NO_CYLINDER, has_walls, image_component, inverse_sides, wrap_into_box
from .initial import poisson
from .result import GenerationResult, make_history

__all__ = ["force_biased"]

#: The boundary kinds `force_biased` handles.
BOUNDARY_KINDS = (PERIODIC, WALLS, CYLINDER)


@njit(cache=True)
def _wall_pushes(x, s, box, periodic, outer, force, inner, cylinder=NO_CYLINDER):
    """Wall terms of an FB step: a flat wall acts on sphere i as its mirror image, a partner
    of the same diameter at distance 2δ (δ the centre's distance to the wall). Adds the
    Bezrukov push σ_i² (1 − (2δ)²/σ_i²) along the wall's inward normal to `force` when the
    sphere overlaps the wall at its nominal size σ_i = s_i · outer, and returns `inner`
    lowered to 2δ/s_i where that is smaller (the scale at which the sphere touches the wall).
    A cylinder (axes `cylinder`, `NO_CYLINDER` without) does the same with δ = L/2 − ρ (ρ:
    the centre's distance from its axis) and the inward normal −ρ̂; its axes have no flat
    walls.
    """
    n, d = x.shape
    if cylinder[0] >= 0:
        inner = _cylinder_pushes(x, s, box, cylinder, outer, force, inner)
    for i in range(n):
        for mu in range(d):
            if periodic[mu] or mu == cylinder[0] or mu == cylinder[1]:
                continue
            for side in range(2):          # the wall at 0 (normal +e_μ), then at L_μ
                distance = x[i, mu] if side == 0 else box[mu] - x[i, mu]
                mirror = 2.0 * distance
                inner = min(inner, mirror / s[i])
                contact = s[i] * outer
                if mirror < contact:
                    push = contact * contact - mirror * mirror
                    force[i, mu] += push if side == 0 else -push
    return inner


@njit(cache=True)
def _cylinder_pushes(x, s, box, cylinder, outer, force, inner):
    """The cylinder's terms of `_wall_pushes`: sphere i, its centre ρ from the axis of the
    cylinder (axes a, b = `cylinder`, diameter L = box[a]), meets its mirror image at
    2δ = 2 (L/2 − ρ); the push σ_i² (1 − (2δ)²/σ_i²) along −ρ̂ when 2δ < σ_i = s_i · outer,
    and `inner` lowered to 2δ/s_i."""
    a, b = cylinder
    half = 0.5 * box[a]
    for i in range(x.shape[0]):
        offset_a = x[i, a] - half
        offset_b = x[i, b] - half
        rho = np.sqrt(offset_a * offset_a + offset_b * offset_b)
        mirror = 2.0 * (half - rho)
        inner = min(inner, mirror / s[i])
        contact = s[i] * outer
        if mirror < contact:           # then ρ > (L − σ_i)/2 > 0: ρ̂ is defined
            push = (contact * contact - mirror * mirror) / rho
            force[i, a] -= push * offset_a
            force[i, b] -= push * offset_b
    return inner


@njit(cache=True)
def _keep_between_walls(x, box, periodic, cylinder=NO_CYLINDER):
    """Hold every centre between the wall planes 0 and L_μ along the walled axes, and inside
    the cylinder's circle (`cylinder`: its axes, or `NO_CYLINDER`): an FB move can carry a
    squeezed sphere past its wall; the wall's push brings it back."""
    n, d = x.shape
    for i in range(n):
        for mu in range(d):
            if not periodic[mu] and mu != cylinder[0] and mu != cylinder[1]:
                x[i, mu] = min(max(x[i, mu], 0.0), box[mu])
    if cylinder[0] >= 0:
        a, b = cylinder
        half = 0.5 * box[a]
        for i in range(n):
            offset_a = x[i, a] - half
            offset_b = x[i, b] - half
            rho = np.sqrt(offset_a * offset_a + offset_b * offset_b)
            if rho > half:
                x[i, a] = half + offset_a * (half / rho)
                x[i, b] = half + offset_b * (half / rho)


@njit(cache=True)
def _fb_steps(x, s, box, outer, phi_unit, step_size, contraction, n_steps, skin, periodic,
              cylinder):
    """Run up to `n_steps` FB steps on positions `x` (in place).

    Each step, at the nominal ("outer") diameters s_i · outer:
      1. over the Verlet pairs, the closest pair sets the inner scale
         inner = min_ij |r_ij| / S_ij (S_ij = (s_i + s_j)/2); if inner ≥ outer nothing
         overlaps and the run is finished;
      2. every overlapping pair pushes its two spheres apart along r_ij with the Bezrukov
         potential p_ij = σ_i σ_j (1 − |r_ij|²/σ_ij²); r_i += step_size Σ_j p_ij r̂_ij / σ_i;
      3. outer ← outer − 0.5^j · contraction, j = ceil(−log10(φ_outer − φ_inner)), with
         φ_outer − φ_inner = φ_outer (1 − (inner/outer)^d) and φ_outer/outer^d =
         `phi_unit` (the packing fraction at scale 1).

    Along the axes that are not `periodic` flat walls at 0 and L_μ, or the cylinder whose
    axes are `cylinder` (`NO_CYLINDER` without), push the spheres back inside
    (`_wall_pushes`) and set the inner scale as a partner would; there is no minimum image
    or wrap along them.

    Returns
    -------
    outer, inner : float
        Scales after the last step (inner from the returned positions).
    steps : int
        Steps taken.
    finished : bool
        True when inner ≥ outer (no overlap at the nominal size).
    """
    n, d = x.shape
    delta = skin * s.mean() * outer
    xb = x.copy()
    start, neighbours = verlet_lists(x, box, s * outer, delta, periodic)
    force = np.zeros((n, d))
    r = np.empty(d)
    inv = inverse_sides(box, periodic)
    inner = 0.0
    walled = has_walls(periodic)
    for step in range(n_steps + 1):
        inner = np.inf
        force[:, :] = 0.0
        for i in range(n):
            for k in range(start[i], start[i + 1]):
                j = neighbours[k]
                if j <= i:
                    continue
                rr = 0.0
                for mu in range(d):
                    dx = image_component(x[i, mu] - x[j, mu], box[mu], inv[mu])
                    r[mu] = dx
                    rr += dx * dx
                sig = 0.5 * (s[i] + s[j])
                dist = np.sqrt(rr)
                if dist < sig * inner:
                    inner = dist / sig
                contact = sig * outer
                if dist < contact:
                    push = s[i] * s[j] * outer * outer * (1.0 - rr / (contact * contact)) / dist
                    for mu in range(d):
                        force[i, mu] += push * r[mu]
                        force[j, mu] -= push * r[mu]
        if walled:
            inner = _wall_pushes(x, s, box, periodic, outer, force, inner, cylinder)
        if inner >= outer:
            return outer, inner, step, True
        if step == n_steps:
            break
        moved = 0.0
        for i in range(n):
            factor = step_size / (s[i] * outer)
            disp2 = 0.0
            for mu in range(d):
                x[i, mu] += factor * force[i, mu]
                dx = x[i, mu] - xb[i, mu]
                disp2 += dx * dx
            moved = max(moved, disp2)
        if walled:
            _keep_between_walls(x, box, periodic, cylinder)
        phi_outer = phi_unit * outer**d
        gap = phi_outer * (1.0 - (inner / outer) ** d)
        j_exp = np.ceil(-np.log10(gap)) if gap > 0 else 0.0
        outer -= 0.5 ** max(j_exp, 0.0) * contraction
        if np.sqrt(moved) > 0.5 * delta:
            wrap_into_box(x, box, periodic)
            xb[:, :] = x
            start, neighbours = verlet_lists(x, box, s * outer, delta, periodic)
    return outer, inner, n_steps, False


def force_biased(diameters, d: int, *, phi_nominal: float | None = None,
                 contraction_rate: float = 1e-3, seed: int = 0, step_size: float = 0.25,
                 max_steps: int = 1_000_000, progress: bool = False,
                 skin: float = 0.5, boundaries: Boundaries | None = None) -> GenerationResult:
    """Force-biased packing generation (Mościński–Bargiel / Jodrey–Tory, Bezrukov forces).

    Spheres start at uniform random centres with their nominal diameters at packing fraction
    `phi_nominal`. Each step overlapping pairs repel each other with the Bezrukov potential
    p_ij = σ_i σ_j (1 − r_ij²/σ_ij²) (which treats polydisperse spheres consistently and
    reduces to the classical form for equal ones), moving sphere i by
    ``step_size · Σ_j p_ij r̂_ij / σ_i``. The true ("inner") diameters are the nominal ones
    scaled to the closest pair, so they never overlap. The nominal diameters shrink every
    step by 0.5^j · τ · σ_nominal,0 with j = ceil(−log10(φ_nominal − φ_inner)) and
    τ = `contraction_rate`, so the contraction slows as the two densities approach; the run
    ends when they meet (nothing overlaps at nominal size).

    Parameters
    ----------
    diameters : array_like, shape (N,)
        Diameters σ_i > 0; only their ratios matter (the result is returned with these
        diameters, in a box sized accordingly).
    d : int
        Dimension (≥ 2).
    phi_nominal : float, optional
        Initial nominal packing fraction in (0, 1); default 1.2 × a typical jamming density
        for d (0.84 for d = 2, (2.56 d − 2.72)/2^d for d ≥ 3).
    contraction_rate : float
        τ, relative shrink of the nominal diameters per step (1e-2 fast … 1e-5 slow and dense).
    seed : int
        Seed of the random centres.
    step_size : float
        ε, the displacement per unit force, in units of the nominal diameter.
    max_steps : int
        Safety limit on the number of steps.
    progress : bool
        Show a tqdm bar (−log10(φ_nominal − φ_inner)); quiet by default.
    skin : float
        Verlet skin in mean nominal diameters.
    boundaries : calippso.Boundaries, optional
        The container: periodic (None, the default), flat hard walls at 0 and L along some
        axes (`Boundaries.walls`) or a cylinder (`Boundaries.cylinder`). A sphere
        overlapping a wall at its nominal size is pushed back inside as by its mirror image
        (Bezrukov push of a partner at distance 2δ; in a cylinder δ = L/2 − ρ along −ρ̂),
        and the wall bounds the inner size as a partner would: the result lies inside the
        container. No minimum image and no wrap along walled axes or the cylinder's.

    Returns
    -------
    GenerationResult
        `reduced_pressure` is nan (FB has no dynamics); `steps` counts FB steps; history
        holds (step, φ_inner, nan, nominal shrink of the step / σ_nominal,0) every 50 steps;
        `extra`: ``phi_nominal_final``, ``overlap_correction``. With walls or a cylinder the
        packing carries the boundaries.

    Raises
    ------
    ValueError
        On non-positive diameters, d < 2, phi_nominal outside (0, 1) or a box too small.
    """
    wall = time.perf_counter()
    diameters = check_diameters(diameters)
    d = check_dimension(d)
    phi_nominal = min(0.95, 1.2 * phi_estimate(d)) if phi_nominal is None else phi_nominal
    phi_nominal = check_phi(phi_nominal, "phi_nominal")
    tau = check_positive(contraction_rate, "contraction_rate")
    step_size = check_positive(step_size, "step_size")
    boundaries = check_boundaries(boundaries, d, "force_biased", BOUNDARY_KINDS)
    start = poisson(diameters, d, phi=phi_nominal, seed=seed, boundaries=boundaries)
    mean = float(diameters.mean())
    # Units of the mean nominal diameter: nominal diameters s (mean 1) at scale `outer`.
    x = start.positions / mean
    box = start.box / mean
    s = diameters / mean
    outer, inner, steps, finished = 1.0, 0.0, 0, False
    rows = []
    bar = Progress(progress, 12.0, "FB -log10(phi_nom - phi_in)")
    try:
        while not finished and steps < max_steps:
            outer, inner, done, finished = _fb_steps(
                x, s, box, outer, phi_nominal, step_size, tau, min(50, max_steps - steps), skin,
                boundaries.periodic, boundaries.cylinder_axes or NO_CYLINDER)
            steps += done
            phi_inner = phi_nominal * inner**d
            gap = max(phi_nominal * outer**d - phi_inner, 0.0)
            j_exp = np.ceil(-np.log10(gap)) if gap > 0 else 0.0
            rows.append((steps, phi_inner, np.nan, 0.5 ** max(j_exp, 0.0) * tau))
            bar.update(-np.log10(gap) if gap > 0 else 12.0, phi=f"{phi_inner:.5f}")
    finally:
        bar.close()
    # The inner scale (closest listed pair in contact) is the final size; the KD-tree check
    # below scales down further in the rare case that an unlisted pair is closer.
    final = inner
    # Back to the caller's diameters: lengths × mean / final.
    factor = mean / final
    sizes, correction = remove_roundoff_overlap(
        x * factor, s * mean, box * factor,
        None if boundaries.is_periodic else boundaries.periodic, boundaries.cylinder_axes)
    packing = Packing(x * factor, sizes, box * factor, boundaries).wrapped()
    status = (f"nominal and inner diameters met after {steps} steps" if finished else
              f"stopped at max_steps = {max_steps} before the nominal and inner sizes met")
    return GenerationResult(
        packing=packing, reduced_pressure=float("nan"), steps=steps,
        wall_time=time.perf_counter() - wall, history=make_history(rows), status=status,
        extra={"phi_nominal_final": phi_nominal * outer**d, "overlap_correction": correction})
