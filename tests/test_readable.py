"""The readable form of `mechsys derive` (mechsys/report/readable.py): no Pythagorean leftovers and no `+ -` in
what is printed, exactly the derived functions (mpmath at 30 digits, every bundled model), `--raw` and JSON as
derived, the time budget and its note, and two models written here whose mass matrices are derived by hand."""
from __future__ import annotations

import itertools
import json
import random
from pathlib import Path

import mpmath
import pytest
import sympy as sp
from typer.testing import CliRunner

import mechsys
from helpers import SYSTEMS_DIR, chain_file, load_system
from mechsys.cli import app
from mechsys.mechanics.model import Equations
from mechsys.report import readable as rd
from mechsys.report.printing import to_text

runner = CliRunner()
TEXTBOOK = ("centrifuge", "gyrostabilizer", "indicator")
FAST_MODELS = sorted(p.stem for p in SYSTEMS_DIR.glob("*.yaml") if p.stem != "bicycle")


def derive(*args: object) -> str:
    result = runner.invoke(app, ["derive", *(str(a) for a in args)])
    assert result.exit_code == 0, result.output
    return result.stdout


def entries(eq: Equations) -> list[sp.Expr]:
    """Every printed expression: T, V, Q, M, f, A, b."""
    return [eq.T, eq.V, *eq.Q, *eq.M, *eq.f, *eq.A, *eq.b]


# ------------------------------------------------------------------------------ an independent leftover check
def sum_pairs(expr: sp.Expr, partners) -> list[tuple[sp.Expr, sp.Expr]]:
    """Pairs (term, partner) of terms of one sum of ``expr``, the partner one of ``partners(term)``: found with
    sympy's own arithmetic on the expression tree, nothing parsed from text."""
    found = []
    for node in sp.preorder_traversal(expr):
        if node.is_Add:
            terms = set(node.args)
            found += [(term, p) for term in node.args for p in partners(term) if p in terms]
    return found


def pythagorean_leftovers(expr: sp.Expr) -> list[tuple[sp.Expr, sp.Expr]]:
    """Pairs of terms of one sum that read c*R*sin(x)**n and c*R*sin(x)**(n-2)*cos(x)**2 (the same cofactor
    c*R)."""
    def partners(term: sp.Expr) -> list[sp.Expr]:
        return [term / f.base ** 2 * sp.cos(f.base.args[0]) ** 2 for f in sp.Mul.make_args(term)
                if f.is_Pow and isinstance(f.base, sp.sin) and f.exp.is_Integer and f.exp >= 2]

    return sum_pairs(expr, partners)


def test_the_leftover_check_finds_what_the_derivation_leaves():
    """The check can fail: the gyrostabilizer as derived has I3*cos(beta)**2*(sin(Omega*t)**2 + cos(Omega*t)**2),
    and a hand-made sum of both kinds is caught."""
    raw = load_system("gyrostabilizer").equations("lagrange")
    assert any(pythagorean_leftovers(e) for e in entries(raw))
    x, a, b = sp.symbols("x a b")
    assert pythagorean_leftovers(a * b * sp.sin(x) ** 2 + a * b * sp.cos(x) ** 2 + 1)
    assert pythagorean_leftovers(sp.sqrt(a * sp.cos(x) ** 2 * sp.sin(x) + a * sp.sin(x) ** 3))
    assert not pythagorean_leftovers(a * sp.sin(x) ** 2 + b * sp.cos(x) ** 2)


@pytest.mark.parametrize("method", ["lagrange", "kane"])
@pytest.mark.parametrize("name", TEXTBOOK)
def test_no_pythagorean_leftovers_in_the_printed_equations(name, method):
    cleanup = rd.readable(load_system(name).equations(method))
    assert cleanup.note() is None
    for e in entries(cleanup.equations):
        assert not pythagorean_leftovers(e), to_text(e)


@pytest.mark.parametrize("fmt", ["text", "latex", "markdown"])
@pytest.mark.parametrize("name", TEXTBOOK + ("rolling_disk",))
def test_no_plus_minus_in_the_printed_equations(name, fmt):
    text = derive(SYSTEMS_DIR / f"{name}.yaml", "-f", fmt)
    assert "+ -" not in text and "readable form" not in text
    if name == "rolling_disk":  # the form as derived had it (a negative mass-matrix entry)
        assert "+ -" in derive(SYSTEMS_DIR / f"{name}.yaml", "-f", fmt, "--raw")


def test_the_headline_leftovers_are_gone():
    """The issue's examples: the gyrostabilizer's I3*cos(Omega*t)**2 + I3*sin(Omega*t)**2 and the rolling disk's
    unit-vector norms (its constraint rows read der(der(x)) - r*cos(yaw)*der(der(spin)))."""
    gyro = derive(SYSTEMS_DIR / "gyrostabilizer.yaml")
    assert "sin(Omega*t)**2" in derive(SYSTEMS_DIR / "gyrostabilizer.yaml", "--raw")
    assert "sin(Omega*t)**2" not in gyro and "(I2x + I3)*der(der(beta))" in gyro
    disk = derive(SYSTEMS_DIR / "rolling_disk.yaml")
    assert "lambda1 [no_slip.x]: der(der(x)) - r*cos(yaw)*der(der(spin)) = " in disk
    assert "spin: m*r**2*sin(lean)/2*der(der(yaw)) + m*r**2/2*der(der(spin)) = " in disk
    assert " - lambda1*r*cos(yaw) - lambda2*r*sin(yaw)\n" in disk


# ------------------------------------------------------------------------------------------------ exactness
def assert_exact(raw: list[sp.Expr], clean: list[sp.Expr], points: int = 3, seed: int = 7) -> None:
    """raw and clean agree to 1e-12 relative at random values of every symbol (lambdified, mpmath at 30 digits,
    so that an exact rewrite agrees to ~1e-28 and only a wrong one can miss)."""
    symbols = sorted(set().union(*(e.free_symbols for e in raw + clean)), key=str)
    f_raw = sp.lambdify(symbols, raw, modules="mpmath", cse=True)
    f_clean = sp.lambdify(symbols, clean, modules="mpmath", cse=True)
    rng = random.Random(seed)
    with mpmath.workdps(30):
        for _ in range(points):
            values = [mpmath.mpf(rng.uniform(0.2, 1.4)) for _ in symbols]
            for k, (a, b) in enumerate(zip(f_raw(*values), f_clean(*values))):
                assert abs(a - b) <= 1e-12 * max(abs(a), abs(b)) + mpmath.mpf("1e-24"), (k, a, b, clean[k])


def test_the_exactness_check_can_fail():
    x, a = sp.symbols("x a")
    with pytest.raises(AssertionError):
        assert_exact([a * sp.sin(x) ** 2 + 2 * a * sp.cos(x) ** 2], [a])
    assert_exact([a * sp.sin(x) ** 2 + a * sp.cos(x) ** 2], [a])


@pytest.mark.parametrize("method", ["lagrange", "kane"])
@pytest.mark.parametrize("name", FAST_MODELS)
def test_the_readable_form_is_exact(name, method):
    raw = load_system(name).equations(method)
    cleanup = rd.readable(raw, budget=10**9)  # the whole clean-up
    assert cleanup.note() is None
    assert_exact(entries(raw), entries(cleanup.equations))


@pytest.mark.slow
def test_the_bicycle_within_the_default_budget_is_exact():
    """The benchmark bicycle (15-45 s to derive): the default budget cleans every entry (no note; a count of node
    visits, so on every machine) and what it prints is exact (the entries that changed, at one point)."""
    raw = load_system("bicycle").equations("lagrange")
    cleanup = rd.readable(raw)
    assert cleanup.note() is None and cleanup.spent < rd.BUDGET_VISITS
    changed = [(r, c) for r, c in zip(entries(raw), entries(cleanup.equations)) if r is not c]
    assert changed
    assert_exact([r for r, _ in changed], [c for _, c in changed], points=1)


def test_unit_vector_norms_and_signs():
    x, y, a, b, c = sp.symbols("x y a b c")
    norm = (sp.cos(x) * sp.cos(y) - sp.sin(x) * sp.sin(y)) ** 2 + (sp.cos(x) * sp.sin(y) + sp.sin(x) * sp.cos(y)) ** 2
    assert rd.clean_expression(sp.sqrt(norm)) == 1
    assert rd.clean_expression(sp.sqrt(sp.cos(a) ** 2 + sp.sin(a) ** 2)) == 1
    assert rd.clean_expression(c * (-a - b) * (-2 * a - 2 * b) / 2) == c * (a + b) ** 2
    assert rd.clean_expression(c - c * sp.sin(x) ** 2) == c * sp.cos(x) ** 2
    assert rd.clean_expression(a * sp.sin(x) ** 4 + a * sp.sin(x) ** 2 * sp.cos(x) ** 2) == a * sp.sin(x) ** 2
    kept = a * sp.sin(x) ** 2 + b * sp.cos(x) ** 2  # different cofactors: nothing to do
    assert rd.clean_expression(kept) == kept


# -------------------------------------------------------------------------------------- --raw and JSON as before
def _old_text(eq: Equations, name: str) -> str:
    """derive's text form before the readable form (copied from mechsys/report/derive.py of commit babd36c)."""
    acc = [f"der(der({c}))" for c in eq.coordinates]
    lines = [f"{name}: equations of motion ({eq.method}), M q'' = f" + (" + A^T lambda" if eq.A.shape[0] else ""),
             "coordinates: " + ", ".join(eq.coordinates), f"T = {to_text(eq.T)}", f"V = {to_text(eq.V)}",
             "generalized forces Q (not derived from V):"]
    lines += [f"  {c}: {to_text(qi)}" for c, qi in zip(eq.coordinates, eq.Q)]
    lines.append("equations:")
    for i, c in enumerate(eq.coordinates):
        terms = [acc[j] if m == 1 else (f"({to_text(m)})" if m.is_Add else to_text(m)) + f"*{acc[j]}"
                 for j, m in enumerate(eq.M.row(i)) if m != 0]
        lam = "".join(f" + lambda{k + 1}*({to_text(a)})" for k, a in enumerate(eq.A.col(i)) if a != 0)
        lines.append(f"  {c}: {' + '.join(terms) or '0'} = {to_text(eq.f[i])}{lam}")
    if eq.A.shape[0]:
        lines.append("constraints (acceleration level, A q'' = b):")
        for k, cname in enumerate(eq.constraint_names):
            row = " + ".join(f"({to_text(a)})*{acc[j]}" for j, a in enumerate(eq.A.row(k)) if a != 0) or "0"
            lines.append(f"  lambda{k + 1} [{cname}]: {row} = {to_text(eq.b[k])}")
    return "\n".join(lines) + "\n"


@pytest.mark.parametrize("name", ["centrifuge", "gyrostabilizer", "rolling_disk", "four_bar"])
def test_raw_prints_what_derive_printed_before(name):
    """Byte for byte, including the rolling disk's `+ -` (a negative mass-matrix entry), multipliers and
    constraint rows."""
    eq = load_system(name).equations("lagrange")
    assert derive(SYSTEMS_DIR / f"{name}.yaml", "--raw") == _old_text(eq, name)


@pytest.mark.parametrize("name", ["gyrostabilizer", "rolling_disk"])
def test_json_keeps_the_expressions_as_derived(name):
    eq = load_system(name).equations("lagrange")
    data = json.loads(derive(SYSTEMS_DIR / f"{name}.yaml", "-f", "json"))
    assert data["mass_matrix"] == [[to_text(m) for m in eq.M.row(i)] for i in range(eq.M.shape[0])]
    assert data["forcing"] == [to_text(f) for f in eq.f] and data["kinetic_energy"] == to_text(eq.T)
    assert data["generalized_forces"] == [to_text(q) for q in eq.Q] and data["potential_energy"] == to_text(eq.V)
    if eq.A.shape[0]:
        assert data["constraints"]["rhs"] == [to_text(b) for b in eq.b]
        assert data["constraints"]["jacobian"] == [[to_text(a) for a in eq.A.row(k)] for k in range(eq.A.shape[0])]
    assert derive(SYSTEMS_DIR / f"{name}.yaml", "-f", "json", "--raw") == json.dumps(data, indent=2) + "\n"


# ------------------------------------------------------------------------------------------------ the budget
def test_a_spent_budget_prints_the_entries_as_derived_with_a_note(monkeypatch, tmp_path):
    monkeypatch.setattr(rd, "BUDGET_VISITS", 0)  # a change of the code: its own cache (the warm outputs' key has
    monkeypatch.setenv("MECHSYS_CACHE", str(tmp_path))  # the package's source, not a constant patched at run time)
    eq = load_system("gyrostabilizer").equations("lagrange")
    text = derive(SYSTEMS_DIR / "gyrostabilizer.yaml")
    n = sum(1 for e in entries(eq) if e.args)
    assert text.endswith(f"readable form: clean-up stopped after 0 node visits; {n} of {n} entries left as derived, "
                         "use "
                         "--simplify for a full (slow) simplification or --raw for none\n")
    assert f"\nT = {to_text(eq.T)}\n" in text and f" = {to_text(eq.f[0])}\n" in text
    assert "sin(Omega*t)**2" in text
    latex = derive(SYSTEMS_DIR / "gyrostabilizer.yaml", "-f", "latex")
    assert latex.endswith(f"\\end{{align*}}\n% readable form: clean-up stopped after 0 node visits; {n} of {n} entries "
                          "left as derived, use --simplify for a full (slow) simplification or --raw for none\n")
    assert "readable form" not in derive(SYSTEMS_DIR / "gyrostabilizer.yaml", "-f", "json")


def test_a_budget_spent_midway_leaves_the_rest_as_derived():
    """At budgets from nothing to enough: the first entries cleaned, the note counts the rest, which are the
    derived expressions themselves, and everything is exact."""
    raw = load_system("gyrostabilizer").equations("lagrange")
    printed = [e for e in entries(raw) if e.args]
    needed = rd.readable(raw, budget=10**9).spent  # node visits of a whole clean-up
    seen = set()
    for budget in [0, *range(1, needed + 10, max(1, needed // 12))]:
        cleanup = rd.readable(raw, budget=budget)
        left = cleanup.left_as_derived
        seen.add(left)
        clean = [e for e, r in zip(entries(cleanup.equations), entries(raw)) if r.args]
        assert clean[len(printed) - left:] == printed[len(printed) - left:]
        assert (cleanup.note() is None) == (left == 0 and cleanup.partly_cleaned == 0)
        if left:
            assert f"; {left} of {len(printed)} entries left as derived," in cleanup.note()
        assert_exact(entries(raw), entries(cleanup.equations), points=1)
    assert 0 in seen and len(printed) in seen and len(seen) > 3


def test_a_budget_spent_before_the_norms_keeps_identities_and_signs(monkeypatch, tmp_path):
    def out_of_time(self, add):
        raise rd.OutOfTime

    monkeypatch.setattr(rd._Cleaner, "_norms", out_of_time)
    # a private cache: the clean-up `derive` stores is keyed by this module's source, which the patch leaves as is
    monkeypatch.setenv("MECHSYS_CACHE", str(tmp_path / "cache"))
    raw = load_system("rolling_disk").equations("lagrange")
    cleanup = rd.readable(raw)
    n = sum(1 for e in entries(raw) if e.args)
    assert cleanup.left_as_derived == 0 and cleanup.partly_cleaned == n
    assert f"; unit-vector norms not tried in {n} of {n} entries, use --simplify" in cleanup.note()
    assert_exact(entries(raw), entries(cleanup.equations), points=1)
    text = derive(SYSTEMS_DIR / "rolling_disk.yaml")
    assert "+ -" not in text and text.endswith(cleanup.note() + "\n")


# -------------------------------------------------------------------------------- models written as a user would
BALL_PENDULUM = """\
name: ball_pendulum
description: A ball on a massless rod hung from a gimbal (a spherical pendulum with a rigid bob)
parameters: {m: 1.5, L: 0.8, a: 0.1, g: 9.81}
coordinates:
  phi: {initial: 0, rate: 1}       # azimuth about the vertical
  theta: {initial: 0.5, rate: 0}   # polar angle from the downward vertical
links:
  gimbal:
    joint: {type: revolute, parent: ground, axis: z, coordinate: phi}
  ball:
    joint: {type: revolute, parent: gimbal, axis: x, coordinate: theta}
    mass: m
    center_of_mass: [0, 0, -L]
    shape: {sphere: {radius: a}}
forces:
  - {type: gravity, acceleration: [0, 0, -g]}
"""

FURUTA = """\
name: furuta
description: Furuta pendulum, a point mass on a rod hinged at the tip of an arm that turns about the vertical
parameters: {J: 0.02, r: 0.2, m: 0.1, l: 0.3, g: 9.81}
coordinates:
  phi: {initial: 0, rate: 0}       # arm angle about the vertical
  theta: {initial: 0.1, rate: 0}   # pendulum angle from the downward vertical, about the arm
links:
  arm:
    joint: {type: revolute, parent: ground, axis: z, coordinate: phi}
    inertia: {zz: J}
  pendulum:
    joint: {type: revolute, parent: arm, axis: x, coordinate: theta, origin: [r, 0, 0]}
    particle: true
    mass: m
    center_of_mass: [0, 0, -l]
forces:
  - {type: gravity, acceleration: [0, 0, -g]}
"""


def _closed_forms() -> dict[str, tuple[str, sp.Matrix]]:
    """Mass matrices derived by hand, coordinates (phi, theta).

    Ball: the centre moves on a sphere of radius L, |v|^2 = L^2 (theta'^2 + sin^2(theta) phi'^2); the angular
    velocity phi' e_z + theta' e_x' has |omega|^2 = phi'^2 + theta'^2 (e_z is perpendicular to e_x'), and the
    central inertia is isotropic, I = 2/5 m a^2: M = diag(m L^2 sin^2(theta) + I, m L^2 + I).

    Furuta: bob at p = (r cos(phi) - l sin(theta) sin(phi), r sin(phi) + l sin(theta) cos(phi), -l cos(theta));
    |dp/dphi|^2 = r^2 + l^2 sin^2(theta), |dp/dtheta|^2 = l^2, dp/dphi . dp/dtheta = r l cos(theta), and the arm
    adds J phi'^2: M = [[J + m (r^2 + l^2 sin^2(theta)), m r l cos(theta)], [m r l cos(theta), m l^2]]."""
    m, L, a, J, r, l = sp.symbols("m L a J r l", real=True)
    th = sp.Symbol("theta", real=True)
    inertia = sp.Rational(2, 5) * m * a ** 2
    ball = sp.diag(m * L ** 2 * sp.sin(th) ** 2 + inertia, m * L ** 2 + inertia)
    furuta = sp.Matrix([[J + m * (r ** 2 + l ** 2 * sp.sin(th) ** 2), m * r * l * sp.cos(th)],
                        [m * r * l * sp.cos(th), m * l ** 2]])
    return {"ball_pendulum": (BALL_PENDULUM, ball), "furuta": (FURUTA, furuta)}


@pytest.mark.parametrize("name", ["ball_pendulum", "furuta"])
def test_printed_mass_matrix_of_a_user_model_is_the_closed_form(name, tmp_path: Path):
    source, closed = _closed_forms()[name]
    path = tmp_path / f"{name}.yaml"
    path.write_text(source)
    model = mechsys.load(path)
    raw = model.equations("lagrange")
    symbols = {s.name: s for e in entries(raw) for s in e.free_symbols}
    closed = closed.xreplace({s: symbols[s.name] for s in closed.free_symbols})
    clean = rd.readable(raw).equations.M
    for i, j in itertools.product(range(2), range(2)):
        assert sp.simplify(clean[i, j] - closed[i, j]) == 0, (i, j, clean[i, j])
    assert clean == closed  # the clean-up prints the closed form itself ...
    assert raw.M != closed  # ... which the derivation alone does not
    text = derive(path)
    for i, c in enumerate(("phi", "theta")):
        entry = closed[i, i]
        coeff = f"({to_text(entry)})" if entry.is_Add else to_text(entry)
        assert f"{coeff}*der(der({c}))" in text


# ------------------------------------------------------------------------ the sum and difference formulas
def angle_leftovers(expr: sp.Expr) -> list[tuple[sp.Expr, sp.Expr]]:
    """Pairs of terms of one sum that read c*R*cos(x)*cos(y) and +-c*R*sin(x)*sin(y), or c*R*sin(x)*cos(y) and
    +-c*R*cos(x)*sin(y) (x != y)."""
    def partners(term: sp.Expr) -> list[sp.Expr]:
        bases = [f for f in sp.Mul.make_args(term) if isinstance(f, (sp.sin, sp.cos))]
        out = []
        for a, b in itertools.permutations(bases, 2):
            if a.args[0] != b.args[0] and isinstance(a, sp.cos):
                other = sp.cos if isinstance(b, sp.sin) else sp.sin
                partner = term / (a * b) * sp.sin(a.args[0]) * other(b.args[0])
                out += [partner, -partner]
        return out

    return sum_pairs(expr, partners)


def test_the_sum_and_difference_formulas():
    x, y, a, b, c, z, q = sp.symbols("x y a b c z q")
    cc, ss = sp.cos(x) * sp.cos(y), sp.sin(x) * sp.sin(y)
    sc, cs = sp.sin(x) * sp.cos(y), sp.cos(x) * sp.sin(y)
    assert rd.clean_expression(a * cc + a * ss) == a * sp.cos(x - y)
    assert rd.clean_expression(a * cc - a * ss) == a * sp.cos(x + y)
    assert rd.clean_expression(2 * a * sc + 2 * a * cs) == 2 * a * sp.sin(x + y)
    assert rd.clean_expression(a * sc - a * cs) == a * sp.sin(x - y)
    assert rd.clean_expression(-a * sc + a * cs) == -a * sp.sin(x - y)
    # a chain's absolute angles: relative ones come out
    q1, q2, q3 = sp.symbols("q1 q2 q3")
    assert rd.clean_expression(c * sp.cos(q1) * sp.cos(q1 + q2) + c * sp.sin(q1) * sp.sin(q1 + q2)) == c * sp.cos(q2)
    assert rd.clean_expression(sp.sin(q1 + q2) * sp.cos(q1 + q2 + q3) - sp.cos(q1 + q2) * sp.sin(q1 + q2 + q3)) == \
        -sp.sin(q3)
    # one power of a square taken out; the rest of the term kept
    assert rd.clean_expression(c * sp.cos(x) ** 2 * sp.cos(y) + c * sp.cos(x) * sp.sin(x) * sp.sin(y)) == \
        c * sp.cos(x) * sp.cos(x - y)
    # a unit-vector norm that only the formulas make smaller: |a e(x) + b e(y)|
    norm = (a * sp.cos(x) + b * sp.cos(y)) ** 2 + (a * sp.sin(x) + b * sp.sin(y)) ** 2
    assert rd.clean_expression(sp.sqrt(norm)) == sp.sqrt(a ** 2 + b ** 2 + 2 * a * b * sp.cos(x - y))
    for kept in (a * cc + b * ss, a * cc + 2 * a * ss, a * sc + a * ss, a * cc + a * sp.sin(x) * sp.sin(z)):
        assert rd.clean_expression(kept) == kept
    # x - y that sympy evaluates to something else than a sin or cos: left as it is (the clean-up's classes hold)
    w = sp.acos(z) + q
    kept = sp.cos(w) * sp.cos(q) + sp.sin(w) * sp.sin(q)
    assert sp.cos(w - q) == z and rd.clean_expression(kept) == kept
    assert not angle_leftovers(a * cc + b * ss)
    assert angle_leftovers(a * cc - a * ss) and angle_leftovers(a * sc + a * cs)


def test_the_double_pendulums_printed_equations_are_the_textbook_ones():
    """Rods of length l1, l2 (centres at the middle), theta2 relative to rod 1. By hand: the centre of rod 2 moves
    with l1 theta1' e1 + l2/2 (theta1' + theta2') e2, e1 . e2 = cos(theta2); with the rods' central inertias
    m l**2/12, M11 = m1 l1**2/3 + m2 (l1**2 + l2**2/4 + l1 l2 cos(theta2)) + m2 l2**2/12,
    M12 = m2 (l2**2/4 + l1 l2 cos(theta2)/2) + m2 l2**2/12, M22 = m2 l2**2/3: it does not depend on theta1, and
    the printed form shows it (the derivation alone does not)."""
    model = load_system("double_pendulum")
    names = {s.name: s for s in model.parameter_symbols}
    m1, m2, l1, l2 = (names[k] for k in ("m1", "m2", "l1", "l2"))
    th1, th2 = model.q
    c2 = sp.cos(th2)
    closed = sp.Matrix([[m1 * l1 ** 2 / 3 + m2 * (l1 ** 2 + l2 ** 2 / 4 + l1 * l2 * c2) + m2 * l2 ** 2 / 12,
                         m2 * (l2 ** 2 / 4 + l1 * l2 * c2 / 2) + m2 * l2 ** 2 / 12],
                        [m2 * (l2 ** 2 / 4 + l1 * l2 * c2 / 2) + m2 * l2 ** 2 / 12, m2 * l2 ** 2 / 3]])
    w1, w2 = model.u
    h, g = m2 * l1 * l2 * sp.sin(th2) / 2, names["g"]
    forcing = sp.Matrix([h * (2 * w1 * w2 + w2 ** 2) - g * m2 * (l2 * sp.sin(th1 + th2) / 2 + l1 * sp.sin(th1))
                         - g * m1 * l1 * sp.sin(th1) / 2,
                         -h * w1 ** 2 - g * m2 * l2 * sp.sin(th1 + th2) / 2])
    for method in ("lagrange", "kane"):
        raw = model.equations(method)
        cleaned = rd.readable(raw).equations
        clean = cleaned.M
        assert (clean - closed).expand() == sp.zeros(2, 2), method  # the same polynomial in cos(theta2)
        assert th1 in raw.M.free_symbols and th1 not in clean.free_symbols, method
        assert not any(angle_leftovers(e) for e in clean), method
        assert (cleaned.f - forcing).expand() == sp.zeros(2, 1), method  # sin(theta2), the Coriolis terms
        assert (raw.f - forcing).expand() != sp.zeros(2, 1), method
    text = derive(SYSTEMS_DIR / "double_pendulum.yaml")
    assert "(m1*l1**2/3 + m2*(l2**2 + 4*l1**2 + 4*l1*l2*cos(theta2))/4 + m2*l2**2/12)*der(der(theta1))" in text
    assert "der(der(theta2)) = -g*l2*m2*sin(theta1 + theta2)/2 + " in text


def test_products_are_multiplied_out_for_the_formulas_alone_only_in_equations_printed_inline(monkeypatch):
    """A product of sums whose multiplied-out form only the sum and difference formulas shorten (no sin**2/cos**2
    pair) is multiplied out when the equations print inline (below printing.AUTO_NODES), not in equations that
    print with named subexpressions, where the sums' trees do not measure the text."""
    x, y, a, b, v, w = sp.symbols("x y a b v w")
    product_ = (a * sp.sin(x) + b * sp.sin(y)) * (a * v * sp.cos(x) + b * w * sp.cos(y))
    crossed = product_ - (a * sp.cos(x) + b * sp.cos(y)) * (a * v * sp.sin(x) + b * w * sp.sin(y))
    small = rd._Cleaner(rd._Work(10**6), angles=True)._norms(crossed)
    assert small == a * b * w * sp.sin(x - y) - a * b * v * sp.sin(x - y)  # by hand: ab (w - v) sin(x - y)
    assert rd.clean_expression(crossed) == small and rd._Cleaner(rd._Work(10**6))._norms(crossed) == crossed
    eq = load_system("four_bar").equations("kane")
    entries_ = [(n, i) for n, i in rd._entries(eq) if rd._get(eq, n, i).args]
    inline = rd.readable(eq).equations.f
    assert rd._inline(eq, entries_)
    monkeypatch.setattr("mechsys.report.printing.AUTO_NODES", 10)
    assert not rd._inline(eq, entries_)
    named = rd.readable(eq).equations.f
    assert named != inline and sum(map(rd._Cleaner(rd._Work(10**6)).size, named)) > \
        sum(map(rd._Cleaner(rd._Work(10**6)).size, inline))
    assert_exact(list(named), list(inline))


ARM = """\
name: arm3
description: A horizontal three-joint arm with point masses at the elbow, the wrist and the hand
parameters: {m1: 1.2, m2: 0.8, m3: 0.5, L1: 0.6, L2: 0.45, L3: 0.3}
coordinates:
  q1: {initial: 0.1, rate: 0}
  q2: {initial: 0.2, rate: 0}
  q3: {initial: 0.3, rate: 0}
links:
  upper:
    joint: {type: revolute, parent: ground, axis: z, coordinate: q1}
    particle: true
    mass: m1
    center_of_mass: [L1, 0, 0]
  fore:
    joint: {type: revolute, parent: upper, axis: z, coordinate: q2, origin: [L1, 0, 0]}
    particle: true
    mass: m2
    center_of_mass: [L2, 0, 0]
  hand:
    joint: {type: revolute, parent: fore, axis: z, coordinate: q3, origin: [L2, 0, 0]}
    particle: true
    mass: m3
    center_of_mass: [L3, 0, 0]
"""


def test_a_user_arms_printed_equations_are_the_closed_forms(tmp_path):
    """Point masses m_k at the tips of links L_k joined by relative angles. By hand: with the absolute angles
    th_j = q1 + ... + qj, the mass k sits at sum_(j<=k) L_j e(th_j), so its velocity's coefficient of qi' is
    sum_(i<=j<=k) L_j e'(th_j) and M_ii' = sum_k m_k sum_(j>=i, j'>=i', j,j'<=k) L_j L_j' cos(th_j - th_j'):
    cosines of relative angles only; with T = u^T M u / 2, f = dT/dq - (dM/dt) u (sympy on this M, nothing of
    mechsys). The printed M and f are those polynomials (term for term after expand), for both methods: a small
    model's products of sums are multiplied out where the sum and difference formulas make them smaller."""
    path = tmp_path / "arm3.yaml"
    path.write_text(ARM)
    model = mechsys.load(path)
    names = {s.name: s for s in model.parameter_symbols}
    m = [names[f"m{k}"] for k in (1, 2, 3)]
    L = [names[f"L{k}"] for k in (1, 2, 3)]
    th = [sum(model.q[:j + 1]) for j in range(3)]
    closed = sp.zeros(3, 3)
    for i, i2, k in itertools.product(range(3), range(3), range(3)):
        closed[i, i2] += m[k] * sum(L[j] * L[j2] * sp.cos(th[j] - th[j2])
                                    for j in range(i, k + 1) for j2 in range(i2, k + 1))
    u = sp.Matrix(model.u)
    kinetic = (u.T * closed * u)[0] / 2
    rates = closed.applyfunc(lambda e: sum(sp.diff(e, q) * w for q, w in zip(model.q, u)))
    forcing = sp.Matrix([sp.diff(kinetic, q) for q in model.q]) - rates * u
    for method in ("lagrange", "kane"):
        raw = model.equations(method)
        cleaned = rd.readable(raw).equations
        clean = cleaned.M
        assert (clean - closed).expand() == sp.zeros(3, 3), method
        assert model.q[0] not in clean.free_symbols and not any(angle_leftovers(e) for e in clean), method
        assert (cleaned.f - forcing).expand() == sp.zeros(3, 1), method
        assert_exact(list(raw.M) + list(raw.f), list(clean) + list(cleaned.f))


@pytest.mark.parametrize("method", ["lagrange", "kane"])
@pytest.mark.parametrize("name", ["double_pendulum", "four_bar"])
def test_no_angle_leftovers_in_the_printed_mass_matrices(name, method, monkeypatch):
    """The bundled models whose mass matrices the other rules leave with such pairs (the others have none)."""
    eq = load_system(name).equations(method)
    cleanup = rd.readable(eq)
    assert cleanup.note() is None
    for e in cleanup.equations.M:
        assert not angle_leftovers(e), to_text(e)
    monkeypatch.setattr(rd, "_pair_angles", lambda terms: None)
    assert any(angle_leftovers(e) for e in rd.readable(eq).equations.M)


# ------------------------------------------------------------------------ the clean-up kept in the cache
@pytest.mark.parametrize("name", ["gyrostabilizer", "rolling_disk", "slider_crank", "double_pendulum"])
def test_a_stored_clean_up_prints_what_a_fresh_one_prints_without_cleaning_again(name, tmp_path, monkeypatch):
    from mechsys.report.derive import render

    path = SYSTEMS_DIR / f"{name}.yaml"
    monkeypatch.setenv("MECHSYS_CACHE", "off")
    fresh = {(method, fmt): render(mechsys.load(path).equations(method), name, fmt)
             for method in ("lagrange", "kane") for fmt in ("text", "latex")}
    monkeypatch.setenv("MECHSYS_CACHE", str(tmp_path / "cache"))
    for round_ in range(2):
        if round_:
            monkeypatch.setattr(rd, "readable", lambda *a, **k: pytest.fail("cleaned up again"))
        for (method, fmt), text in fresh.items():
            model = mechsys.load(path)
            assert render(model.equations(method), name, fmt, model=model) == text


def test_a_stored_clean_up_that_does_not_fit_is_ignored_and_the_budget_is_in_the_key(tmp_path, monkeypatch):
    from mechsys.numeric import cache

    monkeypatch.setenv("MECHSYS_CACHE", str(tmp_path / "cache"))
    model = load_system("gyrostabilizer")
    eq = model.equations("lagrange")
    first = rd.stored_readable(model, eq)
    assert rd.stored_readable(model, eq, budget=10).left_as_derived > 0  # another budget: cleaned anew
    damaged = 0
    for entry in tmp_path.joinpath("cache").glob("*.json"):
        data = cache.load(entry.stem)
        if data is not None and "counts" in data:
            cache.store(entry.stem, {**data, "counts": [1, 2]})  # damaged: the clean-up runs again
            damaged += 1
    assert damaged == 2  # the default budget's entry and budget 10's
    again = rd.stored_readable(load_system("gyrostabilizer"), eq)
    assert entries(again.equations) == entries(first.equations) and again.entries == first.entries


def test_sum_factors_shared_by_many_products_are_tidied_once(monkeypatch):
    """A chain's mass-matrix entries are products of the same few sums: each sum factor's numbers and signs are
    worked out once per clean-up (tidy_signs's memo), and the result is the one without the memo."""
    from mechsys.report import readable as rd

    x = sp.symbols("x0:6")
    sums = [-2 * sp.sin(x[k]) - 2 * sp.cos(x[k + 1]) - x[k + 2] for k in range(4)]
    entries = [sp.Symbol("m") * a * b for a in sums for b in sums]
    expected = [rd.tidy_signs(e) for e in entries]
    calls = []
    real = rd._tidy_factor
    monkeypatch.setattr(rd, "_tidy_factor", lambda f: calls.append(f) or real(f))
    cleaner = rd._Cleaner(rd._Work(10**6), norms=False)
    got = [cleaner.clean(e) for e in entries]
    assert calls and len(calls) == len(set(calls))  # no factor tidied twice
    assert got == expected


def test_the_readable_form_does_not_change_with_the_process(tmp_path):
    """Three `derive` processes whose string hashing differs (PYTHONHASHSEED: the order of every set of sympy
    expressions) print the same bicycle: the unit-vector norms drop the multiplied-out products in the sum's
    order. Before, they were dropped in a set's order and the printed equations changed from run to run."""
    import os
    import subprocess
    import sys

    outputs = set()
    for seed in ("1", "2", "3"):
        env = dict(os.environ, PYTHONHASHSEED=seed, MECHSYS_CACHE=str(tmp_path / f"cache{seed}"))
        run = subprocess.run([sys.executable, "-m", "mechsys", "derive", str(SYSTEMS_DIR / "bicycle.yaml")],
                             capture_output=True, text=True, env=env, timeout=300)
        assert run.returncode == 0, run.stderr
        outputs.add(run.stdout)
    assert len(outputs) == 1


def test_a_stored_clean_up_holds_only_the_entries_it_changed(tmp_path, monkeypatch):
    """The cache keeps the changed entries only (the rest are the derived ones): with a budget that runs out,
    fewer than all; read back, the clean-up and its counts equal a fresh one's."""
    from mechsys.numeric import cache

    monkeypatch.setenv("MECHSYS_CACHE", str(tmp_path / "cache"))
    model = load_system("gyrostabilizer")
    eq = model.equations("lagrange")
    fresh = rd.readable(eq, budget=100)
    first = rd.stored_readable(model, eq, budget=100)
    assert fresh.left_as_derived > 0 and entries(first.equations) == entries(fresh.equations)
    [data] = [d for e in tmp_path.joinpath("cache").glob("*.json") if (d := cache.load(e.stem)) and "counts" in d]
    changed = [k for k, (a, b) in enumerate(zip(rd._flat(fresh.equations), rd._flat(eq))) if a != b]
    assert data["changed"] == changed and 0 < len(changed) < len(rd._flat(eq))
    monkeypatch.setattr(rd, "readable", lambda *a, **k: pytest.fail("cleaned up again"))
    again = rd.stored_readable(load_system("gyrostabilizer"), load_system("gyrostabilizer").equations("lagrange"),
                               budget=100)
    assert entries(again.equations) == entries(fresh.equations)
    assert (again.entries, again.left_as_derived, again.spent) == (fresh.entries, fresh.left_as_derived, fresh.spent)


def test_a_sum_divided_by_its_content_is_the_sum_sympy_builds():
    """_divided builds the divided sum's terms itself (each coefficient divided once, products assembled directly)
    and only re-sorts them: the result must be the very Add of the divided terms (args in order), for rational and
    float coefficients, terms with and without a product, a numeric term, and divisions to 1 and -1."""
    x, y, z, l = sp.symbols("x y z l")
    rng = random.Random(7)
    parts = [x, l * sp.cos(x), l * sp.sin(x + y) * z, sp.cos(y) ** 2, y * z, sp.sin(z)]
    coefficients = [sp.Integer(1), sp.Integer(-1), sp.Rational(1, 2), sp.Rational(-1, 2), sp.Integer(2),
                    sp.Rational(-3, 4), sp.Float(1.5)]
    for _ in range(300):
        chosen = rng.sample(parts, rng.randrange(2, len(parts) + 1))
        terms = [rng.choice(coefficients) * p for p in chosen] + ([sp.Rational(3, 2)] if rng.random() < 0.3 else [])
        base = sp.Add(*terms)
        split = [t.as_coeff_Mul() for t in base.args]
        for number in (sp.Rational(1, 2), sp.Rational(-1, 2), sp.Integer(-1), sp.Rational(3, 4)):
            got = rd._divided(base, split, number)
            want = sp.Add(*[c / number * rest for c, rest in split])
            assert got == want and got.args == want.args, (base, number)


# ------------------------------------------------------------------- the norms' trials, class by class
def _whole_trials(monkeypatch) -> None:
    """Every norms trial built as the whole sum (the reference the signature classes must reproduce)."""
    monkeypatch.setattr(rd._Classes, "of", classmethod(lambda cls, *args: None))


def _cleaned(eq: Equations) -> tuple:
    cleanup = rd.readable(eq)
    return cleanup.spent, cleanup.partly_cleaned, [sp.srepr(e) for e in entries(cleanup.equations)]


@pytest.mark.parametrize("name", ["chain", "rolling_disk", "gyrostabilizer", "wheel_on_axle"])
def test_the_norms_trials_by_signature_class_give_what_the_whole_sums_give(name, tmp_path, monkeypatch):
    """_Classes computes a norms trial class by class (pythagoras never joins terms of different signatures);
    the clean-up must be the one of whole-sum trials: the same expressions (srepr) and the same visits."""
    model = mechsys.load(chain_file(6, tmp_path)) if name == "chain" else load_system(name)
    used = []
    real = rd._Classes.of.__func__
    monkeypatch.setattr(rd._Classes, "of", classmethod(lambda cls, *a: used.append(1) or real(cls, *a)))
    for method in ("kane", "lagrange"):
        eq = model.equations(method)
        by_class = _cleaned(eq)
        with monkeypatch.context() as whole:
            _whole_trials(whole)
            assert _cleaned(eq) == by_class, method
    assert used  # the split was taken


def test_random_sums_give_the_same_norms_by_class_and_whole(monkeypatch):
    """Sums of squared and multiplied small trigonometric sums, with rational and float coefficients, cofactors
    and plain terms: each sum's norms the same by class as whole (float coefficients add in Add.flatten's order),
    and the split taken in most of them."""
    a, b, c, s, m, x, y = sp.symbols("a b c s m x y")
    rng = random.Random(3)
    trig = [sp.cos(x), sp.sin(x), sp.cos(y), sp.sin(y), sp.cos(x + y), sp.sin(x + y)]
    cofactors = [sp.Integer(1), a, c, s, m * a]
    numbers = [sp.Integer(1), sp.Integer(-1), sp.Rational(1, 2), sp.Integer(2), sp.Float(0.1), sp.Float(-0.3)]

    def small_sum():
        return sp.Add(*(rng.choice(numbers) * rng.choice(cofactors) * f for f in rng.sample(trig, rng.randint(2, 3))))

    def term():
        kind = rng.randrange(4)
        if kind == 0:
            return rng.choice(numbers) * rng.choice(cofactors) * small_sum() ** 2
        if kind == 1:
            return rng.choice(numbers) * rng.choice(cofactors) * small_sum() * small_sum()
        if kind == 2:
            return rng.choice(numbers) * rng.choice(cofactors) * rng.choice(trig) ** 2
        return rng.choice(numbers) * rng.choice(cofactors) * rng.choice(trig)

    split = 0
    for _ in range(150):
        add = sp.Add(*(term() for _ in range(rng.randint(3, 7))))
        split += rd._Classes.of(add, {}, rd._Cleaner(rd._Work(10**6))) is not None if add.is_Add else 0
        got = rd._Cleaner(rd._Work(10**6))._norms(add)
        with monkeypatch.context() as whole:
            _whole_trials(whole)
            want = rd._Cleaner(rd._Work(10**6))._norms(add)
        assert sp.srepr(got) == sp.srepr(want), add
    assert split > 75


def test_every_trial_by_class_is_the_whole_trial():
    """Every subset of multiplied-out products of random sums whose like terms meet from several products with
    float coefficients (added in Add.flatten's order, which is not associative): the same trial by class as whole
    (None or not, the size, the expression) and the size that of the expression."""
    a, x, y = sp.symbols("a x y")
    rng = random.Random(11)
    floats = [sp.Float(v) for v in (0.1, 0.3, -0.3)]
    trig = [sp.cos(x), sp.sin(x), sp.cos(y)]
    c, s = sp.symbols("c s")
    norm = (c * sp.cos(y) - s * sp.sin(y)) ** 2 + (c * sp.sin(y) + s * sp.cos(y)) ** 2
    unit = (sp.cos(x) * sp.cos(y) - sp.sin(x) * sp.sin(y)) ** 2 + (sp.cos(x) * sp.sin(y) + sp.sin(x) * sp.cos(y)) ** 2
    fixed = [unit, norm - c ** 2 - s ** 2, norm - s ** 2]  # results of one term and of none

    def small():
        return sp.Add(*(rng.choice(floats) * f for f in rng.sample(trig, 2)))

    def random_sum():
        terms = [rng.choice([1, a]) * rng.choice(floats) * small() ** 2 for _ in range(3)]
        return sp.Add(*terms, *(rng.choice([1, a]) * rng.choice(floats) * rng.choice(trig) ** 2 for _ in range(3)))

    compared = 0
    for add in fixed + [random_sum() for _ in range(150)]:
        cleaner = rd._Cleaner(rd._Work(10**6))
        expanded = {t: cleaner._products(t) for t in add.args if 1 < cleaner._count(t) <= rd._NORM_PRODUCTS}
        by_class = rd._Classes.of(add, expanded, cleaner)
        if by_class is None:
            continue
        whole = rd._Whole(add, expanded, cleaner)
        for k in range(len(expanded) + 1):
            for chosen in itertools.combinations(expanded, k):
                got, want = by_class.result(set(chosen)), whole.result(set(chosen))
                assert (got is None) == (want is None), (add, chosen)
                if got is not None:
                    assert sp.srepr(got.expr()) == sp.srepr(want.expr()), (add, chosen)
                    assert got.size == want.size == cleaner.size(got.expr())
                    compared += 1
    assert compared > 50


def test_a_lone_sum_cofactor_takes_the_whole_sums(monkeypatch):
    """(a + b)*sin(y)**2 + (a + b)*cos(y)**2 gives 1*(a + b), which Add spreads into a and b: terms of other
    signatures (here those of -a and -b, which they cancel). Such a sum is not split (split anyway, its classes'
    sizes would be wrong and the norms left out)."""
    a, b, x, y = sp.symbols("a b x y")
    add = (a + b) * (sp.sin(x) + sp.sin(y)) ** 2 + (a + b) * (sp.sin(x) + sp.cos(y)) ** 2 - a - b
    cleaner = rd._Cleaner(rd._Work(10**6))
    expanded = {t: cleaner._products(t) for t in add.args if cleaner._count(t) > 1}
    assert rd._Classes.of(add, expanded, cleaner) is None
    want = sp.Add(*(sp.Mul(2, a + b, f) for f in (sp.sin(x) ** 2, sp.sin(x) * sp.sin(y), sp.sin(x) * sp.cos(y))))
    assert cleaner._norms(add) == want
    monkeypatch.setattr(rd, "_lone_sum", lambda signature: False)
    assert rd._Cleaner(rd._Work(10**6))._norms(add) != want


# ------------------------------------------------------------------- tidy_signs's products built directly
@pytest.mark.parametrize("name", ["chain", "rolling_disk", "gyrostabilizer", "four_bar"])
def test_the_products_tidy_signs_builds_are_sympys(name, tmp_path, monkeypatch):
    """_product builds Mul(coeff, *factors) itself where Mul's flatten would only multiply numbers and sort: on
    every product a clean-up tidies (both methods), the very Mul sympy builds (srepr, args in order)."""
    model = mechsys.load(chain_file(8, tmp_path)) if name == "chain" else load_system(name)
    real = rd._product
    built = []

    def checked(coeff, factors):
        got = real(coeff, factors)
        if got is not None:
            want = sp.Mul(coeff, *factors)
            assert sp.srepr(got) == sp.srepr(want) and got.args == want.args, (coeff, factors)
            built.append(got)
        return got

    monkeypatch.setattr(rd, "_product", checked)
    for method in ("kane", "lagrange"):
        rd.readable(model.equations(method))
    assert built


def test_products_that_flatten_would_change_go_to_sympys_mul():
    """A float coefficient, one sum left (a number distributes over it), two factors on one base, a numeric
    power, and the plain cases: _product declines the first four, and tidy_signs gives sympy's Mul every time."""
    a, b, x, m = sp.symbols("a b x m")
    declined = [(sp.Integer(2), [sp.Float(0.5), x, a + b]), (sp.Integer(2), [a + b]),
                (sp.Integer(3), [a + b, (a + b) ** 2, x]), (sp.Integer(2), [sp.sqrt(2), x, m])]
    for coeff, factors in declined:
        assert rd._product(coeff, factors) is None
    built = rd._product(sp.Rational(1, 2), [sp.Integer(-4), m, a + b, sp.cos(x) ** 2])
    want = sp.Mul(sp.Rational(1, 2), sp.Integer(-4), m, a + b, sp.cos(x) ** 2)
    assert built is not None and sp.srepr(built) == sp.srepr(want) and built.args == want.args
    for expr in (m * sp.Float(0.5) * (-2 * a - 2 * b) * x, m * (2 * a + 2 * b) ** 2 * (-a - b),
                 m * sp.sqrt(2) * (-2 * a - 2 * b), x * (4 * a - 2 * b) / 3):
        tidy = rd.tidy_signs(expr)
        assert sp.srepr(tidy) == sp.srepr(sp.Mul(*sp.Mul.make_args(tidy))) and sp.simplify(tidy - expr) == 0
