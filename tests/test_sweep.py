"""`mechsys sweep`: grids and samples, the tidy table, resume, per-task failures, and identical results from the
local-process and Dask executors."""
import csv
import json
import math
import sys
from pathlib import Path

import pytest
from typer.testing import CliRunner

from mechsys.analysis.batch import sweep as sw
from mechsys.analysis.batch.tasks import run_task
from mechsys.cli import app

ROOT = Path(__file__).resolve().parents[1]
SYSTEMS = ROOT / "systems"
runner = CliRunner()


@pytest.fixture(autouse=True, scope="module")
def private_cache(tmp_path_factory):
    """One compiled-code cache for this module (workers inherit the environment)."""
    with pytest.MonkeyPatch.context() as mp:
        mp.setenv("MECHSYS_CACHE", str(tmp_path_factory.mktemp("cache")))
        yield


def invoke(*args):
    return runner.invoke(app, ["sweep", *[str(a) for a in args]])


def read(path: Path) -> list[dict]:
    with open(path, newline="") as fh:
        return list(csv.DictReader(fh))


def assert_same_table(a: Path, b: Path, tol: float = 1e-12) -> None:
    """Same columns, same rows; numbers equal to round-off; the wall-time column ignored."""
    with open(a, newline="") as fa, open(b, newline="") as fb:
        ra, rb = list(csv.reader(fa)), list(csv.reader(fb))
    assert ra[0] == rb[0], f"columns differ:\n{ra[0]}\n{rb[0]}"
    assert len(ra) == len(rb)
    skip = ra[0].index("seconds")
    for row_a, row_b in zip(ra[1:], rb[1:]):
        for k, (x, y) in enumerate(zip(row_a, row_b)):
            if k == skip or x == y:
                continue
            fx, fy = float(x), float(y)  # a non-number that differs fails here
            assert abs(fx - fy) <= tol * max(1.0, abs(fx)), f"{ra[0][k]}: {x} != {y}"


def equilibria_at(row: dict) -> dict[float, str]:
    """beta of each equilibrium in a row of an equilibria sweep -> its verdict."""
    out = {}
    for k in range(1, int(row["count"]) + 1):
        out[float(row[f"eq{k}.beta"])] = row[f"eq{k}.stability"]
    return out


# ------------------------------------------------------------------------------------- the indicator map
def test_indicator_grid_gives_the_static_characteristic(tmp_path):
    out = tmp_path / "map.csv"
    r = invoke(SYSTEMS / "indicator.yaml", "--set", "Iz=0.8", "--set", "Omega=150", "--param", "omega1=-10:10:9",
               "--run", "equilibria", "--jobs", 2, "-o", out, "-f", "json")
    assert r.exit_code == 0, r.output + r.stderr
    summary = json.loads(r.stdout)
    assert summary["tasks"] == 9 and summary["done"] == 9 and summary["failed"] == 0
    rows = read(out)
    assert len(rows) == 9 and all(row["status"] == "ok" and row["error"] == "" for row in rows)
    assert [int(row["task"]) for row in rows] == list(range(9))
    header = list(rows[0])
    assert header[:2] == ["task", "omega1"] and header[-3:] == ["status", "error", "seconds"]
    at = {float(row["omega1"]): row for row in rows}
    assert sorted(at) == [-10 + 2.5 * k for k in range(9)]
    # omega1 = -10: 20 cos(beta) - 10 = 0 besides sin(beta) = 0 -> 0, pi stable, +-pi/3 unstable
    found = equilibria_at(at[-10.0])
    expected = {0.0: "asymptotically stable", math.pi: "asymptotically stable",
                math.pi / 3: "unstable", -math.pi / 3: "unstable"}
    assert len(found) == 4
    for beta, verdict in expected.items():
        match = [v for b, v in found.items() if abs(b - beta) < 1e-6]
        assert match == [verdict], (beta, found)
    # omega1 = +10: only the vertical positions, the lower one stable
    found = equilibria_at(at[10.0])
    assert len(found) == 2 and any(abs(b) < 1e-6 and v == "asymptotically stable" for b, v in found.items())


# ------------------------------------------------------------------------------------- executors agree
@pytest.mark.filterwarnings("ignore:Port 8787 is already in use")
def test_processes_and_dask_give_identical_tables(tmp_path):
    """Equilibria on a local cluster started by mechsys (--jobs 2), a simulation on an existing cluster
    (--scheduler ADDRESS): the tables equal those of local processes."""
    distributed = pytest.importorskip("dask.distributed")
    centrifuge = [SYSTEMS / "centrifuge.yaml", "--param", "Mo=30:60:4", "--run", "equilibria"]
    motor_arm = [SYSTEMS / "motor_arm.yaml", "--param", "Mo=1:3:3", "--run", "simulate", "--option", "t_end=2"]
    with distributed.LocalCluster(n_workers=2, threads_per_worker=1, processes=True,
                                  dashboard_address=None) as cluster:
        runs = [(centrifuge, ["--jobs", 2]), (motor_arm, ["--scheduler", cluster.scheduler_address])]
        for k, (args, where) in enumerate(runs):
            local, dask = tmp_path / f"local{k}.csv", tmp_path / f"dask{k}.csv"
            r = invoke(*args, "--jobs", 2, "-o", local, "-f", "json")
            assert r.exit_code == 0, r.output + r.stderr
            r = invoke(*args, "--executor", "dask", *where, "-o", dask, "-f", "json")
            assert r.exit_code == 0, r.output + r.stderr
            summary = json.loads(r.stdout)
            assert summary["executor"] == "dask" and summary["workers"] == 2 and summary["failed"] == 0
            assert all(row["status"] == "ok" for row in read(dask))
            assert_same_table(local, dask)


def test_tasks_equal_a_fresh_load_of_each_point():
    """Compile-once reuse (with_overrides) gives what loading each point afresh gives: derived parameters follow
    (centrifuge dM = Mo/7), initial rates are inputs."""
    path = str(SYSTEMS / "centrifuge.yaml")
    spec = sw.SweepSpec(path, Path(path).read_text(), (), "simulate", {"t_end": 0.5}).payload()
    tasks = sw.make_tasks([sw.Axis("Mo", 30, 60, 2), sw.Axis("der(beta)", -1, 1, 2)])
    for res, values in zip(sw.run_chunk(spec, list(enumerate(tasks))), tasks):
        assert res["status"] == "ok", res
        fresh = run_task(path, "simulate", values, {"t_end": 0.5})
        assert res["outputs"].keys() == fresh.keys()
        for key, value in fresh.items():
            assert res["outputs"][key] == pytest.approx(value, rel=1e-12, abs=1e-12), key


def test_worker_compiles_once_and_rechecks_values_per_task(tmp_path, monkeypatch):
    from mechsys.numeric import cache

    model = tmp_path / "arm.yaml"
    model.write_text("name: arm\nparameters: {m: 1, l: 0.5, g: 9.81}\n"
                     "coordinates:\n  phi: {initial: l, rate: 0}\n"
                     "links:\n  rod:\n    joint: {type: revolute, parent: ground, axis: z, coordinate: phi}\n"
                     "    mass: m\n    center_of_mass: [l, 0, 0]\n"
                     "forces:\n  - {type: potential, value: m*g*l*(1 - cos(phi))}\n")
    calls = []
    real_key = cache.model_key
    monkeypatch.setattr(cache, "model_key", lambda *a, **k: calls.append(a) or real_key(*a, **k))
    spec = sw.SweepSpec(str(model), model.read_text(), (), "simulate", {"t_end": 0.3}).payload()
    tasks = [{"m": 2.0}, {"l": 0.25}, {"m": -1.0}, {"l": 0.7}]
    results = sw.run_chunk(spec, list(enumerate(tasks)))
    kinds = [a[1] for a in calls]
    assert len(kinds) == len(set(kinds)) and "simulate" in kinds  # each kind of compiled code (Python source,
    # native library) built once by the first task; the others reused the worker's base model
    assert [r["status"] for r in results] == ["ok", "ok", "failed", "ok"]
    assert results[2]["error"] == "links.rod.mass: must not be negative"
    for res, values in zip(results, tasks):
        if res["status"] == "ok":  # initial phi = l follows l, as in a fresh load
            assert res["outputs"] == pytest.approx(run_task(str(model), "simulate", values, {"t_end": 0.3}),
                                                   rel=1e-12, abs=1e-12)


def test_a_task_whose_inertia_makes_the_kinetic_energy_negative_fails_as_a_fresh_load_does(tmp_path):
    """A ball-jointed body with xx = yy = zz = 1 and xy = c: its moments are 1 - c, 1, 1 + c, so c = 2.5 gives
    T < 0 about (1, 1, 0)/sqrt(2); `sweep` ran it 'ok' with a negative T, where `--set c=2.5` is refused."""
    model = tmp_path / "top.yaml"
    model.write_text("name: top\nparameters: {m: 1, c: 0}\ncoordinates:\n  a1: {initial: 0.1, rate: 1}\n"
                     "  a2: {initial: 0.2, rate: 0.5}\n  a3: {initial: 0.3, rate: 2}\nlinks:\n  body:\n"
                     "    joint: {type: spherical, parent: ground, coordinates: [a1, a2, a3]}\n    mass: m\n"
                     "    inertia: {xx: 1, yy: 1, zz: 1, xy: c}\n")
    spec = sw.SweepSpec(str(model), model.read_text(), (), "info", {}).payload()
    results = sw.run_chunk(spec, list(enumerate([{"c": 0.5}, {"c": 2.5}])))
    assert [r["status"] for r in results] == ["ok", "failed"]
    assert results[1]["error"] == ("links.body.inertia: its moment about an axis the link turns about is -1.5: the "
                                   "kinetic energy would be negative")
    fresh = CliRunner().invoke(app, ["info", str(model), "--set", "c=2.5"])
    assert fresh.exit_code == 2 and "-1.5, and the kinetic energy would be negative" in fresh.output


def test_workers_get_the_model_text_not_only_its_path(tmp_path):
    """A worker on another machine has no copy of the file: the text travels with the tasks."""
    text = (SYSTEMS / "motor_arm.yaml").read_text()
    spec = sw.SweepSpec(str(tmp_path / "elsewhere" / "motor_arm.yaml"), text, (), "info", {}).payload()
    local = sw._model_file(spec)
    assert local != spec["path"] and Path(local).read_text() == text
    [res] = sw.run_chunk(spec, [(0, {"Mo": 2.0})])
    assert res["status"] == "ok" and res["outputs"]["dof"] == 2


# ------------------------------------------------------------------------------------- resume
def test_resume_skips_finished_tasks_and_equals_a_fresh_run(tmp_path):
    model = SYSTEMS / "motor_arm.yaml"
    common = ["--run", "simulate", "--option", "t_end=2", "--jobs", 1, "-f", "json"]
    out, fresh = tmp_path / "resumed.csv", tmp_path / "fresh.csv"
    r = invoke(model, "--param", "Mo=1:2:2", *common, "-o", out)
    assert r.exit_code == 0 and json.loads(r.stdout)["done"] == 2
    r = invoke(model, "--param", "Mo=1:3:3", *common, "-o", out)
    assert r.exit_code == 0, r.output + r.stderr
    summary = json.loads(r.stdout)
    assert (summary["tasks"], summary["skipped"], summary["done"]) == (3, 2, 1)
    assert invoke(model, "--param", "Mo=1:3:3", *common, "-o", fresh).exit_code == 0
    assert_same_table(out, fresh, tol=0.0)
    # a third run has nothing left to do
    r = invoke(model, "--param", "Mo=1:3:3", *common, "-o", out)
    assert json.loads(r.stdout)["skipped"] == 3 and json.loads(r.stdout)["done"] == 0
    # another set of inputs is refused rather than mixed in
    r = invoke(model, "--param", "m=1:3:3", *common, "-o", out)
    assert r.exit_code == 2 and "holds a sweep over (Mo)" in r.stderr


def test_resume_refuses_a_table_of_another_model_or_options(tmp_path):
    """A sweep run again into the same file after the model changed (a mass in the file, a --set or an
    --option) skipped every task and kept the old model's results. The rows now carry `spec` (the model text,
    --set, --run and --option), and a table made from another spec is refused; the same command still resumes."""
    source = (SYSTEMS / "motor_arm.yaml").read_text()
    model = tmp_path / "arm.yaml"
    model.write_text(source)
    common = ["--param", "Mo=1:2:2", "--run", "simulate", "--jobs", 1, "-f", "json", "-o", tmp_path / "r.csv"]
    r = invoke(model, *common, "--option", "t_end=0.5")
    assert r.exit_code == 0, r.output + r.stderr
    specs = {row["spec"] for row in read(tmp_path / "r.csv")}
    assert len(specs) == 1 and len(specs.pop()) == 12
    assert json.loads(invoke(model, *common, "--option", "t_end=0.5").stdout)["skipped"] == 2
    for changed in (["--option", "t_end=0.6"], ["--option", "t_end=0.5", "--set", "m=2"]):
        r = invoke(model, *common, *changed)
        assert r.exit_code == 2 and "holds results made from another model file" in r.stderr, r.stderr
    model.write_text(source.replace("name:", "# edited\nname:", 1))
    r = invoke(model, *common, "--option", "t_end=0.5")
    assert r.exit_code == 2 and "holds results made from another model file" in r.stderr


# ------------------------------------------------------------------------------------- failures
def test_failing_tasks_are_recorded_not_fatal(tmp_path):
    out = tmp_path / "modes.csv"
    r = invoke(SYSTEMS / "motor_arm.yaml", "--param", "m=-1:1:3", "--run", "modes", "--jobs", 1, "-o", out,
               "-f", "json")
    assert r.exit_code == 0, r.output + r.stderr
    assert json.loads(r.stdout)["failed"] == 2 and "2 of 3 tasks failed" in r.stderr
    rows = read(out)
    assert [row["status"] for row in rows] == ["failed", "failed", "ok"]
    assert rows[0]["error"] == "links.rod.mass: must not be negative"
    assert "static condensation" in rows[1]["error"] and rows[1]["mode1.frequency"] == ""
    assert float(rows[2]["mode2.frequency"]) > 0 and rows[2]["error"] == ""
    # resume re-runs the failed tasks only
    r = invoke(SYSTEMS / "motor_arm.yaml", "--param", "m=-1:1:3", "--run", "modes", "--jobs", 1, "-o", out,
               "-f", "json")
    assert json.loads(r.stdout)["skipped"] == 1 and json.loads(r.stdout)["failed"] == 2


def test_a_task_decides_cyclic_coordinates_at_its_own_values(tmp_path):
    """At m = 0 the rod's angle beta feels no force, so it is cyclic; the task at m = 1 in the same worker took that
    decision over (a with_overrides copy shared it) and vibrated about a wrong steady motion: damping ratio -402,
    6.46 rad/s, status ok. Each task now equals the model loaded fresh at its values."""
    out = tmp_path / "modes.csv"
    r = invoke(SYSTEMS / "motor_arm.yaml", "--param", "m=0:1:2", "--run", "modes", "--jobs", 1, "-o", out)
    assert r.exit_code == 0, r.output + r.stderr
    row = read(out)[1]
    fresh = run_task(str(SYSTEMS / "motor_arm.yaml"), "modes", {"m": 1.0})
    assert row["status"] == "ok"
    for key in ("mode1.frequency", "mode2.frequency", "mode1.damping_ratio", "mode2.damping_ratio"):
        assert float(row[key]) == pytest.approx(fresh[key], rel=1e-12, abs=1e-12), key


def test_every_task_failing_exits_1(tmp_path):
    out = tmp_path / "bad.csv"
    r = invoke(SYSTEMS / "motor_arm.yaml", "--param", "Mo=1:2:2", "--run", "simulate", "--option", "method=Euler",
               "--jobs", 1, "-o", out)
    assert r.exit_code == 1 and "every task failed" in r.stderr
    rows = read(out)
    assert len(rows) == 2 and all(row["status"] == "failed" and "unknown method" in row["error"] for row in rows)


# ------------------------------------------------------------------------------------- sampling and input errors
def test_latin_sampling_is_reproducible_stratified_and_inside_the_box(tmp_path):
    axes = sw.parse_params(["Mo=1:3", "der(alpha)=-2:2:7"], sampled=True)
    a = sw.make_tasks(axes, ("latin", 10), seed=3)
    assert a == sw.make_tasks(axes, ("latin", 10), seed=3) and a != sw.make_tasks(axes, ("latin", 10), seed=4)
    for axis in axes:
        values = [t[axis.name] for t in a]
        assert all(axis.start <= v <= axis.stop for v in values)
        strata = sorted(int((v - axis.start) / (axis.stop - axis.start) * 10) for v in values)
        assert strata == list(range(10))  # one point in each tenth of every axis
    r1, r2 = tmp_path / "s1.csv", tmp_path / "s2.csv"
    for out in (r1, r2):
        r = invoke(SYSTEMS / "motor_arm.yaml", "--param", "Mo=1:3", "--param", "der(alpha)=-2:2", "--run", "info",
                   "--sample", "latin:5", "--seed", 7, "--jobs", 1, "-o", out)
        assert r.exit_code == 0, r.output + r.stderr
    rows = read(r1)
    assert len(rows) == 5 and [row["Mo"] for row in rows] == [row["Mo"] for row in read(r2)]
    assert all(1 <= float(row["Mo"]) <= 3 and -2 <= float(row["der(alpha)"]) <= 2 for row in rows)
    random_tasks = sw.make_tasks(axes, ("random", 50), seed=1)
    assert all(1 <= t["Mo"] <= 3 for t in random_tasks)


@pytest.mark.parametrize("args, message", [
    (["--param", "Mo=1:3", "--run", "equilibria"], "expected NAME=START:STOP:N"),
    (["--param", "Mo=1:x:3", "--run", "equilibria"], "expected NAME=START:STOP:N"),
    (["--param", "Mo=1:3:0", "--run", "equilibria"], "expected NAME=START:STOP:N"),
    (["--run", "equilibria"], "at least one --param"),
    (["--param", "Moo=1:3:3", "--run", "equilibria"], "did you mean 'Mo'"),
    (["--param", "m=1:3:3", "--run", "bifurcations"], "needs --option parameter=... --option start=..."),
    (["--param", "Mo=1:3:3", "--run", "equilibrium"], "did you mean 'equilibria'"),
    (["--param", "Mo=1:3:3", "--run", "simulate", "--option", "t_ned=3"], "did you mean 't_end'"),
    (["--param", "Mo=1:3:3", "--run", "equilibria", "--sample", "sobol:8"], "expected latin:N or random:N"),
    (["--param", "Mo=1:3:3", "--run", "equilibria", "--executor", "ray"], "choose from processes, dask"),
    (["--param", "Mo=1:3:3", "--run", "equilibria", "--scheduler", "tcp://x:8786"], "needs --executor dask"),
    (["--param", "Mo=1:3:3", "--run", "equilibria", "-o", "out.txt"], ".csv or .parquet"),
    (["--param", "Mo=1:3:3", "--run", "equilibria", "--set", "Moo=2"], "Moo"),
])
def test_bad_input_exits_2_with_one_line(args, message):
    r = invoke(SYSTEMS / "motor_arm.yaml", *args)
    assert r.exit_code == 2, r.output + r.stderr
    assert message in r.stderr and len(r.stderr.strip().splitlines()) == 1, r.stderr


def test_prescribed_coordinate_is_not_sweepable():
    r = invoke(SYSTEMS / "indicator.yaml", "--param", "psi=0:1:2", "--run", "equilibria")
    assert r.exit_code == 2 and "psi is prescribed" in r.stderr


def test_dask_missing_is_an_input_error(monkeypatch):
    monkeypatch.setitem(sys.modules, "dask", None)
    monkeypatch.setitem(sys.modules, "dask.distributed", None)
    r = invoke(SYSTEMS / "motor_arm.yaml", "--param", "Mo=1:2:2", "--run", "info", "--executor", "dask")
    assert r.exit_code == 2 and "mechsys[dask]" in r.stderr


def test_parquet_output_or_a_clear_message(tmp_path):
    out = tmp_path / "t.parquet"
    args = [SYSTEMS / "motor_arm.yaml", "--param", "Mo=1:2:2", "--run", "info", "--jobs", 1, "-o", out]
    try:
        import pandas  # noqa: F401
        import pyarrow  # noqa: F401
    except ImportError:
        r = invoke(*args)
        assert r.exit_code == 2 and "pandas and pyarrow" in r.stderr
        return
    assert invoke(*args).exit_code == 0
    r = invoke(SYSTEMS / "motor_arm.yaml", "--param", "Mo=1:3:3", "--run", "info", "--jobs", 1, "-o", out,
               "-f", "json")
    assert json.loads(r.stdout)["skipped"] == 2
    import pandas as pd

    frame = pd.read_parquet(out)
    assert list(frame["Mo"]) == [1.0, 2.0, 3.0] and list(frame["status"]) == ["ok"] * 3


def test_without_output_the_table_goes_to_stdout():
    r = invoke(SYSTEMS / "motor_arm.yaml", "--param", "Mo=1:2:2", "--run", "info", "--jobs", 1, "-q")
    assert r.exit_code == 0
    lines = r.stdout.strip().splitlines()
    assert lines[0].startswith("task,Mo,") and len(lines) == 3 and "sweep summary" in r.stderr


def test_sweep_runs_collide_tasks(tmp_path):
    """Impacts plug into the same task interface: the bullet pendulum over the restitution coefficient follows
    phi' = m2 v rC (1+e)/(IO + m2 rC^2) (Krodkiewski eq. 3.33)."""
    out = tmp_path / "impacts.csv"
    r = runner.invoke(app, ["sweep", str(ROOT / "systems" / "bullet_pendulum.yaml"), "--param", "e=0:1:3",
                            "--run", "collide", "-o", str(out), "--jobs", "1"])
    assert r.exit_code == 0, r.output
    rows = read(out)
    assert len(rows) == 3 and all(row["status"] == "ok" for row in rows)
    for row in rows:
        e = float(row["e"])
        expected = 0.05 * 300 * 0.6 * (1 + e) / (2.0 + 0.05 * 0.6**2)
        assert abs(float(row["after.der(phi)"]) - expected) < 1e-9 * expected


def test_a_swept_start_off_the_constraints_is_named(tmp_path):
    """A slider-crank swept in its crank angle alone: theta3 and x4 keep the file's values, so the start is off the
    loop and the assembly moves it (theta3 and x4; the crank angle swept is held). The table gives where each run
    started (start.*, start_moved) and the summary says how many moved; a start on the loop (the file's theta2)
    moves by round-off only. The assembled start closes the loop: l2O sin(theta2) + l3A sin(theta3) = 0 (the
    file's geometry)."""
    out = tmp_path / "sc.csv"
    r = invoke(SYSTEMS / "slider_crank.yaml", "--param", "theta2=0.785398163397448:1.2:2", "--run", "simulate",
               "--option", "t_end=0.05", "-o", out, "-f", "json")
    assert r.exit_code == 0, r.output
    summary = json.loads(r.stdout)
    assert summary["start_moved"] == 1
    assert summary["notes"][0].startswith("1 task(s) started where the assembly onto the constraints put them")
    on, off = read(out)
    assert float(on["start_moved"]) < 1e-9 < float(off["start_moved"])
    assert abs(float(on["start.theta2"]) - math.pi / 4) < 1e-12
    import mechsys

    p = mechsys.load(SYSTEMS / "slider_crank.yaml").parameters
    th2, th3 = float(off["start.theta2"]), float(off["start.theta3"])
    assert th2 == 1.2
    assert abs(p["l2O"] * math.sin(th2) + p["l3A"] * math.sin(th3)) < 1e-9
