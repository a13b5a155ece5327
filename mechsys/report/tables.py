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


class _Fitted:
    """A table rendered at the console's width without breaking a number: columns whose cells are single tokens
    (numbers, names) never wrap, columns of words wrap at spaces, and a table that does not fit even so is printed
    in blocks of columns, each repeating the first column (a 16-coordinate model's mode shapes: before, rich folded
    -1.173315e-14 onto three lines, "-1.173" on the first). A block that cannot fit one column beside the first
    falls back to aligned plain text, one line per row."""

    def __init__(self, table: Table) -> None:
        from rich.cells import cell_len

        self.table = table
        self.cells = [[_cell(c) for c in row] for row in table.rows]
        columns = [[h, *(row[k] for row in self.cells)] for k, h in enumerate(table.columns)]
        self.tokens = [all(len(c.split()) <= 1 for c in col[1:]) for col in columns]
        # the narrowest each column can be: a token column its widest cell or header, a text column its longest word
        self.least = [max(cell_len(c) for c in col) if token else max(cell_len(w) for c in col for w in [*c.split(), ""])
                      for col, token in zip(columns, self.tokens)]

    def _width(self, columns: list[int]) -> int:
        """The least width of a table of these columns: each padded by one space a side, one rule between and
        around them."""
        return sum(self.least[k] + 2 for k in columns) + len(columns) + 1

    def blocks(self, width: int) -> list[list[int]] | None:
        """The columns of each block at this width (one block when it fits); None if the first column and any
        other do not fit together."""
        n = len(self.table.columns)
        if self._width(list(range(n))) <= width or n <= 1:
            return [list(range(n))]
        out: list[list[int]] = []
        for k in range(1, n):
            if out and self._width([*out[-1], k]) <= width:
                out[-1].append(k)
            elif self._width([0, k]) <= width:
                out.append([0, k])
            else:
                return None
        return out

    def _rich(self, columns: list[int], title: str):
        from rich.markup import escape
        from rich.table import Table as RichTable
        from rich.text import Text

        rt = RichTable(title=escape(title))
        for k in columns:
            rt.add_column(escape(self.table.columns[k]), no_wrap=self.tokens[k], overflow="fold")
        for row in self.cells:
            rt.add_row(*[Text(row[k], overflow="fold") for k in columns])
        return rt

    def __rich_console__(self, console, options):
        from rich.text import Text

        blocks = self.blocks(options.max_width)
        if blocks is None:
            yield _plain_text(self.table, Text)
            return
        for columns in blocks:
            title = self.table.title if len(blocks) == 1 else (
                f"{self.table.title} [{self.table.columns[columns[1]]} to {self.table.columns[columns[-1]]}]")
            yield self._rich(columns, title)


def to_rich(tables: list[Table]) -> Group:
    from rich.console import Group
    from rich.text import Text

    parts = []
    for t in tables:
        parts.append(_plain_text(t, Text) if len(t.rows) > LONG_TABLE else _Fitted(t))
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
