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
