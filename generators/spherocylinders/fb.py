"""Force-biased (FB) packings of spherocylinders (Bargiel 2008), in a periodic cubic box.

Every particle has a fixed shape (diameter d⁰_i, cylinder length l⁰_i = γ_i d⁰_i, the same
volume π/6 for all) times a common scale s. Two scales are followed:

- the nominal ("outer") scale s_out, at which overlaps are computed and pushed apart;
- the inner scale s_in, the largest scale at which the current configuration has no overlap.

Each step, every pair overlapping at s_out (shaft distance δ_ij < s_out σ⁰_ij) pushes its two
particles apart along the line between the closest points of the shafts, with strength
p_ij = d_i d_j (1 − δ_ij² / σ_ij²): r_i += ε Σ_j p_ij n_ji / d_i. It also turns them:
u_i ← normalise(u_i + ε_r Σ_j p_ij^r (λ_i / d_i) (d_i / l_i) t_ij), with
p_ij^r = 1 − δ_ij² / σ_ij², λ_i the position of the contact point on shaft i (|λ_i| ≤ l_i/2,
measured in diameters d_i as in Bargiel's reduced units) and t_ij the unit part of the push
perpendicular to u_i. ε_r = 0 keeps the random orientations fixed (isotropic).

By default ε_r is not one number for all aspect ratios but the rigid-body value
ε_r = ε γ / (k/d)² (`rigid_body_eps_rot`, k the radius of gyration of a solid spherocylinder
about a diameter): the turn is then what the same mobility ε / d_i that moves the centre gives
a rigid rod under the torques λ_ij u_i × F_ij, so that translations and rotations relax
overlaps at matched rates for every γ (a contact at the tip of a slender rod moves 3 times as
far by the turn as by the translation). A fixed ε_r such as Bargiel's 0.02 turns rods more
slowly than the rigid-body value by a factor that depends on γ (docs/notes/spherocylinder-density.md).

The start is Poisson centres with random axes at the nominal density η₀ = min(1.2, 12/γ)
(lower only when N is too small for the box rule). For long rods the start sets the result:
the rods first relax while they overlap many neighbours, and a denser start packs them denser
(docs/spherocylinders.md, "The start"). Holding η₀ γ fixed beyond γ = 10 holds the number of rods each rod
overlaps at the start fixed (the random-contact scaling φ γ ≈ const of long rods), and with
it φ γ of the packing.

The nominal scale then shrinks by the relative amount 0.5^j τ, j = ceil(−log10(φ_out − φ_in))
(τ the contraction rate). When no overlap is left at s_out, the inner and nominal scales meet:
the configuration is a packing. The particles are then grown again (nominal density raised by
a relative `regrowth`) and the pushing resumes; the run stops when a meeting no longer raises
the density by more than a relative `tolerance` (no further densification).
"""

from __future__ import annotations

import math
import time

import numba
import numpy as np

from .._checks import check_positive
from ..checkpoint import Checkpoint, digest
from ..result import GenerationResult, make_history
from .cells import pair_list
from ..periodic import wrap_coordinate
from .geometry import min_distance_ratio, segment_distance2, separation
from .packing import SpherocylinderPacking

__all__ = ["default_initial_density", "estimated_density", "force_biased", "pair_list_skin",
           "rigid_body_eps_rot", "start_density"]

#: Verlet skin, in units of the largest nominal diameter.
SKIN = 0.3
#: The skin when the box holds fewer than 3 cells of one particle reach, where every list is
#: built over all N² pairs (long rods in a small box): a wider skin means fewer builds. There
#: the list is in i < j order whatever the skin, so the pushes are summed in the same order and
#: the packing does not change as long as the box stays in that regime.
BRUTE_FORCE_SKIN = 1.5
#: Bisection steps for the inner scale of one pair (relative precision 2^-40 of the bracket).
BISECTION_STEPS = 40
#: Default nominal density of the start for spheres and rods up to γ = 10: at γ = 10 it gives
#: Bargiel's φ γ ≈ 4.5 (for spheres and short rods the start hardly matters).
INITIAL_DENSITY = 1.2
#: η₀ γ of the default start beyond γ = 10 (η₀ = 12/γ): the γ = 10 start carried over, so that
#: every long rod starts with as many overlapping neighbours.
LONG_ROD_START = 12.0
#: A start must lie this factor above `estimated_density` (PackingGeneration's start rule).
MIN_START = 1.2


def estimated_density(aspect_ratio: float) -> float:
    """Rough random-packing density of spherocylinders: the lowest admissible start is above it.

    min(0.70, 4.5 / γ) (Bargiel 2008: about 0.70 for short rods, φ γ ≈ 4.5 for long ones).
    """
    return 0.70 if aspect_ratio <= 4.5 / 0.70 else 4.5 / aspect_ratio


def start_density(aspect_ratio: float) -> float:
    """Default nominal density of the start for this (mean) aspect ratio, before the box rule:
    min(`INITIAL_DENSITY`, `LONG_ROD_START` / γ), i.e. 1.2 up to γ = 10 and 12/γ beyond."""
    if aspect_ratio <= LONG_ROD_START / INITIAL_DENSITY:
        return INITIAL_DENSITY
    return LONG_ROD_START / aspect_ratio


def default_initial_density(n: int, longest: float, aspect_ratio: float) -> float:
    """Nominal density of the start when `initial_density` is not given.

    `start_density` of the mean aspect ratio, lowered to the densest start the box rule allows
    when N is too small for it (never below `MIN_START` × `estimated_density`, which
    `force_biased` checks).

    Parameters
    ----------
    n : int
        Number of particles.
    longest : float
        Tip-to-tip length l + d of the longest particle, in units where every particle has the
        volume of a sphere of diameter 1.
    aspect_ratio : float
        Mean aspect ratio γ (number mean; with equal volumes also the volume mean).

    Returns
    -------
    float
        η₀, the nominal packing fraction of the start.
    """
    # l + d < L/2 with L³ = N π / (6 η₀)  ⇔  η₀ < N π / (48 (l + d)³)
    densest_allowed = n * math.pi / (48.0 * longest**3) * (1.0 - 1e-9)
    return min(start_density(aspect_ratio), densest_allowed)


def gyration_radius2(aspect_ratio):
    """k² / d²: squared radius of gyration of a solid spherocylinder about a diameter through its
    centre (uniform density), for diameter d = 1 and cylinder length l = γ.

    Cylinder (volume π l/4): l²/12 + 1/16; each hemisphere (volume π/12), about the centre:
    2/5 · 1/4 + l²/4 + 3 l/16 (parallel axes; its centre of mass is 3/16 from the flat face).
    """
    gamma = np.asarray(aspect_ratio, dtype=np.float64)
    cylinder = math.pi * gamma / 4.0
    cap = math.pi / 12.0
    inertia = cylinder * (gamma**2 / 12.0 + 1.0 / 16.0) + 2.0 * cap * (0.1 + gamma**2 / 4.0
                                                                        + 3.0 * gamma / 16.0)
    return inertia / (cylinder + 2.0 * cap)


def rigid_body_eps_rot(aspect_ratio, eps: float = 0.1):
    """ε_r that makes Bargiel's rotation the rigid-body response to the translation's forces.

    A translation step moves the centre by ε Σ_j F_ij / d_i with F_ij = p_ij n_ij (a mobility
    ε / d_i, the same for every particle of the same volume). The same mobility applied to the
    torques λ_ij u_i × F_ij of a rigid body with uniform density turns the axis by
    ε Σ_j p_ij λ_ij n_⊥ / (d_i k_i²), k_i the radius of gyration about a diameter. Bargiel's
    rotation u_i += ε_r Σ_j p^r_ij (λ_ij / l_i) t_ij (p_ij = d_i d_j p^r_ij) equals this for
    ε_r = ε d_j l_i / k_i², i.e. ε_r = ε γ_i / (k_i/d_i)² when d_j = d_i (used for every pair, also
    in mixtures, where it is the rigid-body value for contacts within a species). For ε = 0.1 it
    is 0.25 at γ = 0.4, 0.33 at γ = 1, 0.30 at γ = 2, 0.105 at γ = 10, 0.056 at γ = 20 and
    0.015 at γ = 80; a contact at the tip of a long rod then moves 3 times as far by the turn as
    by the translation (12 λ²/l² at λ = l/2, as for a slender rigid rod). Spheres (γ = 0): 0.
    """
    gamma = np.asarray(aspect_ratio, dtype=np.float64)
    return eps * gamma / gyration_radius2(gamma)


@numba.njit(cache=True)
def _evaluate(positions, axes, d0, h0, box, scale, pairs, rotate, push, turn, overlaps):
    """Pushes and turns of all pairs overlapping at `scale`, and a lower bound of s_in.

    Fills push, turn (N, 3) and the indices of overlapping pairs in `overlaps`; returns
    (number of overlapping pairs, min over them of δ_ij / σ⁰_ij).
    """
    push[:] = 0.0
    turn[:] = 0.0
    inverse = 1.0 / box
    count = 0
    lower = np.inf
    for k in range(pairs.shape[0]):
        i = pairs[k, 0]
        j = pairs[k, 1]
        sigma0 = 0.5 * (d0[i] + d0[j])
        sigma = scale * sigma0
        hi = scale * h0[i]
        hj = scale * h0[j]
        rx, ry, rz = separation(positions, box, inverse, i, j)
        uix, uiy, uiz = axes[i, 0], axes[i, 1], axes[i, 2]
        ujx, ujy, ujz = axes[j, 0], axes[j, 1], axes[j, 2]
        d2, lam, mu = segment_distance2(rx, ry, rz, uix, uiy, uiz, ujx, ujy, ujz, hi, hj)
        if d2 >= sigma * sigma:
            continue
        overlaps[count] = k
        count += 1
        distance = math.sqrt(d2)
        if distance / sigma0 < lower:
            lower = distance / sigma0
        # Unit normal from the contact point on i to the one on j.
        nx = rx + mu * ujx - lam * uix
        ny = ry + mu * ujy - lam * uiy
        nz = rz + mu * ujz - lam * uiz
        if distance > 1e-12 * sigma:
            nx, ny, nz = nx / distance, ny / distance, nz / distance
        else:  # shafts cross: push along u_i × u_j (or any direction normal to u_i)
            nx = uiy * ujz - uiz * ujy
            ny = uiz * ujx - uix * ujz
            nz = uix * ujy - uiy * ujx
            norm = math.sqrt(nx * nx + ny * ny + nz * nz)
            if norm < 1e-12:
                nx, ny, nz = (uiy, -uix, 0.0) if abs(uiz) < 0.9 else (0.0, uiz, -uiy)
                norm = math.sqrt(nx * nx + ny * ny + nz * nz)
            nx, ny, nz = nx / norm, ny / norm, nz / norm
        strength = 1.0 - d2 / (sigma * sigma)
        di = scale * d0[i]
        dj = scale * d0[j]
        p = di * dj * strength
        push[i, 0] -= p * nx / di
        push[i, 1] -= p * ny / di
        push[i, 2] -= p * nz / di
        push[j, 0] += p * nx / dj
        push[j, 1] += p * ny / dj
        push[j, 2] += p * nz / dj
        if rotate:
            # i is pushed along -n at lam, j along +n at mu; turn by the perpendicular part.
            for particle, h, at, sign, ux, uy, uz, dp in ((i, hi, lam, -1.0, uix, uiy, uiz, di),
                                                          (j, hj, mu, 1.0, ujx, ujy, ujz, dj)):
                if h <= 0.0:
                    continue
                along = nx * ux + ny * uy + nz * uz
                tx = sign * (nx - along * ux)
                ty = sign * (ny - along * uy)
                tz = sign * (nz - along * uz)
                tnorm = math.sqrt(tx * tx + ty * ty + tz * tz)
                if tnorm < 1e-12:
                    continue
                weight = strength * at / (2.0 * h * tnorm)
                turn[particle, 0] += weight * tx
                turn[particle, 1] += weight * ty
                turn[particle, 2] += weight * tz
    return count, lower


@numba.njit(cache=True)
def _move(positions, axes, box, push, turn, eps, eps_rot, reach, moved):
    """Apply the moves, wrap, and add to `moved` a bound on how far any shaft point went.

    `eps_rot` holds the rotation step ε_r of every particle (0: the axis stays fixed).
    """
    n = positions.shape[0]
    for i in range(n):
        dx = eps * push[i, 0]
        dy = eps * push[i, 1]
        dz = eps * push[i, 2]
        positions[i, 0] += dx
        positions[i, 1] += dy
        positions[i, 2] += dz
        for a in range(3):
            positions[i, a] = wrap_coordinate(positions[i, a], box[a])
        step = math.sqrt(dx * dx + dy * dy + dz * dz)
        if eps_rot[i] > 0.0:
            ux = axes[i, 0] + eps_rot[i] * turn[i, 0]
            uy = axes[i, 1] + eps_rot[i] * turn[i, 1]
            uz = axes[i, 2] + eps_rot[i] * turn[i, 2]
            norm = math.sqrt(ux * ux + uy * uy + uz * uz)
            ux, uy, uz = ux / norm, uy / norm, uz / norm
            ex = ux - axes[i, 0]
            ey = uy - axes[i, 1]
            ez = uz - axes[i, 2]
            step += reach[i] * math.sqrt(ex * ex + ey * ey + ez * ez)
            axes[i, 0], axes[i, 1], axes[i, 2] = ux, uy, uz
        moved[i] += step


@numba.njit(cache=True)
def _gap(positions, axes, d0, h0, box, inverse, i, j, scale):
    """δ_ij(scale) − scale σ⁰_ij: ≥ 0 when the pair does not overlap at that scale."""
    rx, ry, rz = separation(positions, box, inverse, i, j)
    d2, _, _ = segment_distance2(rx, ry, rz, axes[i, 0], axes[i, 1], axes[i, 2],
                                 axes[j, 0], axes[j, 1], axes[j, 2],
                                 scale * h0[i], scale * h0[j])
    return math.sqrt(d2) - scale * 0.5 * (d0[i] + d0[j])


@numba.njit(cache=True)
def _inner_scale(positions, axes, d0, h0, box, scale, pairs, overlaps, count):
    """The largest scale s ≤ `scale` at which no listed pair overlaps (to ~1e-12 relative).

    Along s, δ_ij(s) can only shrink (the shafts grow about fixed centres) while s σ⁰_ij grows,
    so each pair has one root s*_ij. For a pair overlapping at `scale`, lo = δ(scale)/σ⁰ ≤ s* and
    hi = δ(lo)/σ⁰ ≥ s*. Pairs whose lo exceeds the smallest hi cannot hold the minimum; the
    others are bisected, keeping the feasible end. The result is feasible (no overlap) as
    evaluated in floating point.
    """
    lows = np.empty(count)
    inverse = 1.0 / box
    upper = scale
    for k in range(count):
        i = pairs[overlaps[k], 0]
        j = pairs[overlaps[k], 1]
        sigma0 = 0.5 * (d0[i] + d0[j])
        lo = (_gap(positions, axes, d0, h0, box, inverse, i, j, scale) + scale * sigma0) / sigma0
        lows[k] = lo
        hi = (_gap(positions, axes, d0, h0, box, inverse, i, j, lo) + lo * sigma0) / sigma0
        if hi < upper:
            upper = hi
    result = scale
    for k in range(count):
        lo = lows[k]
        if lo >= upper or lo >= result:
            if lo < result:
                result = lo
            continue
        i = pairs[overlaps[k], 0]
        j = pairs[overlaps[k], 1]
        hi = min(upper, scale)
        if _gap(positions, axes, d0, h0, box, inverse, i, j, lo) < 0.0:  # rounding: step back
            lo *= 1.0 - 1e-12
        for _ in range(BISECTION_STEPS):
            mid = 0.5 * (lo + hi)
            if mid <= lo or mid >= hi:
                break
            if _gap(positions, axes, d0, h0, box, inverse, i, j, mid) >= 0.0:
                lo = mid
            else:
                hi = mid
        if lo < result:
            result = lo
    return result


def _species(n: int, aspect_ratio: float, mixture) -> tuple[np.ndarray, str]:
    """Aspect ratio of every particle, and a description of the composition."""
    if isinstance(n, bool) or not isinstance(n, (int, np.integer)) or n < 2:
        raise ValueError(f"n must be an integer >= 2, got {n!r}")
    gammas = [aspect_ratio]
    if mixture is not None:
        try:
            count, second = mixture
        except (TypeError, ValueError):
            raise ValueError(f"mixture must be a pair (count, aspect_ratio) for the second "
                             f"species, got {mixture!r}") from None
        if isinstance(count, bool) or not isinstance(count, (int, np.integer)) or \
                not 0 < count < n:
            raise ValueError(f"mixture count must be an integer in 1 … n − 1 = {n - 1}, "
                             f"got {count!r}")
        gammas.append(second)
    for gamma in gammas:
        if not isinstance(gamma, (int, float, np.integer, np.floating)) or \
                not math.isfinite(gamma) or gamma < 0:
            raise ValueError(f"aspect ratios must be finite and >= 0, got {gamma!r}")
    if mixture is None:
        return np.full(n, float(aspect_ratio)), f"{n} × γ = {aspect_ratio:g}"
    count, second = mixture
    per_particle = np.full(n, float(aspect_ratio))
    per_particle[n - count:] = float(second)
    return per_particle, f"{n - count} × γ = {aspect_ratio:g} + {count} × γ = {second:g}"


def force_biased(n: int, aspect_ratio: float, *, mixture: tuple[int, float] | None = None,
                 eps: float = 0.1, eps_rot: float | None = None, contraction_rate: float = 1e-4,
                 initial_density: float | None = None, regrowth: float = 1e-3,
                 tolerance: float = 1e-4, max_steps: int = 200_000, seed: int = 0,
                 progress: bool = False, checkpoint=None,
                 checkpoint_every: float = 60.0) -> GenerationResult:
    """Random dense packing of spherocylinders by the force-biased algorithm (Bargiel 2008).

    Parameters
    ----------
    n : int
        Number of particles N (≥ 2).
    aspect_ratio : float
        γ = l / d ≥ 0 (0: spheres) of all particles, or of the first species with `mixture`.
    mixture : (int, float), optional
        (count, γ₂): the last `count` particles form a second species of aspect ratio γ₂. All
        particles have the same volume.
    eps : float
        Translation step ε (> 0), dimensionless.
    eps_rot : float or None
        Rotation step ε_r (≥ 0) of Bargiel's rotation, the same for every particle; 0 keeps
        the random orientations fixed (isotropic packing). None (default): the rigid-body value
        `rigid_body_eps_rot` of each particle's aspect ratio (0.25 at γ = 0.4, 0.30 at γ = 2,
        0.105 at γ = 10, 0.056 at γ = 20, 0.015 at γ = 80, for ε = 0.1).
    contraction_rate : float
        τ in (0, 1): the nominal scale shrinks by 0.5^j τ per step. Slower is denser.
    initial_density : float, optional
        Nominal packing fraction η₀ of the start (Poisson centres, random axes). Default
        (`default_initial_density`): min(1.2, 12/γ) of the mean aspect ratio γ, or the
        densest start the box rule allows for this N when that is lower, but at least
        1.2 × `estimated_density`. For long rods a denser start gives a denser packing
        (γ = 10: φ γ = 3.45 from η₀ = 0.54, 4.36 from 1.2; γ = 20: 4.25 from 0.6, 6.47 from
        1.2); `extra["initial_density"]` records it.
    regrowth : float
        Relative rise of the nominal density after the nominal and inner scales meet.
    tolerance : float
        Stop when a meeting raises φ by less than this relative amount over the previous one.
    max_steps : int
        Hard limit on FB steps (then the densest overlap-free state seen is returned).
    seed : int
        Seed of the random start (numpy `default_rng`).
    progress : bool
        Show a tqdm progress bar.
    checkpoint : str or PathLike, optional
        File (``.npz``) holding the whole state of the run (`generators.checkpoint`): written
        atomically between two steps at most every `checkpoint_every` seconds, and once more
        when the run ends. A call with the same arguments and an existing file continues from
        it, bit for bit as the uninterrupted run; once the run has ended it returns the same
        result again. A file written by a call with other arguments is refused.
    checkpoint_every : float
        Smallest wall time in seconds between two checkpoint writes (0: every step).

    Returns
    -------
    GenerationResult
        `packing` is a `SpherocylinderPacking` without overlaps (checked over all pairs with
        the exact shaft distance), in units where every particle has the volume of a sphere
        of diameter 1. `steps` counts FB steps; `history` samples (step, φ_in, nan,
        relative shrink per step); `extra` holds "phi_nominal", "initial_density", "meetings",
        "list_builds", "nematic_order", "composition" and "seed".

    Raises
    ------
    ValueError
        For bad arguments, or when the box would be too small: a particle (tip to tip,
        l + d) must stay below half the box side, which needs
        N > 48 (γ + 1)³ η₀ / (π (1.5 γ + 1)) (the message gives the N needed); or when
        `checkpoint` names a file of another run.
    """
    started = time.perf_counter()
    gammas, composition = _species(n, aspect_ratio, mixture)
    for name, value, low in (("eps", eps, 0.0), ("contraction_rate", contraction_rate, 0.0),
                             ("regrowth", regrowth, 0.0), ("tolerance", tolerance, 0.0)):
        if not (isinstance(value, (int, float)) and math.isfinite(value) and value > low):
            raise ValueError(f"{name} must be a finite number > {low:g}, got {value!r}")
    if eps_rot is None:
        steps_rot = rigid_body_eps_rot(gammas, eps)
    elif isinstance(eps_rot, (int, float)) and math.isfinite(eps_rot) and eps_rot >= 0:
        steps_rot = np.full(n, float(eps_rot))
    else:
        raise ValueError(f"eps_rot must be None or a finite number >= 0, got {eps_rot!r}")
    rotate = bool(np.any(steps_rot > 0))
    if contraction_rate >= 1:
        raise ValueError(f"contraction_rate must be below 1, got {contraction_rate}")
    d0 = (1.5 * gammas + 1.0) ** (-1.0 / 3.0)  # volume π/6 for every particle
    h0 = 0.5 * gammas * d0
    longest = float(np.max(2.0 * h0 + d0))
    mean_gamma = float(np.mean(gammas))  # equal volumes: number and volume means coincide
    if initial_density is None:
        lowest = MIN_START * estimated_density(mean_gamma)
        eta0 = max(default_initial_density(n, longest, mean_gamma), lowest)
    else:
        eta0 = initial_density
    if not (isinstance(eta0, (int, float)) and 0 < eta0 < 2):
        raise ValueError(f"initial_density must be in (0, 2), got {eta0!r}")
    side = (n * math.pi / 6.0 / eta0) ** (1.0 / 3.0)
    if longest >= 0.5 * side:
        needed = math.floor(48.0 * longest**3 * eta0 / math.pi) + 1
        default = start_density(mean_gamma)
        full = math.floor(48.0 * longest**3 * default / math.pi) + 1
        advice = ("" if initial_density is not None else
                  f" (N >= {full} for the default start at {default:.3g})")
        raise ValueError(
            f"box too small: with N = {n} particles ({composition}) at nominal density "
            f"{eta0:.3g} the box side is {side:.3g} but a particle is {longest:.3g} long "
            f"(l + d must stay below half the box); use N >= {needed}{advice}")
    box = np.full(3, side)

    rng = np.random.default_rng(seed)
    positions = rng.uniform(0.0, side, (n, 3))
    axes = rng.normal(size=(n, 3))
    axes /= np.linalg.norm(axes, axis=1)[:, None]

    push = np.empty((n, 3))
    turn = np.empty((n, 3))
    moved = np.zeros(n)
    total_volume = n * math.pi / 6.0 / side**3  # φ = total_volume · s³
    scale = 1.0
    skin = SKIN * float(d0.max())
    list_skin = skin
    best = (0.0, positions.copy(), axes.copy())
    last_meeting = 0.0
    meetings = list_builds = step = 0
    rows = []
    status = f"stopped after max_steps = {max_steps} steps"
    pairs = np.empty((0, 2), dtype=np.int64)
    overlaps = np.empty(0, dtype=np.int64)
    list_scale = 0.0
    finished = False
    earlier_time = 0.0  # wall time of earlier calls that worked on this run (checkpoint)

    saver = Checkpoint(checkpoint, "spherocylinders.force_biased", {
        "n": n, "gammas": digest(gammas), "eps": eps, "eps_rot": digest(steps_rot),
        "contraction_rate": contraction_rate, "initial_density": eta0, "regrowth": regrowth,
        "tolerance": tolerance, "max_steps": max_steps, "seed": seed},
        every=check_positive(checkpoint_every, "checkpoint_every", allow_zero=True))
    saved = saver.load()
    if saved is not None:
        positions, axes = saved["positions"].copy(), saved["axes"].copy()
        moved = saved["moved"].copy()
        pairs = saved["pairs"].astype(np.int64)
        overlaps = np.empty(pairs.shape[0], dtype=np.int64)
        best = (float(saved["best_scale"]), saved["best_positions"].copy(),
                saved["best_axes"].copy())
        scale, list_scale, list_skin = (float(saved[key]) for key in
                                        ("scale", "list_scale", "list_skin"))
        last_meeting, earlier_time = float(saved["last_meeting"]), float(saved["wall_time"])
        meetings, list_builds, step = (int(saved[key]) for key in
                                       ("meetings", "list_builds", "step"))
        rows = [tuple(row) for row in saved["rows"]]
        status, finished = str(saved["status"]), bool(saved["finished"])

    def state() -> dict:
        return {"positions": positions, "axes": axes, "moved": moved, "pairs": pairs,
                "best_scale": best[0], "best_positions": best[1], "best_axes": best[2],
                "scale": scale, "list_scale": list_scale, "list_skin": list_skin,
                "last_meeting": last_meeting, "meetings": meetings, "list_builds": list_builds,
                "step": step, "rows": np.array(rows, dtype=np.float64).reshape(-1, 4),
                "status": status, "finished": finished,
                "wall_time": earlier_time + time.perf_counter() - started}

    bar = None
    if progress and not finished:
        from tqdm import tqdm
        bar = tqdm(desc="FB spherocylinders", unit=" steps", initial=step)
    while step < max_steps and not finished:
        saver.maybe_save(state())
        top_two = np.partition(moved, n - 2)[n - 2:] if n >= 2 else moved
        if scale > list_scale or top_two.sum() >= list_skin:
            list_scale = scale
            list_skin = pair_list_skin(scale, h0, d0, box, skin)
            pairs = pair_list(positions, axes, scale * h0, scale * d0, box, list_skin)
            overlaps = np.empty(pairs.shape[0], dtype=np.int64)
            moved[:] = 0.0
            list_builds += 1
        count, _ = _evaluate(positions, axes, d0, h0, box, scale, pairs, rotate, push, turn,
                             overlaps)
        if count == 0:
            inner = scale
        else:
            inner = _inner_scale(positions, axes, d0, h0, box, scale, pairs, overlaps, count)
        if inner > best[0]:
            best = (inner, positions.copy(), axes.copy())
        phi_in, phi_out = total_volume * inner**3, total_volume * scale**3
        if count == 0:
            meetings += 1
            if phi_in < last_meeting * (1.0 + tolerance):
                status = (f"no further densification: meeting {meetings} at phi = {phi_in:.6f} "
                          f"after {step} steps")
                rows.append((step, phi_in, math.nan, 0.0))
                break
            last_meeting = max(last_meeting, phi_in)
            scale = min(scale * (1.0 + regrowth) ** (1.0 / 3.0), 1.0)
            rows.append((step, phi_in, math.nan, 0.0))
            continue
        j = max(0, math.ceil(-math.log10(max(phi_out - phi_in, 1e-300))))
        shrink = 0.5**j * contraction_rate
        if step % 10 == 0:
            rows.append((step, phi_in, math.nan, shrink))
            if bar is not None:
                bar.set_postfix(phi_in=f"{phi_in:.5f}", phi_out=f"{phi_out:.5f}", refresh=False)
        _move(positions, axes, box, push, turn, eps, steps_rot, list_scale * h0, moved)
        scale = max(scale * (1.0 - shrink), inner)
        step += 1
        if bar is not None:
            bar.update(1)
    if bar is not None:
        bar.close()
    if not finished:
        finished = True
        saver.save(state())

    packing = _overlap_free(best, d0, h0, box)
    return GenerationResult(
        packing=packing, reduced_pressure=math.nan, steps=step,
        wall_time=earlier_time + time.perf_counter() - started, history=make_history(rows),
        status=status,
        extra={"phi_nominal": total_volume * scale**3, "initial_density": eta0,
               "meetings": meetings, "list_builds": list_builds,
               "nematic_order": packing.nematic_order(), "composition": composition,
               "seed": seed})


def pair_list_skin(scale: float, h0: np.ndarray, d0: np.ndarray, box: np.ndarray,
                   skin: float) -> float:
    """The Verlet skin with which `force_biased` builds a new pair list.

    `skin`, or the wider `BRUTE_FORCE_SKIN` when the cells of `cells.pair_list` (side: the
    longest reach plus `skin`) would number fewer than 3 along a side, so that the list is
    built over all pairs anyway and a wider skin means fewer builds.

    Parameters
    ----------
    scale : float
        Current scale of the particles (their sizes are `scale` × `h0`, `scale` × `d0`).
    h0 : ndarray, shape (N,)
        Nominal half-lengths of the cylinders (length units).
    d0 : ndarray, shape (N,)
        Nominal diameters (length units).
    box : ndarray, shape (3,)
        Periodic box sides (length units).
    skin : float
        The usual skin, `SKIN` × the largest nominal diameter (length units).

    Returns
    -------
    float
        The skin of the new list (length units).
    """
    cell_side = scale * (2.0 * float(h0.max()) + float(d0.max())) + skin
    if np.floor(box.min() / cell_side) >= 3:
        return skin
    return BRUTE_FORCE_SKIN * float(d0.max())


def _overlap_free(best, d0, h0, box) -> SpherocylinderPacking:
    """The densest state as a packing, shrunk (by ~1e-12) until no pair overlaps exactly."""
    scale, positions, axes = best
    factor = scale * (1.0 - 1e-12)
    for _ in range(10):
        packing = SpherocylinderPacking(positions, axes, factor * d0, factor * 2.0 * h0, box)
        ratio = min_distance_ratio(packing)
        if ratio >= 1.0:
            return packing
        factor *= ratio * (1.0 - 1e-12)
    raise RuntimeError("could not remove the last overlaps of the final packing")
