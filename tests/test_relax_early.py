"""The relaxation ends early: after each rung of its pressure ladder but the last it asks
whether the state reached will do (`generators.relax(settle=...)`), and the relaxed route
(`jam(route="relaxed")`) ends it at the first rung whose overlap network network first
certifies.

Input: an LS state of 256 equal spheres in d = 3 compressed at a constant rate to p = 1e5,
whose ladder has four rungs (1e-4 down to 5e-7). Every jamming point is certified
(positive forces, no overlap, isostatic, balance 1e-12)."""

from __future__ import annotations

from types import SimpleNamespace

import numpy as np
import pytest

import calippso
import calippso.routes
import generators
from generators import diameters as dist
from generators.relax import SETTLE_EXCESS

from conftest import assert_jammed

#: Reduced pressure of the constant-rate LS input.
LS_PRESSURE = 1e5
#: Rungs of the input's ladder with `generators.relax`'s defaults.
RUNGS = 4


@pytest.fixture(scope="module")
def spheres(computed_once) -> calippso.Packing:
    """Equal spheres, N = 256, d = 3, LS at a constant rate to `LS_PRESSURE`."""
    return computed_once("relax_early_spheres", lambda: generators.lubachevsky_stillinger(
        dist.monodisperse(256), 3, target_pressure=LS_PRESSURE, seed=1).packing)


def test_relax_asks_after_every_rung_but_the_last_about_near_networks(spheres):
    asked = []

    def settle(reached):
        asked.append((reached.extra["rung"], reached.extra["paused"],
                      reached.extra["isostaticity_gap"]))
        assert reached.packing.n == spheres.n and reached.contacts.shape[1] == 2
        return None

    relaxed = generators.relax(spheres, settle=settle, settle_excess=10_000)
    assert [rung for rung, paused, _ in asked if not paused] == list(range(1, RUNGS))
    assert relaxed.extra["settled"] is None and relaxed.extra["rung"] == RUNGS
    assert relaxed.status.startswith("converged")
    # by default only networks within SETTLE_EXCESS contacts of isostatic, not hypostatic
    near = [excess for _, _, excess in asked if 0 <= excess <= SETTLE_EXCESS]
    asked.clear()
    generators.relax(spheres, settle=settle)
    assert [excess for _, _, excess in asked] == near and near


def test_relax_ends_at_the_rung_it_is_told_and_returns_that_state(spheres):
    handed = {}

    def settle(reached):
        if reached.extra["rung"] < 2:
            return None
        handed["state"] = reached
        return "good enough"

    relaxed = generators.relax(spheres, settle=settle)
    assert relaxed.extra["settled"] == "good enough" and relaxed.extra["rung"] == 2
    assert len(relaxed.history) == 2 and relaxed.extra["pressure"] > relaxed.extra["rungs"][-1]
    assert "ended early" in relaxed.status and "good enough" in relaxed.status
    np.testing.assert_array_equal(relaxed.packing.positions, handed["state"].packing.positions)
    np.testing.assert_array_equal(relaxed.packing.diameters, handed["state"].packing.diameters)
    np.testing.assert_array_equal(relaxed.contacts, handed["state"].contacts)


def test_the_relaxed_route_ends_at_the_first_rung_network_first_certifies(spheres,
                                                                          monkeypatch):
    monkeypatch.setattr(calippso.routes, "EARLY_MAX_EXCESS", 4)
    result = calippso.jam(spheres, route="relaxed")
    assert_jammed(result)
    assert result.route == "relaxed" and result.iterations == 0
    notes = " ".join(result.notes)
    assert f"ended in rung 2 of {RUNGS} of its ladder" in notes
    assert "overlap network at the end of rung 2 certified" in notes
    assert f"in rung 2 of {RUNGS} of the ladder, where network first certified" in result.status


def test_without_the_early_end_the_whole_ladder_runs(spheres, monkeypatch):
    monkeypatch.setattr(calippso.routes, "EARLY_MAX_EXCESS", None)
    result = calippso.jam(spheres, route="relaxed")
    assert_jammed(result)
    assert f"ended in rung {RUNGS} of {RUNGS} of its ladder" in " ".join(result.notes)
    assert "network first tried" not in " ".join(result.notes)


def test_the_settle_stops_trying_networks_after_its_refusals():
    tried = []

    def refusing(packing, *, network):
        tried.append(network.copy())
        raise calippso.JammingError("no network certified")

    early = calippso.NetworkFirstSettle(refusing)
    periodic = SimpleNamespace(boundaries=SimpleNamespace(is_periodic=True))
    for other in range(1, 5):
        reached = SimpleNamespace(packing=periodic, contacts=np.array([[0, other]]),
                                  extra={"isostaticity_gap": 1, "rung": 4, "paused": True})
        assert early(reached) is None
    assert len(tried) == calippso.routes.EARLY_MAX_REFUSALS and early.certified is None
    assert early.summary().count("refused") == calippso.routes.EARLY_MAX_REFUSALS
