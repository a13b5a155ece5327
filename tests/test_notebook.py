"""Notebooks (issue 15): the Python API's objects render in Jupyter (_repr_markdown_, _repr_latex_) with the
tables the CLI prints, and results convert to pandas DataFrames equal to what the CLI writes."""
from __future__ import annotations

import io
import json
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
import scipy.linalg as sla
import sympy as sp
from typer.testing import CliRunner

import mechsys
from mechsys.analysis.equilibrium.equilibria import find_equilibria
from mechsys.analysis.equilibrium.modes import vibration_modes
from mechsys.analysis.motion.simulate import simulate
from mechsys.cli import app
from mechsys.report.printing import to_latex

pd = pytest.importorskip("pandas")

ROOT = Path(__file__).resolve().parents[1]
CENTRIFUGE = ROOT / "systems" / "centrifuge.yaml"
DOUBLE_PENDULUM = ROOT / "systems" / "double_pendulum.yaml"
CART_PENDULUM = ROOT / "systems" / "cart_pendulum.yaml"


def cli(*args) -> str:
    """stdout of a successful `mechsys ARGS` (in this process)."""
    result = CliRunner().invoke(app, [str(a) for a in args])
    assert result.exit_code == 0, result.output
    return result.stdout


def csv_tables(text: str) -> dict[str, "pd.DataFrame"]:
    """The tables of a multi-table `-f csv` output (each under a `# title` line), read with pandas."""
    out = {}
    for chunk in text.strip().split("\n\n"):
        title, body = chunk.split("\n", 1)
        out[title.removeprefix("# ")] = pd.read_csv(io.StringIO(body))
    return out


@pytest.fixture(scope="module")
def centrifuge_equilibria():
    return find_equilibria(mechsys.load(CENTRIFUGE))


# ------------------------------------------------------------------------------------------------ equilibria
def test_equilibria_markdown_is_what_the_cli_prints(centrifuge_equilibria):
    shown = centrifuge_equilibria._repr_markdown_()
    assert shown == cli("equilibria", CENTRIFUGE, "-f", "markdown")
    assert "| 4 | beta = 1.410445 | der(alpha) = 7 | asymptotically stable |" in shown  # docs/equilibria.md


def test_equilibria_dataframe_holds_the_json_values(centrifuge_equilibria):
    frame = centrifuge_equilibria.to_dataframe()
    payload = json.loads(cli("equilibria", CENTRIFUGE, "-f", "json"))["equilibria"]
    assert list(frame.index) == [1, 2, 3, 4] and frame.index.name == "#"
    assert list(frame.columns[:5]) == ["beta", "der(alpha)", "stability", "critical", "reason"]
    for k, e in enumerate(payload, start=1):
        row = frame.loc[k]
        assert row["beta"] == pytest.approx(e["coordinates"]["beta"], rel=1e-12, abs=1e-12)
        assert row["der(alpha)"] == pytest.approx(e["rates"]["alpha"], rel=1e-12)
        assert (row["stability"], row["critical"], row["reason"]) == (e["stability"], e["critical"], e["reason"])
        eigs = [row[f"eigenvalue {j}"] for j in range(1, len(e["eigenvalues"]) + 1)]
        np.testing.assert_allclose(eigs, [complex(re, im) for re, im in e["eigenvalues"]], rtol=1e-12, atol=1e-12)
        assert row["max_real"] == pytest.approx(max(re for re, _ in e["eigenvalues"]), rel=1e-12, abs=1e-12)
    # independent: the drive torque Mo - dM der(alpha) vanishes in a steady motion, der(alpha) = Mo/dM = 7
    np.testing.assert_allclose(frame["der(alpha)"], 50 / (50 / 7), rtol=1e-12)


# ----------------------------------------------------------------------------------------------- simulation
def test_simulation_dataframe_equals_the_csv_the_cli_writes(tmp_path):
    out = tmp_path / "dp.csv"
    cli("simulate", DOUBLE_PENDULUM, "--t-end", "1", "--dt", "0.01", "-o", out)
    written = pd.read_csv(out)
    result = simulate(mechsys.load(DOUBLE_PENDULUM, release_prescribed=True), 1.0, 0.01)
    frame = result.to_dataframe()
    assert list(frame.columns) == list(written.columns)
    assert list(frame.columns[:5]) == ["t", "theta1", "theta2", "der(theta1)", "der(theta2)"]
    assert frame.shape == written.shape == (101, 9)
    np.testing.assert_allclose(frame.to_numpy(), written.to_numpy(), rtol=1e-12, atol=1e-12)
    shown = result._repr_markdown_()
    assert shown.startswith("### simulation summary")
    assert f"| theta1(t_end) | {float(frame['theta1'].iloc[-1]):.6f}".rstrip("0") in shown


# --------------------------------------------------------------------------------------------------- modes
def test_modes_markdown_and_dataframe_are_the_cli_tables():
    modes = vibration_modes(mechsys.load(CART_PENDULUM))
    assert modes._repr_markdown_() == cli("modes", CART_PENDULUM, "-f", "markdown")
    frame = modes.to_dataframe()
    table = next(t for title, t in csv_tables(cli("modes", CART_PENDULUM, "-f", "csv")).items()
                 if title.startswith("natural frequencies"))
    assert list(frame.index) == list(table["mode"]) == [1, 2]
    for column in ("frequency [rad/s]", "frequency [Hz]", "damping ratio"):
        np.testing.assert_allclose(frame[column], table[column], rtol=1e-12, atol=1e-12)
    assert list(frame["rigid body"]) == [False, False]


def test_modes_dataframe_matches_the_closed_form_of_the_double_pendulum():
    """Uniform rods about the hanging position: M and K from the file header's equations, linearised by hand."""
    m1, m2, l1, l2, g = 1.0, 0.8, 0.6, 0.5, 9.81
    M = np.array([[m1 * l1**2 / 3 + m2 * (l1**2 + l2**2 / 3 + l1 * l2), m2 * (l2**2 / 3 + l1 * l2 / 2)],
                  [m2 * (l2**2 / 3 + l1 * l2 / 2), m2 * l2**2 / 3]])
    K = np.array([[(m1 / 2 + m2) * g * l1 + m2 * g * l2 / 2, m2 * g * l2 / 2], [m2 * g * l2 / 2, m2 * g * l2 / 2]])
    omega = np.sqrt(sla.eigh(K, M, eigvals_only=True))
    frame = vibration_modes(mechsys.load(DOUBLE_PENDULUM)).to_dataframe()
    np.testing.assert_allclose(frame["frequency [rad/s]"], omega, rtol=1e-9)
    np.testing.assert_allclose(frame["frequency [Hz]"], omega / (2 * np.pi), rtol=1e-9)
    np.testing.assert_allclose(frame["damping ratio"], 0.0, atol=1e-12)


# ------------------------------------------------------------------------------------ equations and the model
def test_equations_latex_shows_m_qdd_equals_f_with_the_closed_form_mass_matrix():
    model = mechsys.load(DOUBLE_PENDULUM)
    eq = model.equations("lagrange")
    p = model.doc.parameters
    m1, m2, l1, l2 = p["m1"], p["m2"], p["l1"], p["l2"]
    c2 = sp.cos(model.doc.coords["theta2"])
    closed = {(0, 0): m1 * l1**2 / 3 + m2 * (l1**2 + l2**2 / 3 + l1 * l2 * c2),  # uniform rods (not point masses)
              (0, 1): m2 * (l2**2 / 3 + l1 * l2 * c2 / 2), (1, 1): m2 * l2**2 / 3}
    for (i, j), want in closed.items():
        assert sp.simplify(eq.M[i, j] - want) == 0, (i, j)
    shown = eq._repr_latex_()
    assert shown.startswith("$$") and shown.endswith("$$")
    assert "\\begin{aligned}" in shown and shown.count("&=") == 2  # one row per equation, no T, V, Q rows
    assert "\\ddot{\\theta_{1}}" in shown and "\\ddot{\\theta_{2}}" in shown and "l_{1}" in shown
    assert to_latex(eq.M[0, 0]) in shown and to_latex(eq.f[1]) in shown


def test_constrained_equations_latex_has_the_constraint_rows():
    eq = mechsys.load(ROOT / "systems" / "slider_crank.yaml").equations("kane")
    shown = eq._repr_latex_()
    assert shown.count("&=") == len(eq.coordinates) + eq.A.shape[0] and "\\lambda_{1}" in shown


def test_model_markdown_is_the_info_tables_with_state_and_parameters():
    shown = mechsys.load(CENTRIFUGE)._repr_markdown_()
    assert shown.startswith(cli("info", CENTRIFUGE, "-f", "markdown"))
    assert "| beta | 0 | -2.5 |" in shown and "| Mo | 50 |" in shown and "| dM | 7.142857 |" in shown


# --------------------------------------------------------------------------------------- pandas is optional
def test_to_dataframe_without_pandas_names_the_extra(monkeypatch, centrifuge_equilibria):
    monkeypatch.setitem(sys.modules, "pandas", None)  # `import pandas` raises ImportError
    with pytest.raises(ImportError) as info:
        centrifuge_equilibria.to_dataframe()
    message = str(info.value)
    assert "\n" not in message and "mechsys[notebook]" in message and "pandas" in message


def test_the_library_imports_and_renders_without_pandas_and_ipython():
    code = ("import sys; sys.modules['pandas'] = None; sys.modules['IPython'] = None\n"
            "import mechsys, mechsys.report.notebook, mechsys.analysis.motion.simulate, mechsys.analysis.equilibrium.modes\n"
            "from mechsys.analysis.equilibrium.equilibria import find_equilibria\n"
            f"r = find_equilibria(mechsys.load({str(CENTRIFUGE)!r}))\n"
            "assert '1.410445' in r._repr_markdown_()\n"
            "try:\n    r.to_dataframe()\nexcept ImportError as e:\n    print(e)\n")
    res = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=300)
    assert res.returncode == 0, res.stderr
    assert res.stdout.strip() == "to_dataframe() needs pandas: pip install 'mechsys[notebook]'"
