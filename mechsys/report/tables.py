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
    """A table rendered at the console's width without breaking a number. A table that fits is rich's own. One
    that does not gets column widths that shrink only columns of words (wrapped at spaces) and headers (wrapped at
    spaces), never below a column's longest number or name; if even that does not fit, it is printed in blocks of
    columns, each repeating the first (a 16-coordinate model's mode shapes: rich folded -1.173315e-14 onto three
    lines, "-1.173" on the first). A block that cannot fit one column beside the first falls back to aligned plain
    text, one line per row. A title wider than its table is printed above it, not wrapped to the table's width."""

    def __init__(self, table: Table) -> None:
        from rich.cells import cell_len

        self.table = table
        self.cells = [[_cell(c) for c in row] for row in table.rows]
        columns = [[h, *(row[k] for row in self.cells)] for k, h in enumerate(table.columns)]
        tokens = [all(len(c.split()) <= 1 for c in col[1:]) for col in columns]

        def longest_word(texts: list[str]) -> int:
            return max((cell_len(w) for c in texts for w in c.split()), default=0)

        #: the widest each column is, and the narrowest it may be: its longest word, its longest cell when every cell
        #: is one token (a number, a name)
        self.natural = [max(cell_len(c) for c in col) for col in columns]
        self.least = [max(longest_word(col), max(cell_len(c) for c in col[1:]) if token and col[1:] else 0)
                      for col, token in zip(columns, tokens)]

    @staticmethod
    def _total(widths: list[int]) -> int:
        """A table's width: each column padded by one space a side, one rule between and around them."""
        return sum(w + 2 for w in widths) + len(widths) + 1

    def blocks(self, width: int) -> list[list[int]] | None:
        """The columns of each block at this width (one block when it fits); None if the first column and any
        other do not fit together."""
        n = len(self.table.columns)
        least = lambda cols: self._total([self.least[k] for k in cols])  # noqa: E731
        if least(range(n)) <= width or n <= 1:
            return [list(range(n))]
        out: list[list[int]] = []
        for k in range(1, n):
            if out and least([*out[-1], k]) <= width:
                out[-1].append(k)
            elif least([0, k]) <= width:
                out.append([0, k])
            else:
                return None
        return out

    def _widths(self, columns: list[int], width: int) -> list[int] | None:
        """Column widths that fit ``width``: None when the natural ones do (rich lays the table out), else the
        widest column above its least width narrowed one cell at a time."""
        widths = [self.natural[k] for k in columns]
        if self._total(widths) <= width:
            return None
        floor = [self.least[k] for k in columns]
        while self._total(widths) > width:
            k = max((i for i in range(len(widths)) if widths[i] > floor[i]), key=lambda i: widths[i], default=None)
            if k is None:
                break
            widths[k] -= 1
        return widths

    def _rich(self, columns: list[int], title: str, width: int):
        from rich.markup import escape
        from rich.table import Table as RichTable
        from rich.text import Text

        widths = self._widths(columns, width)
        total = self._total(widths if widths is not None else [self.natural[k] for k in columns])
        above = cell_width(title) > total
        rt = RichTable(title=None if above else escape(title))
        for i, k in enumerate(columns):
            rt.add_column(escape(self.table.columns[k]), overflow="fold", width=None if widths is None else widths[i])
        for row in self.cells:
            rt.add_row(*[Text(row[k], overflow="fold") for k in columns])
        return [Text(title), rt] if above else [rt]

    def __rich_console__(self, console, options):
        from rich.text import Text

        width = options.max_width
        blocks = self.blocks(width)
        if blocks is None:
            yield _plain_text(self.table, Text)
            return
        for columns in blocks:
            title = self.table.title
            if len(blocks) > 1:
                names = [self.table.columns[k] for k in columns[1:]]
                title += f" [{names[0]}]" if len(names) == 1 else f" [{names[0]} to {names[-1]}]"
            yield from self._rich(columns, title, width)


def cell_width(text: str) -> int:
    from rich.cells import cell_len

    return cell_len(text)


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
