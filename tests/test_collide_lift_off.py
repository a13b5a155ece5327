"""Resting contacts in `mechsys simulate`: capture at rest, lift-off when the contact force turns tensile, landing.

Model tests/data/block_lift_off.yaml: a block m on a table (gap y, e = 0), gravity g, pull F(t) = k t + A sin(w t).
  * Ramp (A = 0): the contact force is m g - k t, so the block lifts off at t* = m g/k and then
    y'' = (k/m)(t - t*), y = k (t - t*)^3/(6 m); y = 0 before t*.
  * Dropped from h with the ramp: free fall y = h - g t^2/2 + k t^3/(6 m) until it lands (e = 0: it stays), then
    the same lift-off at t*.
  * Pulse (k = 0, A = 2 m g, w = 2 pi): lifts off at sin(w t1) = 1/2, t1 = 1/12 s; in flight
    y = -(2g/w^2)(sin w t - sin w t1) + (2g/w) cos(w t1)(t - t1) - g (t - t1)^2/2 until it lands (root of y), then
    rests until t1 + 1 s: the motion repeats with period 1 s.
A block put on the table at rest stays (before this change, a touching contact at rest was not watched and the
block fell through the table; so did a plastic e = 0 bounce).
"""
from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest
from scipy.optimize import brentq

import mechsys
from mechsys.analysis.motion.simulate import simulate

DATA = Path(__file__).resolve().parent / "data"
ROOT = DATA.parents[1]
G, M, K = 9.81, 2.0, 39.24


def test_ramp_lifts_off_at_mg_over_k():
    r = simulate(mechsys.load(DATA / "block_lift_off.yaml"), 1.0, dt=0.01)
    t_star = M * G / K
    want = np.where(r.t > t_star, K * (r.t - t_star) ** 3 / (6 * M), 0.0)
    np.testing.assert_allclose(r.q[:, 0], want, atol=1e-9)
    assert np.all(np.abs(r.q[r.t <= t_star, 0]) <= 1e-12)
    assert r.impacts == []


def test_dropped_block_lands_rests_and_lifts_off():
    h = 0.2
    r = simulate(mechsys.load(DATA / "block_lift_off.yaml", {"h": h}), 1.0, dt=0.01)
    fall = lambda t: h - G * t**2 / 2 + K * t**3 / (6 * M)  # noqa: E731
    t_land = brentq(fall, 0.01, 0.4)
    assert len(r.impacts) == 1 and r.impacts[0]["t"] == pytest.approx(t_land, rel=1e-9)
    assert r.impacts[0]["rates_after"]["y"] == pytest.approx(0, abs=1e-12)
    t_star = M * G / K
    after = r.t > t_land
    want = np.where(r.t > t_star, K * (r.t - t_star) ** 3 / (6 * M), 0.0)
    np.testing.assert_allclose(r.q[after, 0], want[after], atol=1e-9)


def test_pulse_lifts_off_flies_lands_and_repeats():
    r = simulate(mechsys.load(DATA / "block_lift_off.yaml", {"k": 0, "A": "2*m*g"}), 2.5, dt=0.005)
    w = 2 * math.pi
    t1 = math.pi / (6 * w)

    def flight(t):
        return -(2 * G / w**2) * (np.sin(w * t) - math.sin(w * t1)) + (2 * G / w) * math.cos(w * t1) * (t - t1) \
            - G * (t - t1) ** 2 / 2

    t_land = brentq(flight, 0.3, 1.0)
    assert [i["t"] for i in r.impacts] == pytest.approx([t_land, t_land + 1, t_land + 2][:len(r.impacts)], rel=1e-8)
    assert len(r.impacts) == 2
    for cycle in range(3):
        tt = r.t - cycle
        mask = (tt > t1) & (tt < t_land)
        np.testing.assert_allclose(r.q[mask, 0], flight(tt[mask]), atol=1e-8)
        rest = (tt >= t_land) & (tt <= 1 + t1) if cycle < 2 else (tt >= -1) & (tt < -1)
        assert np.all(np.abs(r.q[rest, 0]) <= 1e-9)
    assert r.q[:, 0].min() >= -1e-12


def test_plastic_ball_stays_on_the_floor():
    """e = 0: one plastic impact at sqrt(2h/g), then the ball rests (it used to fall through the floor)."""
    r = simulate(mechsys.load(ROOT / "systems" / "bouncing_ball.yaml", {"e": 0}), 1.0)
    assert len(r.impacts) == 1 and r.impacts[0]["t"] == pytest.approx(math.sqrt(2 / G), rel=1e-9)
    assert abs(r.q[-1, 0]) <= 1e-12 and abs(r.u[-1, 0]) <= 1e-12
