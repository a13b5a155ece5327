"""Jupyter display (Markdown and LaTeX reprs) and pandas DataFrames of the Python API's objects and results."""
from __future__ import annotations

from typing import TYPE_CHECKING, Any

import numpy as np

from mechsys.report.tables import Table, to_markdown

if TYPE_CHECKING:
    from mechsys.analysis.equilibrium.equilibria import EquilibriaResult
    from mechsys.analysis.equilibrium.modes import Modes
    from mechsys.analysis.motion.simulate import SimulationResult
    from mechsys.mechanics.model import Equations, MechanicalModel

#: The one line an ImportError carries when pandas is missing.
PANDAS_MISSING = "to_dataframe() needs pandas: pip install 'mechsys[notebook]'"


def pandas() -> Any:
    """The pandas module, or an ImportError naming the extra that installs it (pandas is optional)."""
    try:
        import pandas as pd
    except ImportError:
        raise ImportError(PANDAS_MISSING) from None
    return pd


# ----------------------------------------------------------------------------------------------- the model
def model_markdown(model: MechanicalModel) -> str:
    """`mechsys info -f markdown` (links, joints, mobility, DOF, system class), then the initial state and the
    parameter values."""
    from mechsys.analysis.info import system_info
    from mechsys.report.info import render_markdown

    state = Table("initial state", ["coordinate", "initial value", "initial rate"])
    for c in model.coordinates:
        state.add(c, float(model.doc.initial[c]), float(model.doc.initial_rate[c]))
    params = Table("parameters", ["name", "value"])
    for name, value in model.parameters.items():
        params.add(name, float(value))
    return render_markdown(system_info(model)) + "\n" + to_markdown([state, params])


def equations_latex(eq: Equations) -> str:
    """M q'' = f (+ A^T lambda) and the constraint rows A q'' = b, one aligned row each, as `derive -f latex`
    prints them (dotted rates), between $$ delimiters."""
    from mechsys.report.derive import latex_equations

    body = " \\\\\n".join(line for _, line in latex_equations(eq))
    return f"$$\n\\begin{{aligned}}\n{body}\n\\end{{aligned}}\n$$"


# ---------------------------------------------------------------------------------------------- equilibria
def equilibria_markdown(result: EquilibriaResult) -> str:
    """The tables of `mechsys equilibria -f markdown`: equilibria, modes of the linearized motion, verdicts."""
    from mechsys.report.equilibria import equilibria_tables

    return to_markdown(equilibria_tables(result))


def _eigenvalue_columns(result: EquilibriaResult) -> dict[str, list[complex]]:
    """`eigenvalue 1`, `eigenvalue 2`, ... (sorted as in the output), NaN where an equilibrium has fewer."""
    width = max((len(e.eigenvalues) for e in result.equilibria), default=0)
    return {f"eigenvalue {k + 1}": [complex(e.eigenvalues[k]) if k < len(e.eigenvalues) else complex(np.nan, np.nan)
                                    for e in result.equilibria] for k in range(width)}


def _union(names: list[list[str]]) -> list[str]:
    out: list[str] = []
    for group in names:
        out += [n for n in group if n not in out]
    return out


def equilibria_frame(result: EquilibriaResult) -> Any:
    """One row per equilibrium or steady motion (index `#` from 1, the CLI's numbering): each coordinate, each
    steady rate `der(NAME)`, `stability`, `critical`, `reason`, `max_real` (the largest real part of the
    eigenvalues, as in sweep tables) and the eigenvalues `eigenvalue 1..n` (complex)."""
    pd = pandas()
    eqs = result.equilibria
    coords = _union([list(e.coordinates) for e in eqs])
    rates = _union([list(e.rates) for e in eqs])
    columns: dict[str, list] = {c: [e.coordinates.get(c, np.nan) for e in eqs] for c in coords}
    columns.update({f"der({c})": [e.rates.get(c, np.nan) for e in eqs] for c in rates})
    columns["stability"] = [e.stability for e in eqs]
    columns["critical"] = [bool(e.critical) for e in eqs]
    columns["reason"] = [e.reason for e in eqs]
    columns["max_real"] = [float(np.max(e.eigenvalues.real)) if len(e.eigenvalues) else np.nan for e in eqs]
    columns.update(_eigenvalue_columns(result))
    return pd.DataFrame(columns, index=pd.RangeIndex(1, len(eqs) + 1, name="#"))


# --------------------------------------------------------------------------------------------------- modes
def modes_markdown(modes: Modes) -> str:
    """The tables of `mechsys modes -f markdown`: natural frequencies and mode shapes."""
    from mechsys.report.equilibria import modes_tables

    return to_markdown(modes_tables(modes))


def modes_frame(modes: Modes) -> Any:
    """One row per mode (index `mode` from 1): the columns of the CLI's frequency table, `rigid body` a bool."""
    pd = pandas()
    return pd.DataFrame({"frequency [rad/s]": np.asarray(modes.frequencies, dtype=float),
                         "frequency [Hz]": np.asarray(modes.frequencies_hz, dtype=float),
                         "damping ratio": np.asarray(modes.damping_ratios, dtype=float),
                         "rigid body": [bool(r) for r in modes.rigid_body]},
                        index=pd.RangeIndex(1, len(modes.frequencies) + 1, name="mode"))


# ---------------------------------------------------------------------------------------------- simulation
def simulation_markdown(result: SimulationResult) -> str:
    """The summary table `mechsys simulate -f markdown` prints."""
    from mechsys.report.simulation import summary_table

    return to_markdown(summary_table(result))


def simulation_frame(result: SimulationResult) -> Any:
    """One row per output time, the columns of the result file `mechsys simulate -o x.csv` writes: `t`, the
    coordinates, `der(q)`, T, V, E, residual, driving forces and the file's outputs."""
    names, data = result.columns()
    return pandas().DataFrame(np.asarray(data, dtype=float).reshape(-1, len(names)), columns=names)
