"""One table type rendered as rich text, Markdown, CSV, LaTeX or JSON, so every command offers every format."""
from __future__ import annotations

import csv
import io
import json
from dataclasses import dataclass, field
from typing import TYPE_CHECKING

if TYPE_CHECKING:
    from rich.console import Group

TABLE_FORMATS = ("text", "json", "csv", "markdown", "latex")


@dataclass
class Table:
    title: str
    columns: list[str]
    rows: list[list] = field(default_factory=list)
    notes: list[str] = field(default_factory=list)

    def add(self, *cells: object) -> None:
        self.rows.append(list(cells))


def fmt_number(x: object, digits: int = 6) -> str:
    if isinstance(x, complex):
        if abs(x.imag) < 1e-15 * max(1.0, abs(x.real)):
            return fmt_number(x.real, digits)
        sign = "+" if x.imag >= 0 else "-"
        return f"{fmt_number(x.real, digits)} {sign} {fmt_number(abs(x.imag), digits)}i"
    if isinstance(x, float):
        if x == 0:
            return "0"
        if abs(x) >= 1e6 or abs(x) < 1e-4:
            return f"{x:.{digits}e}"
        return f"{x:.{digits}f}".rstrip("0").rstrip(".") if "." in f"{x:.{digits}f}" else f"{x:.{digits}f}"
    return str(x)


def _cell(x) -> str:
    return fmt_number(x) if isinstance(x, (float, complex)) else str(x)


def to_markdown(tables: list[Table]) -> str:
    out = []
    for t in tables:
        out += [f"### {t.title}", "", "| " + " | ".join(t.columns) + " |", "|" + "---|" * len(t.columns)]
        out += ["| " + " | ".join(_cell(c) for c in row) + " |" for row in t.rows]
        out += [""] + [f"- {n}" for n in t.notes] + ([""] if t.notes else [])
    return "\n".join(out) + "\n"


def to_csv(tables: list[Table]) -> str:
    buf = io.StringIO()
    writer = csv.writer(buf, lineterminator="\n")
    for k, t in enumerate(tables):
        if k:
            buf.write("\n")
        if len(tables) > 1:
            buf.write(f"# {t.title}\n")
        writer.writerow(t.columns)
        for row in t.rows:
            writer.writerow([repr(c) if isinstance(c, float) else _cell(c) for c in row])
    return buf.getvalue()


def _latex_escape(text: str) -> str:
    return (str(text).replace("\\", "\\textbackslash{}").replace("_", "\\_").replace("%", "\\%")
            .replace("&", "\\&").replace("#", "\\#"))


def to_latex(tables: list[Table]) -> str:
    out = []
    for t in tables:
        out += [f"% {t.title}", "\\begin{tabular}{" + "l" * len(t.columns) + "}", "\\hline",
                " & ".join(_latex_escape(c) for c in t.columns) + " \\\\", "\\hline"]
        out += [" & ".join(_latex_escape(_cell(c)) for c in row) + " \\\\" for row in t.rows]
        out += ["\\hline", "\\end{tabular}", ""]
    return "\n".join(out)


#: rows above which a table is printed as aligned plain text: rich measures every cell of every row (a sweep's
#: thousands of branch points took half a minute to print)
LONG_TABLE = 300


def _plain_text(t: Table, Text):
    """A long table as aligned columns under its title (numbers as in every format, never cut), one line per row
    whatever the console's width: folded at 80 columns (stdout not a terminal), the 20-link chain's equilibria,
    480 characters a row, came out as 38,576 lines of fragments."""
    cells = [list(t.columns)] + [[_cell(c) for c in row] for row in t.rows]
    widths = [max(len(r[k]) for r in cells) for k in range(len(t.columns))]
    lines = ["  ".join(c.ljust(w) for c, w in zip(r, widths)).rstrip() for r in cells]
    lines.insert(1, "  ".join("-" * w for w in widths))
    return Text("\n".join([t.title, *lines]), no_wrap=True, overflow="ignore")


def to_rich(tables: list[Table]) -> Group:
    from rich.console import Group
    from rich.table import Table as RichTable

    from rich.markup import escape
    from rich.text import Text

    parts = []
    for t in tables:
        if len(t.rows) > LONG_TABLE:
            parts.append(_plain_text(t, Text))
            parts += [Text(f"  {n}") for n in t.notes]
            continue
        rt = RichTable(title=escape(t.title))
        for c in t.columns:  # a narrow terminal folds a number onto two lines, never cuts it ("-2.54…" of -2.54e-17)
            rt.add_column(escape(c), overflow="fold")
        for row in t.rows:
            rt.add_row(*[Text(_cell(c), overflow="fold") for c in row])
        parts.append(rt)
        parts += [Text(f"  {n}") for n in t.notes]
    return Group(*parts)


def render_tables(tables: list[Table], fmt: str, payload: dict | None = None) -> str | object:
    """Text (a rich renderable), or a string in the other formats; JSON uses ``payload`` when given."""
    if fmt == "json":
        data = payload if payload is not None else {t.title: [dict(zip(t.columns, r)) for r in t.rows] for t in tables}
        return json.dumps(data, indent=2, default=_json_default) + "\n"
    if fmt == "csv":
        return to_csv(tables)
    if fmt == "markdown":
        return to_markdown(tables)
    if fmt == "latex":
        return to_latex(tables)
    return to_rich(tables)


def _json_default(x):
    import numpy as np

    if isinstance(x, np.ndarray):
        return x.tolist()
    if isinstance(x, (np.floating, np.integer)):
        return x.item()
    if isinstance(x, complex):
        return [x.real, x.imag]
    raise TypeError(type(x).__name__)
