"""`derive --subexpressions named`: subexpressions that several entries share printed once, as z1, z2, ...

The check is independent of mechsys: the JSON's definitions and entries are read back (the YAML expression parser,
numbers for every name) and compared with M and f from plain sympy Lagrangians (tests/reference_mechanics.py, and
a chain of rods whose Lagrangian tests/test_codegen_jacobian.py writes by hand). The text and LaTeX forms carry
the same definitions; `auto` leaves every textbook system's output as it was and names the bicycle's."""
from __future__ import annotations

import json
import re

import numpy as np
import pytest
import sympy as sp
from typer.testing import CliRunner

import mechsys
from helpers import SYSTEMS_DIR
from mechsys.cli import app
from mechsys.model.expressions import parse_expression
from mechsys.report.derive import render
from mechsys.report.printing import SubexpressionNames, naming, to_latex, to_text
from test_codegen_jacobian import reference_case


def run_cli(*args: str):
    result = CliRunner().invoke(app, [str(a) for a in args])
    result.returncode, result.stderr_text = result.exit_code, result.output
    return result


def _numbers(data: dict, model, q: np.ndarray, u: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """M and f of a `derive -f json` output at (q, u), every subexpression evaluated in order from the text."""
    values = {name: sp.Float(v, 30) for name, v in model.parameters.items()}
    values.update({c: sp.Float(x, 30) for c, x in zip(data["coordinates"], q)})
    rates = {c: sp.Float(x, 30) for c, x in zip(data["coordinates"], u)}
    values["t"] = sp.Float(0)
    for name, text in data.get("subexpressions", {}).items():
        assert name not in values, f"{name} is also a name of the model"
        values[name] = sp.Float(parse_expression(text, values, rates).evalf(30), 30)

    def value(text: str) -> float:
        return float(parse_expression(text, values, rates).evalf(30))

    M = np.array([[value(e) for e in row] for row in data["mass_matrix"]])
    f = np.array([value(e) for e in data["forcing"]])
    return M, f


def _case(name: str, tmp_path):
    path, names, M, f, q, u = reference_case(name, tmp_path)
    return path, names, sp.lambdify((*q, *u), M, "numpy"), sp.lambdify((*q, *u), f, "numpy")


@pytest.mark.parametrize("method", ["lagrange", "kane"])
@pytest.mark.parametrize("case", ["chain", "furuta", "zxz"])
def test_named_json_reads_back_to_the_reference_equations(case, method, tmp_path):
    path, names, ref_M, ref_f = _case(case, tmp_path)
    out = run_cli("derive", str(path), "--method", method, "-f", "json", "--subexpressions", "named")
    assert out.returncode == 0, out.stderr_text
    data = json.loads(out.stdout)
    if case == "chain":
        assert len(data["subexpressions"]) > 5, "nothing shared was named"
    model = mechsys.load(path)
    order = [data["coordinates"].index(n) for n in names]  # reference index -> printed index
    n = len(names)
    rng = np.random.default_rng(31)
    for _ in range(3):
        q, u = rng.uniform(-2, 2, n), rng.uniform(-3, 3, n)
        M, f = _numbers(data, model, q, u)
        want_M = np.asarray(ref_M(*q[order], *u[order]), dtype=float)
        want_f = np.asarray(ref_f(*q[order], *u[order]), dtype=float).ravel()
        scale = max(1.0, float(np.abs(want_f).max()))
        np.testing.assert_allclose(M[np.ix_(order, order)], want_M, rtol=1e-12, atol=1e-12)
        # Lagrange's f is the reference's; Kane's differs by the potential forces' form only, not in value
        np.testing.assert_allclose(f[order], want_f, rtol=0, atol=1e-11 * scale)


def test_named_json_is_the_derived_equations_on_the_bicycle():
    """The bicycle's inline entries are longer than the expression parser reads (4,000 characters); named, each
    definition and entry reads back, and their values are the derived M and f."""
    path = SYSTEMS_DIR / "bicycle.yaml"
    model = mechsys.load(path)
    named = json.loads(run_cli("derive", str(path), "--method", "kane", "-f", "json",
                               "--subexpressions", "named").stdout)
    assert len(named["subexpressions"]) > 100
    eq = model.equations("kane")
    rng = np.random.default_rng(4)
    q, u = rng.uniform(-1, 1, 9), rng.uniform(-1, 1, 9)
    point = {s: v for s, v in zip([*eq.q, *eq.u], [*q, *u])}
    point.update({s: model.parameters[s.name] for s in model.parameter_symbols})
    point[model.t] = 0.0
    args = list(point)
    want_M = np.asarray(sp.lambdify(args, eq.M, cse=True)(*point.values()), dtype=float)
    want_f = np.asarray(sp.lambdify(args, eq.f, cse=True)(*point.values()), dtype=float).ravel()
    M, f = _numbers(named, model, q, u)
    np.testing.assert_allclose(M, want_M, rtol=1e-12, atol=1e-12)
    np.testing.assert_allclose(f, want_f, rtol=1e-12, atol=1e-12 * max(1.0, np.abs(want_f).max()))


@pytest.mark.parametrize("fmt", ["text", "markdown", "latex", "json"])
@pytest.mark.parametrize("path", sorted(SYSTEMS_DIR.glob("*.yaml")), ids=lambda p: p.stem)
def test_auto_is_inline_on_the_textbook_systems_and_named_on_the_bicycle(path, fmt):
    model = mechsys.load(path)
    eq = model.equations("kane")
    auto = render(eq, model.name, fmt, subexpressions="auto")
    named = render(eq, model.name, fmt, subexpressions="named")
    inline = render(eq, model.name, fmt, subexpressions="inline")
    if path.stem == "bicycle" and fmt != "json":
        assert auto == named != inline
        assert len(auto) < 0.1 * len(inline)
    else:
        assert auto == inline


def test_the_text_defines_each_name_once_before_no_use_and_uses_every_name(tmp_path):
    out = run_cli("derive", str(SYSTEMS_DIR / "bicycle.yaml"), "--subexpressions", "named")
    assert out.returncode == 0, out.stderr_text
    head, where = out.stdout.split("where (subexpressions that several entries share, each printed once):\n")
    lines = where.splitlines()
    defined = [line.split(" = ", 1)[0].strip() for line in lines]
    assert defined == [f"z{k}" for k in range(1, len(defined) + 1)]
    for k, line in enumerate(lines):  # a definition uses only names defined before it
        used = {int(x) for x in re.findall(r"\bz(\d+)\b", line.split(" = ", 1)[1])}
        assert all(j <= k for j in used), line
    used_anywhere = {int(x) for x in re.findall(r"\bz(\d+)\b", head + "\n".join(x.split(" = ", 1)[1] for x in lines))}
    assert used_anywhere == set(range(1, len(defined) + 1))  # no name defined and never used


def test_a_subexpression_is_named_when_shared_and_long_enough():
    x, y, a, b, c = sp.symbols("x y a b c")
    long = a * sp.cos(x + y) + b * sp.sin(x - y) + c  # 29 characters
    short = sp.cos(x)
    names = SubexpressionNames([long * a + short, long ** 2 * short, b])
    with naming(names):
        assert names.definitions == [long]
        assert to_text(long * a + short) == "a*z1 + cos(x)"
        assert to_text(long ** 2 * short) == "z1**2*cos(x)"
        assert to_latex(long * b) == "b z_{1}"  # no brackets around a named sum
        assert to_text(-a * long) == "-a*z1"
    assert to_text(long * a) == "a*(c + a*cos(x + y) + b*sin(x - y))"  # outside the block: written out


def test_the_prefix_avoids_the_models_names():
    z1, zz2, x = sp.symbols("z1 zz2 x")
    shared = z1 * sp.cos(x) + zz2 * sp.sin(x) + x ** 3
    names = SubexpressionNames([shared * x, shared ** 2])
    assert names.prefix == "zzz"
    with naming(names):
        assert to_text(shared ** 2) == "zzz1**2"


def test_a_chain_too_deep_for_recursion_is_counted(tmp_path):
    """The census walks without recursion: a sum nested 5,000 deep (deeper than Python's default stack)."""
    x = sp.Symbol("x")
    e = x
    for k in range(5000):
        e = sp.Add(sp.Mul(sp.Integer(k + 2), e, evaluate=False), x, evaluate=False)
    names = SubexpressionNames([e, e])
    assert names.inline_nodes == 2 * (1 + 4 * 5000)


def test_the_kept_output_follows_the_option(tmp_path, monkeypatch):
    """`derive` keeps its printed output (report/warm.py): the option is part of the key."""
    monkeypatch.setenv("MECHSYS_CACHE", str(tmp_path / "cache"))
    path = str(SYSTEMS_DIR / "double_pendulum.yaml")
    named = run_cli("derive", path, "--subexpressions", "named").stdout
    inline = run_cli("derive", path, "--subexpressions", "inline").stdout
    again = run_cli("derive", path, "--subexpressions", "named").stdout
    assert named == again != inline
    assert "where (" in named and "where (" not in inline


@pytest.mark.parametrize("fmt", ["latex", "markdown"])
def test_latex_and_markdown_define_the_names_they_use(fmt):
    """The LaTeX forms name the same subexpressions as the text (z_{k}, the same numbers), define each once, after
    the equations, in dependency order, and use every one (a named negative product stays a name in a sum, where
    LaTeX's sum takes a term's sign out)."""
    text = run_cli("derive", str(SYSTEMS_DIR / "bicycle.yaml"), "--subexpressions", "named").stdout
    out = run_cli("derive", str(SYSTEMS_DIR / "bicycle.yaml"), "--subexpressions", "named", "-f", fmt)
    assert out.returncode == 0, out.stderr_text
    marker = "\\intertext{where}\n" if fmt == "latex" else "**where** (subexpressions that several entries share"
    head, where = out.stdout.split(marker)
    definitions = re.findall(r"^z_\{(\d+)\} &?= (.*?)(?: \\\\)?$", where, flags=re.M)
    assert [int(k) for k, _ in definitions] == list(range(1, len(definitions) + 1))
    assert len(definitions) == len(re.findall(r"^  z\d+ = ", text, flags=re.M))
    for k, body in definitions:
        assert all(int(j) < int(k) for j in re.findall(r"z_\{(\d+)\}", body)), k
    used = {int(j) for j in re.findall(r"z_\{(\d+)\}", head + "".join(b for _, b in definitions))}
    assert used == set(range(1, len(definitions) + 1))


def test_simplified_equations_read_back_in_the_model_language(tmp_path):
    """`derive --simplify` of a cart on a spring to a wall (its length |x + 1|): sympy's simplify writes the
    spring's force as Piecewise(..., Eq(x, -1)), which the model language does not have. Such an entry is printed
    as derived, so every printed expression reads back (and has the values of the plain derivation)."""
    path = tmp_path / "cart.yaml"
    path.write_text("""\
name: cart_on_a_spring
parameters: {M: 3, k: 200, c: 0.5}
coordinates: {x: {initial: 0.2}}
ground:
  points: {wall: [-1, 0, 0]}
links:
  cart:
    joint: {type: prismatic, parent: ground, axis: x, coordinate: x}
    mass: M
forces:
  - {type: spring, between: [cart, ground.wall], stiffness: k, free_length: 0.5}
  - {type: damper, between: [cart, ground.wall], coefficient: c}
""")
    r = run_cli("derive", path, "--simplify", "-f", "json")
    assert r.returncode == 0, r.stderr_text
    data = json.loads(r.stdout)
    assert "Piecewise" not in r.stdout
    model = mechsys.load(path)
    M, f = _numbers(data, model, np.array([0.2]), np.array([0.7]))
    # closed form: M x'' = -k (x + 1 - 0.5) - c x' for x > -1
    assert np.allclose(M, [[3.0]]) and np.allclose(f, [-200 * 0.7 - 0.5 * 0.7], rtol=1e-12)


def test_multipliers_take_a_name_no_parameter_has(tmp_path):
    """A four-bar whose coupler mass is called lambda1: the multipliers were printed lambda1, lambda2 beside the
    mass lambda1 (and \\lambda_{1} in LaTeX for both). They are then called mu1, mu2; without the clash, lambda."""
    text = (SYSTEMS_DIR / "four_bar.yaml").read_text().split("expect:")[0]
    path = tmp_path / "four_bar_lambda.yaml"
    path.write_text(re.sub(r"\bm3\b", "lambda1", text))
    out = run_cli("derive", path).stdout
    assert "M q'' = f + A^T mu" in out and "  mu1 [" in out and "  mu2 [" in out and "lambda1*" in out
    latex = run_cli("derive", path, "-f", "latex").stdout
    assert "\\mu_{1}" in latex
    plain = run_cli("derive", SYSTEMS_DIR / "four_bar.yaml").stdout
    assert "M q'' = f + A^T lambda" in plain and "  lambda1 [" in plain


def test_a_name_ending_in_dot_is_not_printed_as_a_rate(tmp_path):
    """A damping parameter called thetadot: sympy's LaTeX writes it \\dot{\\theta}, the rate der(theta)'s, so
    thetadot*der(theta) read as a square. It is printed upright as written; the rate keeps its dot."""
    path = tmp_path / "pendulum.yaml"
    path.write_text("""\
name: damped
parameters: {m: 1, l: 1, g: 9.81, thetadot: 0.3}
coordinates: {theta: {initial: 0.1}}
links:
  rod:
    joint: {type: revolute, parent: ground, axis: z, coordinate: theta}
    mass: m
    center_of_mass: [0, -l, 0]
forces:
  - {type: gravity, acceleration: [0, -g, 0]}
  - {type: generalized_force, coordinate: theta, value: -thetadot*der(theta)}
""")
    latex = run_cli("derive", path, "-f", "latex").stdout
    assert "\\dot{\\theta} \\mathrm{thetadot}" in latex and "\\dot{\\theta} \\dot{\\theta}" not in latex


def test_names_sympy_would_print_alike_are_printed_as_written(tmp_path):
    """Parameters l2 and l_2 (and alpha1, alpha_1) are both l_{2} (\\alpha_{1}) in sympy's LaTeX, so an equation
    with both read as one symbol. Such names are printed upright as written, in LaTeX and Markdown; a name without
    a twin keeps sympy's form (l_{3}, theta's \\theta). A parameter z_7 printed like the subexpression z7: the
    subexpressions then take another prefix."""
    path = tmp_path / "twins.yaml"
    path.write_text("""\
name: twins
parameters: {m: 1, l2: 0.5, l_2: 0.3, l3: 0.2, alpha1: 0.1, alpha_1: 0.2, g: 9.81}
coordinates: {theta: {initial: 0.1}, phi: {initial: 0.2}}
links:
  upper:
    joint: {type: revolute, parent: ground, axis: z, coordinate: theta}
    mass: m
    center_of_mass: [0, -l2, 0]
  lower:
    joint: {type: revolute, parent: upper, axis: z, coordinate: phi, origin: [0, -l_2 - l3, 0]}
    mass: m
    center_of_mass: [0, -l2, 0]
forces:
  - {type: gravity, acceleration: [0, -g, 0]}
  - {type: generalized_force, coordinate: phi, value: -alpha1*der(phi) - alpha_1*der(theta)}
""")
    for fmt in ("latex", "markdown"):
        out = run_cli("derive", path, "-f", fmt).stdout
        assert "\\mathrm{l2}" in out and "\\mathrm{l\\_2}" in out and "l_{2}" not in out
        assert "\\mathrm{alpha1}" in out and "\\mathrm{alpha\\_1}" in out and "\\alpha_{1}" not in out
        assert "l_{3}" in out and "\\dot{\\theta}" in out
    plain = run_cli("derive", SYSTEMS_DIR / "four_bar.yaml", "-f", "latex").stdout
    assert "l_{2}" in plain and "\\mathrm" not in plain
    shared = tmp_path / "shared.yaml"
    shared.write_text(path.read_text().replace("l3", "z_1"))
    named = run_cli("derive", shared, "-f", "latex", "--subexpressions", "named").stdout
    assert "z_{1}" in named and "zz_{1}" in named
