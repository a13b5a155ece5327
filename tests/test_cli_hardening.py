"""The command line never gives a silent wrong answer: numeric options, output files, model files, result files,
--version, help texts and library warnings (issue 10)."""
from __future__ import annotations

import errno
import json
import os
import resource
import stat
import subprocess
import sys
from pathlib import Path

import pytest
from typer.testing import CliRunner

from mechsys.cli import app

ROOT = Path(__file__).resolve().parents[1]
PENDULUM = ROOT / "systems" / "double_pendulum.yaml"
runner = CliRunner()


def invoke(*args):
    return runner.invoke(app, [str(a) for a in args])


def one_line(result, code: int = 2) -> str:
    """The single stderr line of a failed command (no traceback, no usage box, nothing on stdout)."""
    detail = f"exit={result.exit_code} stdout={result.stdout!r} stderr={result.stderr!r}"
    assert result.exit_code == code, detail
    assert "Traceback" not in result.stderr and "internal error" not in result.stderr, detail
    assert result.stdout == "" and len(result.stderr.strip().splitlines()) == 1, detail
    return result.stderr.strip()


def run_cli(args: list, tmp_path: Path, timeout: float = 60, memory: int | None = None) -> subprocess.CompletedProcess:
    env = {k: v for k, v in os.environ.items() if k != "MECHSYS_DEBUG"}
    env["PYTHONPATH"] = str(ROOT) + os.pathsep + env.get("PYTHONPATH", "")
    env["MECHSYS_CACHE"] = str(tmp_path / "cache")

    def limit() -> None:  # a runaway read fails with MemoryError instead of taking the machine down
        if memory:
            resource.setrlimit(resource.RLIMIT_AS, (memory, memory))

    return subprocess.run([sys.executable, "-m", "mechsys", *map(str, args)], cwd=tmp_path, env=env,
                          capture_output=True, text=True, timeout=timeout, preexec_fn=limit)


@pytest.fixture
def no_analysis(monkeypatch):
    """Options must be refused before any model is loaded or analysed."""
    def fail(*args, **kwargs):
        pytest.fail("the command went on to load the model")

    monkeypatch.setattr("mechsys.load", fail)
    monkeypatch.setattr("mechsys.analysis.motion.warm.simulate_file", fail)


# ----------------------------------------------------------------------------------------- 1. numeric options
NUMERIC_CASES = [
    (["simulate", PENDULUM, "--t-end", "inf"], "--t-end inf: must be a finite number"),
    (["simulate", PENDULUM, "--t-end", "nan"], "--t-end nan: must be a finite number"),
    (["simulate", PENDULUM, "--t-end", "1e300"], "--t-end 1e+300: must be at most 1e+09"),
    (["simulate", PENDULUM, "--t-end", "-1"], "--t-end -1: must be positive"),
    (["simulate", PENDULUM, "--t-end", "1", "--dt", "-1"], "--dt -1: must be positive"),
    (["simulate", PENDULUM, "--t-end", "1", "--dt", "nan"], "--dt nan: must be a finite number"),
    (["simulate", PENDULUM, "--t-end", "1", "--dt", "1e-12"], "--dt 1e-12: 1e+12 output points"),
    (["simulate", PENDULUM, "--t-end", "1", "--dt", "5"], "--dt 5: must be at most 1 (the horizon --t-end is 1)"),
    (["simulate", PENDULUM, "--rtol", "0"], "--rtol 0: must be at least 2.22e-14 (100 x machine epsilon"),
    (["simulate", PENDULUM, "--rtol", "-1"], "--rtol -1: must be at least 2.22e-14"),
    (["simulate", PENDULUM, "--rtol", "1"], "--rtol 1: must be less than 1"),
    (["simulate", PENDULUM, "--atol", "0"], "--atol 0: must be positive"),
    (["simulate", PENDULUM, "--atol", "-1"], "--atol -1: must be positive"),
    (["simulate", PENDULUM, "--atol", "nan"], "--atol nan: must be a finite number"),
    (["simulate", PENDULUM, "--max-steps", "nan"], "--max-steps nan: must be a finite number"),
    (["simulate", PENDULUM, "--max-steps", "0"], "--max-steps 0: must be at least 1"),
    (["simulate", PENDULUM, "--max-steps", "-3"], "--max-steps -3: must be at least 1"),
    (["simulate", PENDULUM, "--capture-velocity", "nan"], "--capture-velocity nan: must be a finite number"),
    (["simulate", PENDULUM, "--plot", "x.foo"], "--plot x.foo: unsupported figure format '.foo'"),
    (["bench", PENDULUM, "--t-end", "nan"], "--t-end nan: must be a finite number"),
    (["bench", PENDULUM, "--rtols", "1e-6,0"], "--rtols 0: must be at least 2.22e-14"),
    (["equilibria", PENDULUM, "--sweep", "m1=1:2:1000000000000"], "N 1e+12: must be at most 1000"),
    (["equilibria", PENDULUM, "--sweep", "m1=1:inf:10"], "--sweep 'm1=1:inf:10': inf is not a finite number"),
    (["equilibria", PENDULUM, "--search", "theta1=nan:1"], "nan is not a finite number"),
    (["equilibria", PENDULUM, "--search", "theta1=5:-5"], "--search 'theta1=5:-5': LO must be less than HI"),
    (["modes", PENDULUM, "--frf", "0:nan:10"], "--frf '0:nan:10': nan is not a finite number"),
    (["modes", PENDULUM, "--frf", "0:10:100000000000"], "N 1e+11: must be at most 1e+07"),
    (["modes", PENDULUM, "--frf", "-5:10:10"], "START -5: must be at least 0"),
    (["modes", PENDULUM, "--frf", "10:1:10"], "START must be less than STOP"),
    (["modes", PENDULUM, "--at", "theta1=nan"], "--at theta1: nan: must be a finite number"),
    (["check", "--jobs", "0", PENDULUM], "--jobs 0: must be at least 1"),
    (["check", "--jobs", "-2", PENDULUM], "--jobs -2: must be at least 1"),
    (["sweep", PENDULUM, "-p", "m1=1:2:3", "-r", "info", "--jobs", "0"], "--jobs 0: must be at least 1"),
    (["sweep", PENDULUM, "-p", "m1=1:2:3", "-r", "info", "--seed", "-1"], "--seed -1: must be at least 0"),
    (["sweep", PENDULUM, "-p", "m1=1:2:100000000", "-r", "info"], "--param: 100000000 = 100000000 tasks"),
    (["sweep", PENDULUM, "-p", "m1=1:2", "--sample", "latin:100000000000", "-r", "info"], "must be at most 1e+06"),
    (["sweep", PENDULUM, "-p", "m1=1:2:3", "-r", "simulate", "--option", "t_end=nan"],
     "--option t_end nan: must be a finite number"),
    (["sweep", PENDULUM, "-p", "m1=1:2:3", "-r", "simulate", "--option", "t_end=1", "--option", "dt=-1"],
     "--option dt -1: must be positive"),
    (["sweep", PENDULUM, "-p", "m1=1:2:3", "-r", "simulate", "--option", "t_end=abc"],
     "--option t_end=abc: expected a number"),
    (["sweep", PENDULUM, "-p", "m1=1:2:3", "-r", "bifurcations", "--option", "parameter=m2", "--option", "start=0",
      "--option", "stop=1", "--option", "points=5000"], "--option points 5000: must be at most 1000"),
]


@pytest.mark.parametrize("args, message", NUMERIC_CASES, ids=[" ".join(map(str, a[2:])) or a[0]
                                                               for a, _ in NUMERIC_CASES])
def test_numeric_options_are_refused_with_one_line_before_any_work(args, message, no_analysis, tmp_path,
                                                                   monkeypatch):
    monkeypatch.chdir(tmp_path)
    monkeypatch.setattr("mechsys.analysis.batch.check.run_checks", lambda *a, **k: pytest.fail("checks ran"))
    line = one_line(invoke(*args))
    assert message in line


# ----------------------------------------------------------------------------------------- 2. output files
def test_output_to_a_directory_is_one_line_before_the_run(tmp_path, no_analysis):
    target = tmp_path / "out.csv"
    target.mkdir()
    line = one_line(invoke("simulate", PENDULUM, "-o", target))
    assert line == f"mechsys: cannot write {target}: it is a directory"


def test_output_to_a_fifo_or_a_device_is_refused_and_left_alone(tmp_path, no_analysis):
    fifo = tmp_path / "fifo.csv"
    os.mkfifo(fifo)
    targets = [fifo]
    if os.geteuid() == 0:  # a /dev/full of our own: writes fail with ENOSPC
        device = tmp_path / "full.csv"
        os.mknod(device, stat.S_IFCHR | 0o666, os.makedev(1, 7))
        targets.append(device)
    for target in targets:
        line = one_line(invoke("simulate", PENDULUM, "-o", target))
        assert line == f"mechsys: cannot write {target}: not a regular file (a device, FIFO or socket); give a " \
                       "file name"
        assert not stat.S_ISREG(os.lstat(target).st_mode)
    fifo_out = tmp_path / "fifo.txt"
    os.mkfifo(fifo_out)
    assert "not a regular file" in one_line(invoke("derive", PENDULUM, "-o", fifo_out))
    assert stat.S_ISFIFO(os.lstat(fifo_out).st_mode)


def test_output_in_a_missing_or_unwritable_folder(tmp_path, monkeypatch):
    missing = tmp_path / "nodir"
    line = one_line(invoke("derive", PENDULUM, "-o", missing / "x.txt"))
    assert line == f"mechsys: cannot write {missing / 'x.txt'}: directory {missing} does not exist"
    real_access = os.access
    monkeypatch.setattr(os, "access", lambda p, mode, **k: False if Path(p) == tmp_path else real_access(p, mode))
    line = one_line(invoke("derive", PENDULUM, "-o", tmp_path / "x.txt"))
    assert line == f"mechsys: cannot write {tmp_path / 'x.txt'}: permission denied (directory {tmp_path})"


def test_a_full_disk_is_one_line_and_leaves_no_file(tmp_path, monkeypatch):
    def full(self, data, *args, **kwargs):
        with open(self, "w") as fh:
            fh.write(data[:10])
        raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC))

    monkeypatch.setattr(Path, "write_text", full)
    target = tmp_path / "eq.txt"
    line = one_line(invoke("derive", PENDULUM, "-o", target))
    assert line == f"mechsys: cannot write {target}: no space left on device"
    assert list(tmp_path.iterdir()) == []


def test_a_permission_error_while_creating_the_temporary_file(tmp_path, monkeypatch):
    def denied(*args, **kwargs):
        raise PermissionError(errno.EACCES, os.strerror(errno.EACCES))

    monkeypatch.setattr("tempfile.mkstemp", denied)
    target = tmp_path / "schema.json"
    assert one_line(invoke("schema", "-o", target)) == f"mechsys: cannot write {target}: permission denied"


def test_output_through_a_symlink_writes_the_target_and_keeps_the_link(tmp_path):
    target, link = tmp_path / "real.json", tmp_path / "link.json"
    target.write_text("old")
    link.symlink_to(target)
    r = invoke("schema", "-o", link)
    assert r.exit_code == 0, r.stderr
    assert link.is_symlink() and json.loads(target.read_text())["title"]
    assert sorted(p.name for p in tmp_path.iterdir()) == ["link.json", "real.json"]


@pytest.mark.parametrize("error", [KeyboardInterrupt, OSError(errno.ENOSPC, "No space left on device")])
def test_an_interrupted_figure_leaves_neither_the_figure_nor_a_temporary_file(tmp_path, monkeypatch, error):
    from matplotlib.figure import Figure

    result = tmp_path / "r.json"
    result.write_text(json.dumps({"columns": ["t", "x", "der(x)"], "data": [[0, 1, 0], [1, 0, -1], [2, -1, 0]]}))

    def broken(self, fname, *args, **kwargs):
        Path(fname).write_bytes(b"\x89PNG half a figure")
        raise error

    monkeypatch.setattr(Figure, "savefig", broken)
    png = tmp_path / "r.png"
    r = invoke("plot", result, "-o", png)
    if error is KeyboardInterrupt:
        assert r.exit_code == 130 and "interrupted" in r.stderr
    else:
        assert one_line(r) == f"mechsys: cannot write {png}: no space left on device"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["r.json"]


def test_figures_of_the_analyses_are_written_atomically(tmp_path, monkeypatch):
    """modes --plot goes through the atomic writer: the temporary file keeps the suffix, so the format is right."""
    seen = []
    import mechsys.report.files as files

    real = files.atomic_write
    monkeypatch.setattr(files, "atomic_write", lambda path, write: (seen.append(Path(path)), real(path, write)))
    svg = tmp_path / "modes.svg"
    r = invoke("modes", PENDULUM, "--plot", svg)
    assert r.exit_code == 0, r.stderr
    assert seen == [svg] and svg.read_text().lstrip().startswith("<?xml")
    assert sorted(p.name for p in tmp_path.iterdir()) == ["modes.svg"]


# ----------------------------------------------------------------------------------------- 3. model files
def test_a_fifo_as_model_file_is_refused_instead_of_hanging(tmp_path):
    fifo = tmp_path / "model.yaml"
    os.mkfifo(fifo)
    for command in (["info"], ["simulate"], ["sweep", "-p", "m1=1:2:2", "-r", "info"]):
        proc = run_cli([command[0], fifo, *command[1:]], tmp_path, timeout=60)
        assert proc.returncode == 2 and proc.stdout == "", proc.stderr
        assert proc.stderr == f"mechsys: {fifo}: cannot read: not a regular file (a device, FIFO or socket)\n"


def test_dev_zero_as_model_file_is_refused_instead_of_read_forever(tmp_path):
    proc = run_cli(["simulate", "/dev/zero"], tmp_path, timeout=60, memory=2 * 2**30)
    assert proc.returncode == 2, proc.stderr
    assert proc.stderr == "mechsys: /dev/zero: cannot read: not a regular file (a device, FIFO or socket)\n"


def test_a_model_file_over_10_mb_is_refused(tmp_path):
    big = tmp_path / "big.yaml"
    with open(big, "wb") as fh:
        fh.truncate(10 * 2**20 + 1)
    line = one_line(invoke("info", big))
    assert line == f"mechsys: {big}: cannot read: larger than 10 MB (the limit of a model file)"


def test_an_unreadable_model_file_is_one_line(tmp_path, monkeypatch):
    model = tmp_path / "model.yaml"
    model.write_text(PENDULUM.read_text())
    if os.geteuid() != 0:
        model.chmod(0)
    else:  # root reads anything: make the open fail as it would for a user
        real_open = os.open

        def deny(path, *args, **kwargs):
            if Path(path) == model:
                raise PermissionError(errno.EACCES, os.strerror(errno.EACCES), str(path))
            return real_open(path, *args, **kwargs)

        monkeypatch.setattr(os, "open", deny)
    assert one_line(invoke("info", model)) == f"mechsys: {model}: cannot read: permission denied"


# ----------------------------------------------------------------------------------------- 4. result files
BAD_RESULTS = [
    ("latin1.csv", b"t,x\n0,1\n\xff\xfe,2\n", "not a mechsys result file: not UTF-8 text (byte 8)"),
    ("empty.csv", b"", "(CSV with a header row): the file is empty"),
    ("header.csv", b"t,x\n", "(CSV with a header row): no rows"),
    ("cut.csv", b"t,x\n0,1\n1,", "(CSV with a header row): line 3 is not a row of numbers"),
    ("twice.csv", b"t,x,x\n0,1,2\n", "repeated column 'x'"),
    ("cut.json", b'{"columns": ["t"], "da', "invalid JSON at line 1, column 20"),
    ("list.json", b"[1, 2]", "expected an object with 'columns' and 'data'"),
    ("letters.json", b'{"columns": "tx", "data": [[0, 1]]}', "the columns must be a list of names"),
    ("wide.json", b'{"columns": ["t", "x"], "data": [[0, 1, 2]]}', "a row does not have 2 values"),
    ("text.json", b'{"columns": ["t", "x"], "data": [[0, "1"]]}', "a value is not a number"),
    ("sweep.csv", b"m,status\n\xff,ok\n", "not UTF-8 text"),
    ("map.csv", b"task,m,status,eq1.x,eq1.stability\n1,abc,ok,0.5,stable\n", "column 'm': 'abc' is not a number"),
]


BAD_CASES = [(c, o, *bad) for c, o in (("plot", "out.png"), ("export", "out.json")) for bad in BAD_RESULTS
             if c == "plot" or bad[0] != "map.csv"]  # a sweep table (map.csv) is plotted, never exported


@pytest.mark.parametrize("command, out, name, content, message", BAD_CASES,
                         ids=[f"{c[0]}-{c[2]}" for c in BAD_CASES])
def test_bad_result_files_are_one_line(tmp_path, command, out, name, content, message):
    path = tmp_path / name
    path.write_bytes(content)
    line = one_line(invoke(command, path, "-o", tmp_path / out))
    assert line.startswith(f"mechsys: {path}: ") and message in line
    assert not (tmp_path / out).exists()


def test_plot_of_a_table_without_time_names_the_file(tmp_path):
    path = tmp_path / "x.csv"
    path.write_text("x,y\n0,1\n")
    assert one_line(invoke("plot", path, "-o", tmp_path / "x.png")) == \
        f"mechsys: {path}: not a simulation result (no 't' column)"


# ----------------------------------------------------------------------------------------- usage errors
@pytest.mark.parametrize("args, message", [
    (["simulate", PENDULUM, "--t-end", "abc"], "Invalid value for '--t-end'"),
    (["simulate"], "Missing argument"),
    (["simulatee", PENDULUM], "No such command 'simulatee'. Did you mean 'simulate'?"),
    (["info", PENDULUM, "--bogus"], "No such option: --bogus"),
    (["info", PENDULUM, "-f", "yaml"], "Invalid value for '--format'"),
])
def test_usage_errors_are_one_line_with_exit_2(args, message, tmp_path):
    """click/typer print usage errors as a usage block (or a box); the mechsys entry point says them in one line
    like every other invalid input."""
    proc = run_cli(args, tmp_path)
    assert proc.returncode == 2, proc.stderr
    lines = proc.stderr.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("mechsys: ") and message in lines[0], proc.stderr
    assert "--help" in lines[0]


def test_no_command_still_shows_the_help(tmp_path):
    proc = run_cli([], tmp_path)
    assert "Usage: " in proc.stdout + proc.stderr and "simulate" in proc.stdout + proc.stderr


# ----------------------------------------------------------------------------------------- 5-7
def test_version_prints_the_version_and_exits_0():
    import mechsys

    r = invoke("--version")
    assert r.exit_code == 0 and r.stdout == f"mechsys {mechsys.__version__}\n", r.output


@pytest.mark.parametrize("command, unit", [("simulate", "End time [s]."), ("modes", "[rad/s]"),
                                            ("bench", "Horizon [s]")])
def test_help_keeps_the_units_in_brackets(command, unit):
    r = invoke(command, "--help")
    assert r.exit_code == 0
    assert unit in " ".join(r.stdout.split())


def test_library_warnings_do_not_reach_the_terminal(tmp_path):
    code = ("import numpy as np\n"
            "import typer\n"
            "from mechsys.cli import run\n"
            "try:\n"
            "    run(lambda: 0 if np.all(np.isinf(np.ones(2) / np.zeros(2))) else 1)\n"
            "except typer.Exit as exc:\n"
            "    raise SystemExit(exc.exit_code)\n")
    env = {k: v for k, v in os.environ.items() if k not in ("MECHSYS_DEBUG", "PYTHONWARNINGS")}
    env["PYTHONPATH"] = str(ROOT)
    proc = subprocess.run([sys.executable, "-c", code], env=env, capture_output=True, text=True, timeout=60)
    assert proc.returncode == 0 and proc.stderr == "", proc.stderr


def test_overflowing_linearizations_are_reasoned_not_internal_errors(tmp_path):
    """A slider-crank whose rod is 1e200 long (found by the CLI fuzz, seed 20261126161154): its mass matrix
    overflows. codegen's regularity check evaluated the generated code with Python's raising float arithmetic
    (OverflowError, an internal error); the stability of an equilibrium ran an SVD on infinities (LinAlgError).
    Now codegen and modes refuse with one line, and equilibria reports the equilibrium undecided, saying why. The
    crank is held (w = 0) for modes and equilibria: driven, the model is non-autonomous and has no equilibria (the
    overflow had hidden that: d/dt of its equations was inf and compared as 0)."""
    text = (ROOT / "tests" / "data" / "crank_past_its_limit.yaml").read_text()
    text = text.replace("b: 0.16", "b: 1.0e+200").replace("{initial: -asin(a*sin(th0)/b), rate: 0}",
                                                           "{initial: 0.1, rate: 0}")
    model = tmp_path / "crank.yaml"
    model.write_text(text)
    assert "1.0e+200" in model.read_text() and "initial: 0.1" in model.read_text()
    line = one_line(invoke("codegen", model, "-t", "c", "-m", "kane", "-o", tmp_path / "package", "--set", "m=0"), 1)
    assert "singular" in line
    for extra in ([], ["--set", "m=0"]):
        assert "not finite" in one_line(invoke("modes", model, "--set", "w=0", *extra), 1)
    assert "non-autonomous" in one_line(invoke("equilibria", model, "--set", "m=0"), 1)
    result = invoke("equilibria", model, "--set", "m=0", "--set", "w=0", "-f", "json")
    assert result.exit_code == 0, result.output
    verdicts = {(e["stability"], e["reason"].split(" (")[0]) for e in json.loads(result.stdout)["equilibria"]}
    assert ("undecided", "the linearized equations are not finite here") in verdicts


@pytest.mark.parametrize("force", ["{type: torsional_damper, coordinate: psi, coefficient: 0.1}",
                                   "{type: generalized_force, coordinate: psi, value: 1}"])
def test_a_damper_or_force_on_a_prescribed_coordinate_is_one_line_with_the_key(tmp_path, force):
    """yaml-reference.md §12.8 and §12.9 (they said 'ignored'): exit 2 naming the file, line and key."""
    path = tmp_path / "arm.yaml"
    path.write_text("name: arm\ncoordinates:\n  psi: {prescribed: 2*t}\n  th: {initial: 0.1}\nlinks:\n  arm:\n"
                    "    joint: {type: revolute, parent: ground, axis: z, coordinate: psi}\n  rod:\n"
                    "    joint: {type: revolute, parent: arm, axis: y, coordinate: th}\n    mass: 1\n"
                    f"    center_of_mass: [0.1, 0, 0]\nforces:\n  - {force}\n")
    line = one_line(invoke("info", path))
    assert "arm.yaml:13:" in line and "forces[0].coordinate: coordinate 'psi' is prescribed" in line
