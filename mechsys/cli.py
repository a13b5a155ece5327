"""The `mechsys` command line: parses options, calls the library, renders; exit 0 ok, 1 failed, 2 bad input."""
from __future__ import annotations

import json
import os
import sys
import tempfile
from enum import Enum
from pathlib import Path
from typing import Callable, List, Optional

import typer

from mechsys.errors import InputError, MechsysError

app = typer.Typer(
    name="mechsys",
    help="Dynamics of mechanical systems from one validated YAML model.",
    add_completion=False,
    pretty_exceptions_enable=False,
    no_args_is_help=True,
)

SetOption = typer.Option(None, "--set", "-s", metavar="NAME=VALUE",
                         help="Override a parameter, a coordinate's initial value, or der(NAME) its rate. Repeatable.")
OutputOption = typer.Option(None, "--output", "-o", help="Write to this file (atomically) instead of stdout.")


class DeriveFormat(str, Enum):
    text = "text"
    latex = "latex"
    markdown = "markdown"
    json = "json"


class InfoFormat(str, Enum):
    text = "text"
    markdown = "markdown"
    json = "json"


class Method(str, Enum):
    lagrange = "lagrange"
    kane = "kane"


def write_atomic(path: Path, text: str) -> None:
    """Write ``text`` to ``path`` through a temporary file and a rename, so a failure never leaves half a file."""
    path = Path(path)
    directory = path.parent if str(path.parent) else Path(".")
    if not directory.is_dir():
        raise InputError(f"--output {path}: directory {directory} does not exist")
    fd, tmp = tempfile.mkstemp(prefix=f".{path.name}.", dir=directory)
    try:
        with os.fdopen(fd, "w", encoding="utf-8") as fh:
            fh.write(text)
        os.replace(tmp, path)
    except BaseException:
        if os.path.exists(tmp):
            os.unlink(tmp)
        raise


def emit(text: str, output: Optional[Path]) -> None:
    if output is None:
        sys.stdout.write(text)
    else:
        write_atomic(output, text)


def run(action: Callable[[], int | None]) -> None:
    """Run a command body; report mechsys errors as one line on stderr with their exit code."""
    try:
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


def load_model(file: Path, assignments: Optional[List[str]]):
    import mechsys
    from mechsys.model.load import parse_assignments

    return mechsys.load(file, parse_assignments(assignments))


@app.command()
def derive(
    file: Path = typer.Argument(..., help="Model file (YAML)."),
    method: Method = typer.Option(Method.lagrange, "--method", "-m", help="Formulation to print."),
    check: bool = typer.Option(False, "--check", help="Verify that Lagrange and Kane give the same M and f."),
    simplify: bool = typer.Option(False, "--simplify", help="Simplify every expression before printing (slow)."),
    fmt: DeriveFormat = typer.Option(DeriveFormat.text, "--format", "-f", help="Output format."),
    set_: Optional[List[str]] = SetOption,
    output: Optional[Path] = OutputOption,
) -> None:
    """Print T, V, the generalized forces Q and the equations of motion M(q,t) q'' = f(q, q', t)."""

    def body() -> int:
        from mechsys.report.derive import render, simplified

        model = load_model(file, set_)
        eq = model.equations(method.value)
        extra: dict = {}
        verdict = None
        if check:
            from mechsys.analysis.crosscheck import cross_check

            result = cross_check(model)
            verdict = result
            extra["check"] = {"agree": result.agree, "states": result.states,
                              "max_relative_difference": result.max_rel_diff, "symbolic": result.symbolic}
        if simplify:
            eq = simplified(eq)
        text = render(eq, model.name, fmt.value, extra)
        if verdict is not None and fmt.value != "json":
            prefix = "% " if fmt.value == "latex" else ""
            text += f"{prefix}check: {verdict.summary()}\n"
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
        from mechsys.analysis.info import system_info
        from mechsys.report.info import render_json, render_markdown, render_rich

        result = system_info(load_model(file, set_))
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


@app.command()
def schema(output: Optional[Path] = OutputOption) -> None:
    """Print the JSON Schema of the model language (for editor completion)."""

    def body() -> int:
        from mechsys.model.schema import json_schema

        emit(json.dumps(json_schema(), indent=2) + "\n", output)
        return 0

    run(body)


@app.callback()
def _root(version: bool = typer.Option(False, "--version", help="Print the version and exit.")) -> None:
    if version:
        from mechsys import __version__

        typer.echo(f"mechsys {__version__}")
        raise typer.Exit(0)


def main() -> None:
    app()


if __name__ == "__main__":
    main()
