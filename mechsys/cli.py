"""The `mechsys` command line: parses options, calls the library, renders; exit 0 ok, 1 failed, 2 bad input."""
from __future__ import annotations

import gc
import json
import math
import os
import sys
import warnings
from contextlib import contextmanager
from enum import Enum
from pathlib import Path
from typing import TYPE_CHECKING, Callable, Iterator, List, Optional

import typer

from mechsys.errors import InputError, MechsysError

if TYPE_CHECKING:
    from mechsys.analysis.equilibrium.equilibria import SteadyOptions
    from mechsys.mechanics.model import MechanicalModel
    from mechsys.report.tables import Table

app = typer.Typer(
    name="mechsys",
    help="Dynamics of mechanical systems from one validated YAML model.",
    add_completion=False,
    pretty_exceptions_enable=False,
    no_args_is_help=True,
    rich_markup_mode=None,  # plain help: rich markup would eat the units in brackets ("End time [s].")
)

SetOption = typer.Option(None, "--set", "-s", metavar="NAME=VALUE",
                         help="Override a parameter, a coordinate's initial value, or der(NAME) its rate. Repeatable.")
OutputOption = typer.Option(None, "--output", "-o", help="Write to this file (atomically) instead of stdout.")


class DeriveFormat(str, Enum):
    text = "text"
    latex = "latex"
    markdown = "markdown"
    json = "json"


class Subexpressions(str, Enum):
    auto = "auto"
    inline = "inline"
    named = "named"


class InfoFormat(str, Enum):
    text = "text"
    markdown = "markdown"
    json = "json"


class Method(str, Enum):
    lagrange = "lagrange"
    kane = "kane"


def write_atomic(path: Path, text: str) -> None:
    """Write ``text`` to ``path`` through a temporary file and a rename, so a failure never leaves half a file."""
    from mechsys.report.files import write_text_atomic

    write_text_atomic(path, text)


def emit(text: str, output: Optional[Path]) -> None:
    if output is None:
        sys.stdout.write(text)
    else:
        write_atomic(output, text)


def check_outputs(*paths: Optional[Path]) -> None:
    """Refuse output files that cannot be written (a directory, a device, a missing folder) before any work."""
    from mechsys.report.files import output_target

    for path in paths:
        if path is not None:
            output_target(path)


def check_figures(**paths: Optional[Path]) -> None:
    """Refuse figure files (option name -> path) with a suffix matplotlib cannot write, before any work."""
    from mechsys.report.files import check_figure_path

    for option, path in paths.items():
        if path is not None:
            check_figure_path(path, "--" + option.replace("_", "-"))


def write_figure(path: Path, draw: Callable[[str], None], option: str = "--plot") -> None:
    """Draw a figure through a temporary file of the same suffix: written atomically like every output."""
    from mechsys.report.files import write_figure as write

    write(path, draw, option)


def _constant(text: str, what: str) -> float:
    """A number, or a constant expression of the model language (`pi`, `-pi/2`, `sqrt(2)/2`: no names), as a float;
    an input error naming ``what`` otherwise. The parser is imported only for an expression (the warm path)."""
    try:
        return float(text)
    except ValueError:
        pass
    from mechsys.model.expressions import ExpressionError, parse_expression

    try:
        value = parse_expression(text.strip(), {})
        if value.is_number and value.is_real:
            return float(value)
    except (ExpressionError, TypeError, ValueError):
        pass
    raise InputError(f"{what}: expected NAME=VALUE with a number or a constant expression such as pi/2")


def check_model_file(file: Path) -> None:
    """One line (exit 2) for a model file that is missing, unreadable, not a regular file (a FIFO would hang
    the run) or too large, before anything else reads it."""
    from mechsys.model.files import read_model_text  # light: the warm path must not import sympy or pydantic

    read_model_text(file)


# ----------------------------------------------------------------------------------------- numeric options
MAX_POINTS = 10**7  # output grid points of simulate and --frf
MAX_TASKS = 10**6  # tasks of one sweep
MAX_SWEEP_POINTS = 1000  # continuation points of --sweep (each point costs an eigenvalue problem)
MAX_T_END = 1e9  # [s]: beyond, steps fall below the time resolution of double precision
MIN_RTOL = 100 * sys.float_info.epsilon  # tighter tolerances than ~2e-14 cannot be met in double precision
MAX_JOBS = 256


def _num(x: float) -> str:
    """A bound as people write it: 1000, 1e+07, 2.22e-14."""
    return str(int(x)) if x == int(x) and abs(x) < 1e6 else f"{x:.3g}"


def check_number(option: str, value: float | None, low: float | None = None, high: float | None = None, *,
                 open_low: bool = False, open_high: bool = False, whole: bool = False, why: str = "") -> None:
    """The one rule of every numeric option: a finite number within [low, high] (an open end excludes the bound),
    a whole number if ``whole``; otherwise an InputError naming the option, the value and the reason."""
    if value is None:
        return
    because = f" ({why})" if why else ""
    if not math.isfinite(value):
        raise InputError(f"{option} {value}: must be a finite number")
    if low is not None and (value <= low if open_low else value < low):
        bound = "positive" if low == 0 and open_low else f"{'greater than' if open_low else 'at least'} {_num(low)}"
        raise InputError(f"{option} {value:g}: must be {bound}{because}")
    if high is not None and (value >= high if open_high else value > high):
        raise InputError(f"{option} {value:g}: must be {'less than' if open_high else 'at most'} {_num(high)}{because}")
    if whole and value != int(value):
        raise InputError(f"{option} {value:g}: must be a whole number")


def check_time_grid(t_end: float, dt: Optional[float], option: str = "--t-end", dt_option: str = "--dt") -> None:
    """A finite positive horizon and, when given, a finite positive output interval whose grid is not huge."""
    check_number(option, t_end, 0.0, open_low=True)
    check_number(option, t_end, high=MAX_T_END, why="longer horizons exceed the time resolution of double "
                                                     "precision")
    if dt is None:
        return
    check_number(dt_option, dt, 0.0, open_low=True)
    check_number(dt_option, dt, high=t_end, why=f"the horizon {option} is {t_end:g}")
    points = math.floor(t_end / dt) + 1
    if points > MAX_POINTS:
        raise InputError(f"{dt_option} {dt:g}: {points:.3g} output points over {t_end:g} s "
                         f"(at most {MAX_POINTS:.0e}; use a larger {dt_option})")


def check_tolerances(rtol: float, atol: Optional[float] = None, option: str = "--rtol") -> None:
    """rtol in [100 eps, 1) (what double precision can meet), atol finite and positive."""
    check_number(option, rtol, MIN_RTOL, why="100 x machine epsilon: tighter cannot be met in double precision")
    check_number(option, rtol, high=1.0, open_high=True)
    check_number("--atol", atol, 0.0, open_low=True)


@contextmanager
def quiet_numerics() -> Iterator[None]:
    """No raw library warnings (numpy's divide-by-zero RuntimeWarnings and the like) on the user's terminal: the
    analyses report what matters themselves. MECHSYS_DEBUG=1 shows them."""
    with warnings.catch_warnings():
        if not os.environ.get("MECHSYS_DEBUG"):
            warnings.simplefilter("ignore")
        yield


def run(action: Callable[[], int | None]) -> None:
    """Run a command body; report mechsys errors as one line on stderr with their exit code."""
    try:
        with quiet_numerics():
            code = action() or 0
    except MechsysError as exc:
        sys.stderr.write(f"mechsys: {exc}\n" if not isinstance(exc, InputError) or not exc.file else f"{exc}\n")
        raise typer.Exit(exc.exit_code) from None
    except KeyboardInterrupt:
        sys.stderr.write("mechsys: interrupted\n")
        raise typer.Exit(130) from None
    except (typer.Exit, typer.Abort):
        raise
    except Exception as exc:  # noqa: BLE001 - the last line of defence: no traceback for users
        if os.environ.get("MECHSYS_DEBUG"):
            raise
        sys.stderr.write(f"mechsys: internal error: {type(exc).__name__}: {exc} (set MECHSYS_DEBUG=1 for details)\n")
        raise typer.Exit(1) from None
    raise typer.Exit(code)


def load_model(file: Path, assignments: Optional[List[str]]) -> MechanicalModel:
    import mechsys
    from mechsys.model.load import parse_assignments

    model = mechsys.load(file, parse_assignments(assignments))
    from mechsys.report import warm

    warm.loaded(file, model.doc.text)  # (a kept output is this text's)
    if _ONE_SHOT:
        gc.freeze()  # see entry()
    return model


@app.command()
def derive(
    file: Path = typer.Argument(..., help="Model file (YAML)."),
    method: Method = typer.Option(Method.lagrange, "--method", "-m", help="Formulation to print."),
    check: bool = typer.Option(False, "--check", help="Verify that Lagrange and Kane give the same M and f."),
    simplify: bool = typer.Option(False, "--simplify", help="Simplify every expression before printing (slow)."),
    raw: bool = typer.Option(False, "--raw", help="Print the expressions as derived, without the quick clean-up "
                                                 "(trigonometric identities, signs) of text, LaTeX and Markdown."),
    fmt: DeriveFormat = typer.Option(DeriveFormat.text, "--format", "-f", help="Output format."),
    subexpressions: Subexpressions = typer.Option(
        Subexpressions.auto, "--subexpressions",
        help="named: print each subexpression that several entries share once, as z1, z2, ... defined at the end; "
             "inline: write every entry out in full; auto: named when the inline form would be large (text, "
             "LaTeX, Markdown; JSON stays inline)."),
    set_: Optional[List[str]] = SetOption,
    output: Optional[Path] = OutputOption,
) -> None:
    """Print T, V, the generalized forces Q and the equations of motion M(q,t) q'' = f(q, q', t)."""

    def body() -> int:
        from mechsys.report import warm

        check_outputs(output)
        key = None if check else warm.output_key("derive", file, {"set": list(set_ or []), "method": method.value,
                                                                  "format": fmt.value, "raw": raw,
                                                                  "simplify": simplify,
                                                                  "subexpressions": subexpressions.value})
        text = warm.load_text(key)
        if text is not None:
            emit(text, output)
            return 0
        from mechsys.report.derive import render, simplified

        model = load_model(file, set_)
        eq = model.equations(method.value)
        # JSON: the parameter values of this load (with --set), so that the symbolic equations can be evaluated
        extra: dict = {"parameters": dict(model.parameters)} if fmt.value == "json" else {}
        verdict = None
        if check:
            from mechsys.analysis.crosscheck import cross_check

            result = cross_check(model)
            verdict = result
            extra["check"] = {"agree": result.agree, "states": result.states,
                              "max_relative_difference": result.max_rel_diff, "symbolic": result.symbolic}
        if simplify:
            eq = simplified(eq)
        text = render(eq, model.name, fmt.value, extra, raw=raw, model=None if simplify else model,
                      subexpressions=subexpressions.value)
        if verdict is not None and fmt.value != "json":
            prefix = "% " if fmt.value == "latex" else ""
            text += f"{prefix}check: {verdict.summary()}\n"
        warm.store_text(key, text)
        emit(text, output)
        if verdict is not None and not verdict.agree:
            sys.stderr.write(f"mechsys: check failed: {verdict.summary()}\n")
            return 1
        return 0

    run(body)


@app.command()
def info(
    file: Path = typer.Argument(..., help="Model file (YAML)."),
    fmt: InfoFormat = typer.Option(InfoFormat.text, "--format", "-f", help="Output format."),
    set_: Optional[List[str]] = SetOption,
    output: Optional[Path] = OutputOption,
) -> None:
    """Links, joint classes, mobility, degrees of freedom and the system's class."""

    def body() -> int:
        from mechsys.report import warm
        from mechsys.report.info import render_json, render_markdown, render_rich

        check_outputs(output)
        key = warm.output_key("info", file, {"set": list(set_ or [])})
        result = warm.load_info(key)
        if result is None:
            from mechsys.analysis.info import system_info

            result = system_info(load_model(file, set_))
            warm.store_info(key, result)
        if fmt == InfoFormat.json:
            emit(render_json(result), output)
        elif fmt == InfoFormat.markdown:
            emit(render_markdown(result), output)
        else:
            from rich.console import Console

            if output is None:
                Console().print(render_rich(result))
            else:
                console = Console(record=True, width=100, file=open(os.devnull, "w"))
                console.print(render_rich(result))
                write_atomic(output, console.export_text())
        return 0

    run(body)


class TableFormat(str, Enum):
    text = "text"
    json = "json"
    csv = "csv"
    markdown = "markdown"
    latex = "latex"


def emit_tables(tables: list[Table], fmt: "TableFormat", output: Optional[Path], payload: dict | None = None) -> None:
    from mechsys.report.tables import render_tables

    rendered = render_tables(tables, fmt.value, payload)
    if isinstance(rendered, str):
        emit(rendered, output)
        return
    from rich.console import Console

    # crop=False: a long table's rows are whole lines wider than the console (tables.to_rich); rich's own tables
    # fit its width anyway
    if output is None:
        Console().print(rendered, crop=False)
    else:
        console = Console(record=True, width=160, file=open(os.devnull, "w"))
        console.print(rendered, crop=False)
        write_atomic(output, console.export_text())


def emit_kept_tables(key: Optional[str], fmt: "TableFormat", output: Optional[Path]) -> bool:
    """Print the tables a previous run of the same command kept (report/warm.py); False when there are none."""
    from mechsys.report import warm

    kept = warm.load_tables(key)
    if kept is not None:
        emit_tables(kept[0], fmt, output, kept[1])
    return kept is not None


def parse_ranges(items: Optional[List[str]], option: str, count: bool = False) -> dict:
    """NAME=LO:HI (or NAME=START:STOP:N with count) into {name: (lo, hi[, n])}."""
    out = {}
    for item in items or []:
        name, sep, rest = item.partition("=")
        parts = rest.split(":")
        try:
            if not sep or len(parts) != (3 if count else 2) or not name.strip():
                raise ValueError
            values = [float(x) for x in parts[:2]]
            if count:
                values.append(int(parts[2]))
                if values[2] < 2:
                    raise ValueError
        except ValueError:
            form = "NAME=START:STOP:N (N >= 2)" if count else "NAME=LO:HI"
            raise InputError(f"{option} {item!r}: expected {form}") from None
        check_range(f"{option} {item!r}", values[0], values[1], ordered=not count)
        if count:
            check_number(f"{option} {item!r}: N", values[2], high=MAX_SWEEP_POINTS,
                         why="each point costs an eigenvalue problem; narrow the range instead")
        out[name.strip()] = tuple(values)
    return out


def check_range(option: str, lo: float, hi: float, ordered: bool = True, ends: str = "LO HI") -> None:
    """Finite ends; with ``ordered``, LO < HI (a search box, a frequency range)."""
    for value in (lo, hi):
        if not math.isfinite(value):
            raise InputError(f"{option}: {value} is not a finite number")
    if ordered and not lo < hi:
        first, second = ends.split()
        raise InputError(f"{option}: {first} must be less than {second}")


def steady_options(given: Optional[List[str]], solve: Optional[List[str]],
                   independent: Optional[str]) -> SteadyOptions:
    """--given, --solve and --independent as the library's SteadyOptions."""
    from mechsys.analysis.equilibrium.equilibria import SteadyOptions

    names = [c.strip() for c in (independent or "").split(",") if c.strip()]
    if independent is not None and not names:
        raise InputError("--independent: expected comma-separated coordinate names")
    return SteadyOptions([g.strip() for g in given or []], [s.strip() for s in solve or []], names)


@app.command()
def equilibria(
    file: Path = typer.Argument(..., help="Model file (YAML)."),
    search: Optional[List[str]] = typer.Option(None, "--search", metavar="NAME=LO:HI",
                                               help="Search box of a coordinate or cyclic rate (angles: (-pi, pi])."),
    sweep_: Optional[str] = typer.Option(None, "--sweep", metavar="NAME=START:STOP:N",
                                         help="Follow every branch as parameter NAME varies (continuation)."),
    plot: Optional[Path] = typer.Option(None, "--plot", help="With --sweep: bifurcation diagram (.png, .svg)."),
    plot_coordinate: Optional[str] = typer.Option(None, "--plot-coordinate",
                                                  help="Coordinate on the diagram's axis, or eigenvalues (Re and Im "
                                                       "against the parameter)."),
    linearize_: bool = typer.Option(False, "--linearize", help="Print M, C, G, K, N and A, B about each equilibrium."),
    numeric: bool = typer.Option(False, "--numeric", help="With --linearize: numbers at each equilibrium "
                                                          "(default: expressions, then numbers)."),
    hurwitz: bool = typer.Option(False, "--hurwitz", help="Characteristic polynomial and Routh-Hurwitz conditions."),
    verify: bool = typer.Option(False, "--verify", help="Integrate from small perturbations of each equilibrium and "
                                                        "check the verdicts against the motion (exit 1 if one "
                                                        "disagrees)."),
    exhaustive: bool = typer.Option(False, "--exhaustive", help="Every isolated root of equations polynomial in the "
                                                                "unknowns, sin and cos (half-angle substitution, "
                                                                "Groebner basis) instead of the multistart; exit 2 "
                                                                "when they are not, or too large."),
    given: Optional[List[str]] = typer.Option(None, "--given", metavar="NAME",
                                              help="Nonholonomic: hold this coordinate at its file (or --set) value."),
    solve: Optional[List[str]] = typer.Option(None, "--solve", metavar="der(NAME)",
                                              help="Nonholonomic: solve for this given rate of a family instead."),
    independent: Optional[str] = typer.Option(None, "--independent", metavar="NAMES",
                                              help="Nonholonomic: comma-separated coordinates whose rates are "
                                                   "independent speeds; --linearize prints M, C, K over them."),
    fmt: TableFormat = typer.Option(TableFormat.text, "--format", "-f", help="Output format."),
    set_: Optional[List[str]] = SetOption,
    output: Optional[Path] = OutputOption,
) -> None:
    """Equilibria and steady motions, their Lyapunov stability, and (with --sweep) bifurcations."""

    def body() -> int:
        from mechsys.report import warm

        boxes = parse_ranges(search, "--search")
        sweep_spec = parse_ranges([sweep_], "--sweep", count=True) if sweep_ else {}
        if plot is not None and not sweep_spec:
            raise InputError("--plot needs --sweep")
        if verify and sweep_spec:
            raise InputError("--verify cannot be combined with --sweep (verify the equilibria at one parameter value)")
        if exhaustive and (boxes or sweep_spec):
            raise InputError("--exhaustive returns every root: it cannot be combined with --search or --sweep")
        check_figures(plot=plot)
        check_outputs(output)
        key = None if verify or plot is not None else warm.output_key(
            "equilibria", file, {"set": list(set_ or []), "search": list(search or []), "sweep": sweep_,
                                 "linearize": linearize_, "numeric": numeric, "hurwitz": hurwitz,
                                 "exhaustive": exhaustive, "given": list(given or []), "solve": list(solve or []),
                                 "independent": independent, "format": fmt.value, **warm.numeric_path()})
        if emit_kept_tables(key, fmt, output):
            return 0
        from mechsys.analysis.equilibrium.equilibria import find_equilibria
        from mechsys.report import equilibria as rep

        options = steady_options(given, solve, independent)
        model = load_model(file, set_)
        result = find_equilibria(model, boxes, exhaustive=exhaustive, options=options)
        tables = rep.equilibria_tables(result)
        verifications, failed = None, []
        if verify:
            from mechsys.analysis.equilibrium.verify import disagreements, verify_equilibria

            verifications = verify_equilibria(model, result)
            failed = disagreements(result, verifications)
            tables.append(rep.verification_table(result, verifications))
        bifurcations: list = []
        sweep_notes = None
        if sweep_spec:
            from mechsys.analysis.equilibrium.bifurcation import plot_sweep, sweep

            (name, (start, stop, n)), = sweep_spec.items()
            swept = sweep(model, name, start, stop, int(n), boxes, options, result.problem)
            bifurcations, sweep_notes = swept.bifurcations, swept.notes
            tables += rep.sweep_tables(swept)
            if plot is not None:
                write_figure(plot, lambda tmp: plot_sweep(swept, tmp, plot_coordinate))
        if (linearize_ or hurwitz) and not model.is_holonomic:
            from mechsys.analysis.equilibrium.equilibria import make_problem
            from mechsys.analysis.equilibrium.nonholonomic import linearize_steady

            problem = make_problem(model, options)
            for k, e in enumerate(result.equilibria, start=1):
                tables += rep.steady_linearization_tables(linearize_steady(problem, e), f"steady motion {k}",
                                                          options.independent, hurwitz)
        elif linearize_ or hurwitz:
            from mechsys.analysis.equilibrium.linearize import linearize, symbolic_matrices

            if linearize_ and not numeric:
                tables += rep.symbolic_tables(symbolic_matrices(model), model.coordinates)
            reduced = bool(result.cyclic) or bool(model.kin.constraints)
            for k, e in enumerate(result.equilibria, start=1):
                lin = linearize(model, e)
                label = f"equilibrium {k}" + (" (coordinate singularity: the matrices of a singular chart; the "
                                              "verdict is not read from them)" if e.chart else "")
                J = e.jacobian if reduced else None
                tables += (rep.linearization_tables(lin, label, hurwitz, J) if linearize_
                           else rep.hurwitz_tables(lin, label, J))
        payload = rep.equilibria_payload(result, bifurcations, verifications, sweep_notes)
        if sweep_spec and fmt == TableFormat.csv:
            tables, payload = [t for t in tables if t.title.startswith("branches")], None
        if not failed:
            warm.store_tables(key, tables, payload)
        emit_tables(tables, fmt, output, payload)
        for line in failed:
            sys.stderr.write(f"mechsys: verification disagrees: {line}\n")
        return 1 if failed else 0

    run(body)


@app.command()
def modes(
    file: Path = typer.Argument(..., help="Model file (YAML)."),
    at: Optional[List[str]] = typer.Option(None, "--at", metavar="NAME=VALUE",
                                           help="Equilibrium to vibrate about (default: the stable rest the model "
                                                "settles at from its initial configuration, else the first stable "
                                                "one found)."),
    frf: Optional[str] = typer.Option(None, "--frf", metavar="START:STOP:N",
                                      help="Receptance over a frequency range [rad/s]."),
    frf_input: Optional[str] = typer.Option(None, "--input", help="FRF: coordinate the force acts on."),
    frf_output: Optional[str] = typer.Option(None, "--response", help="FRF: coordinate observed."),
    plot: Optional[Path] = typer.Option(None, "--plot", help="Mode shapes (or, with --frf, the FRF) as .png/.svg."),
    state_space: bool = typer.Option(False, "--state-space", help="Print the state-space matrices A, B, C, D."),
    transfer: bool = typer.Option(False, "--transfer", help="Transfer function from --input to --response."),
    given: Optional[List[str]] = typer.Option(None, "--given", metavar="NAME",
                                              help="Nonholonomic: hold this coordinate at its file (or --set) value."),
    solve: Optional[List[str]] = typer.Option(None, "--solve", metavar="der(NAME)",
                                              help="Nonholonomic: solve for this given rate of a family instead."),
    independent: Optional[str] = typer.Option(None, "--independent", metavar="NAMES",
                                              help="Nonholonomic: coordinates whose rates are independent speeds."),
    fmt: TableFormat = typer.Option(TableFormat.text, "--format", "-f", help="Output format."),
    set_: Optional[List[str]] = SetOption,
    output: Optional[Path] = OutputOption,
) -> None:
    """Linear vibration: natural frequencies, damping ratios, mass-normalised modes, FRF, state space."""

    def body() -> int:
        from mechsys.report import warm

        point = {}
        for item in at or []:
            name, sep, value = item.partition("=")
            if not sep:
                raise InputError(f"--at {item!r}: expected NAME=VALUE")
            point[name.strip()] = _constant(value, f"--at {item!r}")
            check_number(f"--at {name.strip()}:", point[name.strip()])
        frf_range = None
        if frf:
            parts = frf.split(":")
            try:
                frf_range = (float(parts[0]), float(parts[1]), int(parts[2]))
                if len(parts) != 3 or frf_range[2] < 2:
                    raise ValueError
            except (ValueError, IndexError):
                raise InputError(f"--frf {frf!r}: expected START:STOP:N (N >= 2)") from None
            check_range(f"--frf {frf!r}", frf_range[0], frf_range[1], ends="START STOP")
            check_number(f"--frf {frf!r}: START", frf_range[0], 0.0, why="frequencies in rad/s")
            check_number(f"--frf {frf!r}: N", frf_range[2], high=MAX_POINTS)
        check_figures(plot=plot)
        check_outputs(output)
        key = None if plot is not None else warm.output_key(
            "modes", file, {"set": list(set_ or []), "at": list(at or []), "frf": frf, "input": frf_input,
                            "response": frf_output, "state_space": state_space, "transfer": transfer,
                            "given": list(given or []), "solve": list(solve or []), "independent": independent,
                            "format": fmt.value, **warm.numeric_path()})
        if emit_kept_tables(key, fmt, output):
            return 0
        from mechsys.analysis.equilibrium import modes as modal
        from mechsys.report import equilibria as rep
        from mechsys.report.tables import Table

        options = steady_options(given, solve, independent)
        model = load_model(file, set_)
        result = modal.vibration_modes(model, point or None, options)
        if result.system is None and (frf_range is not None or state_space or transfer):
            raise InputError("--frf, --state-space and --transfer need a second-order system on the coordinates; "
                             "a nonholonomic steady motion has none: `mechsys equilibria --linearize` prints its "
                             "A and B")
        tables = rep.modes_tables(result)
        payload = result.to_dict()
        if not result.coordinates and (frf_range is not None or state_space or transfer):
            raise InputError("--frf, --state-space and --transfer need a coordinate that vibrates; this steady "
                             "motion has none (every coordinate is cyclic or fixed by the constraints)")
        inp = frf_input or (result.coordinates[0] if result.coordinates else None)
        out = frf_output or inp
        if frf_range is not None:
            import numpy as np

            omegas = np.linspace(*frf_range)
            H = modal.frf(model, result, omegas, inp, out)
            t = Table(f"receptance {out}/{inp}", ["omega [rad/s]", "magnitude", "phase [rad]"])
            for w, h in zip(omegas, H):
                t.add(float(w), float(abs(h)), float(np.angle(h)))
            tables = [t] if fmt == TableFormat.csv else tables + [t]
            payload["frf"] = {"input": inp, "response": out, "omega": omegas.tolist(),
                              "magnitude": np.abs(H).tolist(), "phase": np.angle(H).tolist()}
            if plot is not None:
                write_figure(plot, lambda tmp: modal.plot_frf(omegas, H, tmp, f"{out}/{inp}"))
        elif plot is not None:
            write_figure(plot, lambda tmp: modal.plot_modes(result, tmp))
        if state_space or transfer:
            A, B, C, D = result.system.state_space()
            states = result.system.names + [f"der({c})" for c in result.system.names]
            if state_space:
                tables += [rep.matrix_table("A", states, A), rep.matrix_table("B", result.coordinates, B, states),
                           rep.matrix_table("C", states, C, result.coordinates),
                           rep.matrix_table("D", result.coordinates, D)]
                payload["state_space"] = {"states": states, "A": A.tolist(), "B": B.tolist(), "C": C.tolist(),
                                          "D": D.tolist()}
            if transfer:
                num, den = modal.transfer_function(result, inp, out)
                t = Table(f"transfer function {out}/{inp} (highest power first)", ["", "coefficients"])
                t.add("numerator", ", ".join(f"{c:.10g}" for c in num))
                t.add("denominator", ", ".join(f"{c:.10g}" for c in den))
                tables.append(t)
                payload["transfer_function"] = {"input": inp, "response": out, "numerator": list(num),
                                                "denominator": list(den)}
        warm.store_tables(key, tables, payload)
        emit_tables(tables, fmt, output, payload)
        return 0

    run(body)


@app.command()
def simulate(
    file: Path = typer.Argument(..., help="Model file (YAML)."),
    t_end: float = typer.Option(10.0, "--t-end", help="End time [s]."),
    dt: Optional[float] = typer.Option(None, "--dt", help="Output interval [s] (default t_end/1000)."),
    method: str = typer.Option("auto", "--method", "-m",
                               help="auto (stiffness check), native (compiled DOP853), RK45, DOP853, Radau, "
                                    "BDF or LSODA."),
    rtol: float = typer.Option(1e-10, "--rtol", help="Relative tolerance."),
    atol: float = typer.Option(1e-12, "--atol", help="Absolute tolerance."),
    output: Optional[Path] = typer.Option(None, "--output", "-o",
                                          help="Result file: .csv, .json or .parquet (atomic)."),
    plot: Optional[Path] = typer.Option(None, "--plot", help="Time histories, phase portrait, energy (.png/.svg)."),
    animate: Optional[Path] = typer.Option(None, "--animate",
                                           help="Animation (atomic): .html, a 3-D view of any model (one offline "
                                                "file, needs plotly); .gif, a planar mechanism."),
    fps: Optional[float] = typer.Option(None, "--fps", help="Frames per second of --animate (default: real time)."),
    events_file: Optional[Path] = typer.Option(None, "--events", help="Write the recorded events (.csv or .json)."),
    impacts_file: Optional[Path] = typer.Option(None, "--impacts", help="Write the impact table (.csv or .json)."),
    capture: float = typer.Option(1e-10, "--capture-velocity",
                                  help="Rest rule: slower impacts are plastic and the contact stays closed."),
    max_steps: float = typer.Option(1e6, "--max-steps",
                                    help="Work budget: integrator steps (20x as many RHS evaluations for scipy "
                                         "and CVODE); a run that needs more stops with the reason."),
    reactions: bool = typer.Option(False, "--reactions",
                                   help="Add joint reactions reaction(LINK).Fx..Mz (ground axes) to the result file."),
    fmt: TableFormat = typer.Option(TableFormat.text, "--format", "-f", help="Format of the summary."),
    set_: Optional[List[str]] = SetOption,
) -> None:
    """Integrate the equations of motion from the file's initial state and report speed and accuracy measures."""

    def body() -> int:
        from mechsys.report.simulation import (check_result_path, plot_histories, summary_payload, summary_table,
                                               write_result)

        check_time_grid(t_end, dt)
        check_tolerances(rtol, atol)
        check_number("--max-steps", max_steps, 1.0)
        check_number("--capture-velocity", capture, 0.0)
        if output is not None:
            check_result_path(output)  # reject a bad suffix (or Parquet without pyarrow) first
        if animate is not None:
            from mechsys.report.view3d import check_animate, write_animate

            check_animate(animate, fps)  # the suffix chooses: .html (3-D, any model) or .gif (planar)
        check_figures(plot=plot)
        check_outputs(output, animate, events_file, impacts_file)
        check_model_file(file)  # before the warm path reads it: a FIFO would hang, a device never end
        from mechsys.analysis.motion.simulate import SimulationOptions
        from mechsys.analysis.motion.warm import simulate_file
        from mechsys.report.progress import ProgressBar

        bar = ProgressBar(t_end)
        options = SimulationOptions(t_end, dt, method, rtol, atol, capture, max_steps)
        try:
            result, model = simulate_file(file, set_ or [], options, progress=bar,
                                          need_model=bool(animate or reactions))
        finally:
            bar.close()
        names, data = result.columns()
        if animate is not None:  # first: a non-planar model fails before any other file is written
            write_animate(model, result, animate, fps, source=file)
        if reactions:
            from mechsys.analysis.motion.reactions import append_reactions

            names, data = append_reactions(model, result, names, data, output)
        if output is not None:
            write_result(output, names, data)
        if plot is not None:
            plot_histories(*result.columns(), str(plot))  # atomically, through report/files.py
        if impacts_file is not None:
            from mechsys.report.simulation import impacts_text

            write_atomic(impacts_file, impacts_text(result.impacts, result.coordinates, impacts_file.suffix))
        if events_file is not None:
            from mechsys.report.simulation import events_text

            write_atomic(events_file, events_text(result.events, result.coordinates, events_file.suffix))
        emit_tables(summary_table(result), fmt, None, summary_payload(result))
        return 0

    run(body)


@app.command()
def view(
    file: Path = typer.Argument(..., help="Model file (YAML)."),
    output: Optional[Path] = typer.Option(None, "--output", "-o",
                                          help="HTML file (atomic; default: the model file's name with .html, in "
                                               "the current folder)."),
    set_: Optional[List[str]] = SetOption,
) -> None:
    """Write a 3-D view of the initial configuration as one offline HTML file (needs plotly; no integration)."""

    def body() -> int:
        from mechsys.report.view3d import check_html_path, default_view_path, write_initial_view

        target = output if output is not None else default_view_path(file)
        check_html_path(target, "--output")
        check_model_file(file)
        write_initial_view(load_model(file, set_), target)
        sys.stdout.write(f"wrote {target}\n")
        return 0

    run(body)


@app.command()
def bench(
    file: Path = typer.Argument(..., help="Model file (YAML)."),
    t_end: float = typer.Option(5.0, "--t-end", help="Horizon [s] (inside the predictability horizon)."),
    methods: str = typer.Option("native,RK45,DOP853,Radau,LSODA", "--methods", help="Comma-separated methods."),
    rtols: str = typer.Option("1e-4,1e-6,1e-8,1e-10", "--rtols", help="Comma-separated relative tolerances."),
    dt: Optional[float] = typer.Option(None, "--dt", help="Output interval [s] (default t_end/1000); it does not "
                                                          "limit the step (closed loops are projected about every "
                                                          "20 steps, at an output point)."),
    plot: Optional[Path] = typer.Option(None, "--plot", help="Work-precision diagram (.png/.svg)."),
    fmt: TableFormat = typer.Option(TableFormat.text, "--format", "-f", help="Output format."),
    set_: Optional[List[str]] = SetOption,
    output: Optional[Path] = OutputOption,
) -> None:
    """Speed against error: wall time, RHS evaluations, final error, energy balance error and constraint residual for a
    grid of methods and tolerances, against a tight reference solution."""

    def body() -> int:
        from mechsys.analysis.motion.simulate import METHODS
        from mechsys.analysis.motion.workprecision import plot_work_precision, work_precision
        from mechsys.report.tables import Table

        chosen = [m.strip() for m in methods.split(",") if m.strip()]
        bad = [m for m in chosen if m not in METHODS or m == "auto"]
        if bad:
            raise InputError(f"--methods: unknown {', '.join(bad)} (choose from {', '.join(METHODS[1:])})")
        try:
            tols = [float(x) for x in rtols.split(",") if x.strip()]
        except ValueError:
            raise InputError(f"--rtols {rtols!r}: expected comma-separated numbers") from None
        if not chosen or not tols:
            raise InputError("--methods and --rtols need at least one entry each")
        check_time_grid(t_end, dt)
        for tol in tols:
            check_tolerances(tol, option="--rtols")
        check_figures(plot=plot)
        check_outputs(output)
        points, reference = work_precision(load_model(file, set_), t_end, chosen, tols, dt)
        t = Table(f"work-precision (reference: {reference.label})",
                  ["method", "rtol", "wall time [s]", "RHS evaluations", "final error",
                   "energy balance error", "constraint residual", "note"])
        for p in points:
            t.add(p.method, p.rtol, p.seconds, p.rhs_evaluations, p.final_error, p.energy_balance_error, p.residual, p.failed)
        t.notes.append(f"reference run: {reference.seconds:.3g} s")
        if reference.note:
            t.notes.append(f"reference: {reference.note}; {reference.label} instead")
        if plot is not None:
            write_figure(plot, lambda tmp: plot_work_precision(points, tmp))
        emit_tables([t], fmt, output)
        return 0

    run(body)


@app.command("plot")
def plot_result(
    result: Path = typer.Argument(..., help="A result file written by `mechsys simulate` (.csv, .json, .parquet)."),
    output: Path = typer.Option(..., "--output", "-o", help="Figure file (.png, .svg, .pdf)."),
) -> None:
    """Plot a simulation result (time histories, rates, energy, phase portrait) or a sweep table of equilibria
    (a stability map)."""

    def body() -> int:
        from mechsys.report.simulation import is_sweep_table, plot_histories, plot_sweep_table, read_result

        check_figures(output=output)
        if is_sweep_table(result):  # a sweep table: the stability map
            plot_sweep_table(result, str(output))
            return 0
        names, data = read_result(result)
        if "t" not in names:
            raise InputError(f"{result}: not a simulation result (no 't' column)")
        plot_histories(names, data, str(output), "--output")
        return 0

    run(body)


@app.command("export")
def export_result(
    result: Path = typer.Argument(..., help="A result file written by `mechsys simulate` (.csv, .json, .parquet)."),
    output: Path = typer.Option(..., "--output", "-o",
                                help="Converted file (.csv, .json or .parquet), written atomically."),
) -> None:
    """Convert a simulation result between CSV, JSON and Parquet."""

    def body() -> int:
        from mechsys.report.simulation import check_result_path, read_result, write_result

        check_result_path(output)
        check_outputs(output)
        names, data = read_result(result)
        write_result(output, names, data)
        return 0

    run(body)


@app.command()
def collide(
    file: Path = typer.Argument(..., help="Model file (YAML) with 'contacts'."),
    impact: Optional[str] = typer.Option(None, "--impact", help="Contact to resolve (default: every approaching one)."),
    percussion: bool = typer.Option(False, "--percussion", help="Report the centre of percussion of a hinged link."),
    link: Optional[str] = typer.Option(None, "--link", help="With --percussion: the hinged link."),
    fmt: TableFormat = typer.Option(TableFormat.text, "--format", "-f", help="Output format."),
    set_: Optional[List[str]] = SetOption,
    output: Optional[Path] = OutputOption,
) -> None:
    """Resolve an impact at the file's state: velocities of separation, contact and joint impulses, energy lost."""

    def body() -> int:
        import mechsys
        from mechsys.analysis.impact.collide import centre_of_percussion, resolve
        from mechsys.model.load import parse_assignments
        from mechsys.report.tables import Table

        check_outputs(output)
        model = mechsys.load(file, parse_assignments(set_), release_prescribed=True)
        if percussion:
            cp = centre_of_percussion(model, link)
            t = Table(f"centre of percussion of {cp['link']}", ["quantity", "value"])
            t.add("I_O (about the hinge axis)", cp["I_O"])
            t.add("r_G (axis to centre of mass)", cp["r_G"])
            t.add("r_C = I_O/(m r_G)", cp["distance"])
            t.add("point (link axes)", ", ".join(f"{x:.10g}" for x in cp["point_in_link_axes"]))
            emit_tables([t], fmt, output, cp)
            return 0
        result = resolve(model, impact)
        rates = Table("velocities", ["coordinate", "before", "after"])
        for c, a, b in zip(result.coordinates, result.rates_before, result.rates_after):
            rates.add(f"der({c})", float(a), float(b))
        contacts = Table("contacts", ["contact", "normal velocity before", "after", "impulse", "tangential impulse",
                                      "mode"])
        tangential = result.to_dict()["tangential_impulse"]
        tangential = [tangential] if len(result.contacts) == 1 else tangential
        for k, name in enumerate(result.contacts):
            contacts.add(name, float(result.normal_velocity_before[k]), float(result.normal_velocity_after[k]),
                         float(result.impulses[k]), ", ".join(f"{x:.7g}" for x in tangential[k]),
                         result.modes[k] or "-")
        joints = Table("joint impulses on each link from its parent (ground axes)", ["link", "x", "y", "z"])
        for name, vec in result.joint_impulses.items():
            joints.add(name, *vec)
        energy = Table("kinetic energy", ["before", "after", "lost"])
        energy.add(result.energy_before, result.energy_after, result.energy_loss)
        for name, what in result.apart.items():
            energy.notes.append(f"contact {name!r} does not touch at this state ({what}), and its impulse depends on "
                                "where the bodies are: an impact acts where the two sides meet, so move them there "
                                "(--set) for the impact they will have")
        if result.further:
            verb = "touches and approaches" if len(result.further) == 1 else "touch and approach"
            energy.notes.append(f"after this impact {', '.join(result.further)} {verb}: further impacts follow at "
                                "the same instant (resolve again from the rates after, or run `mechsys simulate`, "
                                "which chains them)")
        tables = [rates, contacts, joints, energy]
        if result.restitution_factor < 1:
            note = Table("restitution lowered (friction would otherwise create energy)", ["factor on e"])
            note.add(result.restitution_factor)
            tables.append(note)
        emit_tables(tables, fmt, output, result.to_dict())
        return 0

    run(body)


@app.command()
def inverse(
    file: Path = typer.Argument(..., help="Model file (YAML)."),
    at: float = typer.Option(0.0, "--at", help="Time t of the instant [s] (prescribed coordinates are taken there)."),
    fmt: TableFormat = typer.Option(TableFormat.text, "--format", "-f", help="Output format."),
    set_: Optional[List[str]] = SetOption,
    output: Optional[Path] = OutputOption,
) -> None:
    """Inverse dynamics at one instant, without integrating: the file's state (prescribed coordinates at --at)
    assembled onto the constraints, its accelerations, driving forces, constraint multipliers, joint reactions
    and outputs."""

    def body() -> int:
        import mechsys
        from mechsys.analysis.motion.inverse import inverse_dynamics
        from mechsys.model.load import parse_assignments
        from mechsys.report.inverse import instant_payload, instant_tables

        check_number("--at", at)
        check_outputs(output)
        model = mechsys.load(file, parse_assignments(set_), release_prescribed=True)
        inst = inverse_dynamics(model, at)
        emit_tables(instant_tables(inst), fmt, output, instant_payload(inst))
        return 0

    run(body)


@app.command()
def check(
    paths: List[Path] = typer.Argument(..., help="Model files or directories (searched recursively)."),
    jobs: Optional[int] = typer.Option(None, "--jobs", "-j", help="Local worker processes (default: all cores)."),
    junit: Optional[Path] = typer.Option(None, "--junit", help="Write a JUnit XML report."),
    markdown: Optional[Path] = typer.Option(None, "--markdown", help="Write a Markdown report."),
    fmt: TableFormat = typer.Option(TableFormat.text, "--format", "-f", help="Format of the summary on stdout."),
) -> None:
    """Run the expectations (`expect:` or FILE.check.yaml) of model files; exit 0 only if all pass."""

    def body() -> int:
        from mechsys.analysis.batch.check import junit_xml, run_checks
        from mechsys.report.tables import Table, render_tables

        check_number("--jobs", jobs, 1, MAX_JOBS)
        check_outputs(junit, markdown)
        for path in paths:
            if path.exists() and not path.is_dir():
                check_model_file(path)
        results = run_checks([str(p) for p in paths], jobs)
        table = Table("checks", ["file", "check", "status", "measured", "expected", "message"])
        for r in results:
            table.add(os.path.relpath(r["file"]) if not r["file"].startswith("..") else r["file"], r["name"], r["status"].upper(), r["measured"], r["expected"], r["message"])
        passed = sum(r["status"] == "pass" for r in results)
        failed = sum(r["status"] == "fail" for r in results)
        errors = sum(r["status"] == "error" for r in results)
        table.notes.append(f"{passed} passed, {failed} failed, {errors} errors")
        if not results:
            table.notes.append("no expectations found")
        if junit is not None:
            write_atomic(junit, junit_xml(results))
        if markdown is not None:
            write_atomic(markdown, render_tables([table], "markdown"))
        emit_tables([table], fmt, None, {"results": results, "passed": passed, "failed": failed, "errors": errors})
        return 0 if failed == 0 and errors == 0 else 1

    run(body)


def check_task_count(axes: list, sampling: Optional[tuple[str, int]]) -> None:
    """At most MAX_TASKS tasks: the grid's product of point counts, or the --sample size."""
    if sampling is not None:
        check_number(f"--sample {sampling[0]}:N", sampling[1], high=MAX_TASKS, why="tasks of one sweep")
        return
    count = math.prod(a.n for a in axes)
    if count > MAX_TASKS:
        sizes = " x ".join(str(a.n) for a in axes)
        raise InputError(f"--param: {sizes} = {count} tasks (at most {MAX_TASKS} in one sweep)")


def _option_number(options: dict, key: str) -> Optional[float]:
    value = options.get(key)
    if isinstance(value, str):
        raise InputError(f"--option {key}={value}: expected a number")
    return value


def check_sweep_options(options: dict) -> None:
    """The numeric --option values of a sweep follow the rules of the matching command options."""
    t_end, dt = _option_number(options, "t_end"), _option_number(options, "dt")
    horizon = 10.0 if t_end is None else t_end  # the simulate task's default horizon (analysis/batch/tasks.py)
    check_time_grid(horizon, dt, "--option t_end", "--option dt")
    for key in ("start", "stop"):
        check_number(f"--option {key}", _option_number(options, key))
    check_number("--option points", _option_number(options, "points"), 2, MAX_SWEEP_POINTS, whole=True)
    for name, (lo, hi) in options.get("search", {}).items():
        check_range(f"--option search.{name}", lo, hi)
    for name, value in options.get("at", {}).items():
        check_number(f"--option at.{name}", value)


@app.command()
def sweep(
    file: Path = typer.Argument(..., help="Model file (YAML)."),
    param: Optional[List[str]] = typer.Option(
        None, "--param", "-p", metavar="NAME=START:STOP:N",
        help="Swept input: a parameter, a coordinate's initial value or der(NAME) its initial rate; N points from "
             "START to STOP. Repeatable (Cartesian grid). With --sample: NAME=LO:HI is the box."),
    run_: str = typer.Option(..., "--run", "-r", help="Analysis of each task: equilibria, simulate, modes, info, "
                                                       "bifurcations, collide or derive "
                                                       "(mechsys/analysis/batch/tasks.py)."),
    sample: Optional[str] = typer.Option(None, "--sample", metavar="latin:N|random:N",
                                         help="N points drawn inside the --param boxes instead of the grid."),
    seed: int = typer.Option(0, "--seed", help="Seed of --sample."),
    option: Optional[List[str]] = typer.Option(
        None, "--option", metavar="KEY=VALUE",
        help="Analysis option (simulate: t_end, dt, method; equilibria: search.NAME=LO:HI; modes: at.NAME=VALUE). "
             "Repeatable."),
    executor: str = typer.Option("processes", "--executor", "-e", help="processes (local) or dask."),
    jobs: Optional[int] = typer.Option(None, "--jobs", "-j", help="Worker processes (default: the CPU count)."),
    scheduler: Optional[str] = typer.Option(None, "--scheduler", metavar="ADDRESS",
                                            help="With --executor dask: an existing scheduler (tcp://host:8786); "
                                                 "default: a local cluster of --jobs workers."),
    quiet: bool = typer.Option(False, "--quiet", "-q", help="No progress bar."),
    fmt: TableFormat = typer.Option(TableFormat.text, "--format", "-f", help="Format of the summary."),
    set_: Optional[List[str]] = SetOption,
    output: Optional[Path] = typer.Option(
        None, "--output", "-o",
        help="Tidy table (.csv or .parquet), written atomically as tasks finish; an existing one is resumed. "
             "Default: CSV on stdout (summary on stderr)."),
) -> None:
    """Run one analysis over a grid or a sample of parameters and initial values: one tidy table, resumable,
    on local processes or a Dask cluster. Exit 1 only when every task failed."""

    def body() -> int:
        import difflib

        import mechsys
        from mechsys.analysis.batch import sweep as sw
        from mechsys.analysis.batch.tasks import ANALYSES
        from mechsys.model.load import parse_assignments
        from mechsys.report.tables import Table, render_tables

        analysis = run_.strip()
        if analysis not in ANALYSES:
            close = difflib.get_close_matches(analysis, list(ANALYSES), n=1)
            hint = f" (did you mean {close[0]!r}?)" if close else ""
            raise InputError(f"--run {analysis!r}: unknown analysis{hint} (choose from {', '.join(ANALYSES)})")
        if executor not in sw.EXECUTORS:
            raise InputError(f"--executor {executor!r}: choose from {', '.join(sw.EXECUTORS)}")
        if scheduler and executor != "dask":
            raise InputError("--scheduler needs --executor dask")
        check_number("--jobs", jobs, 1, MAX_JOBS)
        check_number("--seed", seed, 0)
        sampling = sw.parse_sample(sample)
        axes = sw.parse_params(param, sampled=sampling is not None)
        check_task_count(axes, sampling)
        options = sw.parse_options(option, analysis)
        check_sweep_options(options)
        sw.check_output(output)
        check_outputs(output)
        sets = parse_assignments(set_)
        model = mechsys.load(file, sets, release_prescribed=analysis == "simulate")
        sw.check_names(model, axes)
        names = [a.name for a in axes]
        tasks = sw.make_tasks(axes, sampling, seed)
        spec = sw.SweepSpec(str(file.resolve()), model.doc.text, tuple(sets.items()), analysis, options)
        resume = sw.load_resume(output, names, model, spec)

        from rich.console import Console
        from rich.progress import (BarColumn, MofNCompleteColumn, Progress, TextColumn, TimeElapsedColumn,
                                   TimeRemainingColumn)

        err = Console(stderr=True)
        bar = Progress(TextColumn(f"sweep {analysis}"), BarColumn(), MofNCompleteColumn(), TimeElapsedColumn(),
                       TimeRemainingColumn(), console=err, disable=quiet or not err.is_terminal, transient=True)
        with bar:
            job = bar.add_task("sweep", total=None)
            table, summary = sw.sweep(spec, names, tasks, resume, output, executor, jobs, scheduler,
                                      lambda k, total: bar.update(job, total=total, advance=k))
        if output is None:
            sys.stdout.write(sw.table_csv(table))
        t = Table("sweep summary", ["", "value"])
        for label, value in (("tasks", summary.tasks), ("done", summary.done), ("failed", summary.failed),
                             ("skipped (finished before)", summary.skipped), ("kept (other tasks in the file)",
                                                                             summary.kept),
                             ("executor", f"{summary.executor} ({summary.workers} worker"
                                          f"{'s' if summary.workers != 1 else ''})"),
                             ("wall time [s]", round(summary.seconds, 3)), ("output", summary.output or "stdout")):
            t.add(label, value)
        t.notes += summary.notes() + summary.errors
        payload = {**summary.to_dict(), "notes": summary.notes(), "errors": summary.errors}
        rendered = render_tables([t], fmt.value, payload)
        if isinstance(rendered, str):  # the summary goes to stderr when the table takes stdout
            (sys.stdout if output is not None else sys.stderr).write(rendered)
        else:
            (Console() if output is not None else err).print(rendered)
        if summary.tasks and summary.done + summary.skipped == 0:
            sys.stderr.write("mechsys: every task failed (see the error column)\n")
            return 1
        if summary.failed:
            sys.stderr.write(f"mechsys: {summary.failed} of {summary.tasks} tasks failed (see the error column)\n")
        return 0

    run(body)


@app.command()
def codegen(
    file: Path = typer.Argument(..., help="Model file (YAML)."),
    target: str = typer.Option(..., "--target", "-t", help="Language of the package: c, python or matlab; or fmu "
                                                           "(an FMI 2.0 Model Exchange FMU built with gcc)."),
    output: Path = typer.Option(..., "--output", "-o", help="Directory of the package (new, empty, or a previous "
                                                            "package, which is replaced; written atomically), or "
                                                            "the NAME.fmu file of --target fmu."),
    method: Method = typer.Option(Method.lagrange, "--method", "-m", help="Formulation of M and f."),
    set_: Optional[List[str]] = SetOption,
) -> None:
    """Write the equations of motion as a standalone C, Python or MATLAB/Octave package (no mechsys needed), or as
    an FMI 2.0 Model Exchange FMU."""

    def body() -> int:
        from mechsys.codegen import check_destination, check_target, render, write_directory
        from mechsys.report import warm

        if check_target(target) == "fmu":
            from mechsys.codegen.fmu import check_fmu_output, find_gcc, write_fmu

            check_fmu_output(output)
            find_gcc()
            summary = write_fmu(load_model(file, set_), output, method.value)
            for warning in summary.warnings:
                sys.stderr.write(f"mechsys: warning: {warning}\n")
            sys.stdout.write(summary.line() + "\n")
            return 0
        check_destination(output)
        # the file's name is printed in the package (its README and headers), not only its content
        key = warm.output_key("codegen", file, {"set": list(set_ or []), "method": method.value, "target": target,
                                                "name": file.name})
        files = warm.load_files(key)
        if files is None:
            files = render(load_model(file, set_), target, method.value)
            warm.store_files(key, files)
        write_directory(output, files)
        sys.stdout.write(f"wrote {output}: {', '.join(sorted(files))}\n")
        return 0

    run(body)


@app.command()
def schema(output: Optional[Path] = OutputOption) -> None:
    """Print the JSON Schema of the model language (for editor completion)."""

    def body() -> int:
        from mechsys.model.schema import json_schema

        emit(json.dumps(json_schema(), indent=2) + "\n", output)
        return 0

    run(body)


def _print_version(value: bool) -> None:
    """--version is eager: it answers before click asks for a command ("Missing command")."""
    if value:
        from mechsys import __version__

        typer.echo(f"mechsys {__version__}")
        raise typer.Exit(0)


@app.callback()
def _root(version: bool = typer.Option(False, "--version", callback=_print_version, is_eager=True,
                                       help="Print the version and exit.")) -> None:
    """Dynamics of mechanical systems from one validated YAML model."""


def main() -> None:
    """Entry point: like ``app()``, but a usage error (bad option value, missing argument, unknown command or
    option) is one line on stderr with exit 2, as every other invalid input."""
    try:
        code = app(standalone_mode=False)
    except typer.Abort:
        sys.stderr.write("mechsys: interrupted\n")
        code = 130
    except Exception as exc:  # click's ClickException family (vendored by recent typer releases): duck-typed
        if not (hasattr(exc, "format_message") and hasattr(exc, "exit_code")):
            raise
        if type(exc).__name__ == "NoArgsIsHelpError":
            exc.show()  # `mechsys` or `mechsys COMMAND` alone: the help text
        else:
            ctx = getattr(exc, "ctx", None)
            where = f" (see '{ctx.command_path} --help')" if ctx is not None else ""
            sys.stderr.write(f"mechsys: {exc.format_message()}{where}\n")
        code = exc.exit_code
    sys.exit(code if isinstance(code, int) else 0)


_ONE_SHOT = False  # main() runs in a process of its own (entry), not in a long one (tests)


#: collections of the oldest generation: after this many of the middle one (Python's default is 10)
FULL_COLLECTION_EVERY = 1000


#: entries of each of sympy's constructor caches in a `mechsys` process (sympy's default is 1,000): a derivation
#: builds the same sums and products from the same arguments far apart, and a hit gives back the object built
#: first, so equal subexpressions are one object and whatever is remembered per object (the differentiator, the
#: clean-up, the printers) works once. The 80-link chain's `derive --method kane`: 19.7 -> 18.1 s, the 40-link
#: chain's `derive` 20.7 -> 18.1 s, the same text; 40 to 70 MB more peak memory. Results are equal either way.
SYMPY_CACHE_SIZE = 100_000


def size_sympy_cache() -> None:
    """Ask for SYMPY_CACHE_SIZE entries in sympy's caches, unless the user chose a size (the variable is set) or
    sympy is imported already (its caches are sized at import). Child processes (sweep's workers) inherit it."""
    if "sympy" not in sys.modules:
        os.environ.setdefault("SYMPY_CACHE_SIZE", str(SYMPY_CACHE_SIZE))


def entry() -> None:
    """The `mechsys` executable: main() in a process of its own. What a command has loaded once its model is
    loaded (sympy, the model's expressions) lives until the process ends, so it is moved out of the garbage
    collector's view there (gc.freeze): the full collections during the analysis scan only its own objects, and
    the exit skips collecting everything (together 0.5 to 1 s of a bicycle sweep). The symbolic stages then
    build millions of expression objects, which are trees (freed by their reference counts, never by the
    collector): a full collection scans all of them and finds nothing, so full collections are made 100 times
    rarer (the young generations, where reference cycles die, are collected as usual). The 80-link chain's
    `derive --method kane`: 30.5 s -> 25.9 s, the same peak memory. Tests call main() many times in one long
    process, which must collect as usual. Before anything imports sympy, its caches are sized for derivations
    (size_sympy_cache)."""
    global _ONE_SHOT
    _ONE_SHOT = True
    size_sympy_cache()
    young, middle, _ = gc.get_threshold()
    gc.set_threshold(young, middle, FULL_COLLECTION_EVERY)
    try:
        main()
    finally:
        gc.freeze()


if __name__ == "__main__":
    entry()
