"""Steady motions and linearization of nonholonomic systems (issue 12): the rolling disk of the textbook and a
rim-heavy wheel written for these tests, against the independent derivation of tests/reference_nonholonomic.py
(Kane's method by hand, no mechsys import); CLI behaviour and input errors."""
from __future__ import annotations

import functools
import json
import math
import sys
from pathlib import Path

import numpy as np
import pytest
from typer.testing import CliRunner

from mechsys.analysis.equilibrium.equilibria import SteadyOptions, find_equilibria, make_problem
from mechsys.analysis.equilibrium.nonholonomic import NonholonomicProblem, linearize_steady
from mechsys.cli import app

sys.path.insert(0, str(Path(__file__).parent))
import reference_nonholonomic as ref  # noqa: E402
from helpers import DATA_DIR, SYSTEMS_DIR, load_data, load_system  # noqa: E402

runner = CliRunner()
DISK = SYSTEMS_DIR / "rolling_disk.yaml"
WHEEL = DATA_DIR / "nonholonomic" / "wheel.yaml"
G = 9.81


@functools.lru_cache(maxsize=None)
def cli_json(*args: str) -> dict:
    result = runner.invoke(app, [str(a) for a in args] + ["-f", "json"])
    assert result.exit_code == 0, result.output
    return json.loads(result.stdout)


def eig(e: dict) -> np.ndarray:
    return np.sort_complex(np.array([complex(a, b) for a, b in e["eigenvalues"]]))


def upright(eqs: dict) -> dict:
    (e,) = [e for e in eqs["equilibria"] if abs(e["coordinates"]["lean"]) < 1e-9]
    return e


# --------------------------------------------------------------------------------------------- upright rolling
@pytest.mark.parametrize("v", [0.5, 0.98, 1.0, 2.0, 4.0])
def test_thin_disk_upright_lean_roots_equal_the_reference(v):
    """Thin disk (m = 2, r = 0.3): the two lean roots of upright rolling at speed v equal
    s^2 = [m g r - Ia (Ia + m r^2) v^2 / (Id r^2)] / (Id + m r^2) with Ia = m r^2/2, Id = m r^2/4; the zeros of
    x, y, yaw, spin and of the two families (der(yaw), der(spin)) are reported apart."""
    m, r = 2.0, 0.3
    out = cli_json("equilibria", DISK, "--set", "lean=0", "--set", "der(yaw)=0", "--set", f"der(spin)={v / r!r}",
                   "--search", "lean=-1:1")
    e = upright(out)
    want = ref.wheel_upright_eigenvalues(m, r, m * r * r / 2, m * r * r / 4, G, v)
    assert np.allclose(eig(e), want, rtol=1e-10, atol=1e-12)
    assert e["stability"] == ("unstable" if v < ref.thin_disk_critical_speed(r, G) else "stable")
    assert "x, y, yaw, spin" in e["structural_zeros"] and "der(yaw), der(spin)" in e["structural_zeros"]
    assert out["formulation"].startswith("independent speeds der(yaw), der(lean), der(spin)")


def test_thin_disk_critical_speed_from_the_sweep():
    """v_c = sqrt(g r / 3) for a thin disk: the sweep of the spin rate finds the zero eigenvalue there."""
    r = 0.3
    out = cli_json("equilibria", DISK, "--set", "lean=0", "--set", "der(yaw)=0", "--search", "lean=-0.5:0.5",
                   "--sweep", "der(spin)=2:5:31")
    (bif,) = [b for b in out["bifurcations"] if b["kind"] == "zero_eigenvalue"]
    assert bif["value"] * r == pytest.approx(ref.thin_disk_critical_speed(r, G), rel=1e-8)


def test_rim_heavy_wheel_critical_speed_and_roots():
    """General axisymmetric wheel (Ia = 0.8 m r^2, Id = 0.45 m r^2): v_c = r sqrt(m g r Id / (Ia (Ia + m r^2)));
    roots at v = 3 and the stability change across v_c, through the parameter v of the file (its rates follow)."""
    m, r = 1.5, 0.35
    Ia, Id = 0.8 * m * r * r, 0.45 * m * r * r
    vc = ref.wheel_critical_speed(m, r, Ia, Id, G)
    e = upright(cli_json("equilibria", WHEEL, "--search", "lean=-1:1"))
    assert np.allclose(eig(e), ref.wheel_upright_eigenvalues(m, r, Ia, Id, G, 3.0), rtol=1e-10)
    out = cli_json("equilibria", WHEEL, "--search", "lean=-0.5:0.5", "--sweep", "v=0.2:3:29")
    (bif,) = [b for b in out["bifurcations"] if b["kind"] == "zero_eigenvalue"]
    assert bif["value"] == pytest.approx(vc, rel=1e-8)


# --------------------------------------------------------------------------------------------- steady turning
@pytest.mark.parametrize("lean, roots", [(0.3, 2), (-0.3, 2), (-0.7, 0)])
def test_steady_turning_at_a_given_lean_gives_both_yaw_rates(lean, roots):
    """--given lean --solve der(yaw): both roots of (Ia + m r^2 - Id) sin cos psi'^2 + (Ia + m r^2) cos phi' psi'
    + m g r sin = 0 (the thin disk at spin rate 1/r); none where its discriminant is negative (lean -0.7)."""
    m, r = 2.0, 0.3
    out = cli_json("equilibria", DISK, "--set", f"lean={lean}", "--given", "lean", "--solve", "der(yaw)")
    got = sorted(e["rates"]["yaw"] for e in out["equilibria"])
    want = ref.steady_turning_yaw_rates(m, r, m * r * r / 2, m * r * r / 4, G, lean, 1 / r)
    assert len(want) == roots and len(got) == roots and np.allclose(got, want, rtol=1e-10)
    if not roots:
        assert out["message"].startswith("no equilibrium found")
    for e in out["equilibria"]:
        assert e["coordinates"]["lean"] == lean
        assert "lean" in e["structural_zeros"]  # the family along the given lean is deflated too


def test_steady_turning_lean_from_the_file_rates():
    """Default: the rates of the ignorable coordinates are the file's (yaw 0.5 rad/s, spin 1/r); the leans that
    make them a steady turn satisfy the steady-turning condition."""
    m, r = 2.0, 0.3
    out = cli_json("equilibria", DISK)
    assert out["equilibria"]
    for e in out["equilibria"]:
        res = ref.steady_turning_residual(m, r, m * r * r / 2, m * r * r / 4, G, e["coordinates"]["lean"], 1 / r, 0.5)
        assert abs(res) < 1e-10


def test_a_steady_turn_simulated_keeps_its_lean():
    """The steady turn found by equilibria, integrated by simulate (another code path), keeps its lean."""
    out = cli_json("equilibria", DISK, "--set", "lean=0.3", "--given", "lean", "--solve", "der(yaw)")
    e = out["equilibria"][0]
    sets = [f"lean={e['coordinates']['lean']!r}"] + [f"der({c})={v!r}" for c, v in e["rates"].items()]
    args = ["simulate", DISK, "--t-end", "2", "--dt", "0.5"] + [x for s in sets for x in ("--set", s)]
    summary = cli_json(*args)["simulation summary"]
    assert abs(summary["lean(t_end)"] - 0.3) < 1e-8 and abs(summary["der(lean)(t_end)"]) < 1e-8


# --------------------------------------------------------------------------------------------- formulations
def test_lagrange_and_kane_linearizations_agree():
    model = load_system("rolling_disk", {"lean": 0.2})
    eqs = {}
    for method in ("kane", "lagrange"):
        problem = NonholonomicProblem(model, method=method)
        res = find_equilibria(model)
        e = min(res.equilibria, key=lambda e: abs(e.coordinates["lean"]))
        lin = linearize_steady(problem, e)
        eqs[method] = lin
    a, b = eqs["kane"], eqs["lagrange"]
    assert np.allclose(a.jacobian, b.jacobian, rtol=1e-10, atol=1e-12)
    assert np.allclose(a.M, b.M, rtol=1e-12) and np.allclose(a.K, b.K, rtol=1e-10, atol=1e-12)


@pytest.mark.parametrize("name, method", [("rolling_disk", "kane"), ("rolling_disk", "lagrange")])
def test_the_saddle_residuals_are_the_matrix_products(name, method):
    """R = M a - f - A^T lambda and S = A a - b built entry by entry are sympy's matrix expressions (srepr; the
    bicycle's Kane form too, checked once by hand: 16 s of derivation and matrix products, too slow for the suite)."""
    import sympy as sp

    from mechsys.analysis.equilibrium.nonholonomic import saddle_residuals

    model = load_system(name)
    eq = model.equations(method)
    lam = sp.symbols(f"lam0:{eq.A.shape[0]}")
    R, S = saddle_residuals(eq.M, eq.f, eq.A, eq.b, model.a, lam)
    a = sp.Matrix(model.a)
    expected = list(eq.M * a - eq.f - eq.A.T * sp.Matrix(lam)) + list(eq.A * a - eq.b)
    assert len(R + S) == len(expected) and all(sp.srepr(x) == sp.srepr(y) for x, y in zip(R + S, expected))


def test_the_continuations_eigenvalues_are_those_of_the_deflated_pencil():
    """A sweep reads the eigenvalues the linearization computed (no second eigensolve of the pencil (A, I))."""
    from mechsys.analysis.equilibrium.stability import eigen, pencil_eigenvalues, reduced_pencil

    model = load_system("rolling_disk", {"lean": 0.2})
    res = find_equilibria(model)
    assert res.equilibria
    for e in res.equilibria:
        A, B, _ = reduced_pencil(res.problem, e)
        assert np.allclose(pencil_eigenvalues(res.problem, e), eigen(A, B)[0], rtol=1e-12, atol=1e-12)


def test_steady_problem_split_is_reported_and_structural():
    model = load_data("nonholonomic/wheel")
    problem = make_problem(model)
    assert problem.split.dependent == ["x", "y"]
    assert problem.split.ignorable == ["x", "y", "yaw", "spin"]
    assert problem.fixed_rates == {"yaw": 0.0, "spin": pytest.approx(3.0 / 0.35)}


# --------------------------------------------------------------------------------------------- CLI and errors
def test_independent_coordinates_that_couple_get_kanes_form_with_a_note():
    result = runner.invoke(app, ["equilibria", str(DISK), "--set", "lean=0", "--set", "der(yaw)=0", "--search",
                                 "lean=-1:1", "--independent", "lean", "--linearize"])
    assert result.exit_code == 0, result.output
    assert "the equations of lean involve der(yaw) at this steady motion: no second-order form" in \
        " ".join(result.stdout.split())
    assert "Kane's generalized mass" in result.stdout


def test_modes_of_a_rolling_wheel():
    out = cli_json("modes", WHEEL, "--at", "lean=0")
    m, r = 1.5, 0.35
    want = ref.wheel_upright_eigenvalues(m, r, 0.8 * m * r * r, 0.45 * m * r * r, G, 3.0)
    (mode,) = out["modes"]
    assert mode["frequency_rad_s"] == pytest.approx(abs(want[0]), rel=1e-10)
    assert mode["shape"] == {"lean": 1.0}


@pytest.mark.parametrize("args, message, code", [
    (["equilibria", DISK, "--given", "tilt"], "--given tilt: unknown coordinate", 2),
    (["equilibria", DISK, "--given", "yaw"], "--given yaw: yaw is ignorable", 2),
    (["equilibria", DISK, "--solve", "der(lean)"], "--solve der(lean): not the independent rate", 2),
    (["equilibria", SYSTEMS_DIR / "double_pendulum.yaml", "--given", "theta1"], "this model is holonomic", 2),
    (["equilibria", DISK, "--verify"], "--verify is not available for nonholonomic", 2),
    (["modes", DISK, "--frf", "1:2:3"], "a nonholonomic steady motion has none", 2),
])
def test_input_errors_are_one_line(args, message, code):
    result = runner.invoke(app, [str(a) for a in args])
    assert result.exit_code == code, result.output
    lines = [line for line in result.output.splitlines() if line.strip()]
    assert len(lines) == 1 and message in lines[0], result.output
    assert "Traceback" not in result.output


def test_cached_pieces_equal_uncached_ones_and_skip_the_derivation(tmp_path, monkeypatch):
    """The compiled steady-motion pieces come back from the on-disk cache (no symbolic work: deriving raises) and
    give the same numbers, bit for bit, as the freshly derived ones; another structure gets another entry."""
    import mechsys
    from mechsys.analysis.equilibrium.nonholonomic import ConstrainedPieces

    monkeypatch.setenv("MECHSYS_CACHE", str(tmp_path))
    fresh = ConstrainedPieces(mechsys.load(WHEEL), "kane")
    assert list(tmp_path.glob("*.json"))
    model = mechsys.load(WHEEL)
    monkeypatch.setattr(type(model), "equations", lambda *a, **k: (_ for _ in ()).throw(AssertionError("derived")))
    cached = ConstrainedPieces(model, "kane")
    rng = np.random.default_rng(5)
    p = np.array(list(model.parameters.values()))
    for _ in range(3):
        q, u, a, lam = rng.normal(size=5), rng.normal(size=5), rng.normal(size=5), rng.normal(size=2)
        x, y = fresh.evaluate(q, u, a, lam, p), cached.evaluate(q, u, a, lam, p)
        assert all(np.array_equal(x[k], y[k]) for k in x)
    monkeypatch.undo()
    monkeypatch.setenv("MECHSYS_CACHE", str(tmp_path))
    before = set(tmp_path.glob("*.json"))
    ConstrainedPieces(mechsys.load(DISK), "kane")  # another model: another key
    assert set(tmp_path.glob("*.json")) - before


def test_compiled_pieces_are_cached_and_the_python_path_remains(tmp_path, monkeypatch):
    """With a C compiler the pieces are compiled once into the cache (a signed library whose key includes the
    source's hash) and loaded from there; MECHSYS_NATIVE=off keeps the generated Python, with the same numbers."""
    import mechsys
    from mechsys.analysis.equilibrium.nonholonomic import ConstrainedPieces
    from mechsys.numeric.native import compiler

    if compiler() is None:
        pytest.skip("no C compiler")
    monkeypatch.setenv("MECHSYS_CACHE", str(tmp_path))
    first = ConstrainedPieces(mechsys.load(WHEEL), "kane")
    libraries = list(tmp_path.glob("*.so"))
    assert first._native is not None and len(libraries) == 1
    again = ConstrainedPieces(mechsys.load(WHEEL), "kane")
    assert again._native is not None and list(tmp_path.glob("*.so")) == libraries
    monkeypatch.setenv("MECHSYS_NATIVE", "off")
    python = ConstrainedPieces(mechsys.load(WHEEL), "kane")
    assert python._native is None
    rng = np.random.default_rng(8)
    model = mechsys.load(WHEEL)
    p = np.array(list(model.parameters.values()))
    for _ in range(3):
        state = (rng.normal(size=5), rng.normal(size=5), rng.normal(size=5), rng.normal(size=2), p)
        x, y = again.evaluate(*state), python.evaluate(*state)
        assert all(np.allclose(x[k], y[k], rtol=1e-14, atol=1e-14) for k in x)
        assert np.allclose(again.residual(*state), python.residual(*state), rtol=1e-14, atol=1e-14)


def test_a_narrow_terminal_neither_cuts_nor_folds_numbers():
    """rich cut -2.542378e-17 to '-2.542…' in an 80-column table of many columns: a silently wrong number. Folded
    onto two lines instead, '-2.542' could still be read as the number. The table is now printed in blocks of
    columns that fit, each repeating the first column, every number whole on its line; the words of a text column
    wrap at spaces; a table whose first column and one more do not fit at all is printed as aligned plain text."""
    from rich.console import Console

    from mechsys.report.tables import Table, to_rich

    t = Table("branches", ["branch", "v", "lean", "pitch", "steer", "chi", "stable", "verdict"])
    t.add(1, 0.0497, -2.542378e-17, 2.645751, 8.628101e-17, -2.645751, False, "unstable (saddle)")
    console = Console(width=60, record=True)
    console.print(to_rich([t]))
    text = console.export_text()
    assert "…" not in text and max(len(line) for line in text.splitlines()) <= 60
    cells = [c.strip() for line in text.splitlines() if line.startswith("│") for c in line.split("│")[1:-1]]
    for number in ("0.0497", "-2.542378e-17", "2.645751", "8.628101e-17", "-2.645751"):
        assert number in cells, number
    headers = [line for line in text.splitlines() if line.startswith("┃")]
    assert len(headers) >= 2 and all(h.split("┃")[1].strip() == "branch" for h in headers)  # the first column again
    assert "branches [v to" in text  # each block's title names its columns
    wide = Console(width=200, record=True)
    wide.print(to_rich([t]))
    assert sum(line.startswith("┃") for line in wide.export_text().splitlines()) == 1  # fits: one table
    narrow = Console(width=20, record=True)
    narrow.print(to_rich([t]), crop=False)  # as the CLI prints (emit_tables)
    lines = narrow.export_text().splitlines()
    assert lines[0] == "branches" and lines[3].split()[:3] == ["1", "0.0497", "-2.542378e-17"]


def test_a_long_table_prints_as_aligned_text_with_every_row():
    """Thousands of sweep points print as plain aligned columns (rich measured every cell: half a minute)."""
    from rich.console import Console

    from mechsys.report.tables import LONG_TABLE, Table, to_rich

    t = Table("branches over v", ["branch", "v", "lean"])
    for k in range(LONG_TABLE + 5):
        t.add(1, k * 0.1, -2.542378e-17 * k)
    t.notes.append("a note")
    console = Console(width=200, record=True)
    console.print(to_rich([t]))
    lines = console.export_text().splitlines()
    assert lines[0] == "branches over v" and lines[1].split() == ["branch", "v", "lean"]
    assert len(lines) == 3 + LONG_TABLE + 5 + 1 and lines[-1] == "  a note"
    assert lines[-2].split() == ["1", "30.4", "-7.728829e-15"]


@pytest.mark.parametrize("to_file", [False, True])
def test_a_long_wide_table_keeps_one_line_per_row_on_a_narrow_console(capsys, monkeypatch, tmp_path, to_file):
    """Rows wider than the console (stdout piped: 80 columns; a file: 160) stay whole lines, neither folded into
    fragments nor cut (the 20-link chain's equilibria: 38,576 lines of fragments for 504 rows)."""
    from mechsys.cli import TableFormat, emit_tables
    from mechsys.report.tables import LONG_TABLE, Table

    monkeypatch.setenv("COLUMNS", "80")
    t = Table("equilibria", ["#", "coordinates", "stability"])
    for k in range(LONG_TABLE + 1):
        t.add(k + 1, [round(0.001 * k * j, 6) for j in range(30)], "an eigenvalue has a positive real part")
    out = tmp_path / "table.txt"
    emit_tables([t], TableFormat.text, out if to_file else None)
    lines = (out.read_text() if to_file else capsys.readouterr().out).splitlines()
    assert len(lines) == 3 + LONG_TABLE + 1 and max(len(line) for line in lines) > 200
    assert lines[-1].startswith(f"{LONG_TABLE + 1}  [") and lines[-1].endswith("an eigenvalue has a positive real part")


def test_a_parameter_the_residual_does_not_read_has_an_exact_zero_derivative():
    """The bicycle's speed v sets only the given rates: its generated residual reads no v, so dE/dv (what a
    speed sweep's predictor asks for) is returned as zeros without evaluating E, exactly what the central
    difference gives; g is read and its derivative is the difference as before."""
    import mechsys
    from mechsys.analysis.equilibrium import equilibria as eq
    from mechsys.numeric.parameters import parameter_values
    from tests.helpers import SYSTEMS_DIR

    model = mechsys.load(SYSTEMS_DIR / "bicycle.yaml")
    problem = eq.make_problem(model)
    p = parameter_values(model)
    names = [s.name for s in model.parameter_symbols]
    read = dict(zip(names, problem._parameters_read))
    assert not read["v"] and read["g"] and sum(read.values()) == len(names) - 1
    z = np.random.default_rng(5).uniform(-0.3, 0.3, len(problem.unknowns))
    for name in ("v", "g"):
        e = np.eye(len(p))[names.index(name)]
        h = 1e-6 * max(1.0, float(np.linalg.norm(p)))
        difference = (problem.F(z, p + h * e) - problem.F(z, p - h * e)) / (2 * h)
        assert np.array_equal(problem.Fp_along(z, p, e), difference)
        assert np.any(difference) == (name == "g")


def test_with_a_compiler_the_pieces_store_no_python_and_make_it_when_asked(tmp_path, monkeypatch):
    """A C compiler builds the stored C form, so the entry holds no Python sources (their CSE and printing were
    a sixth of a cold bicycle command); the Python functions are made when asked, agree with the library, and
    read the parameters the stored flags say (checked against the names the generated code uses)."""
    import ast

    import mechsys
    from mechsys.analysis.equilibrium.nonholonomic import ConstrainedPieces
    from mechsys.numeric import cache
    from mechsys.numeric.native import compiler

    if compiler() is None:
        pytest.skip("no C compiler")
    monkeypatch.setenv("MECHSYS_CACHE", str(tmp_path))
    model = mechsys.load(WHEEL)
    pieces = ConstrainedPieces(model, "kane")
    entry = cache.load(cache.model_key(model, "constrained-pieces-kane"))
    assert entry["source"] is None and entry["values"] is None and isinstance(entry["c"], str)
    assert pieces._native is not None
    function = ast.parse(pieces._python_text()[1]).body[0]  # made now
    used = {node.id for stmt in function.body for node in ast.walk(stmt) if isinstance(node, ast.Name)}
    first = len(function.args.args) - len(model.parameter_symbols)
    assert list(pieces.read) == [f"a{first + k}" in used for k in range(len(model.parameter_symbols))]
    rng = np.random.default_rng(2)
    p = np.array(list(model.parameters.values()))
    for _ in range(3):
        args = np.concatenate([rng.normal(size=5), rng.normal(size=5), rng.normal(size=5), rng.normal(size=2), p])
        np.testing.assert_allclose(pieces._native("mechsys_full", args), np.asarray(pieces._fn(*args), dtype=float),
                                   rtol=1e-13, atol=1e-13)
        np.testing.assert_allclose(pieces._native("mechsys_values", args),
                                   np.asarray(pieces._values(*args), dtype=float), rtol=1e-13, atol=1e-13)


@pytest.mark.parametrize("frame, key", [("", "link"), (", frame: disk", "frame")])
def test_a_contact_given_in_axes_that_spin_with_the_body_is_refused(tmp_path, frame, key):
    """The rolling disk with `frame` left out (the default: the disk itself) or set to the disk: the contact
    vector [0, 0, -r] then turns with the disk, a point of the rim whose rows pin it. It 'rolled' 0.25 m where
    the disk rolls r der(spin) t = 2 m, with exit 0; now one line at the constraint (the file's own disk, with
    its non-spinning lean frame, covers the 2 m: its `expect` in systems/rolling_disk.yaml)."""
    text = DISK.read_text(encoding="utf-8").replace(", frame: lean_link", frame)
    assert text != DISK.read_text(encoding="utf-8")
    path = tmp_path / "disk.yaml"
    path.write_text(text, encoding="utf-8")
    r = runner.invoke(app, ["simulate", str(path), "--t-end", "2"])
    assert r.exit_code == 2
    (line,) = r.output.strip().splitlines()
    assert f"constraints[0].{key}: the contact vector is given in axes that turn with 'disk'" in line
    assert line.startswith(f"{path}:33:")


def test_modes_of_a_steady_motion_without_shape_coordinates():
    """A two-wheel robot running straight at v = 0.5 m/s (tests/data/beyond/diffdrive.yaml, written from the docs):
    every coordinate is cyclic, so its one mode is of the speeds: the heading rate decays at m_b d v / J with
    J = m_b d^2 + Izb + 2 mw b^2 + 2 Id + 2 Ia b^2 / r^2 (the reduced equations by hand: J w' + m_b d v w = 0).
    `modes` raised IndexError; now the table and a note, and --frf says why it has nothing to respond."""
    path = DATA_DIR / "beyond" / "diffdrive.yaml"
    out = cli_json("modes", str(path), "--set", "tauL=0", "--set", "tauR=0")
    mb, Izb, d, mw, r, b, v = 4.0, 0.12, 0.1, 0.5, 0.08, 0.2, 0.5
    J = mb * d**2 + Izb + 2 * mw * b**2 + 2 * mw * r**2 / 4 + 2 * (mw * r**2 / 2) * b**2 / r**2
    assert out["coordinates"] == []
    (mode,) = out["modes"]
    assert mode["frequency_rad_s"] == pytest.approx(mb * d * v / J, rel=1e-9)
    text = runner.invoke(app, ["modes", str(path), "--set", "tauL=0", "--set", "tauR=0"])
    assert text.exit_code == 0 and "no shape coordinates" in text.output
    frf = runner.invoke(app, ["modes", str(path), "--set", "tauL=0", "--set", "tauR=0", "--frf", "0:1:3"])
    assert frf.exit_code == 2 and "--frf" in frf.output and "Traceback" not in frf.output


def test_redundant_rolling_rows_are_named_with_their_rank_and_the_way_out(tmp_path):
    """The two-wheel robot with both wheels' sideways rows (the same row): `equilibria` said only 'redundant or
    singular constraint rows'; now their rank and `components:`; `info`'s note said the rank 'gives 3' (the DOF)."""
    text = (DATA_DIR / "beyond" / "diffdrive.yaml").read_text(encoding="utf-8")
    both = text.replace("frame: body, components: [x]}", "frame: body, components: [x, y]}")
    assert both != text
    path = tmp_path / "robot.yaml"
    path.write_text(both, encoding="utf-8")
    r = runner.invoke(app, ["equilibria", str(path), "--set", "tauL=0", "--set", "tauR=0"])
    assert r.exit_code == 1
    flat = " ".join(r.output.split())
    assert "their rank is 3 of 4 rows" in flat and "`components:`" in flat
    info = runner.invoke(app, ["info", str(path)])
    assert "the constraint Jacobian's rank 3 gives 5 - 3 = 2" in " ".join(info.output.split())
