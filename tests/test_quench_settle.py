"""The soft quench ends early: during and after the rungs of its pressure ladder it asks
whether the state reached will do (`generators.soft_quench(settle=...)`), and
`calippso.NetworkFirstSettle` ends it at the first overlap network that network first
certifies with no LP.

Input: a soft quench of 256 equal spheres in d = 3 (ladder 1e-2 down to 5e-8). Every jamming
point is certified (positive forces, no overlap, isostatic, balance 1e-12)."""

from __future__ import annotations

import functools

import numpy as np
import pytest

import calippso
import generators

from conftest import assert_jammed

N, D, SEED = 256, 3, 1
#: Networks this many contacts beyond isostatic are asked about (at N = 256 the overlap
#: network comes within it some rungs above the last).
EXCESS = 12
#: The certified jamming point's φ lies this close (relative) to that of the state handed.
PHI_CLOSE = 1e-3


def test_the_quench_asks_about_near_networks_and_runs_on_when_told():
    asked = []

    def settle(reached):
        asked.append((reached.extra["rung"], reached.extra["paused"],
                      reached.extra["isostaticity_gap"]))
        assert reached.packing.n == N and reached.contacts.shape[1] == 2
        np.testing.assert_array_equal(reached.packing.diameters, np.ones(N))
        return None

    quench = generators.soft_quench(np.ones(N), D, seed=SEED, settle=settle,
                                    settle_excess=EXCESS)
    assert asked and all(0 <= excess <= EXCESS for _, _, excess in asked)
    assert all(rung <= len(quench.extra["rungs"]) for rung, _, _ in asked)
    assert quench.extra["settled"] is None and quench.status.startswith("converged")
    assert quench.extra["rung"] == len(quench.extra["rungs"])


def test_network_first_settle_ends_the_quench_at_a_certified_network():
    settle = calippso.NetworkFirstSettle(functools.partial(calippso.jam,
                                                           network_first="require"))
    quench = generators.soft_quench(np.ones(N), D, seed=SEED, settle=settle,
                                    settle_excess=EXCESS)
    assert quench.extra["settled"] is not None
    assert "network first certified" in quench.status
    assert quench.extra["pressure"] > quench.extra["target_pressure"]
    result = settle.certified
    assert result is not None and result.iterations == 0
    assert result.stop_reason in (calippso.StopReason.NETWORK_FIRST,
                                  calippso.StopReason.CERTIFIED_PIVOTS)
    assert_jammed(result)
    # the jamming point of the state the quench returned, close to it
    assert result.packing.n == N and abs(result.phi / quench.packing.phi - 1) < PHI_CLOSE
    assert settle.tried[-1][2] and "certified" in settle.summary()


def test_a_negative_settle_excess_is_refused():
    with pytest.raises(ValueError, match="settle_excess"):
        generators.soft_quench(np.ones(N), D, seed=SEED, settle=lambda reached: None,
                               settle_excess=-1)
