"""Bucklers, and the split of contact forces into localised and extended ones.

A buckler is a stable particle with exactly d + 1 contacts. Its d + 1 contact normals n_k
span R^d with one linear relation, so force balance Σ_k f_k n_k = 0 fixes the forces up to a
common factor: by Cramer's rule f_k ∝ |det(n_j, j ≠ k)|. The weakest force of a buckler is
therefore the contact opposite the d normals that are closest to lying in one hyperplane
through the centre: the buckler can move out of that hyperplane against that single weak
contact (the localised buckling excitation of Lerner, Düring & Wyart 2013). Following
Charbonneau, Corwin, Parisi & Zamponi (2015), such forces are "localised" and all others are
"extended"; see `localized_contacts` for the two rules offered.
"""

from __future__ import annotations

from collections.abc import Iterable

import numpy as np

from ..result import JammingResult
from ._inputs import as_results
from .sample import PooledSample

__all__ = ["LOCALIZATION_RULES", "FORCE_KINDS", "bucklers", "localized_contacts",
           "normalized_forces", "pooled_forces"]

#: Rules accepted by `localized_contacts`.
LOCALIZATION_RULES = ("weakest", "all")
#: Force sets accepted by `pooled_forces`.
FORCE_KINDS = ("all", "localized", "extended")


def bucklers(result: JammingResult) -> np.ndarray:
    """Stable particles with exactly d + 1 contacts.

    Returns
    -------
    ndarray, shape (N,), bool
    """
    return (result.contact_numbers == result.d + 1) & ~result.rattlers


def normalized_forces(result: JammingResult) -> np.ndarray:
    """Contact forces divided by their mean over the packing, shape (M,)."""
    forces = np.asarray(result.forces, dtype=np.float64)
    if forces.size == 0:
        return forces.copy()
    return forces / forces.mean()


def localized_contacts(result: JammingResult, rule: str = "weakest") -> np.ndarray:
    """Which contacts carry a localised force.

    Parameters
    ----------
    result : JammingResult
    rule : {"weakest", "all"}
        "weakest" (default): the weakest contact of every buckler, the one that the buckling
        excitation loads (see the module notes). A contact can be the weakest of both its
        particles; it is counted once. "all": every contact with a buckler at either end.

    Returns
    -------
    ndarray, shape (M,), bool
        True for localised contacts, aligned with `result.contacts`.
    """
    if rule not in LOCALIZATION_RULES:
        raise ValueError(f"rule must be one of {LOCALIZATION_RULES}, got {rule!r}")
    is_buckler = bucklers(result)
    contacts = result.contacts
    m = contacts.shape[0]
    if rule == "all":
        return is_buckler[contacts[:, 0]] | is_buckler[contacts[:, 1]]
    particle = contacts.T.ravel()                 # both ends of every contact
    edge = np.tile(np.arange(m), 2)
    on_buckler = is_buckler[particle]
    particle, edge = particle[on_buckler], edge[on_buckler]
    order = np.lexsort((result.forces[edge], particle))  # by particle, then by force
    _, first = np.unique(particle[order], return_index=True)
    localized = np.zeros(m, dtype=bool)
    localized[edge[order][first]] = True
    return localized


def pooled_forces(results: JammingResult | Iterable[JammingResult], kind: str = "all",
                  rule: str = "weakest") -> PooledSample:
    """Forces normalised by their mean in each packing, pooled.

    Parameters
    ----------
    results : JammingResult or iterable of JammingResult
    kind : {"all", "localized", "extended"}
        Which forces: every contact, the localised ones (`localized_contacts` with `rule`), or
        the others.
    rule : {"weakest", "all"}
        See `localized_contacts`.

    Returns
    -------
    PooledSample
        Normalised by the number of forces of the chosen kind, so that the cumulative is the
        distribution function G(f) of that kind.
    """
    if kind not in FORCE_KINDS:
        raise ValueError(f"kind must be one of {FORCE_KINDS}, got {kind!r}")
    parts = []
    for result in as_results(results):
        forces = normalized_forces(result)
        if kind != "all":
            localized = localized_contacts(result, rule)
            forces = forces[localized if kind == "localized" else ~localized]
        parts.append(forces)
    return PooledSample.concatenate([(part, part.size) for part in parts])
