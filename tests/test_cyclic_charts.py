"""Issue 11: cyclic coordinates decided semantically (and declared in the file), steady rates solved from their
equations, the search report, and rotation charts (gimbal lock) in `equilibria` and `simulate`.

Each model here is written as a user would; the reference values are closed forms, not mechsys output."""
from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np
import pytest
import sympy as sp
from typer.testing import CliRunner

from mechsys.cli import app
from mechsys.mechanics.symmetry import _constant_in
from mechsys.numeric.rotations import angles_of, rate_matrix, ratio, rotation

ROOT = Path(__file__).resolve().parent.parent
runner = CliRunner()

FURUTA = """name: furuta
parameters: {m1: 0.3, L1: 0.4, m2: 0.1, L2: 0.3, g: 9.81}
coordinates:
  th1: {initial: 0, rate: 0%s}
  th2: {initial: 0.1, rate: 0%s}
links:
  arm:
    joint: {type: revolute, parent: ground, axis: z, coordinate: th1}
    mass: m1
    center_of_mass: [L1/2, 0, 0]
    shape: {rod: {length: L1, axis: x}}
  pend:
    joint: {type: revolute, parent: arm, axis: x, coordinate: th2, origin: [L1, 0, 0]}
    mass: m2
    center_of_mass: [0, 0, L2/2]
    shape: {rod: {length: L2, axis: z}}
forces:
  - {type: gravity, acceleration: [0, 0, -g]}
"""

# a rigid body on a zyx spherical joint, centre of mass below the joint: the zyx chart is singular where the
# middle angle is +-pi/2, and there f = 0 holds at four points that are no equilibrium (the gravity moment acts
# about the one direction the singular chart cannot express)
SPHERICAL_BODY = """name: spherical_body
parameters: {m: 1, l: 0.5, g: 9.81}
coordinates:
  psi: {initial: 0, rate: 0}
  theta: {initial: 0.3, rate: 0}
  phi: {initial: 0.2, rate: 0}
links:
  bob:
    joint: {type: spherical, parent: ground, sequence: zyx, coordinates: [psi, theta, phi]}
    mass: m
    center_of_mass: [0, 0, -l]
    inertia: {xx: 0.01, yy: 0.02, zz: 0.03}
forces:
  - {type: gravity, acceleration: [0, 0, -g]}
"""


def _write(tmp_path: Path, name: str, text: str) -> str:
    path = tmp_path / name
    path.write_text(text)
    return str(path)


def _json(*args: str) -> dict:
    result = runner.invoke(app, [*args, "-f", "json"])
    assert result.exit_code == 0, result.output
    return json.loads(result.stdout)


# ----------------------------------------------------------------------------------------- symmetry, symbolically
def test_constant_combinations_of_sines_and_cosines_are_recognised():
    q, a, b = sp.symbols("q a b", real=True)
    assert _constant_in(sp.cos(q) ** 2 * a + a * sp.sin(q) ** 2, q)
    assert _constant_in(sp.cos(q + b) ** 2 + sp.sin(q + b) ** 2, q)
    assert _constant_in((sp.cos(2 * q) + 2 * sp.sin(q) ** 2) / (a + sp.sin(q) ** 2 + sp.cos(q) ** 2), q)
    assert not _constant_in(a * sp.sin(q), q)
    assert not _constant_in(sp.cos(q) ** 2 - sp.sin(q) ** 2, q)
    assert not _constant_in(q * sp.cos(q) ** 2 + q * sp.sin(q) ** 2, q)  # q itself: not proven, not claimed


def test_furuta_arm_rod_is_cyclic_and_both_relative_equilibria_are_found(tmp_path):
    """The arm rod leaves cos(th1)**2 + sin(th1)**2 in M: th1 is still cyclic, and the hanging position (stable)
    is found next to the upright one (unstable) without hints."""
    path = _write(tmp_path, "furuta.yaml", FURUTA % ("", ""))
    info = _json("info", path)
    assert info["cyclic"] == ["th1"] and info["cyclic_basis"] == {"th1": "symbolic"}
    eq = _json("equilibria", path)
    found = {round(e["coordinates"]["th2"], 9): e["stability"] for e in eq["equilibria"]}
    assert found == {0.0: "unstable", round(math.pi, 9): "stable"}
    # hanging: the reduced pendulum frequency with the arm free and its momentum zero (closed form)
    m1, L1, m2, L2, g = 0.3, 0.4, 0.1, 0.3, 9.81
    J1 = m1 * L1**2 / 3 + m2 * L1**2  # arm about the axis, pendulum hanging: its axis is vertical
    Jp, c = m2 * L2**2 / 3, m2 * L1 * L2 / 2
    w = math.sqrt(m2 * g * L2 / 2 / (Jp - c**2 / J1))
    hanging = next(e for e in eq["equilibria"] if e["stability"] == "stable")
    assert max(abs(im) for _, im in hanging["eigenvalues"]) == pytest.approx(w, rel=1e-9)


def test_cyclic_key_declares_and_denies(tmp_path):
    wrong = _write(tmp_path, "wrong.yaml", FURUTA % ("", ", cyclic: true"))
    result = runner.invoke(app, ["info", wrong])
    assert result.exit_code == 2
    assert "wrong.yaml:5:" in result.output and "coordinates.th2.cyclic: declared cyclic" in result.output
    assert "Traceback" not in result.output
    declared = _write(tmp_path, "declared.yaml", FURUTA % (", cyclic: true", ""))
    assert _json("info", declared)["cyclic_basis"] == {"th1": "declared"}
    denied = _write(tmp_path, "denied.yaml", FURUTA % (", cyclic: false", ""))
    info = _json("info", denied)
    assert info["cyclic"] == [] and info["cyclic_denied"] == ["th1"]
    eq = _json("equilibria", denied)
    assert eq["cyclic"] == [] and "not isolated" in eq["message"]


# ----------------------------------------------------------------------------------------- steady rates, search
def test_steady_rates_linear_in_the_rate_are_solved_not_boxed():
    """Centrifuge at a steady speed of 25 rad/s (far outside any +-10 box): the torque balance is linear in
    der(alpha), solved at every start; all four arm angles found, each a root of the closed-form beta equation."""
    out = _json("equilibria", str(ROOT / "systems" / "centrifuge.yaml"), "--set", "dM=50/7", "--set", "Mo=25*50/7")
    assert out["search"]["solved_rates"] == ["der(alpha)"] and out["search"]["spread_rates"] == []
    I2x, I2y, I2z, m, a, l, g, w = 2.0, 2.0, 0.2, 8.0, 0.3, 0.5, 9.81, 25.0

    def balance(b: float) -> float:
        """d/dbeta (T - V) at beta' = 0: centre of mass at radius a + l sin(beta) and height -l cos(beta), the
        arm's moment about the vertical I2y sin^2 + I2z cos^2."""
        return (w**2 * (m * (a + l * math.sin(b)) * l * math.cos(b) + (I2y - I2z) * math.sin(b) * math.cos(b))
                - m * g * l * math.sin(b))
    betas = [e["coordinates"]["beta"] for e in out["equilibria"]]
    assert len(betas) == 4 and all(abs(balance(b)) < 1e-8 for b in betas)
    assert all(e["rates"]["alpha"] == pytest.approx(25.0, rel=1e-12) for e in out["equilibria"])


def test_rates_nonlinear_in_the_rate_are_spread_over_decades(tmp_path):
    text = (ROOT / "systems" / "centrifuge.yaml").read_text().split("\nexpect:")[0]
    text = text.replace("value: Mo - dM*der(alpha)}", "value: Mo - dM*der(alpha)**3/49}")
    out = _json("equilibria", _write(tmp_path, "cubic.yaml", text))
    assert out["search"]["spread_rates"] == ["der(alpha)"] and out["search"]["region"]["der(alpha)"] == [0.1, 1000.0]
    assert sorted(round(e["coordinates"]["beta"], 6) for e in out["equilibria"]) == \
        [-2.879372, -1.24942, -0.423246, 1.410445]  # the textbook's four at 7 rad/s (cube root of 49*Mo/dM)


def test_text_output_reports_the_search():
    result = runner.invoke(app, ["equilibria", str(ROOT / "systems" / "centrifuge.yaml")])
    assert result.exit_code == 0
    assert "search: deflated Newton from 74 starts: beta in [-3.142, 3.142], der(alpha)" in result.output


# ----------------------------------------------------------------------------------------- rotation charts
def test_sequences_numerically():
    rng = np.random.default_rng(1)
    a = rng.uniform(-1, 1, 3)
    R = rotation("zxz", a)
    b = angles_of("zyx", R)
    assert np.allclose(rotation("zyx", b), R, atol=1e-12)
    assert ratio(rate_matrix("zyx", [0.3, math.pi / 2, 0.1])) < 1e-12
    assert ratio(rate_matrix("zxz", [0.3, 0.0, 0.1])) < 1e-12
    assert ratio(rate_matrix("zxz", [0.3, 1.0, 0.1])) > 0.1


def test_gimbal_lock_artefacts_are_not_listed_as_equilibria(tmp_path):
    """Before: four 'stable' equilibria at theta = +-pi/2, phi = +-pi/2, where gravity has a moment about the
    direction the zyx angles cannot express. Now: only the genuine hanging and upright positions."""
    out = _json("equilibria", _write(tmp_path, "body.yaml", SPHERICAL_BODY))
    assert all(abs(abs(e["coordinates"]["theta"]) - math.pi / 2) > 1e-3 for e in out["equilibria"])
    assert "4 solution(s) at a gimbal-lock point are not steady motions" in out["message"]
    for e in out["equilibria"]:
        th, ph = e["coordinates"]["theta"], e["coordinates"]["phi"]
        # centre of mass height: -l times the third row of R (zyx) dotted with e_z
        height = -0.5 * math.cos(th) * math.cos(ph)
        assert e["stability"] == ("stable" if height < 0 else "unstable")


@pytest.mark.parametrize("axis", ["minor", "major"])
def test_torque_free_spin_at_gimbal_lock_is_classified_in_another_sequence(axis):
    """A spin about ground z with the body's x axis vertical is a gimbal lock of zyx. Before: 'undecided' (minor
    axis). Now: classified in a regular sequence: stable, with the nutation frequency of the closed form."""
    I = {"minor": (1.0, 2.0, 4.0), "major": (4.0, 2.0, 1.0)}[axis]
    out = _json("equilibria", str(ROOT / "tests" / "data" / "torque_free_body.yaml"),
                "--set", f"Ix={I[0]}", "--set", f"Iy={I[1]}", "--set", f"Iz={I[2]}")
    locked = [e for e in out["equilibria"] if abs(abs(e["coordinates"]["theta"]) - math.pi / 2) < 1e-9]
    assert locked, out
    w, (I1, I2, I3) = 2.0, I
    nutation = w * math.sqrt((I2 - I1) * (I3 - I1) / (I2 * I3))
    for e in locked:
        assert e["stability"] == "stable" and "classified in the" in e["reason"]
        assert any(abs(im - nutation) < 1e-9 for _, im in e["eigenvalues"])
        assert max(abs(complex(*v)) for v in e["eigenvalues"]) < 10


def test_simulate_from_a_gimbal_lock_names_the_chart_not_the_inertia(tmp_path):
    """A time-dependent torque keeps simulate from re-charting (analysis/motion/charted.py needs an autonomous model;
    tests/test_charted_simulation.py runs the torque-free start): it stops and names the chart."""
    text = (ROOT / "tests" / "data" / "torque_free_body.yaml").read_text()
    text = text.replace("theta: {initial: 0, rate: 0}", "theta: {initial: pi/2, rate: 1}")
    text += "forces:\n  - {type: torque, on: body, value: [0, 0, 0.1*sin(t)], frame: ground}\n"
    result = runner.invoke(app, ["simulate", _write(tmp_path, "lock.yaml", text), "--t-end", "1",
                                 "-o", str(tmp_path / "out.csv")])
    assert result.exit_code == 1
    assert "coordinate singularity: the zyx angles of the spherical joint of 'body'" in result.output
    assert "carries no mass" not in result.output


TOP_ZXZ = """name: top_zxz
parameters: {m: 1, l: 0.1, A: 0.002, C: 0.004, g: 9.81}
coordinates:
  psi: {initial: 0, rate: 0}
  theta: {initial: 0.5, rate: 0}
  phi: {initial: 0, rate: 60}
links:
  top:
    joint: {type: spherical, parent: ground, sequence: zxz, coordinates: [psi, theta, phi]}
    mass: m
    center_of_mass: [0, 0, l]
    inertia: {xx: A, yy: A, zz: C}
forces:
  - {type: gravity, acceleration: [0, 0, -g]}
"""


@pytest.mark.parametrize("factor", [0.95, 1.05])
def test_sleeping_top_in_zxz_angles_is_classified_in_a_regular_chart(tmp_path, factor):
    """theta = 0 is the zxz gimbal lock. Closed form: the upright top is stable iff C^2 w^2 > 4 A' m g l with A'
    the transverse moment about the pivot (A + m l^2)."""
    m, l, A, C, g = 1.0, 0.1, 0.002, 0.004, 9.81
    critical = 2 * math.sqrt((A + m * l**2) * m * g * l) / C
    path = _write(tmp_path, "top.yaml", TOP_ZXZ)
    out = _json("equilibria", path, "--set", f"der(phi)={factor * critical}")
    upright = next(e for e in out["equilibria"] if abs(e["coordinates"]["theta"]) < 1e-9)
    assert upright["stability"] == ("stable" if factor > 1 else "unstable")
    assert "classified in the" in upright["reason"] and "zxz angles are singular here" in upright["reason"]
    assert sorted(_json("info", path)["cyclic"]) == ["phi", "psi"]


def test_modes_never_linearize_in_a_singular_chart():
    """Before: `modes` picked the gimbal-lock steady spin (the first stable one) and failed with 'the reduced mass
    matrix is not positive definite'. Now it vibrates about a regular one, and --at a gimbal lock says why not."""
    path = str(ROOT / "tests" / "data" / "torque_free_body.yaml")
    out = runner.invoke(app, ["modes", path])
    assert out.exit_code == 0 and "about theta = 0, phi = 0" in out.output
    out = runner.invoke(app, ["modes", path, "--at", f"theta={math.pi / 2}"])
    assert out.exit_code == 1 and "--at is at a coordinate singularity" in out.output


def _zyx(psi: float, theta: float, phi: float) -> np.ndarray:
    """Body -> ground rotation of the zyx sequence, written out here (independent of mechsys)."""
    def rz(a):
        return np.array([[math.cos(a), -math.sin(a), 0], [math.sin(a), math.cos(a), 0], [0, 0, 1]])

    def ry(a):
        return np.array([[math.cos(a), 0, math.sin(a)], [0, 1, 0], [-math.sin(a), 0, math.cos(a)]])

    def rx(a):
        return np.array([[1, 0, 0], [0, math.cos(a), -math.sin(a)], [0, math.sin(a), math.cos(a)]])
    return rz(psi) @ ry(theta) @ rx(phi)


def test_each_steady_spin_is_listed_once_whatever_the_chart_does():
    """A torque-free body spinning about ground z has exactly six steady motions: a principal axis, either way
    up, along ground z. The zyx chart reaches each orientation twice and the x-axis ones at a gimbal lock (a
    continuum of angles there): before, 9 rows and a 'not isolated' note; now one row per steady motion, with
    the intermediate-axis theorem's verdicts (Ix = 1 < Iy = 2 < Iz = 4)."""
    out = _json("equilibria", str(ROOT / "tests" / "data" / "torque_free_body.yaml"))
    axes = []
    for e in out["equilibria"]:
        n = _zyx(0.0, e["coordinates"]["theta"], e["coordinates"]["phi"]).T @ np.array([0, 0, 1.0])
        k = int(np.argmax(np.abs(n)))
        assert abs(abs(n[k]) - 1) < 1e-9
        axes.append(("xyz"[k], int(np.sign(n[k]))))
        assert e["stability"] == ("unstable" if k == 1 else "stable"), e
    assert sorted(axes) == sorted((a, s) for a in "xyz" for s in (-1, 1))
    assert "not isolated" not in out["message"]


ELASTIC = """name: elastic_spherical_pendulum
parameters: {m: 1, k: 100, L0: 1, g: 9.81, w: 4}
coordinates:
  az: {initial: 0, rate: w}
  pol: {initial: 0.5, rate: 0}
  r: {initial: 1.1, rate: 0}
links:
  gimbal:
    joint: {type: universal, parent: ground, axes: [z, y], coordinates: [az, pol]}
  bob:
    particle: true
    joint: {type: prismatic, parent: gimbal, axis: -z, coordinate: r}
    mass: m
forces:
  - {type: gravity, acceleration: [0, 0, -g]}
  - {type: spring, between: [gimbal.origin, bob.origin], stiffness: k, free_length: L0}
"""


def test_elastic_spherical_pendulum_azimuth_and_its_steady_motions(tmp_path):
    """The azimuth of a particle on a universal joint is cyclic (cos^2 + sin^2 in T). At az' = 4: the conical
    motion r = k L0/(k - m w^2), cos(pol) = g/(w^2 r), once (pol and -pol, or -r, are the same motion); on the
    axis (hanging, upright) the azimuth moves no mass: a coordinate singularity, not a verdict."""
    path = _write(tmp_path, "elastic.yaml", ELASTIC)
    assert _json("info", path)["cyclic_basis"] == {"az": "symbolic"}
    out = _json("equilibria", path)
    m, k, L0, g, w = 1.0, 100.0, 1.0, 9.81, 4.0
    conical = [e for e in out["equilibria"] if 0.1 < abs(e["coordinates"]["pol"]) < 3.0]
    assert len(conical) == 1 and conical[0]["stability"] == "stable"
    r = k * L0 / (k - m * w**2)
    assert conical[0]["coordinates"]["r"] == pytest.approx(r, rel=1e-10)
    assert math.cos(conical[0]["coordinates"]["pol"]) == pytest.approx(g / (w**2 * r), rel=1e-10)
    on_axis = [e for e in out["equilibria"] if e not in conical]
    assert sorted(round(e["coordinates"]["r"], 6) for e in on_axis) == [round(L0 - m * g / k, 6), round(L0 + m * g / k, 6)]
    assert all(e["stability"] == "undecided" and e["reason"].startswith("coordinate singularity: az moves no mass")
               for e in on_axis)


def test_the_physical_state_code_is_cached_and_equals_a_fresh_one(tmp_path, monkeypatch):
    """charts._state_fn (the physical state that tells two roots are one steady motion) is generated once per
    model structure and read back from the cache: the same numbers as freshly generated code, and an entry that
    is not arithmetic code is ignored and replaced."""
    import mechsys
    from mechsys.analysis.equilibrium import charts
    from mechsys.numeric import cache

    monkeypatch.setenv("MECHSYS_CACHE", str(tmp_path / "cache"))
    path = ROOT / "systems" / "rolling_disk.yaml"
    generated = []
    real = charts.generate_source
    monkeypatch.setattr(charts, "generate_source", lambda *a: generated.append(1) or real(*a))
    args = np.random.default_rng(2).uniform(-1, 1, 3 * 7 + 1)

    def state():
        model = mechsys.load(path)  # a new model object: a new command
        p = [model.parameters[s.name] for s in model.parameter_symbols]
        q, u = args[:len(model.q)], args[len(model.q):2 * len(model.q)]
        return np.array(charts._state_fn(model)(*q, *u, *p, 0.3))

    fresh = state()
    cached = state()
    assert generated == [1] and np.array_equal(fresh, cached) and fresh.size > 0
    model = mechsys.load(path)
    cache.store(cache.model_key(model, "chart-state"), {"source": "import os\nos.system('true')"})
    assert np.array_equal(state(), fresh) and generated == [1, 1]


@pytest.mark.parametrize("name", ["bicycle", "gyrostabilizer", "indicator", "rolling_disk", "four_bar"])
def test_the_physical_state_velocities_are_the_time_derivative_of_the_positions(name):
    """charts._state_fn (the state two roots are compared by) takes its velocities from the link-by-link
    propagation: they must be d/dt of its positions, here by a central difference along (u, 1) in (q, t)."""
    import mechsys
    from mechsys.analysis.equilibrium.charts import _state_fn

    model = mechsys.load(ROOT / "systems" / f"{name}.yaml")
    fn = _state_fn(model)
    n = len(model.q)
    p = mechsys.numeric.parameters.parameter_values(model)
    rng = np.random.default_rng(3)
    bodies = [(b.particle) for b, *_ in model._body_kinematics]
    checked = 0
    for _ in range(3):
        q, u, t = rng.uniform(-1, 1, n), rng.uniform(-1, 1, n), float(rng.uniform(0, 1))
        h = 1e-6
        plus = np.array(fn(*(q + h * u), *u, *p, t + h), dtype=float)
        minus = np.array(fn(*(q - h * u), *u, *p, t - h), dtype=float)
        state = np.array(fn(*q, *u, *p, t), dtype=float)
        k = 0
        for particle in bodies:
            r_dot = (plus[k:k + 3] - minus[k:k + 3]) / (2 * h)
            assert np.allclose(state[k + 3:k + 6], r_dot, rtol=1e-6, atol=1e-6 * (1 + np.max(np.abs(r_dot))))
            k += 6 if particle else 6 + 9 + 3
            checked += 1
        assert k == len(state) - 1  # then the potential energy
        assert state[-1] == pytest.approx(float(model.potential_energy.subs(
            {**dict(zip(model.q, q)), **dict(zip(model.parameter_symbols, p)), model.t: t})), rel=1e-9, abs=1e-12)
    assert checked >= 3


def test_review_computes_each_roots_physical_state_once(monkeypatch):
    """charts.review compares every root with the kept ones (quadratic in the roots): each root's physical state
    is computed once, not once per pair (the 10-link chain's 240 roots: 3.6 s of 24 s before)."""
    import mechsys
    from mechsys.analysis.equilibrium import charts
    from mechsys.analysis.equilibrium import equilibria as eqm
    from mechsys.numeric.parameters import parameter_values

    model = mechsys.load(Path(__file__).resolve().parent.parent / "systems" / "double_pendulum.yaml")
    problem = eqm.make_problem(model)
    roots = [eqm.Equilibrium({"theta1": a, "theta2": b}, {}, []) for a in (0.0, math.pi) for b in (0.0, math.pi)]
    roots += [eqm.Equilibrium({"theta1": 2 * math.pi, "theta2": 0.0}, {}, [])]  # the first again
    calls = []
    real = charts._physical
    monkeypatch.setattr(charts, "_physical", lambda *a: calls.append(a) or real(*a))
    kept, _note = charts.review(problem, roots, parameter_values(model))
    assert len(kept) == 4
    assert len(calls) == len(roots)


@pytest.mark.parametrize("name", ["top_zxz.yaml", "top_cardan.yaml"])
def test_review_compares_with_all_kept_motions_at_once_as_pair_by_pair(name):
    """charts._Motions answers, for each new root, the first kept motion that same_motion (pair by pair) calls
    the same: on tops with cyclic angles, with roots repeated a full turn away, a half turn of each cyclic angle
    away, with a changed rate, and unrelated."""
    import mechsys
    from mechsys.analysis.equilibrium import charts
    from mechsys.analysis.equilibrium import equilibria as eqm
    from mechsys.numeric.parameters import parameter_values

    model = mechsys.load(Path(__file__).resolve().parent / "data" / "beyond" / name)
    problem = eqm.make_problem(model)
    p = parameter_values(model)
    rng = np.random.default_rng(7)
    turning = [c for c in problem.cyclic if problem.angles.get(c, False)]
    assert turning, "the test needs a cyclic angle"
    base = []
    for _ in range(4):
        coords = {c: float(rng.uniform(0.2, 1.2)) for c in model.coordinates}
        rates = {c: float(rng.uniform(-2, 2)) for c in turning}  # steady spins
        base.append(eqm.Equilibrium(coords, rates, []))
    roots = list(base)
    for e in base:
        roots.append(eqm.Equilibrium({c: v + 2 * math.pi for c, v in e.coordinates.items()}, dict(e.rates), []))
        roots.append(eqm.Equilibrium({c: v + (math.pi if c in turning else 0.0) for c, v in e.coordinates.items()},
                                     dict(e.rates), []))
        first = turning[0]
        roots.append(eqm.Equilibrium(dict(e.coordinates), {**e.rates, first: e.rates[first] + 1e-3}, []))
    order = rng.permutation(len(roots))
    roots = [roots[k] for k in order]
    motions, kept, hits = charts._Motions(problem, p, {}), [], 0
    for e in roots:
        expected = next((j for j, a in enumerate(kept) if charts.same_motion(problem, a, e, p)), None)
        assert motions.first_same(e) == expected
        if expected is None:
            kept.append(e)
            motions.keep(e)
        else:
            hits += 1
    assert hits >= 4 and len(kept) >= 8  # full turns are the same motion; a changed spin rate is not


def test_a_force_naming_the_angles_is_not_re_charted(tmp_path):
    """A sleeping zxz top with a righting potential written in its own angles, kp*(1 - cos(theta)): read in another
    sequence it is another function (1 - cos of the x angle alone penalises tilt about one axis only), so the steady
    motions at the lock (theta = 0 and pi) were classified with the wrong physics ('stable', classified in zxy).
    They are now 'undecided' at the coordinate singularity, naming the force."""
    text = (ROOT / "tests" / "data" / "beyond" / "top_zxz.yaml").read_text()
    text += "  - {type: potential, value: 0.3*(1 - cos(theta))}\n"
    out = _json("equilibria", _write(tmp_path, "top.yaml", text))
    locked = [e for e in out["equilibria"] if abs(math.sin(e["coordinates"]["theta"])) < 1e-9]
    assert len(locked) == 2
    for e in locked:
        assert e["stability"] == "undecided"
        assert "forces[1].value names theta, which another sequence of the joint would change" in e["reason"]
