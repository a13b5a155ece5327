"""Text tables at the console's width (report/tables.py `_Fitted`): numbers are never cut or broken across lines,
words and headers wrap at spaces, wide tables print in blocks of columns, and a title wider than its table is
printed above it whole (a 1 x 1 matrix's title came out one or two words per line)."""
from __future__ import annotations

from rich.console import Console

from mechsys.report.tables import Table, to_rich


def _render(table: Table, width: int) -> list[str]:
    console = Console(width=width, record=True)
    console.print(to_rich([table]), crop=False)
    return console.export_text().splitlines()


def test_a_narrow_table_keeps_its_long_title_on_one_line_above_it():
    t = Table("C+G (about any state of rest; expressions of the coordinates)", ["", "th"])
    t.add("th", "c")
    lines = _render(t, 80)
    assert lines[0] == "C+G (about any state of rest; expressions of the coordinates)"
    assert lines[1].startswith("┏") and max(len(line) for line in lines) <= 80


def test_a_table_that_fits_keeps_rich_layout_and_centred_title():
    t = Table("verdicts", ["#", "reason"])
    t.add(1, "all eigenvalues have negative real parts")
    lines = _render(t, 80)
    assert lines[0].strip() == "verdicts" and lines[0].startswith(" ")  # centred over the table, as rich does
    assert "all eigenvalues have negative real parts" in lines[-2]


def test_words_and_headers_wrap_numbers_do_not():
    """Five columns wider than 80 as they stand: the text column and the long header wrap at spaces; every number
    stays whole on one line, and the table is one block."""
    t = Table("modes of the linearized motion", ["#", "eigenvalue", "natural frequency [rad/s]", "frequency [Hz]",
                                                 "damping ratio"])
    t.add(1, complex(-0.2, 5.026639), 5.030616, 0.800647, 0.039757)
    t.add(2, -4.25216, "-", "-", "non-oscillatory (real root)")
    lines = _render(t, 80)
    assert max(len(line) for line in lines) <= 80
    assert sum(line.startswith("┏") for line in lines) == 1
    cells = {c.strip() for line in lines if line.startswith("│") for c in line.split("│")[1:-1]}
    assert {"-0.2 + 5.026639i", "5.030616", "0.800647", "0.039757", "-4.25216"} <= cells
    assert "non-oscillatory" in cells and "(real root)" in cells


def test_a_block_of_one_column_is_titled_by_it():
    t = Table("shapes", ["coordinate", "mode 1", "mode 2"])
    t.add("x", -1.173315e-14, 2.5)
    lines = _render(t, 31)
    assert any(line.strip() == "shapes [mode 1]" for line in lines)
    assert any(line.strip() == "shapes [mode 2]" for line in lines)
