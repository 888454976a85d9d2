"""Numba event-driven molecular dynamics of growing hard spheres in d dimensions (LS and MLS).

Model (mass 1, k_B = 1): particle i has diameter σ_i(t) = s_i · a(t), a(t) = a₀ + γ t, with
s_i its nominal diameter and γ the growth rate (length per time unit, for s = 1). Between
events the spheres move ballistically.

Events, one per particle, kept in an indexed binary min-heap:

* collision with a Verlet neighbour j: the smallest τ > 0 with |r_ij + v_ij τ| = S_ij a(t + τ),
  S_ij = (s_i + s_j)/2. The normal relative velocity u is replaced by 2w − u, w = S_ij γ the
  speed at which the contact distance grows, so the pair separates faster than it grows; the
  impulse J = w − u goes into the collisional virial. A prediction stores the partner's
  collision counter and is discarded when it is popped after the partner has collided.
* collision with a flat wall (along an axis that is not periodic, walls at 0 and L_μ): the
  smallest τ > 0 with x_iμ + v_iμ τ = σ_i(t + τ)/2 (wall at 0) or L_μ − σ_i(t + τ)/2 (at L_μ).
  The wall is a fixed body of infinite mass: the normal velocity u = v_i·n (n the wall's
  inward normal) is replaced by 2w − u, w = s_i γ/2 the speed at which the contact distance
  σ_i/2 grows, as in a pair collision with the partner held still; the impulse 2(w − u) times
  the contact distance σ_i/2 goes into the collisional virial (the pressure on the walls,
  docs/theory.md). Its prediction is valid until particle i itself collides.
* collision with a cylinder (two axes a, b with equal sides L, `cylinder` = (a, b), no
  minimum image along either): with ρ the centre's offset from the cylinder's axis in the
  circle's plane and w its velocity there, the smallest τ > 0 with
  |ρ + w τ| = L/2 − σ_i(t + τ)/2, a quadratic in τ solved in the cancellation-free forms of
  the pair collisions (`_cylinder_event`). The normal is −ρ̂ at contact, and the reflection,
  the impulse and its virial term (σ_i/2, the centre's distance to the wall along the
  radius, × the impulse: the wall's gap under an affine dilation of the box, as for a flat
  wall) are those of a flat wall. It is wall number 2d (`calippso.geometry.walls.cylinder_wall`).
* neighbour-list expiry: the Verlet lists hold every pair with |r_ij| < S_ij a_b + δ at the
  build (scale a_b). A pair outside the lists cannot touch while every particle has moved less
  than h(t) = (δ − s_max (a(t) − a_b))/2 since the build, so the moment a particle reaches that
  distance is an event; it rebuilds the lists (all particles synchronised, cell lists).

Every `rescale_every` collisions all particles are synchronised, the velocities are rescaled to
the target temperature (the growth injects kinetic energy) and every prediction is redone.
"""

from __future__ import annotations

import numpy as np
from numba import njit

from .cells import verlet_lists
from .periodic import NO_CYLINDER, has_walls, image_component, inverse_sides, wrap_into_box

__all__ = ["run_window", "skin_length"]

_NO_EVENT = -2
_LIST_EXPIRY = -1
#: Event partner of a collision with wall w (2μ at 0, 2μ + 1 at L_μ, 2d the cylinder):
#: _WALL − w.
_WALL = -3


@njit(cache=True)
def skin_length(box: np.ndarray, n: int, scale: float, s_mean: float, s_max: float,
                skin: float) -> float:
    """Verlet skin δ: `skin` mean diameters, widened at low density to the mean spacing.

    δ = max(skin · s̄ a, (V/N)^{1/d} − s_max a), capped so that the list radius s_max a + δ
    stays below 0.49 L_min (minimum image). Returns a negative value if the particles are too
    large for the box.
    """
    d = box.shape[0]
    volume = 1.0
    for mu in range(d):
        volume *= box[mu]
    spacing = (volume / n) ** (1.0 / d)
    delta = max(skin * s_mean * scale, spacing - s_max * scale)
    return min(delta, 0.49 * box.min() - s_max * scale)


@njit(cache=True)
def _sift_up(heap, where, key, k):
    item = heap[k]
    while k > 0:
        parent = (k - 1) >> 1
        if key[heap[parent]] <= key[item]:
            break
        heap[k] = heap[parent]
        where[heap[k]] = k
        k = parent
    heap[k] = item
    where[item] = k


@njit(cache=True)
def _sift_down(heap, where, key, k):
    n = heap.shape[0]
    item = heap[k]
    while True:
        child = 2 * k + 1
        if child >= n:
            break
        if child + 1 < n and key[heap[child + 1]] < key[heap[child]]:
            child += 1
        if key[item] <= key[heap[child]]:
            break
        heap[k] = heap[child]
        where[heap[k]] = k
        k = child
    heap[k] = item
    where[item] = k


@njit(cache=True)
def _heapify(heap, where, key):
    n = heap.shape[0]
    for k in range(n):
        heap[k] = k
        where[k] = k
    for k in range(n // 2 - 1, -1, -1):
        _sift_down(heap, where, key, k)


@njit(cache=True)
def _reposition(heap, where, key, i):
    _sift_up(heap, where, key, where[i])
    _sift_down(heap, where, key, where[i])


@njit(cache=True)
def _expiry_time(x, xb, v, i, c, e):
    """Smallest τ > 0 with |D + v τ| = c − e τ (D = x_i − xb_i, |D| < c), at most c/e."""
    d = x.shape[1]
    dd = 0.0
    dv = 0.0
    vv = 0.0
    for mu in range(d):
        disp = x[i, mu] - xb[i, mu]
        dd += disp * disp
        dv += disp * v[i, mu]
        vv += v[i, mu] * v[i, mu]
    if c <= 0.0 or dd >= c * c:
        return 0.0
    limit = c / e if e > 0.0 else np.inf
    qa = vv - e * e
    qb = dv + c * e
    qc = dd - c * c  # < 0
    disc = qb * qb - qa * qc
    tau = np.inf
    if qa > 0.0:
        root = np.sqrt(disc)
        if qb < 0.0:
            tau = (-qb + root) / qa
        elif qb + root > 0.0:  # 0 only for a particle at rest (|v|² denormal, seen in MLS)
            tau = -qc / (qb + root)
    elif qa < 0.0 and disc >= 0.0:
        root = np.sqrt(disc)
        for cand in ((-qb + root) / qa, (-qb - root) / qa):
            if 0.0 < cand < tau:
                tau = cand
    elif qa == 0.0 and qb > 0.0:
        tau = -qc / (2.0 * qb)
    return min(tau, limit)


@njit(cache=True)
def _wall_event(i, x, v, s, box, periodic, scale, rate, cylinder=NO_CYLINDER):
    """Time to the first collision of particle i (synchronised) with a flat wall, and the
    wall's number 2μ + side (side 0 at 0, 1 at L_μ); (inf, _NO_EVENT) without walls.

    The gap to a wall closes at w − u, u the velocity along the wall's inward normal and
    w = s_i γ/2 the growth of the radius; a particle touching (or, by round-off, crossing)
    a wall and approaching it collides at once. The `cylinder`'s axes (if any) have no flat
    walls (`_cylinder_event`)."""
    best = np.inf
    wall = _NO_EVENT
    radius = 0.5 * s[i] * scale
    growth = 0.5 * s[i] * rate
    for mu in range(x.shape[1]):
        if periodic[mu] or mu == cylinder[0] or mu == cylinder[1]:
            continue
        for side in range(2):
            gap = x[i, mu] - radius if side == 0 else box[mu] - x[i, mu] - radius
            closing = growth - v[i, mu] if side == 0 else growth + v[i, mu]
            if closing <= 0.0:
                continue
            tau = max(gap, 0.0) / closing
            if tau < best:
                best = tau
                wall = 2 * mu + side
    return best, wall


@njit(cache=True)
def _wall_collision(i, wall, v, s, scale, rate):
    """Reflect particle i off `wall` (2μ + side) at contact: u → 2w − u along the inward
    normal (w = s_i γ/2); return the virial term (σ_i/2) × impulse (≥ 0)."""
    mu = wall // 2
    normal = 1.0 if wall % 2 == 0 else -1.0
    u = v[i, mu] * normal
    impulse = max(2.0 * (0.5 * s[i] * rate - u), 0.0)
    v[i, mu] += impulse * normal
    return 0.5 * s[i] * scale * impulse


@njit(cache=True)
def _cylinder_event(i, x, v, s, box, cylinder, scale, rate):
    """Time to the collision of particle i (synchronised) with the cylinder whose circle lies
    in the axes (a, b) = `cylinder`, of diameter L = box[a] and centred at (L/2, L/2); inf if
    there is none.

    With ρ the centre's offset from the cylinder's axis, w its velocity in the circle's
    plane, R = (L − σ_i)/2 and g = s_i γ/2 the growth of the radius, the contact is the
    smallest τ > 0 with |ρ + w τ| = R − g τ. Its square is the quadratic
    qa τ² + 2 qb τ + qc = 0 with qa = |w|² − g², qb = ρ·w + R g, qc = |ρ|² − R², and
    qb > 0 means approaching. Inside (qc < 0) the smallest positive root of the quadratic is
    the first zero of the gap R − g τ − |ρ + w τ| (before it R − g τ stays positive): for
    qb > 0 it is −qc / (qb + √disc) whatever the sign of qa, for qb ≤ 0 it exists only when
    qa > 0, (−qb + √disc)/qa (disc = qb² − qa qc). A particle touching (or, by round-off,
    crossing) the cylinder and approaching it collides at once; one receding (just
    reflected) meets it again at the far root."""
    a, b = cylinder
    half = 0.5 * box[a]
    offset_a = x[i, a] - half
    offset_b = x[i, b] - half
    reach = half - 0.5 * s[i] * scale
    growth = 0.5 * s[i] * rate
    qa = v[i, a] * v[i, a] + v[i, b] * v[i, b] - growth * growth
    qb = offset_a * v[i, a] + offset_b * v[i, b] + reach * growth
    qc = offset_a * offset_a + offset_b * offset_b - reach * reach
    disc = max(qb * qb - qa * qc, 0.0)
    if qb > 0.0:
        if qc >= 0.0:
            return 0.0
        return -qc / (qb + np.sqrt(disc))
    if qa > 0.0:
        return (-qb + np.sqrt(disc)) / qa
    return np.inf


@njit(cache=True)
def _cylinder_collision(i, x, v, s, box, cylinder, scale, rate):
    """Reflect particle i off the cylinder at contact as off a flat wall (`_wall_collision`)
    with the inward normal −ρ̂; return the virial term (σ_i/2) × impulse (≥ 0)."""
    a, b = cylinder
    half = 0.5 * box[a]
    offset_a = x[i, a] - half
    offset_b = x[i, b] - half
    rho = np.sqrt(offset_a * offset_a + offset_b * offset_b)
    normal_a = -offset_a / rho
    normal_b = -offset_b / rho
    u = v[i, a] * normal_a + v[i, b] * normal_b
    impulse = max(2.0 * (0.5 * s[i] * rate - u), 0.0)
    v[i, a] += impulse * normal_a
    v[i, b] += impulse * normal_b
    return 0.5 * s[i] * scale * impulse


@njit(cache=True)
def _predict(i, t, x, v, tl, s, box, inv, scale, rate, start, neighbours, counter, xb, c_exp,
             e_exp, ev_time, ev_partner, ev_count):
    """Next event of particle i (synchronised at time t) among its list expiry and its pair
    collisions; stored in the ev_* arrays (`_predict_wall` adds the walls)."""
    d = x.shape[1]
    best = t + _expiry_time(x, xb, v, i, c_exp, e_exp)
    partner = _LIST_EXPIRY
    count = 0
    for k in range(start[i], start[i + 1]):
        j = neighbours[k]
        dt = t - tl[j]
        rr = 0.0
        rv = 0.0
        vv = 0.0
        for mu in range(d):
            dx = image_component(x[i, mu] - x[j, mu] - v[j, mu] * dt, box[mu], inv[mu])
            dv = v[i, mu] - v[j, mu]
            rr += dx * dx
            rv += dx * dv
            vv += dv * dv
        sig = 0.5 * (s[i] + s[j])
        contact = sig * scale
        qa = vv - sig * sig * rate * rate
        qb = rv - sig * contact * rate
        qc = rr - contact * contact
        if qc <= 0.0:
            if qb >= 0.0:
                continue
            tau = 0.0
        elif qb < 0.0:
            disc = qb * qb - qa * qc
            if disc < 0.0:
                continue
            tau = qc / (-qb + np.sqrt(disc))
        elif qa < 0.0:
            tau = (-qb - np.sqrt(qb * qb - qa * qc)) / qa
        else:
            continue
        if t + tau < best:
            best = t + tau
            partner = j
            count = counter[j]
    ev_time[i] = best
    ev_partner[i] = partner
    ev_count[i] = count


@njit(cache=True)
def _predict_wall(i, t, x, v, s, box, periodic, cylinder, scale, rate, ev_time, ev_partner):
    """After `_predict`: the collision of particle i with a wall (flat, or the cylinder, wall
    2d) replaces its next event if it comes first. Kept out of `_predict`, so that a
    periodic run runs the same code."""
    tau, wall = _wall_event(i, x, v, s, box, periodic, scale, rate, cylinder)
    if cylinder[0] >= 0:
        tau_cylinder = _cylinder_event(i, x, v, s, box, cylinder, scale, rate)
        if tau_cylinder < tau:
            tau, wall = tau_cylinder, 2 * x.shape[1]
    if t + tau < ev_time[i]:
        ev_time[i] = t + tau
        ev_partner[i] = _WALL - wall


@njit(cache=True)
def _advance(x, v, tl, i, t):
    dt = t - tl[i]
    for mu in range(x.shape[1]):
        x[i, mu] += v[i, mu] * dt
    tl[i] = t


@njit(cache=True)
def _temperature(v):
    n, d = v.shape
    total = 0.0
    for i in range(n):
        for mu in range(d):
            total += v[i, mu] * v[i, mu]
    return total / (n * d)


@njit(cache=True)
def run_window(x, v, s, box, scale, rate, temperature, n_collisions, rescale_every, skin,
               max_time, periodic, cylinder=NO_CYLINDER):
    """Run event-driven MD with growing diameters for `n_collisions` collisions.

    Parameters
    ----------
    x : ndarray, shape (N, d)
        Positions (non-overlapping at `scale`, inside the walls); updated in place, wrapped
        into the box along the periodic axes.
    v : ndarray, shape (N, d)
        Velocities; updated in place.
    s : ndarray, shape (N,)
        Nominal diameters; the diameters are s · a(t).
    box : ndarray, shape (d,)
        Box sides.
    scale : float
        a at the start of the window.
    rate : float
        Growth rate γ = da/dt (0 for equilibration at fixed diameters).
    temperature : float
        Target kT; velocities are rescaled to it every `rescale_every` collisions.
    n_collisions : int
        Collisions to process.
    rescale_every : int
        Collisions between velocity rescalings (and full re-predictions).
    skin : float
        Verlet skin in mean nominal diameters (see `skin_length`).
    max_time : float
        Stop at this time even if fewer collisions happened.
    periodic : ndarray, shape (d,), bool
        Periodic axes; flat hard walls at 0 and L_μ along the others (no minimum image, no
        wrap, wall collisions as events), except the cylinder's.
    cylinder : tuple of int, optional
        The two axes (a, b) of a hard cylinder (box[a] = box[b]), or `NO_CYLINDER`.

    Returns
    -------
    elapsed : float
        Simulated time of the window.
    scale_end : float
        a at the end.
    virial : float
        Σ_c |r_c| J_c over the collisions (length × momentum); a wall collision (flat or the
        cylinder) adds σ_i/2 × its impulse.
    kt_time : float
        ∫ kT dt over the window (trapezoid between rescalings), for the reduced pressure
        p = 1 + virial / (d N kt_time).
    collisions : int
        Pair and wall collisions.
    rebuilds : int
        Neighbour-list rebuilds.
    """
    n, d = x.shape
    s_mean = s.mean()
    s_max = s.max()
    tl = np.zeros(n)
    xb = np.empty_like(x)
    counter = np.zeros(n, dtype=np.int64)
    ev_time = np.empty(n)
    ev_partner = np.empty(n, dtype=np.int64)
    ev_count = np.empty(n, dtype=np.int64)
    heap = np.empty(n, dtype=np.int64)
    where = np.empty(n, dtype=np.int64)
    t = 0.0
    virial = 0.0
    kt_time = 0.0
    collisions = 0
    rebuilds = -1
    t_rescale = 0.0
    kt_start = _temperature(v)
    since_rescale = 0
    rebuild = True
    resync = True
    build_scale = scale
    delta = 0.0
    start = np.zeros(n + 1, dtype=np.int64)
    neighbours = np.zeros(0, dtype=np.int64)
    r = np.empty(d)
    inv = inverse_sides(box, periodic)
    walled = has_walls(periodic)
    while True:
        if rebuild or resync:
            for i in range(n):
                _advance(x, v, tl, i, t)
            if rebuild:
                rebuilds += 1
                wrap_into_box(x, box, periodic)
                xb[:, :] = x
                build_scale = scale + rate * t
                delta = skin_length(box, n, build_scale, s_mean, s_max, skin)
                if delta <= 0.0:
                    raise ValueError("particles too large for the box: no room for a "
                                     "neighbour list")
                start, neighbours = verlet_lists(x, box, s * build_scale, delta, periodic)
            now = scale + rate * t
            c_exp = 0.5 * (delta - s_max * (now - build_scale))
            for i in range(n):
                _predict(i, t, x, v, tl, s, box, inv, now, rate, start, neighbours, counter, xb,
                         c_exp, 0.5 * s_max * rate, ev_time, ev_partner, ev_count)
                if walled:
                    _predict_wall(i, t, x, v, s, box, periodic, cylinder, now, rate, ev_time,
                                  ev_partner)
            _heapify(heap, where, ev_time)
            rebuild = False
            resync = False
        if collisions >= n_collisions:
            break
        i = heap[0]
        t_event = ev_time[i]
        if t_event >= max_time:
            t = max_time
            for k in range(n):
                _advance(x, v, tl, k, t)
            break
        t = t_event
        now = scale + rate * t
        c_exp = 0.5 * (delta - s_max * (now - build_scale))
        e_exp = 0.5 * s_max * rate
        j = ev_partner[i]
        if j == _LIST_EXPIRY:
            rebuild = True
            continue
        at_wall = j <= _WALL
        if j == _NO_EVENT or (not at_wall and ev_count[i] != counter[j]):
            _advance(x, v, tl, i, t)
            _predict(i, t, x, v, tl, s, box, inv, now, rate, start, neighbours, counter, xb, c_exp,
                     e_exp, ev_time, ev_partner, ev_count)
            if walled:
                _predict_wall(i, t, x, v, s, box, periodic, cylinder, now, rate, ev_time,
                              ev_partner)
            _reposition(heap, where, ev_time, i)
            continue
        _advance(x, v, tl, i, t)
        if at_wall:
            if _WALL - j == 2 * d:
                virial += _cylinder_collision(i, x, v, s, box, cylinder, now, rate)
            else:
                virial += _wall_collision(i, _WALL - j, v, s, now, rate)
            counter[i] += 1
        else:
            _advance(x, v, tl, j, t)
            rr = 0.0
            u = 0.0
            for mu in range(d):
                dx = image_component(x[i, mu] - x[j, mu], box[mu], inv[mu])
                r[mu] = dx
                rr += dx * dx
            dist = np.sqrt(rr)
            for mu in range(d):
                r[mu] /= dist
                u += (v[i, mu] - v[j, mu]) * r[mu]
            impulse = 0.5 * (s[i] + s[j]) * rate - u
            if impulse < 0.0:
                impulse = 0.0
            for mu in range(d):
                v[i, mu] += impulse * r[mu]
                v[j, mu] -= impulse * r[mu]
            virial += dist * impulse
            counter[i] += 1
            counter[j] += 1
        collisions += 1
        since_rescale += 1
        if since_rescale >= rescale_every:
            for k in range(n):
                _advance(x, v, tl, k, t)
            kt_now = _temperature(v)
            kt_time += 0.5 * (kt_start + kt_now) * (t - t_rescale)
            factor = np.sqrt(temperature / kt_now)
            for k in range(n):
                for mu in range(d):
                    v[k, mu] *= factor
            kt_start = temperature
            t_rescale = t
            since_rescale = 0
            resync = True
            continue
        for k in (i, j):
            _predict(k, t, x, v, tl, s, box, inv, now, rate, start, neighbours, counter, xb, c_exp,
                     e_exp, ev_time, ev_partner, ev_count)
            if walled:
                _predict_wall(k, t, x, v, s, box, periodic, cylinder, now, rate, ev_time,
                              ev_partner)
            _reposition(heap, where, ev_time, k)
            if at_wall:                     # (j is a wall: particle i alone)
                break
    kt_time += 0.5 * (kt_start + _temperature(v)) * (t - t_rescale)
    for i in range(n):
        _advance(x, v, tl, i, t)
    wrap_into_box(x, box, periodic)
    return t, scale + rate * t, virial, kt_time, collisions, rebuilds
