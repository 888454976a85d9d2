"""`JamSettings`: every tolerance and parameter of `calippso.jam`, with documented defaults.

All lengths are in units of the mean diameter of the input packing.
"""

from __future__ import annotations

from dataclasses import dataclass, fields, replace

__all__ = ["JamSettings", "INTERIOR_LP_MIN_COLUMNS"]

#: Values accepted by ``jam(..., network_first=...)``.
NETWORK_FIRST_MODES = ("auto", "off", "require")
#: Values accepted by ``jam(..., pivots=...)``.
PIVOT_MODES = ("network_first", "off")
#: Values of ``pivots`` that were removed, and why (`JamSettings` raises ValueError with this
#: text).
REMOVED_PIVOT_MODES = {
    "always": "pivots='always' (contact pivots in the LP loop) was removed; use the default "
              "'network_first' or 'off'",
}

#: Names accepted by ``jam(..., interior_point=...)`` (HiGHS backend).
INTERIOR_POINT_SOLVERS = ("auto", "ipx", "hipo")

#: Values accepted by ``jam(..., crossover=...)``.
CROSSOVER_MODES = ("auto", "on", "off")
#: With ``crossover="auto"``, a periodic or walled run whose LPs have this many columns or
#: more (d N + 1: N ≥ 6667 in d = 3) solves them without crossover. Measured on 2 cores: at
#: N = 8192, d = 3 (24,577 columns) one LP without crossover takes 44 s and the first LP
#: with crossover more than 20 minutes; at N = 10⁴ HiPO's interior point takes 36 s and the
#: crossover 86 s more, and the warm simplex of the next LP had not finished in 8 minutes.
#: Below, the vertex loop's warm-started LPs are the faster engine (N = 1000: several times
#: faster in all).
INTERIOR_LP_MIN_COLUMNS = 20_000

#: Options `jam` no longer takes, and what replaces each (`JamSettings.from_options` raises
#: TypeError with this text).
REMOVED_OPTIONS = {
    "precompress_pressure": "jam's precompress_pressure option was removed: call "
                            "calippso.protocols.precompress(packing, pressure) first and jam "
                            "its .packing",
}


@dataclass(frozen=True)
class JamSettings:
    """Parameters of the CALiPPSO loop.

    Attributes
    ----------
    solver : str
        LP backend: "highs" (interior point + crossover, default), "clarabel", "cvxpy", or
        any backend added with `calippso.solvers.register_backend`.
    fallback_solvers : tuple of str
        Backends tried, in order, when the chosen one fails twice on the same LP (a list is
        stored as a tuple). The names of `solver` and `fallback_solvers` are checked against
        the registry when `jam` starts (`calippso.solvers.policy.prepare_backends`).
    tol_gamma : float
        Convergence when √Γ − 1 < tol_gamma.
    tol_s : float
        ... and max |s_iμ| over non-rattlers < tol_s (mean diameters).
    max_iters : int
        Largest number of LPs in the main loop.
    initial_step : float or None
        First bound on each displacement component. None: chosen from the nearest-neighbour
        gaps of the input (`ilp.initial_step_bound`).
    max_step : float
        Largest bound on a displacement component.
    min_step : float
        Smallest bound; kept well above `tol_s` so that a converged step is never a clipped one.
    step_growth : float
        Factor applied to the bound when a non-rattler's displacement reached it.
    step_margin : float
        Otherwise the next bound is `step_margin` × the largest non-rattler displacement.
    contact_threshold : float
        A pair is a contact when its dual exceeds this fraction of the largest dual (HiGHS).
    interior_contact_threshold : float
        The same for interior-point solutions without crossover (Clarabel, cvxpy).
    overlap_tolerance : float
        Input overlaps up to this relative gap (h > −overlap_tolerance) are round-off and
        accepted; larger ones raise ValueError.
    feasibility_tolerance : float
        Primal and dual feasibility tolerances of HiGHS (`solvers.highs.HighsOptions`; rows
        are in mean diameters). Clarabel and cvxpy use `solvers.clarabel.ClarabelOptions`.
    balance_tolerance : float
        A final force clean-up LP is solved when the force balance is worse than this.
    newton : bool
        Once an LP's contact network is isostatic, solve its contact equations by Newton's
        method and certify the result (`calippso.certification.newton`), instead of more LPs.
    newton_start : float
        ... once the LP's largest displacement of a stable particle is below this (mean
        diameters): earlier networks are rarely the jammed one.
    network_first : str
        Before any LP, guess the input's own contact network (a hint passed as
        ``jam(..., network=pairs)`` first, then the pairs below the largest jump of the sorted
        gaps, `calippso.certification.network_guess`) and, if one is isostatic, prove its jamming point by
        the Newton stage and its certificate. "auto" (default): try, and run the LP loop
        when no guess is certified; "off": LPs only; "require": raise `JammingError` instead
        of running an LP (for large N, where an LP costs minutes).
    pivots : str
        Where contact pivots (`calippso.certification.pivots`) repair an isostatic network whose jamming
        point has non-positive forces and no overlap: "network_first" (default) in the
        network-first stage, before another round of the restricted LP (and, with
        ``crossover="off"``, in the LP loop's Newton stage too); "off": never.
    verify_newton : bool
        After a certified Newton stage, solve one more LP at the final configuration and
        continue the loop unless it meets the convergence criteria.
    warm_start : bool
        Start each LP from the optimal basis of the previous one (HiGHS: primal simplex from
        that basis, interior point + crossover when it does not pay off).
    interior_point : str
        HiGHS's interior-point solver for the LPs solved from scratch: "ipx", "hipo"
        (HiGHS's newer interior point with a direct, METIS-ordered factorisation; it needs
        the `hipo` extra, `pip install "calippso[hipo]"`), or "auto" (default): HiPO for LPs
        of `solvers.highs.HIPO_MIN_COLUMNS` columns or more (d N + 1) when it is installed,
        IPX otherwise.
        All end with a crossover to a vertex, unless the crossover is off.
    crossover : str
        "auto" (default): "off" for LPs of `INTERIOR_LP_MIN_COLUMNS` columns or more (d N + 1),
        "on" below (and always in a deformable box); `resolved` says which.
        "on": every HiGHS LP ends at a vertex, whose duals name the contacts.
        "off": every LP is solved from scratch by interior point without crossover (the
        one ``interior_point`` names, at `solvers.highs.INTERIOR_OPTIMALITY_TOLERANCE`), its
        network read by strict complementarity (`calippso.complementarity`), rattlers
        removed, and the Newton stage, the contact pivots and the certificate run after
        every LP. The LP steps are then centres of the optimal face: rattlers and floppy
        directions end mid-range rather than at the bound.
    time_limit : float or None
        Stop the loop, with `StopReason.TIME_LIMIT`, after the first LP (and its Newton
        stage) that ends this many seconds after the loop began (network first included;
        neither it nor an LP is interrupted). The result holds the configuration reached;
        with a checkpoint, a second call resumes there. None (default): no limit.
    pin : bool
        Fix one particle's displacement to remove the d translational zero modes.
    verbose : bool
        Print one line per LP.
    """

    solver: str = "highs"
    fallback_solvers: tuple[str, ...] = ("highs", "clarabel")
    tol_gamma: float = 1e-12
    tol_s: float = 1e-9
    max_iters: int = 1000
    initial_step: float | None = None
    max_step: float = 0.1
    min_step: float = 1e-7
    step_growth: float = 4.0
    step_margin: float = 4.0
    contact_threshold: float = 1e-10
    interior_contact_threshold: float = 1e-6
    overlap_tolerance: float = 1e-10
    feasibility_tolerance: float = 1e-10
    balance_tolerance: float = 1e-12
    newton: bool = True
    newton_start: float = 1e-4
    network_first: str = "auto"
    pivots: str = "network_first"
    verify_newton: bool = False
    warm_start: bool = True
    interior_point: str = "auto"
    crossover: str = "auto"
    time_limit: float | None = None
    pin: bool = True
    verbose: bool = False

    def __post_init__(self) -> None:
        if isinstance(self.fallback_solvers, str):
            raise TypeError(f"fallback_solvers must be a sequence of backend names, not the "
                            f"string {self.fallback_solvers!r}")
        object.__setattr__(self, "fallback_solvers", tuple(self.fallback_solvers))
        if self.network_first not in NETWORK_FIRST_MODES:
            raise ValueError(f"unknown network_first {self.network_first!r}: choose one of "
                             f"{', '.join(NETWORK_FIRST_MODES)}")
        if self.pivots in REMOVED_PIVOT_MODES:
            raise ValueError(REMOVED_PIVOT_MODES[self.pivots])
        if self.pivots not in PIVOT_MODES:
            raise ValueError(f"unknown pivots {self.pivots!r}: choose one of "
                             f"{', '.join(PIVOT_MODES)}")
        if self.interior_point not in INTERIOR_POINT_SOLVERS:
            raise ValueError(f"unknown interior_point {self.interior_point!r}: choose one of "
                             f"{', '.join(INTERIOR_POINT_SOLVERS)}")
        if self.crossover not in CROSSOVER_MODES:
            raise ValueError(f"unknown crossover {self.crossover!r}: choose one of "
                             f"{', '.join(CROSSOVER_MODES)}")
        for name in ("tol_gamma", "tol_s", "max_step", "min_step", "feasibility_tolerance",
                     "contact_threshold", "interior_contact_threshold", "balance_tolerance",
                     "newton_start"):
            if not getattr(self, name) > 0:
                raise ValueError(f"{name} must be > 0, got {getattr(self, name)!r}")
        if self.time_limit is not None and not self.time_limit > 0:
            raise ValueError(f"time_limit must be > 0 seconds, got {self.time_limit!r}")
        if self.initial_step is not None and not self.initial_step > 0:
            raise ValueError(f"initial_step must be > 0, got {self.initial_step!r}")
        if not self.min_step <= self.max_step:
            raise ValueError(f"min_step {self.min_step} exceeds max_step {self.max_step}")
        if not (isinstance(self.max_iters, int) and self.max_iters >= 1):
            raise ValueError(f"max_iters must be a positive integer, got {self.max_iters!r}")
        if self.step_growth <= 1 or self.step_margin <= 1:
            raise ValueError("step_growth and step_margin must be > 1")

    @classmethod
    def from_options(cls, **options) -> "JamSettings":
        """Build settings from keyword options, naming any unknown option in the error."""
        removed = sorted(options.keys() & REMOVED_OPTIONS.keys())
        if removed:
            raise TypeError(REMOVED_OPTIONS[removed[0]])
        known = {f.name for f in fields(cls)}
        unknown = sorted(set(options) - known)
        if unknown:
            raise TypeError(f"unknown jam option(s) {unknown}; known options: {sorted(known)}")
        return cls(**options)

    def resolved(self, n: int, d: int) -> "JamSettings":
        """These settings for a run of N particles in d dimensions: ``crossover="auto"``
        becomes "off" when the LPs have `INTERIOR_LP_MIN_COLUMNS` columns or more
        (d N + 1), "on" otherwise."""
        if self.crossover != "auto":
            return self
        interior = d * n + 1 >= INTERIOR_LP_MIN_COLUMNS
        return replace(self, crossover="off" if interior else "on")

    def with_changes(self, **changes) -> "JamSettings":
        """A copy with some fields changed."""
        return replace(self, **changes)

