"""Impacts inside closed-loop simulations: a four-bar whose crank strikes a stop (Krodkiewski ch. 3 impulse law on
a one-degree-of-freedom mechanism).

With one degree of freedom every rate is proportional to the crank rate, so Newton's hypothesis at the stop
reverses the whole velocity state: q'+ = -e q'-, the kinetic energy drops by the factor e^2, and the loop-closure
constraints stay satisfied to rounding through every impact (segments are projected onto them)."""
from __future__ import annotations

import numpy as np
import pytest

import mechsys
from mechsys.analysis.motion.simulate import simulate
from tests.helpers import SYSTEMS_DIR


@pytest.fixture(scope="module")
def four_bar_with_stop(tmp_path_factory):
    text = (SYSTEMS_DIR / "four_bar.yaml").read_text().split("expect:")[0]
    text += "contacts:\n  - {name: stop, gap: theta2 - 0.3, restitution: e}\n"
    text = text.replace("parameters:\n", "parameters:\n  e: 0.5\n", 1)
    path = tmp_path_factory.mktemp("stop") / "four_bar_stop.yaml"
    path.write_text(text)
    return path


@pytest.mark.parametrize("e", [0.5, 1.0])
def test_four_bar_crank_on_a_stop_reverses_the_state_by_e(four_bar_with_stop, e):
    model = mechsys.load(four_bar_with_stop, {"e": str(e)})
    r = simulate(model, 1.0 if e == 1.0 else 3.0)
    assert r.impacts, "the crank falls onto the stop"
    assert np.max(r.residual) <= 1e-10
    for imp in r.impacts:
        if imp["captured"]:
            continue
        before = np.array(list(imp["rates_before"].values()))
        after = np.array(list(imp["rates_after"].values()))
        assert np.allclose(after, -e * before, rtol=1e-8, atol=1e-12)
    k = model.coordinates.index("theta2")
    assert np.min(r.q[:, k]) >= 0.3 - 1e-9  # never through the stop


def test_four_bar_on_a_stop_with_e_half_comes_to_rest(four_bar_with_stop):
    """Speeds halve at each impact: finitely many impacts, then the rest rule holds the crank on the stop."""
    model = mechsys.load(four_bar_with_stop)
    r = simulate(model, 3.0)
    assert 10 < len(r.impacts) < 200
    assert r.impacts[-1]["captured"]
    k = model.coordinates.index("theta2")
    assert abs(r.q[-1, k] - 0.3) < 1e-9 and np.max(np.abs(r.u[-1])) < 1e-8


def _struck_four_bar_by_hand(q: list[float], u0: np.ndarray) -> tuple[np.ndarray, dict[str, np.ndarray]]:
    """tests/data/beyond/fourbar_struck.yaml by hand (sympy, its own positions): the rates after the impact and
    the impulse each joint applies to its link. Unknowns u+, the contact impulse U and the pin impulse Lambda of
    M (u+ - u-) = Jn^T U + A^T Lambda, A u+ = 0, vn+ = -e vn-; the joint impulses from each subtree's momentum
    change minus the contact impulse and the pin impulse acting on it (Lambda on the coupler's C, -Lambda on the
    rocker's)."""
    import sympy as sp

    a, b, c, d, m2, m3, m4, mb, rb, h, e = 0.1, 0.35, 0.25, 0.3, 0.5, 1.2, 0.9, 0.4, 0.02, 0.15, 0.6
    qs = sp.symbols("th2 th3 th4 xb yb tb")
    th2, th3, th4, xb, yb, tb = qs

    def rz(x):
        return sp.Matrix([[sp.cos(x), -sp.sin(x), 0], [sp.sin(x), sp.cos(x), 0], [0, 0, 1]])

    crank_tip, D = rz(th2) * sp.Matrix([a, 0, 0]), sp.Matrix([d, 0, 0])
    G2, G3 = rz(th2) * sp.Matrix([a / 2, 0, 0]), crank_tip + rz(th2 + th3) * sp.Matrix([b / 2, 0.03, 0])
    G4, C3 = D + rz(th4) * sp.Matrix([c / 2, 0, 0]), crank_tip + rz(th2 + th3) * sp.Matrix([b, 0, 0])
    C4, P, ball = D + rz(th4) * sp.Matrix([c, 0, 0]), D + rz(th4) * sp.Matrix([h, 0, 0]), sp.Matrix([xb, yb, 0])
    at = dict(zip(qs, q))

    def jac(x):  # velocity = jac(x) @ rates
        return np.array(x.jacobian(qs).subs(at), dtype=float)

    spin = np.zeros((6, 6))  # the rotational part of M: crank, coupler (th2 + th3), rocker, ball
    for rows, inertia in (([0], m2 * a**2 / 12), ([0, 1], 0.015), ([2], m4 * c**2 / 12), ([5], mb * rb**2 / 2)):
        w = np.zeros(6)
        w[rows] = 1.0
        spin += inertia * np.outer(w, w)
    M = spin + sum(m * jac(G).T @ jac(G) for m, G in ((m2, G2), (m3, G3), (m4, G4), (mb, ball)))
    n = np.array((rz(th4) * sp.Matrix([0, 1, 0])).subs(at), dtype=float).ravel()
    Jn = n @ (jac(ball) - jac(P))
    A = (jac(C3) - jac(C4))[:2]
    K = np.zeros((9, 9))
    K[:6, :6], K[:6, 6], K[:6, 7:], K[6, :6], K[7:, :6] = M, -Jn, -A.T, Jn, A
    sol = np.linalg.solve(K, np.r_[M @ u0, -e * (Jn @ u0), 0.0, 0.0])
    up, U, lam = sol[:6], sol[6], np.r_[sol[7:], 0.0]

    def dp(G, m):
        return m * jac(G) @ (up - u0)

    return up, {"crank": dp(G2, m2) + dp(G3, m3) - lam, "coupler": dp(G3, m3) - lam,
                "rocker": dp(G4, m4) + lam + U * n, "ball": np.zeros(3)}


def test_joint_impulses_of_a_struck_loop_include_the_pin_impulse():
    """A four-bar struck on its rocker (a user's model): each joint's impulse is its subtree's momentum change
    minus the contact impulse and the loop pin's impulse on it. Without the pin's impulse every joint impulse was
    off by it (crank (0.951, -0.520) instead of (-0.443, -0.826)), with the rates and the contact impulse right."""
    from mechsys.analysis.impact.collide import resolve

    from tests.helpers import DATA_DIR

    model = mechsys.load(DATA_DIR / "beyond" / "fourbar_struck.yaml", {"der(xb)": "4", "der(yb)": "-0.5"})
    res = resolve(model)
    q = [model.doc.initial[c] for c in model.coordinates]
    up, joints = _struck_four_bar_by_hand(q, np.array([0, 0, 0, 4.0, -0.5, 0]))
    assert np.allclose(res.rates_after, up, rtol=1e-10, atol=1e-10)
    for link, want in joints.items():
        assert np.allclose(res.joint_impulses[link], want, rtol=1e-9, atol=1e-10), link
