"""Routes to a jamming point: the CALiPPSO loop from the input itself, or from the input
relaxed as soft spheres.

* ``route="lp"``: the loop of `calippso.ilp` from the input (network first, then LPs).
* ``route="relaxed"``: the input is relaxed as harmonic soft spheres at its own positions and
  diameters (`generators.relax`: inflated to a small pressure, walked down the soft quench's
  pressure ladder, shrunk to hard contact in its own box); its overlap network goes to the
  network-first stage, and to the LPs when that stage refuses it. Inputs compressed at a
  constant rate (LS, FB → LS) keep collective channels along which the LPs slide them for
  tens to hundreds of LPs (docs/notes/wandering-phase.md); the relaxation settles them in a
  nearby basin instead. Its jamming point is another one than the loop's, nearby. With
  `EARLY_MAX_EXCESS` set (None, off, by default), network first (alone, no LP) tries each
  settled overlap network of the ladder that lies within that many contacts of isostatic,
  and the relaxation ends at the first one it certifies (`NetworkFirstSettle`, which also
  ends a `generators.soft_quench` early).
* ``route="auto"``: the relaxed route where the LP route is predicted to be slow
  (`lp_route_slow`), the LP route elsewhere.

Every route records on the result how far its jamming point lies from the input. This
module imports the generators (and numba) only when the relaxed route runs, the pair search
only when `gap_spread` runs, and never the loop itself: `calippso.ilp.jam` hands it the loop
as a function.
"""

from __future__ import annotations

import os
import time
from dataclasses import replace
from typing import Callable

import numpy as np

from .errors import JammingError
from .geometry.packing import Packing
from .geometry.periodic import displacements
from .result import JammingResult

__all__ = ["ROUTES", "DEFAULT_MAX_DISPLACEMENT", "AUTO_MIN_PARTICLES", "EARLY_MAX_EXCESS",
           "NetworkFirstSettle",
           "check_route", "gap_spread", "lp_route_slow", "jam_by_route", "relaxed_checkpoint"]

#: Values of ``jam(..., route=...)``.
ROUTES = ("lp", "relaxed", "auto")
#: The relaxed route's bound on the distance of any particle from its place in the input
#: (mean diameters) when the caller gives none. Half a diameter: input centres of equal
#: spheres lie at least a diameter apart, so within it every particle stays nearer its own
#: place than any other's, and the jamming point is the input's particle by particle. The
#: relaxation of constant-rate inputs moves particles by a median ~1e-2 and the farthest
#: by 0.05–0.34, more the larger N (docs/notes/relaxed-route.md).
DEFAULT_MAX_DISPLACEMENT = 0.5
#: route="auto" takes the relaxed route only from this many particles on: below it an LP
#: costs little, and the loop's wandering phase takes seconds.
AUTO_MIN_PARTICLES = 1024
#: ... and only for an input that is not near a jamming point (`gap_spread`): one whose
#: closest pairs hold no rigid network (hypostatic: LS and FB → LS at a constant rate to
#: p = 1e12, the shared PackingGeneration and Skoge–Donev files), or whose gaps up to the
#: first rigid network spread over more than this many decades (N = 512, d = 3, seeds 1, 2:
#: LS at a constant rate 1.85–1.96 at p = 1e5 and 3.7–4.0 at 1e7; with a slow end, 1.4–1.6
#: at 1e5 and 2.2 at 1e7; jammed packings 0.1–0.2).
AUTO_SPREAD_DECADES = 1.7
#: The spread of `gap_spread` is between the gap of this rank (a fraction of the first rigid
#: network's count) and the largest gap of that network.
SPREAD_FROM_RANK = 0.5
#: The relaxed route tries the overlap network of a rung of the ladder above the last one
#: by network first only when it has at most this many contacts beyond the isostatic count
#: (and is not hypostatic); None: never, the whole ladder runs.
EARLY_MAX_EXCESS: int | None = None
#: ... and stops trying after this many networks refused (each refusal costs network first's
#: rounds and pivots: seconds at N = 1024, more at larger N).
EARLY_MAX_REFUSALS = 2


def check_route(route: str, max_displacement: float | None, network) -> None:
    """ValueError (one line) for an unknown route, a non-positive `max_displacement`, or a
    network hint given with ``route="relaxed"`` (the relaxation makes its own network)."""
    if route not in ROUTES:
        raise ValueError(f"unknown route {route!r}: choose one of {', '.join(ROUTES)}")
    if max_displacement is not None and not max_displacement > 0:
        raise ValueError(f"max_displacement must be > 0 (mean diameters), got "
                         f"{max_displacement!r}")
    if route == "relaxed" and network is not None:
        raise ValueError("route='relaxed' makes its own contact network: give no network, "
                         "or take route='lp'")


def gap_spread(packing: Packing) -> tuple[int, float]:
    """How near a jamming point `packing` looks from its relative gaps h = |r|/σ − 1 of the
    particle pairs within `calippso.certification.network_guess.CANDIDATE_GAP` of contact.

    Returns
    -------
    count : int
        The fewest closest pairs whose network, rattlers removed recursively, is not
        hypostatic (`calippso.certification.network_guess.fewest_not_hypostatic`); 0 when even all of them
        are.
    spread : float
        Decades between the gap of rank `SPREAD_FROM_RANK` × `count` and the gap of rank
        `count` (gaps below round-off count as round-off); inf when `count` is 0.
    """
    from .geometry.contacts import isostaticity_gap, remove_rattlers
    from .geometry.neighbors import NeighborSearch
    from .certification.network_guess import CANDIDATE_GAP, ROUNDOFF_GAP, fewest_not_hypostatic

    n, d = packing.n, packing.d
    scale = packing.mean_diameter
    search = NeighborSearch(packing.positions / scale, packing.diameters / scale,
                            packing.box / scale,
                            None if packing.boundaries.is_periodic else packing.periodic)
    pairs = search.pairs_within(float(search.diameters.max()) * (1.0 + CANDIDATE_GAP))
    gaps = pairs.gaps
    near = np.flatnonzero(gaps < CANDIDATE_GAP)
    near = near[np.argsort(gaps[near], kind="stable")]
    i, j, gaps = pairs.i[near], pairs.j[near], np.maximum(gaps[near], ROUNDOFF_GAP)

    def excess(count: int) -> int:
        rattlers, kept = remove_rattlers(n, d, i[:count], j[:count])
        stable = int(n - rattlers.sum())
        return isostaticity_gap(int(kept.sum()), stable, d) if stable else -1

    count = fewest_not_hypostatic(near.size, excess)
    if count == 0:
        return 0, float("inf")
    low = gaps[max(int(SPREAD_FROM_RANK * count), 1) - 1]
    return count, float(np.log10(gaps[count - 1] / low))


def lp_route_slow(packing: Packing) -> str | None:
    """Why the LP route is predicted to be slow for `packing`, or None.

    Predicted slow: at least `AUTO_MIN_PARTICLES` particles, and an input that is not near
    a jamming point (`gap_spread`): fewer pairs near contact than the isostatic count
    d (N − 1) + 1 (hypostatic), or the smallest isostatic count of gaps spread over more
    than `AUTO_SPREAD_DECADES` decades.

    Returns
    -------
    str or None
        The reason in words (for the notes), or None.
    """
    n = packing.n
    if n < AUTO_MIN_PARTICLES:
        return None
    count, spread = gap_spread(packing)
    if count == 0:
        return (f"N = {n} and the input is hypostatic: its pairs near contact hold no rigid "
                f"network")
    if spread > AUTO_SPREAD_DECADES:
        return (f"N = {n} and the input's {count} smallest gaps spread over {spread:.1f} "
                f"decades")
    return None


def relaxed_checkpoint(checkpoint: str | os.PathLike | None) -> str | None:
    """Where the relaxation of the relaxed route keeps its state, beside `jam`'s checkpoint
    (``<name>.relax.npz``), or None."""
    if checkpoint is None:
        return None
    path = os.fspath(checkpoint)
    return (path[:-4] if path.endswith(".npz") else path) + ".relax.npz"


def jam_by_route(packing: Packing, route: str, max_displacement: float | None, network,
                 checkpoint: str | os.PathLike | None,
                 loop: Callable[[Packing, object, object], JammingResult]) -> JammingResult:
    """Jam `packing` by `route` and record how far the jamming point lies from it.

    Parameters
    ----------
    packing : Packing
        The checked input.
    route : {"lp", "relaxed", "auto"}
    max_displacement : float or None
        Largest distance a particle may move from the input (mean diameters). None: no
        bound on the LP route, `DEFAULT_MAX_DISPLACEMENT` on the relaxed one.
    network : array_like or None
        The caller's network hint (LP route only).
    checkpoint : str or PathLike or None
        `jam`'s checkpoint file; the relaxation keeps its own beside it.
    loop : callable
        ``loop(packing, network, checkpoint)``: the CALiPPSO loop (`calippso.ilp`).

    Raises
    ------
    JammingError
        One line, when a route moved a particle further than `max_displacement`. The
        relaxation stops as soon as a particle lies that far from the input
        (`generators.relax`), and the relaxed route then refuses without running the loop.
    """
    started = time.perf_counter()
    check_route(route, max_displacement, network)
    reason = lp_route_slow(packing) if route == "auto" and network is None else None
    if route == "lp" or (route == "auto" and reason is None):
        return _bounded(_recorded(loop(packing, network, checkpoint), packing, "lp"),
                        max_displacement)
    limit = DEFAULT_MAX_DISPLACEMENT if max_displacement is None else max_displacement
    relaxed_at = time.perf_counter()
    early = NetworkFirstSettle(
        lambda reached, network: loop(reached, network, None, network_only=True))
    relaxation = _relax(packing, checkpoint, limit,
                        None if EARLY_MAX_EXCESS is None else early)
    relaxing = time.perf_counter() - relaxed_at
    if relaxation.extra["max_displacement"] > limit:
        message = _too_far(relaxation.extra, limit, len(relaxation.history))
        if route == "relaxed":
            raise JammingError(f"{message}; raise max_displacement or take route='lp'",
                               packing=packing)
        result = _recorded(loop(packing, network, checkpoint), packing, "lp")
        result.notes.append(f"route 'auto' predicted a slow LP route ({reason}) but {message}: "
                            f"the LP route ran")
        return _bounded(result, max_displacement)
    hint = relaxation.contacts if packing.boundaries.is_periodic else None
    jammed = early.certified if relaxation.extra["settled"] else \
        loop(relaxation.packing, hint, checkpoint)
    result = _recorded(jammed, packing, "relaxed")
    if reason is not None:
        result.notes.append(f"route 'auto' took the relaxed route: {reason}")
    rungs = relaxation.extra["rungs"]
    result.notes.append(f"the soft-sphere relaxation took {relaxing:.1f} s "
                        f"({relaxation.steps} minimiser steps, {relaxation.extra['minimiser']}; "
                        f"ended in rung {relaxation.extra['rung']} of {len(rungs)} of its ladder"
                        f"{early.summary()})")
    words = _in_words(result, relaxation.extra, reason)
    result = replace(result, status=f"{result.status} {words}",
                     wall_time=time.perf_counter() - started)
    return _bounded(result, limit)


def _relax(packing: Packing, checkpoint: str | os.PathLike | None, limit: float,
           settle: Callable | None):
    """`generators.relax` of the input, stopped once a particle lies further than `limit`
    from it, or at the rung `settle` accepts (imported here: the generators load numba)."""
    from generators import relax

    options = {} if settle is None else {"settle": settle, "settle_excess": EARLY_MAX_EXCESS}
    return relax(packing, checkpoint=relaxed_checkpoint(checkpoint), max_displacement=limit,
                 **options)


class NetworkFirstSettle:
    """A ``settle`` for `generators.soft_quench` and `generators.relax`: network first alone
    (no LP) on each settled overlap network handed to it; the quench or relaxation ends at
    the first one it certifies, and the certified result is kept.

    Parameters
    ----------
    certify : callable
        ``certify(packing, network=hint)``: network first with no LP on `packing` with the
        hint `hint` (None in a container, where it reads the contacts from the gaps), a
        `JammingResult`, or `JammingError` when it certifies no network; typically
        ``functools.partial(calippso.jam, network_first="require")``, with further `jam`
        options if wanted.
    max_refusals : int
        Stop trying after this many networks refused (each refusal costs network first's
        rounds and pivots: seconds at N = 1024, minutes at N = 8192).

    Attributes
    ----------
    certified : JammingResult or None
        The result of the network that network first certified.
    tried : list of tuple
        One (where, seconds, certified) per network tried.

    Examples
    --------
    >>> settle = calippso.NetworkFirstSettle(
    ...     functools.partial(calippso.jam, network_first="require"))
    >>> quench = generators.soft_quench(np.ones(N), 3, seed=1, settle=settle, settle_excess=16)
    >>> result = settle.certified or calippso.jam(quench.packing, network=quench.contacts)
    """

    def __init__(self, certify: Callable[..., JammingResult],
                 max_refusals: int = EARLY_MAX_REFUSALS) -> None:
        if int(max_refusals) != max_refusals or max_refusals < 1:
            raise ValueError(f"max_refusals must be a positive integer, got {max_refusals!r}")
        self.certify = certify
        self.max_refusals = int(max_refusals)
        self.certified: JammingResult | None = None
        self.tried: list[tuple[str, float, bool]] = []

    def __call__(self, reached) -> str | None:
        """None to go on down the ladder, or why the run ends at `reached` (a
        `generators.GenerationResult` shrunk to hard contact in or after a rung)."""
        if sum(not ok for _, _, ok in self.tried) >= self.max_refusals:
            return None
        started = time.perf_counter()
        where = (f"{'during' if reached.extra['paused'] else 'at the end of'} rung "
                 f"{reached.extra['rung']}")
        periodic = reached.packing.boundaries.is_periodic
        try:
            self.certified = self.certify(reached.packing,
                                          network=reached.contacts if periodic else None)
        except JammingError:
            self.tried.append((where, time.perf_counter() - started, False))
            return None
        self.tried.append((where, time.perf_counter() - started, True))
        return (f"network first certified the overlap network {where} "
                f"({reached.extra['isostaticity_gap']} contacts beyond isostatic)")

    def summary(self) -> str:
        """The networks tried, in words for the notes ("" when none was)."""
        if not self.tried:
            return ""
        words = ", ".join(f"{where} {'certified' if ok else 'refused'} in {seconds:.1f} s"
                          for where, seconds, ok in self.tried)
        return f"; network first tried the overlap network {words}"


def _too_far(relaxed: dict, limit: float, begun: int) -> str:
    """Why a relaxation (its `extra`, `begun` rungs of its ladder begun) is refused."""
    rungs = relaxed["rungs"]
    when = (f"the relaxation stopped there, at pressure {rungs[begun - 1]:.0e}, rung "
            f"{begun} of {len(rungs)}" if relaxed["halted"] else "at the end of the relaxation")
    return (f"the relaxed route moved particle {relaxed['farthest']} by "
            f"{relaxed['max_displacement']:.3g} mean diameters, more than max_displacement = "
            f"{limit:g} ({when})")


def _recorded(result: JammingResult, packing: Packing, route: str) -> JammingResult:
    """`result` with its route and its distance from the input `packing` recorded."""
    lengths, _ = displacements(packing.positions, result.packing.positions, packing.box,
                               packing.periodic)
    scale = packing.mean_diameter
    return replace(result, route=route, phi_input=packing.phi,
                   displacement_max=float(lengths.max()) / scale,
                   displacement_median=float(np.median(lengths)) / scale)


def _bounded(result: JammingResult, max_displacement: float | None) -> JammingResult:
    """`result`, or JammingError (one line) when it moved a particle further than
    `max_displacement` (None: no bound)."""
    if max_displacement is not None and result.displacement_max > max_displacement:
        raise JammingError(f"the {result.route} route moved a particle by "
                           f"{result.displacement_max:.3g} mean diameters, more than "
                           f"max_displacement = {max_displacement:g}", packing=result.packing,
                           history=result.history)
    return result


def _in_words(result: JammingResult, relaxed: dict, reason: str | None) -> str:
    """The sentence the relaxed route adds to the status."""
    chosen = "" if reason is None else " (chosen by route 'auto')"
    ended = (f" (in rung {relaxed['rung']} of {len(relaxed['rungs'])} of the ladder, where "
             f"network first certified its overlap network)" if relaxed["settled"] else "")
    return (f"Relaxed route{chosen}: the input was relaxed as soft spheres from pressure "
            f"{relaxed['start_pressure']:.0e} to {relaxed['pressure']:.1e}{ended} before the "
            f"loop; "
            f"the jamming point lies at most {result.displacement_max:.1e} and a median "
            f"{result.displacement_median:.1e} mean diameters from the input, phi "
            f"{result.phi_change:+.1e}.")
