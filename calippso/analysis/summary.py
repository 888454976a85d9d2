"""`analyze`: every analysis of one packing or an ensemble, gathered once (the report's input)."""

from __future__ import annotations

from collections.abc import Iterable
from dataclasses import dataclass, field

import numpy as np

from ..result import JammingResult
from ._inputs import as_results
from .exponents import UPPER, Exponent, exponent_from_sample, resolve_models, window_scan
from .forces import DEFAULT_RULE, bucklers, canonical_rule, split_forces
from .gaps import DEFAULT_MAX_GAP, pooled_gaps
from .layering import DensityProfile, pooled_density_profile
from .sample import PooledSample
from .structure import ContactStatistics, contact_statistics
from .wall_forces import pooled_wall_forces, wall_force_summary, wall_load_rows

__all__ = ["Analysis", "analyze"]


@dataclass(frozen=True)
class Analysis:
    """Contacts, gaps, forces and exponents of a pooled set of packings.

    Attributes
    ----------
    contacts : ContactStatistics
    gaps : PooledSample
        Non-contact gaps h ≤ `max_gap` between stable particles.
    forces : dict of str to PooledSample
        "all", "extended" and "localized" forces, normalised by the mean of each packing.
    exponents : dict of str to Exponent
        "gamma", "theta_e", "theta_l", "theta" (those that could be fitted).
    exponent_errors : dict of str to str
        Why an exponent could not be fitted (e.g. too few small forces in one small packing).
    n_bucklers : int
        Stable particles with d + 1 contacts, over all packings.
    max_gap : float
        Largest gap collected.
    rule : str
        Localisation rule.
    window_scans : dict of str to list of dict
        Per exponent, the value fitted with the window top moved over 3 decades
        (`calippso.analysis.exponents.window_scan`): the check of the window rule.
    wall_forces : PooledSample or None
        Forces on the walls, in units of the mean particle–particle force of their packing
        (`calippso.analysis.wall_forces`); None when no packing has walls. `forces` never
        holds them.
    wall_loads : list of dict
        Per packing and wall: its contacts, load and pressure
        (`calippso.analysis.wall_forces.wall_load_rows`).
    layering : DensityProfile or None
        Packing fraction against the distance from the nearest wall, pooled
        (`calippso.analysis.layering`); None when no packing has walls.
    """

    contacts: ContactStatistics
    gaps: PooledSample
    forces: dict[str, PooledSample]
    exponents: dict[str, Exponent]
    exponent_errors: dict[str, str]
    n_bucklers: int
    max_gap: float
    rule: str
    wall_times: np.ndarray = field(default_factory=lambda: np.zeros(0))
    window_scans: dict[str, list[dict]] = field(default_factory=dict)
    wall_forces: PooledSample | None = None
    wall_loads: list[dict] = field(default_factory=list)
    layering: DensityProfile | None = None

    def to_dict(self) -> dict:
        """The summary as plain numbers (JSON-ready)."""
        c = self.contacts
        return {
            "d": c.d,
            "packings": c.n_packings,
            "particles": c.n_particles,
            "phi": {"mean": float(np.mean(c.phi)), "std": float(np.std(c.phi)),
                    "min": float(np.min(c.phi)), "max": float(np.max(c.phi)),
                    "values": c.phi.tolist()},
            "mean_z_stable": c.mean_z,
            "rattler_fraction": c.rattler_fraction,
            "stable_particles": c.n_stable,
            "contacts": c.n_contacts,
            "touching_outside_network": c.n_touching,
            "isostatic_packings": c.n_isostatic,
            "isostaticity_gaps": c.isostaticity_gaps.tolist(),
            "bucklers": self.n_bucklers,
            "buckler_fraction": self.n_bucklers / c.n_stable if c.n_stable else float("nan"),
            "localized_forces": len(self.forces["localized"]),
            "extended_forces": len(self.forces["extended"]),
            "localization_rule": self.rule,
            "max_gap": self.max_gap,
            "gaps_collected": len(self.gaps),
            "jam_wall_time_s": {"total": float(np.sum(self.wall_times)),
                                "mean": float(np.mean(self.wall_times))
                                if self.wall_times.size else float("nan")},
            "exponents": {name: e.to_dict() for name, e in self.exponents.items()},
            "exponent_errors": dict(self.exponent_errors),
            "window_scan": {name: list(rows) for name, rows in self.window_scans.items()},
            **({} if self.layering is None else {"walls": self._walls_dict()}),
        }

    def _walls_dict(self) -> dict:
        """The walls' part of the summary: wall forces (units of the mean particle–particle
        force), loads and pressures per wall, the layering profile (distance in mean
        diameters)."""
        return {"wall_forces": wall_force_summary(self.wall_forces),
                "loads": [dict(row) for row in self.wall_loads],
                "layering": {"distance": self.layering.distance.tolist(),
                             "phi": self.layering.phi.tolist()}}


def analyze(results: JammingResult | Iterable[JammingResult], *,
            max_gap: float = DEFAULT_MAX_GAP, rule: str = DEFAULT_RULE,
            upper: dict[str, float] | None = None,
            model: str | dict[str, str] | None = None, **fit_options) -> Analysis:
    """Analyse one packing, or pool an ensemble of packings of one dimension.

    Parameters
    ----------
    results : JammingResult or iterable of JammingResult
    max_gap : float
        Largest gap h collected.
    rule : {"bucklers", "weakest", "response"}
        Localisation rule (`calippso.analysis.forces.localized_contacts`).
    upper : dict, optional
        Upper ends of the fit windows by exponent name (defaults:
        `calippso.analysis.exponents.UPPER`).
    model : None, str or dict
        Fit models by exponent (`calippso.analysis.exponents.resolve_models`; defaults:
        `calippso.analysis.exponents.MODEL`).
    **fit_options
        Passed to `fit_cumulative_power_law` (min_count, method, n_bootstrap, confidence,
        seed).

    Returns
    -------
    Analysis
        An exponent whose fit window holds too few points is left out of `exponents`, with
        the reason in `exponent_errors`. Packings with walls add the wall forces, loads and
        the layering profile of those packings.
    """
    items = as_results(results)
    rule = canonical_rule(rule)
    uppers = {**UPPER, **(upper or {})}
    models = resolve_models(model)
    gaps = pooled_gaps(items, max_gap)
    forces = split_forces(items, rule)
    samples = {"gamma": gaps, "theta_e": forces["extended"], "theta_l": forces["localized"],
               "theta": forces["all"]}
    exponents, errors, scans = {}, {}, {}
    scan_options = {k: v for k, v in fit_options.items() if k == "min_count"}
    for name, sample in samples.items():
        scans[name] = window_scan(name, sample, upper=uppers[name],
                                  largest=max_gap if name == "gamma" else None,
                                  **scan_options)
        try:
            exponents[name] = exponent_from_sample(name, sample, upper=uppers[name],
                                                   model=models[name], **fit_options)
        except ValueError as error:
            errors[name] = str(error)
    walled = [r for r in items if not r.packing.boundaries.is_periodic]
    return Analysis(
        contacts=contact_statistics(items), gaps=gaps, forces=forces, exponents=exponents,
        exponent_errors=errors,
        n_bucklers=int(sum(np.count_nonzero(bucklers(r)) for r in items)),
        max_gap=float(max_gap), rule=rule,
        wall_times=np.array([r.wall_time for r in items], dtype=np.float64),
        window_scans=scans,
        wall_forces=pooled_wall_forces(walled) if walled else None,
        wall_loads=wall_load_rows(items),
        layering=pooled_density_profile(walled) if walled else None)
