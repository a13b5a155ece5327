"""Parquet result files: `simulate -o r.parquet`, `export`, `plot`, and the message when pyarrow is missing."""
import json
import sys
from pathlib import Path

import numpy as np
import pytest
from typer.testing import CliRunner

from mechsys.cli import app

ROOT = Path(__file__).resolve().parents[1]
runner = CliRunner()


def invoke(*args):
    return runner.invoke(app, [str(a) for a in args])


def read_csv(path: Path) -> tuple[list[str], np.ndarray]:
    lines = path.read_text().splitlines()
    return lines[0].split(","), np.array([[float(x) for x in ln.split(",")] for ln in lines[1:]])


def simulate_to(out: Path, model: str = "slider_crank") -> None:
    r = invoke("simulate", ROOT / "systems" / f"{model}.yaml", "--t-end", 0.3, "--dt", 0.01, "-o", out)
    assert r.exit_code == 0, r.stderr


def test_simulate_parquet_equals_csv(tmp_path):
    pq = pytest.importorskip("pyarrow.parquet")
    simulate_to(tmp_path / "r.csv")
    simulate_to(tmp_path / "r.parquet")
    names, values = read_csv(tmp_path / "r.csv")
    table = pq.read_table(tmp_path / "r.parquet")
    assert table.column_names == names
    assert names[:4] == ["t", "theta2", "theta3", "x4"] and "der(theta2)" in names
    assert all(str(table.schema.field(n).type) == "double" for n in names)
    data = np.column_stack([table.column(n).to_numpy() for n in names])
    assert data.shape == values.shape == (31, len(names))
    assert np.array_equal(data, values)  # bit for bit: CSV floats are written with repr()


def test_export_and_plot_read_parquet(tmp_path):
    pytest.importorskip("pyarrow")
    simulate_to(tmp_path / "r.csv", "double_pendulum")
    assert invoke("export", tmp_path / "r.csv", "-o", tmp_path / "r.parquet").exit_code == 0
    r = invoke("export", tmp_path / "r.parquet", "-o", tmp_path / "back.json")
    assert r.exit_code == 0, r.stderr
    names, values = read_csv(tmp_path / "r.csv")
    back = json.loads((tmp_path / "back.json").read_text())
    assert back["columns"] == names and np.array_equal(np.array(back["data"]), values)
    png = tmp_path / "r.png"
    r = invoke("plot", tmp_path / "r.parquet", "-o", png)
    assert r.exit_code == 0, r.stderr
    assert png.stat().st_size > 1000
    leftovers = sorted(p.name for p in tmp_path.iterdir())
    assert leftovers == ["back.json", "r.csv", "r.parquet", "r.png"]  # atomic writes leave no temporary files


def test_unreadable_parquet_is_an_input_error(tmp_path):
    pytest.importorskip("pyarrow")
    bad = tmp_path / "bad.parquet"
    bad.write_text("t,x\n0,1\n")
    r = invoke("plot", bad, "-o", tmp_path / "x.png")
    assert r.exit_code == 2 and "not a mechsys result file" in r.stderr and "Traceback" not in r.stderr
    r = invoke("export", tmp_path / "missing.parquet", "-o", tmp_path / "x.csv")
    assert r.exit_code == 2 and "cannot read" in r.stderr


def _without_pyarrow(monkeypatch):
    for mod in ("pyarrow", "pyarrow.parquet"):
        monkeypatch.setitem(sys.modules, mod, None)


def test_parquet_without_pyarrow_names_the_extra(tmp_path, monkeypatch):
    _without_pyarrow(monkeypatch)
    monkeypatch.setattr("mechsys.analysis.motion.simulate.simulate", lambda *a, **k: pytest.fail("simulated"))
    out = tmp_path / "r.parquet"
    r = invoke("simulate", ROOT / "systems" / "double_pendulum.yaml", "-o", out)
    assert r.exit_code == 2 and "pip install mechsys[parquet]" in r.stderr
    assert len(r.stderr.strip().splitlines()) == 1 and "Traceback" not in r.stderr
    assert not out.exists()
    csv = tmp_path / "r.csv"
    csv.write_text("t,x\n0.0,1.0\n")
    r = invoke("export", csv, "-o", out)
    assert r.exit_code == 2 and "pip install mechsys[parquet]" in r.stderr and not out.exists()
    r = invoke("plot", tmp_path / "other.parquet", "-o", tmp_path / "x.png")
    assert r.exit_code == 2 and "pip install mechsys[parquet]" in r.stderr


def test_csv_and_json_unchanged_and_bad_suffix_lists_parquet(tmp_path):
    from mechsys.report.simulation import result_bytes, result_text

    names, data = ["t", "x"], np.array([[0.0, 0.1], [0.5, 1 / 3]])
    assert result_bytes(names, data, ".csv") == result_text(names, data, ".csv").encode()
    assert result_text(names, data, ".csv") == "t,x\n0.0,0.1\n0.5,0.3333333333333333\n"
    assert json.loads(result_bytes(names, data, ".json")) == {"columns": names, "data": data.tolist()}
    r = invoke("simulate", ROOT / "systems" / "double_pendulum.yaml", "-o", tmp_path / "r.txt")
    assert r.exit_code == 2 and ".csv, .json or .parquet" in r.stderr
