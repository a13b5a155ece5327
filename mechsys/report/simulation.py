"""Simulation outputs: result files (CSV, JSON, Parquet by suffix), the run summary table and time-history plots."""
from __future__ import annotations

import json
import re
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from mechsys.errors import InputError
from mechsys.report.tables import Table

if TYPE_CHECKING:
    from mechsys.analysis.motion.simulate import SimulationResult


RESULT_SUFFIXES = ".csv, .json or .parquet"


def result_text(names: list[str], data: np.ndarray, suffix: str) -> str:
    if suffix == ".json":
        return json.dumps({"columns": names, "data": data.tolist()}) + "\n"
    if suffix in (".csv", ""):
        lines = [",".join(names)] + [",".join(repr(float(x)) for x in row) for row in data]
        return "\n".join(lines) + "\n"
    raise InputError(f"unsupported result file suffix {suffix!r} (use {RESULT_SUFFIXES})")


def _pyarrow(path: Path | None, action: str):
    """pyarrow and pyarrow.parquet, or a one-line input error naming the extra that installs them."""
    try:
        import pyarrow
        import pyarrow.parquet as pq
    except ImportError:
        where = f"{path}: " if path is not None else ""
        raise InputError(f"{where}{action} Parquet needs pyarrow: pip install mechsys[parquet] "
                         "(or use .csv or .json)") from None
    return pyarrow, pq


def check_result_path(path: Path) -> None:
    """Reject a result file name before any work: unknown suffix, or Parquet without pyarrow installed."""
    path = Path(path)
    if path.suffix.lower() == ".parquet":
        _pyarrow(path, "writing")
    else:
        result_text([], np.zeros((0, 0)), path.suffix)


def result_bytes(names: list[str], data: np.ndarray, suffix: str) -> bytes:
    """The result file's content: Parquet (one float64 column per name) for .parquet, else result_text."""
    if suffix.lower() != ".parquet":
        return result_text(names, data, suffix).encode("utf-8")
    pa, pq = _pyarrow(None, "writing")
    data = np.asarray(data, dtype=float).reshape(-1, len(names))
    table = pa.table({name: pa.array(data[:, k], type=pa.float64()) for k, name in enumerate(names)})
    sink = pa.BufferOutputStream()
    pq.write_table(table, sink)
    return sink.getvalue().to_pybytes()


def write_result(path: Path, names: list[str], data: np.ndarray) -> None:
    """Write a result file atomically, its format chosen by the suffix (.csv, .json, .parquet)."""
    from mechsys.report.files import atomic_write

    content = result_bytes(names, data, Path(path).suffix)
    atomic_write(Path(path), lambda tmp: Path(tmp).write_bytes(content))


def plot_sweep_table(path: Path, out: str) -> None:
    """A stability map from a `mechsys sweep ... --run equilibria` table: the equilibrium coordinates against the
    first swept input, filled where stable and hollow where not (the book's static characteristic)."""
    import csv

    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from mechsys.report.files import write_figure

    rows = list(csv.DictReader(read_text_file(Path(path), "a sweep table").splitlines()))
    if not rows or "status" not in rows[0]:
        raise InputError(f"{path}: neither a simulation result nor a sweep table")
    try:
        fig = _sweep_figure(rows, path)
        write_figure(out, fig.savefig, "--output")
    finally:
        plt.close("all")


def is_sweep_table(path: Path) -> bool:
    """A CSV whose header row has a 'status' column: a `mechsys sweep` table (plotted as a stability map)."""
    if Path(path).suffix.lower() != ".csv" or not Path(path).is_file():
        return False
    header = read_text_file(Path(path)).split("\n", 1)[0]
    return "status" in [c.strip() for c in header.split(",")]


def _number(cell: str | None, path: Path, column: str) -> float:
    try:
        return float(cell)  # type: ignore[arg-type]
    except (TypeError, ValueError):
        raise InputError(f"{path}: column {column!r}: {cell!r} is not a number") from None


def _sweep_figure(rows: list[dict], path: Path):
    import matplotlib.pyplot as plt

    cols = list(rows[0])
    x_name = cols[1] if cols[0] in ("task", "id") else cols[0]
    coords = sorted({c.split(".", 1)[1] for c in cols if c.startswith("eq") and "." in c
                     and not c.endswith((".stability", ".max_real")) and "der(" not in c})
    if not coords:
        raise InputError(f"{path}: the sweep table has no equilibrium coordinates to map")
    fig, ax = plt.subplots(figsize=(7, 4.5))
    for r in rows:
        if r.get("status") != "ok":
            continue
        x = _number(r[x_name], path, x_name)
        k = 1
        while f"eq{k}.{coords[0]}" in r and r[f"eq{k}.{coords[0]}"] not in ("", None):
            y = _number(r[f"eq{k}.{coords[0]}"], path, f"eq{k}.{coords[0]}")
            stable = r.get(f"eq{k}.stability") in ("stable", "asymptotically stable")
            ax.plot([x], [y], "o", ms=4, color="C0" if stable else "C3", mfc="C0" if stable else "none")
            k += 1
    ax.set_xlabel(x_name)
    ax.set_ylabel(coords[0])
    ax.set_title("equilibria (filled: stable, hollow: unstable)")
    ax.grid(True, alpha=0.3)
    fig.tight_layout()
    return fig


def read_text_file(path: Path, what: str = "a mechsys result file") -> str:
    """A result or table file's text, or a one-line input error: missing, unreadable, not a regular file, not
    UTF-8 (a binary or foreign-encoded file)."""
    path = Path(path)
    if path.exists() and not path.is_file():
        raise InputError(f"{path}: cannot read: not a regular file (expected {what})")
    try:
        return path.read_text(encoding="utf-8")
    except UnicodeDecodeError as exc:
        raise InputError(f"{path}: not {what}: not UTF-8 text (byte {exc.start})") from None
    except OSError as exc:
        raise InputError(f"{path}: cannot read ({exc.strerror or exc})") from None


def _check_names(names: object) -> list[str]:
    """Distinct, non-empty column names, or ValueError."""
    if not isinstance(names, list) or not names or not all(isinstance(n, str) and n for n in names):
        raise ValueError("the columns must be a list of names")
    if len(set(names)) != len(names):
        raise ValueError(f"repeated column {next(n for n in names if names.count(n) > 1)!r}")
    return names


def _checked(names: object, data: object) -> tuple[list[str], np.ndarray]:
    """Column names (distinct strings) and a numeric table with one column per name, or ValueError."""
    names = _check_names(names)
    if not isinstance(data, list) or not all(isinstance(row, list) for row in data):
        raise ValueError("the data must be a list of rows")
    if not data:
        raise ValueError("no rows")
    if any(len(row) != len(names) for row in data):
        raise ValueError(f"a row does not have {len(names)} values")
    if any(isinstance(x, bool) or not isinstance(x, (int, float)) for row in data for x in row):
        raise ValueError("a value is not a number")
    return names, np.array(data, dtype=float).reshape(len(data), len(names))


def _parse_csv(text: str) -> tuple[list, list]:
    lines = [ln for ln in text.splitlines() if ln.strip()]
    if not lines:
        raise ValueError("the file is empty")
    names = [n.strip() for n in lines[0].split(",")]
    rows = []
    for k, ln in enumerate(lines[1:], start=2):
        try:
            rows.append([float(x) for x in ln.split(",")])
        except ValueError:
            raise ValueError(f"line {k} is not a row of numbers") from None
    return names, rows


def _parse_json(text: str) -> tuple[object, object]:
    obj = json.loads(text)
    if not isinstance(obj, dict) or "columns" not in obj or "data" not in obj:
        raise ValueError("expected an object with 'columns' and 'data'")
    return obj["columns"], obj["data"]


def read_result(path: Path) -> tuple[list[str], np.ndarray]:
    """Read a result file written by `mechsys simulate` (CSV, JSON or Parquet); anything else (empty, truncated,
    not UTF-8, ragged rows, repeated columns) is a one-line InputError naming the file."""
    if Path(path).suffix.lower() == ".parquet":
        return _read_parquet(Path(path))
    text = read_text_file(Path(path))
    is_json = Path(path).suffix.lower() == ".json"
    try:
        names, data = _parse_json(text) if is_json else _parse_csv(text)
        return _checked(names, data)
    except (ValueError, RecursionError) as exc:  # json.JSONDecodeError is a ValueError
        kind = "JSON with 'columns' and 'data'" if is_json else "CSV with a header row"
        detail = (f": invalid JSON at line {exc.lineno}, column {exc.colno} ({exc.msg})"
                  if isinstance(exc, json.JSONDecodeError) else f": {exc}")
        raise InputError(f"{path}: not a mechsys result file ({kind}){detail}") from None


def _read_parquet(path: Path) -> tuple[list[str], np.ndarray]:
    pa, pq = _pyarrow(path, "reading")
    if path.exists() and not path.is_file():
        raise InputError(f"{path}: cannot read: not a regular file (expected a mechsys result file)")
    if not path.is_file():
        raise InputError(f"{path}: cannot read (No such file or directory)")
    try:
        table = pq.read_table(path)
        names = [str(n) for n in table.column_names]
        columns = [np.asarray(table.column(k).to_numpy(), dtype=float) for k in range(table.num_columns)]
    except (OSError, ValueError, TypeError, pa.ArrowException):
        raise InputError(f"{path}: not a mechsys result file (Parquet with numeric columns)") from None
    try:
        _check_names(names)
        if not table.num_rows:
            raise ValueError("no rows")
    except ValueError as exc:
        raise InputError(f"{path}: not a mechsys result file (Parquet with numeric columns): {exc}") from None
    return names, np.column_stack(columns) if columns[0].size else np.zeros((0, len(names)))


def _stopped_by(result: SimulationResult) -> dict | None:
    """The event with action stop that ended the run (at its last output time), or None."""
    last = float(result.t[-1]) if len(result.t) else 0.0
    stops = [ev for ev in result.events
             if ev.get("action") == "stop" and abs(ev["t"] - last) <= 1e-9 * max(1.0, abs(last))]
    return stops[-1] if stops else None


def summary_table(result: SimulationResult) -> list[Table]:
    t = Table("simulation summary", ["quantity", "value"])
    t.add("method", result.method)
    t.add("output points", len(result.t))
    t.add("integrator steps", result.steps if result.steps is not None else "n/a")
    t.add("RHS evaluations", result.rhs_evaluations)
    stop = _stopped_by(result)
    if stop is not None:  # the (t_end) values below are at the stop, not at --t-end
        t.add("stopped by event", stop["event"])
        t.add("stopped at t", float(result.t[-1]))
    for c, q, u in zip(result.coordinates, result.q[-1], result.u[-1]):
        t.add(f"{c}(t_end)", float(q))
        t.add(f"der({c})(t_end)", float(u))
    t.add("energy E(t_end) - E(0)", float(result.E[-1] - result.E[0]))
    if result.conservative:
        t.add("max relative energy drift", result.energy_drift)
    else:
        if result.work is not None:
            t.add("work of non-conservative forces W(t_end)", float(result.work[-1]))
        if result.impacts:
            t.add("energy lost in impacts", float(sum(im["energy_loss"] for im in result.impacts)))
        t.add("max relative energy balance error", result.energy_balance_error)
        if result.work is not None:
            t.add("of which quadrature of W on the output grid (estimate)", result.work_quadrature_error)
    t.add("max constraint residual", float(np.max(result.residual)) if len(result.residual) else 0.0)
    t.add("events recorded", len(result.events) + len(result.impacts))
    if result.impacts:
        t.add("impacts", len(result.impacts))
        t.add("last impact at t", result.impacts[-1]["t"])
    for name, values in result.driving.items():
        t.add(f"driving force on {name} at t_end", float(values[-1]))
    for k, v in result.timings.items():
        t.add(f"wall time: {k} [s]", float(v))
    t.notes += result.warnings
    if not result.conservative:
        t.notes.append("energy balance: E(t) - E(0) - W(t) + (energy lost in impacts up to t), W the work of the "
                       "non-conservative forces (damping, applied forces, drives, moving constraints, joints or "
                       "springs moving with t; a fourth-order quadrature on the output grid); relative to "
                       "max(|E(0)|, max T, max |W|)")
        if result.work is not None and result.energy_balance_error <= 3 * result.work_quadrature_error:
            t.notes.append("the energy balance error is of the size of the quadrature error of W on this output "
                           "grid: a finer --dt tells the integration's own error")
        elif result.work is not None and result.energy_balance_error > 1e-3:
            t.notes += _between_rows(result)
    return [t]


def _between_rows(result: SimulationResult) -> list[str]:
    """A note when the energy changes by more than a tenth of its scale within one output interval: W is a
    quadrature of the power on the output grid, and a transient between two rows (a stiff damper dissipating
    21,000 J in the first 0.01 s) is missed by it and by its error estimate alike; the balance error then says
    nothing about the integration."""
    E, t = np.asarray(result.E), np.asarray(result.t)
    if len(E) < 2:
        return []
    scale = max(abs(float(E[0])), float(np.max(np.abs(result.T))), 1e-300)
    jumps = np.abs(np.diff(E)) / scale
    k = int(np.argmax(jumps))
    if jumps[k] <= 0.1:
        return []
    return [f"the energy changes by {jumps[k]:.3g} of its scale within one output interval (t = {t[k]:.6g} to "
            f"{t[k + 1]:.6g} s): W, summed on the output grid, misses a transient there, so the balance error does "
            "not measure the integration; a finer --dt over that interval resolves it"]


def summary_payload(result: SimulationResult) -> dict:
    """The JSON of the summary: one object keyed by quantity (the rows of summary_table), and the notes."""
    (table,) = summary_table(result)
    return {"simulation summary": {row[0]: row[1] for row in table.rows}, "notes": list(table.notes)}


#: Panels drawn for the columns that are not coordinates or rates (outputs, driving forces, reactions), two a row.
MAX_EXTRA_PANELS = 6
_PART = re.compile(r"^(.+)\.(x|y|z|Fx|Fy|Fz|Mx|My|Mz)$")


def other_column_groups(names: list[str]) -> list[tuple[str, list[str]]]:
    """The columns of a result other than t, coordinates, rates, T, V, E and residual, as (title, columns) panels:
    the components of one vector together (H.x, H.y, H.z; a reaction's forces apart from its moments), driving
    forces together, the other scalar columns together; in the order of the file."""
    coords = {n for n in names if f"der({n})" in names}
    skip = coords | {f"der({c})" for c in coords} | {"t", "T", "V", "E", "residual"}
    groups: dict[str, list[str]] = {}
    for n in names:
        if n in skip:
            continue
        m = _PART.match(n)
        if m:
            key = f"{m.group(1)} ({'moment' if m.group(2).startswith('M') else 'force'})" \
                if m.group(2) in ("Fx", "Fy", "Fz", "Mx", "My", "Mz") else m.group(1)
        else:
            key = "driving forces" if n.startswith("driving(") else "outputs"
        groups.setdefault(key, []).append(n)
    return list(groups.items())


def plot_histories(names: list[str], data: np.ndarray, path: str, option: str = "--plot") -> None:
    """Coordinates, rates, energy and a phase portrait of the first coordinate, then a row of panels for every
    two groups of the other columns (outputs, driving forces, reactions; at most MAX_EXTRA_PANELS, the rest named
    in the title), written atomically."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from mechsys.report.files import write_figure

    if "t" not in names:
        raise InputError("the result has no 't' column")
    t = data[:, names.index("t")]
    coords = [n for n in names if f"der({n})" in names]  # not outputs, reactions or driving forces
    groups = other_column_groups(names)
    shown = groups[:MAX_EXTRA_PANELS]
    rows = 2 + -(-len(shown) // 2)
    fig, grid = plt.subplots(rows, 2, figsize=(10, 3.5 * rows), squeeze=False)
    axes = grid[:2]
    for ax, (title, columns) in zip(grid[2:].flat, shown):
        for c in columns:
            ax.plot(t, data[:, names.index(c)], label=c)
        ax.set_title(title)
        ax.grid(True, alpha=0.3)
        ax.set_xlabel("t [s]")
        if len(columns) > 1:
            ax.legend(fontsize=8)
    for ax in list(grid[2:].flat)[len(shown):]:
        ax.set_visible(False)
    if len(groups) > len(shown):
        fig.suptitle(f"{len(groups) - len(shown)} more groups of columns are in the file, not drawn", fontsize=9)
    for c in coords:
        axes[0, 0].plot(t, data[:, names.index(c)], label=c)
        if f"der({c})" in names:
            axes[0, 1].plot(t, data[:, names.index(f"der({c})")], label=f"der({c})")
    axes[0, 0].set_title("coordinates")
    axes[0, 1].set_title("rates")
    if "E" in names:
        E = data[:, names.index("E")]
        axes[1, 0].plot(t, E - E[0])
        axes[1, 0].set_title("energy E(t) - E(0)")
    # phase portrait of the coordinate with the smallest range (a cyclic angle's portrait says little)
    bounded = sorted(coords, key=lambda c: float(np.ptp(data[:, names.index(c)])))
    if bounded and f"der({bounded[0]})" in names:
        c0 = bounded[0]
        axes[1, 1].plot(data[:, names.index(c0)], data[:, names.index(f"der({c0})")])
        axes[1, 1].set_title(f"phase portrait of {c0}")
        coords = [c0] + [c for c in coords if c != c0]
    for ax in axes.flat:
        ax.grid(True, alpha=0.3)
        ax.set_xlabel("t [s]" if ax is not axes[1, 1] else (coords[0] if coords else ""))
    for ax in axes[0]:
        if ax.lines:
            ax.legend(fontsize=8)
    fig.tight_layout()
    try:
        write_figure(path, fig.savefig, option)
    finally:
        plt.close(fig)


def events_text(events: list[dict], coordinates: list[str], suffix: str) -> str:
    """The event table: t, event, action, then the state at the crossing."""
    if suffix == ".json":
        return json.dumps(events, indent=1) + "\n"
    if suffix not in (".csv", ""):
        raise InputError(f"unsupported events file suffix {suffix!r} (use .csv or .json)")
    cols = [*coordinates, *[f"der({c})" for c in coordinates]]
    lines = [",".join(["t", "event", "action", *cols])]
    for ev in events:
        lines.append(",".join([repr(ev["t"]), ev["event"], ev["action"], *[repr(ev["state"][c]) for c in cols]]))
    return "\n".join(lines) + "\n"


def impacts_text(impacts: list[dict], coordinates: list[str], suffix: str) -> str:
    """The impact table: t, contact, impulse, energy lost, captured, then the rates before and after."""
    if suffix == ".json":
        return json.dumps(impacts, indent=1) + "\n"
    if suffix not in (".csv", ""):
        raise InputError(f"unsupported impacts file suffix {suffix!r} (use .csv or .json)")
    cols = ["t", "contact", "impulse", "energy_loss", "captured"]
    cols += [f"before.der({c})" for c in coordinates] + [f"after.der({c})" for c in coordinates]
    lines = [",".join(cols)]
    for im in impacts:
        row = [repr(im["t"]), im["contact"], repr(im["impulse"]), repr(im["energy_loss"]), str(im["captured"])]
        row += [repr(im["rates_before"][c]) for c in coordinates] + [repr(im["rates_after"][c]) for c in coordinates]
        lines.append(",".join(row))
    return "\n".join(lines) + "\n"
