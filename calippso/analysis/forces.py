"""Bucklers, and the split of contact forces into localised and extended ones.

A buckler is a stable particle with exactly d + 1 contacts. Charbonneau, Corwin, Parisi &
Zamponi (PRL 114, 125504, 2015) separate the contribution of these *particles*, which carry the
localised buckling excitations of Lerner, Düring & Wyart (Soft Matter 9, 8252, 2013), from the
others: the localised forces are the forces acting on bucklers (every contact with a buckler at
either end, rule "bucklers", the default), the extended forces are all the others.

A buckler's d + 1 unit normals n_k span R^d with one linear relation, so force balance
Σ_k f_k n_k = 0 fixes its forces up to a common factor: by Cramer's rule
f_k ∝ |det(n_j, j ≠ k)|. Its weakest force is the contact opposite the d normals closest to
one hyperplane through the centre, the one loaded by the buckling motion; only the weak end of
the localised distribution matters for θ_ℓ, and it is made of these forces. Rule "weakest"
keeps only that contact of each buckler as localised (the others go to the extended set), for
comparison.

Rule "response" uses the criterion of Lerner, Düring & Wyart directly: a contact is localised
when opening it (all other contacts kept closed) moves essentially one particle, i.e. when one
particle carries more than `RESPONSE_THRESHOLD` of the squared displacement of the response
(`calippso.analysis.response`). It needs isostatic packings.
"""

from __future__ import annotations

from collections.abc import Iterable

import numpy as np

from ..result import JammingResult
from ._inputs import as_results
from .sample import PooledSample

__all__ = ["DEFAULT_RULE", "LOCALIZATION_RULES", "FORCE_KINDS", "RESPONSE_THRESHOLD", "bucklers",
           "canonical_rule", "localized_contacts", "normalized_forces", "pooled_forces",
           "split_forces"]

#: Rules accepted by `localized_contacts`.
LOCALIZATION_RULES = ("bucklers", "weakest", "response")
#: Rule "response": a contact is localised when one particle carries more than this share of
#: the squared displacement of its opening response.
RESPONSE_THRESHOLD = 0.5
#: Default localisation rule.
DEFAULT_RULE = "bucklers"
#: Former name of rule "bucklers", still accepted.
_RULE_ALIASES = {"all": "bucklers"}
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


def canonical_rule(rule: str) -> str:
    """`rule` checked against `LOCALIZATION_RULES` ("all" is the former name of "bucklers")."""
    rule = _RULE_ALIASES.get(rule, rule)
    if rule not in LOCALIZATION_RULES:
        raise ValueError(f"rule must be one of {LOCALIZATION_RULES}, got {rule!r}")
    return rule


def localized_contacts(result: JammingResult, rule: str = DEFAULT_RULE) -> np.ndarray:
    """Which contacts carry a localised force.

    Parameters
    ----------
    result : JammingResult
    rule : {"bucklers", "weakest", "response"}
        "bucklers" (default): every contact with a buckler at either end, the forces acting on
        bucklers (Charbonneau et al. 2015). "weakest": only the weakest contact of every
        buckler, the one that the buckling excitation loads (see the module notes); a contact
        can be the weakest of both its particles, it is counted once. "response": the contacts
        whose opening response is localised on one particle (share above
        `RESPONSE_THRESHOLD`; isostatic packings only).

    Returns
    -------
    ndarray, shape (M,), bool
        True for localised contacts, aligned with `result.contacts`.
    """
    rule = canonical_rule(rule)
    if rule == "response":
        from .response import opening_response

        return opening_response(result).localized(RESPONSE_THRESHOLD)
    is_buckler = bucklers(result)
    contacts = result.contacts
    m = contacts.shape[0]
    if rule == "bucklers":
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


def split_forces(results: JammingResult | Iterable[JammingResult],
                 rule: str = DEFAULT_RULE) -> dict[str, PooledSample]:
    """All, localised and extended forces, normalised by the mean of each packing, pooled.

    Each packing's contacts are classified once (rule "response" solves a linear system per
    packing).

    Parameters
    ----------
    results : JammingResult or iterable of JammingResult
    rule : {"bucklers", "weakest", "response"}
        See `localized_contacts`.

    Returns
    -------
    dict
        {"all", "localized", "extended"} → PooledSample, each normalised by its own number of
        forces, so that its cumulative is the distribution function G(f) of that kind.
    """
    rule = canonical_rule(rule)
    parts: dict[str, list[np.ndarray]] = {kind: [] for kind in FORCE_KINDS}
    for result in as_results(results):
        forces = normalized_forces(result)
        localized = localized_contacts(result, rule)
        parts["all"].append(forces)
        parts["localized"].append(forces[localized])
        parts["extended"].append(forces[~localized])
    return {kind: PooledSample.concatenate([(part, part.size) for part in kind_parts])
            for kind, kind_parts in parts.items()}


def pooled_forces(results: JammingResult | Iterable[JammingResult], kind: str = "all",
                  rule: str = DEFAULT_RULE) -> PooledSample:
    """Forces of one kind, normalised by their mean in each packing, pooled.

    Parameters
    ----------
    results : JammingResult or iterable of JammingResult
    kind : {"all", "localized", "extended"}
        Which forces: every contact, the localised ones (`localized_contacts` with `rule`), or
        the others.
    rule : {"bucklers", "weakest", "response"}
        See `localized_contacts`.

    Returns
    -------
    PooledSample
        Normalised by the number of forces of the chosen kind, so that the cumulative is the
        distribution function G(f) of that kind.
    """
    if kind not in FORCE_KINDS:
        raise ValueError(f"kind must be one of {FORCE_KINDS}, got {kind!r}")
    if kind == "all":
        parts = [normalized_forces(result) for result in as_results(results)]
        return PooledSample.concatenate([(part, part.size) for part in parts])
    return split_forces(results, rule)[kind]
