"""Parameter sweeps: many independent tasks (one analysis at one point of a grid or a sample) run on local
processes or a Dask cluster, collected in one tidy table that a later run resumes.

The worker side is compile-once: each worker process keeps the base model of a sweep (loaded once, keyed by
the model file's content, the ``--set`` items and the analysis) and runs every task on
``base.with_overrides(task_values)``, which shares the derivations and the compiled code. The first task a
worker runs derives and compiles (or reads the on-disk cache, see mechsys/numeric/cache.py); later tasks only
evaluate. Each task's result depends only on its inputs, so the table is the same whichever executor ran it,
in whatever order, and across resumes (only the ``seconds`` column, a wall time, differs).
"""
from __future__ import annotations

import csv
import hashlib
import io
import itertools
import json
import math
import os
import re
import tempfile
import threading
import time
from collections import OrderedDict
from dataclasses import dataclass, field
from functools import cached_property
from pathlib import Path
from typing import TYPE_CHECKING, Any, Callable, Iterable

import numpy as np

from mechsys.errors import InputError, MechsysError

if TYPE_CHECKING:
    from dask.distributed import Client, LocalCluster

    from mechsys.mechanics.model import MechanicalModel

EXECUTORS = ("processes", "dask")
FIXED_TAIL = ("status", "error", "seconds")
TASK = "task"
SPEC = "spec"  # what made the row besides its inputs: SweepSpec.fingerprint (resume refuses another)
OPTION_KEYS = {  # analysis -> option keys it understands (see mechsys/analysis/batch/tasks.py); others: any key
    "simulate": ("t_end", "dt", "method"),
    "equilibria": ("search",),
    "modes": ("at",),
    "info": (),
    "bifurcations": ("parameter", "start", "stop", "points"),
    "derive": ("method",),
}
REQUIRED_OPTIONS = {"bifurcations": ("parameter", "start", "stop")}


# ===================================================================================== specification
@dataclass(frozen=True)
class Axis:
    """One swept input: a parameter, a coordinate's initial value (``name``) or its initial rate (``der(name)``)."""

    name: str
    start: float
    stop: float
    n: int | None  # grid points (None: sampled, LO:HI only)

    def grid(self) -> list[float]:
        return [float(x) for x in np.linspace(self.start, self.stop, self.n)]


_NAME = re.compile(r"^(der\(\s*[A-Za-z_]\w*\s*\)|[A-Za-z_]\w*)$")


def parse_params(items: Iterable[str] | None, sampled: bool = False) -> list[Axis]:
    """``NAME=START:STOP:N`` (grid) into axes; with ``sampled``, ``NAME=LO:HI`` is accepted too (N is unused)."""
    axes: list[Axis] = []
    form = "NAME=LO:HI or NAME=START:STOP:N" if sampled else "NAME=START:STOP:N (N >= 1)"
    for item in items or []:
        name, sep, rest = item.partition("=")
        name = name.replace(" ", "")
        parts = rest.split(":")
        try:
            if not sep or not _NAME.match(name) or len(parts) not in ((2, 3) if sampled else (3,)):
                raise ValueError
            start, stop = float(parts[0]), float(parts[1])
            n = int(parts[2]) if len(parts) == 3 else None
            if n is not None and n < 1:
                raise ValueError
            if not (math.isfinite(start) and math.isfinite(stop)):
                raise ValueError
        except ValueError:
            raise InputError(f"--param {item!r}: expected {form}") from None
        if any(a.name == name for a in axes):
            raise InputError(f"--param {item!r}: {name} is given twice")
        axes.append(Axis(name, start, stop, n))
    if not axes:
        raise InputError("give at least one --param NAME=START:STOP:N")
    return axes


def parse_sample(text: str | None) -> tuple[str, int] | None:
    """``latin:N`` or ``random:N`` into (kind, N); None means the Cartesian grid."""
    if text is None:
        return None
    kind, sep, count = text.partition(":")
    try:
        n = int(count)
        if not sep or kind not in ("latin", "random") or n < 1:
            raise ValueError
    except ValueError:
        raise InputError(f"--sample {text!r}: expected latin:N or random:N (N >= 1)") from None
    return kind, n


def _number_or_text(value: str) -> float | str:
    try:
        return float(value)
    except ValueError:
        return value.strip()


def parse_options(items: Iterable[str] | None, analysis: str) -> dict:
    """``--option KEY=VALUE`` into the analysis options: numbers become floats, other values stay text;
    ``search.NAME=LO:HI`` (equilibria) and ``at.NAME=VALUE`` (modes) build the nested options."""
    import difflib

    out: dict[str, Any] = {}
    allowed = OPTION_KEYS.get(analysis)
    for item in items or []:
        key, sep, value = item.partition("=")
        key = key.strip()
        if not sep or not key or not value.strip():
            raise InputError(f"--option {item!r}: expected KEY=VALUE")
        head, dot, sub = key.partition(".")
        if allowed is None:  # an analysis this module does not know: pass the option on
            out[key] = _number_or_text(value)
            continue
        if head not in allowed or (head in ("search", "at")) != bool(dot) or (dot and not sub):
            names = [f"{k}.NAME" if k in ("search", "at") else k for k in allowed]
            close = difflib.get_close_matches(key, names, n=1)
            hint = f" (did you mean {close[0]!r}?)" if close else ""
            choices = ", ".join(names) if names else "none"
            raise InputError(f"--option {item!r}: {analysis} has no option {key!r}{hint} (options: {choices})")
        if head == "search":
            lo, colon, hi = value.partition(":")
            try:
                if not colon:
                    raise ValueError
                out.setdefault("search", {})[sub] = (float(lo), float(hi))
            except ValueError:
                raise InputError(f"--option {item!r}: expected search.NAME=LO:HI") from None
        elif head == "at":
            v = _number_or_text(value)
            if isinstance(v, str):
                raise InputError(f"--option {item!r}: expected at.NAME=NUMBER")
            out.setdefault("at", {})[sub] = v
        else:
            out[head] = _number_or_text(value)
    missing = [k for k in REQUIRED_OPTIONS.get(analysis, ()) if k not in out]
    if missing:
        raise InputError(f"--run {analysis} needs " + " ".join(f"--option {k}=..." for k in missing))
    return out


def sweepable_names(model: MechanicalModel) -> list[str]:
    """Names a sweep may vary: parameters, free coordinates (initial value) and der(free coordinate)."""
    doc = model.doc
    free = [n for n, c in doc.spec.coordinates.items() if c.prescribed is None]
    return list(doc.parameters) + free + [f"der({n})" for n in free]


def check_names(model: MechanicalModel, axes: list[Axis]) -> None:
    names = sweepable_names(model)
    for a in axes:
        if a.name not in names:
            prescribed = [n for n, c in model.doc.spec.coordinates.items() if c.prescribed is not None]
            bare = a.name[4:-1] if a.name.startswith("der(") else a.name
            why = f": {bare} is prescribed (its motion is given by the file)" if bare in prescribed else ""
            raise InputError(f"--param {a.name}: not a parameter, free coordinate or der(coordinate) of "
                             f"{model.name}{why}{model.doc.suggest(a.name, names)}")


def make_tasks(axes: list[Axis], sample: tuple[str, int] | None = None, seed: int = 0) -> list[dict[str, float]]:
    """The task list: the Cartesian product of the axes' grids (the first --param varies slowest), or N points
    drawn inside the boxes (``random``: uniform; ``latin``: a Latin hypercube, one point in each of N equal
    strata of every axis), reproducible for a seed."""
    names = [a.name for a in axes]
    if sample is None:
        return [dict(zip(names, point)) for point in itertools.product(*(a.grid() for a in axes))]
    kind, n = sample
    rng = np.random.default_rng(seed)
    if kind == "random":
        unit = rng.random((n, len(axes)))
    else:
        unit = np.empty((n, len(axes)))
        for j in range(len(axes)):
            unit[:, j] = (rng.permutation(n) + rng.random(n)) / n
    lo = np.array([a.start for a in axes])
    hi = np.array([a.stop for a in axes])
    points = lo + unit * (hi - lo)
    return [{name: float(v) for name, v in zip(names, row)} for row in points]


@dataclass
class SweepSpec:
    """What a worker needs (plain data: pickled to processes and Dask workers). The model file's text travels
    with the tasks, so workers on other machines need mechsys installed but not the file."""

    path: str
    text: str
    sets: tuple[tuple[str, str], ...]
    analysis: str
    options: dict = field(default_factory=dict)

    @cached_property
    def digest(self) -> str:
        return hashlib.sha256(self.text.encode("utf-8")).hexdigest()[:20]

    @cached_property
    def fingerprint(self) -> str:
        """The model file's text, `--set`, `--run` and `--option`: the same for every row of one sweep, another
        for a table made from anything else (the `spec` column)."""
        data = json.dumps({"text": self.text, "sets": [list(kv) for kv in self.sets], "analysis": self.analysis,
                           "options": self.options}, sort_keys=True, default=str)
        return hashlib.sha256(data.encode("utf-8")).hexdigest()[:12]

    def payload(self) -> dict:
        return {"path": self.path, "text": self.text, "digest": self.digest, "sets": list(self.sets),
                "analysis": self.analysis, "options": self.options}


# ===================================================================================== worker side
_BASES: "OrderedDict[tuple, _Base]" = OrderedDict()  # per worker process: compile once, reuse for every task
_MAX_BASES = 8
_LOCK = threading.Lock()


class _Base:
    """A loaded base model and what a task needs beyond ``with_overrides``: the initial values that depend on
    parameters (re-evaluated per task, as a fresh load would) and the value checks a fresh load makes
    (masses not negative, central inertias without a negative moment about an axis the link turns about, finite
    real numbers)."""

    def __init__(self, model) -> None:
        import sympy as sp

        from mechsys.model.load import T

        self.model = model
        # compiled code lives in attributes of the model; make the containers exist on the base so every
        # with_overrides copy shares them (see EquilibriumProblem._memo)
        model.__dict__.setdefault("_equilibrium_memo", {})
        doc = model.doc
        self.dependent: list[tuple[str, str, Any]] = []
        for name, c in doc.spec.coordinates.items():
            if name in doc.released:
                motion = doc.released[name]
                exprs = [("initial", motion.xreplace({T: 0})), ("rate", sp.diff(motion, T).xreplace({T: 0}))]
            elif c.prescribed is None:
                exprs = [(kind, doc.parse(getattr(c, kind), ("coordinates", name, kind), "initial"))
                         for kind in ("initial", "rate")]
            else:
                continue
            for kind, expr in exprs:
                if sp.sympify(expr).free_symbols:
                    self.dependent.append((kind, name, expr))
        self.checks: list[tuple[str, Any, bool]] = []
        for lname, spec in doc.spec.links.items():
            lp = ("links", lname)
            self.checks.append((f"links.{lname}.mass", doc.parse(spec.mass, lp + ("mass",), "parameter"), True))
            for i, v in enumerate(spec.center_of_mass):
                self.checks.append((f"links.{lname}.center_of_mass.{i}",
                                    doc.parse(v, lp + ("center_of_mass", i), "parameter"), False))
            if spec.inertia is not None:
                for k in ("xx", "yy", "zz", "xy", "xz", "yz"):
                    self.checks.append((f"links.{lname}.inertia.{k}",
                                        doc.parse(getattr(spec.inertia, k), lp + ("inertia", k), "parameter"),
                                        k in ("xx", "yy", "zz")))
        self.checks = [c for c in self.checks if sp.sympify(c[1]).free_symbols]
        # the central tensors that move with the parameters, checked as a fresh load does (negative_moment)
        self.inertias = [(b.name, b.inertia, model.kin.frames[b.name].omega) for b in model.kin.bodies
                         if not b.particle and b.inertia.free_symbols & set(doc.parameters.values())]

    def adopt(self, clone) -> None:
        """Keep on the base what a task compiled or derived on its copy (symbolic expressions and compiled
        code, never numbers: those live in the copy's document), so the next copy starts with it."""
        from mechsys.mechanics.model import VALUE_DEPENDENT, MechanicalModel

        if clone.kin is not self.model.kin:
            return  # these values changed the structure: the clone was built anew and shares nothing
        base = self.model.__dict__
        for name, value in clone.__dict__.items():
            if name in base or name == "doc" or name in VALUE_DEPENDENT:
                continue
            if name in ("_simulation_compiled", "_linear_pieces") or isinstance(
                    getattr(MechanicalModel, name, None), cached_property):
                base[name] = value

    def task_model(self, values: dict[str, float]):
        import sympy as sp

        from mechsys.mechanics.build import negative_moment

        clone = self.model.with_overrides(values, as_set=True)  # (a start value swept is held)
        doc = clone.doc
        subs = {doc.parameters[n]: sp.Float(v) for n, v in doc.parameter_values.items()}
        for label, expr, nonnegative in self.checks:
            val = complex(sp.sympify(expr).xreplace(subs).evalf())
            if abs(val.imag) > 1e-12 * max(1.0, abs(val.real)) or not math.isfinite(val.real):
                raise InputError(f"{label}: must evaluate to a finite real number")
            if nonnegative and val.real < 0:
                raise InputError(f"{label}: must not be negative")
        for name, inertia, omega in self.inertias:
            point = dict(subs)
            point.update({s: sp.Float(doc.initial.get(c, 0.0)) for c, s in doc.coords.items()})
            moment = negative_moment(inertia, omega, list(doc.rates.values()), point)
            if moment is not None:
                raise InputError(f"links.{name}.inertia: its moment about an axis the link turns about is "
                                 f"{moment:.6g}: the kinetic energy would be negative")
        for kind, name, expr in self.dependent:
            key = name if kind == "initial" else f"der({name})"
            if key in values:
                continue
            val = complex(sp.sympify(expr).xreplace(subs).evalf())
            if abs(val.imag) > 1e-12 * max(1.0, abs(val.real)) or not math.isfinite(val.real):
                raise InputError(f"coordinates.{name}.{kind}: does not evaluate to a finite real number")
            (doc.initial if kind == "initial" else doc.initial_rate)[name] = val.real
        return clone


_PRIVATE: list[Path] = []


def _private_folder() -> Path:
    """This process's own folder for model copies (mkdtemp: unpredictable, 0700), removed when it exits."""
    if not _PRIVATE:
        import atexit
        import shutil

        _PRIVATE.append(Path(tempfile.mkdtemp(prefix="mechsys-sweep-")))
        atexit.register(shutil.rmtree, _PRIVATE[0], True)
    return _PRIVATE[0]


def _model_file(spec: dict) -> str:
    """The model file on this machine: the original path when it holds the same text, else a private copy."""
    path = Path(spec["path"])
    try:
        if path.is_file() and path.read_text(encoding="utf-8") == spec["text"]:
            return str(path)
    except OSError:
        pass
    folder = _private_folder()
    copy = folder / f"{spec['digest']}-{path.name}"
    if not copy.exists():
        fd, tmp = tempfile.mkstemp(dir=folder, prefix=".model.")
        with os.fdopen(fd, "w", encoding="utf-8") as fh:
            fh.write(spec["text"])
        os.replace(tmp, copy)
    return str(copy)


def _base(spec: dict) -> _Base:
    key = (spec["path"], spec["digest"], frozenset(map(tuple, spec["sets"])), spec["analysis"])
    base = _BASES.get(key)
    if base is None:
        import mechsys

        model = mechsys.load(_model_file(spec), dict(map(tuple, spec["sets"])),
                             release_prescribed=spec["analysis"] == "simulate")
        base = _BASES[key] = _Base(model)
        while len(_BASES) > _MAX_BASES:
            _BASES.popitem(last=False)
    _BASES.move_to_end(key)
    return base


def one_line(exc: BaseException) -> str:
    text = str(exc) if isinstance(exc, MechsysError) else f"{type(exc).__name__}: {exc}"
    text = " ".join(text.split())
    return text if len(text) <= 500 else text[:497] + "..."


def _scalar(v: Any) -> Any:
    if isinstance(v, (bool, np.bool_)):
        return bool(v)
    if isinstance(v, (int, np.integer)):
        return int(v)
    if isinstance(v, (float, np.floating)):
        return float(v)
    if v is None or isinstance(v, str):
        return v
    return str(v)


def run_chunk(spec: dict, chunk: list[tuple[int, dict[str, float]]]) -> list[dict]:
    """Run tasks (id, input values) in this worker; every failure is recorded, none escapes."""
    with _LOCK:  # a Dask worker may run several threads: tasks of one process share the base model
        return _run_chunk(spec, chunk)


def _run_chunk(spec: dict, chunk: list[tuple[int, dict[str, float]]]) -> list[dict]:
    from mechsys.analysis.batch.tasks import ANALYSES

    results = []
    try:
        base = _base(spec)
    except Exception as exc:  # noqa: BLE001 - recorded per task
        message = one_line(exc)
        return [{"task": tid, "values": values, "outputs": {}, "status": "failed", "error": message,
                 "seconds": 0.0} for tid, values in chunk]
    analysis = ANALYSES[spec["analysis"]]
    for tid, values in chunk:
        t0 = time.perf_counter()
        try:
            model = base.task_model(values)
            try:
                outputs = analysis(model, spec["options"])
            finally:
                base.adopt(model)
            row = {"outputs": {k: _scalar(v) for k, v in outputs.items()}, "status": "ok", "error": ""}
        except Exception as exc:  # noqa: BLE001 - a failing task is recorded, never fatal
            row = {"outputs": {}, "status": "failed", "error": one_line(exc)}
        row.update(task=tid, values=values, seconds=time.perf_counter() - t0)
        results.append(row)
    return results


def worker_version() -> str:
    import mechsys

    return mechsys.__version__


# ===================================================================================== the table
def _natural(key: str) -> list:
    return [int(t) if t.isdigit() else t for t in re.split(r"(\d+)", key)]


def input_key(values: dict, names: list[str]) -> tuple[str, ...]:
    """How inputs are compared on resume: exactly, as repr() of the floats (what the CSV holds)."""
    return tuple(repr(float(values[n])) for n in names)


@dataclass
class Table:
    """The tidy table: one row per task; rows are dicts column -> value (old CSV rows keep their text)."""

    inputs: list[str]
    rows: list[dict]

    @property
    def columns(self) -> list[str]:
        fixed = {TASK, *self.inputs, SPEC, *FIXED_TAIL}
        outputs = sorted({c for r in self.rows for c in r if c not in fixed}, key=_natural)
        return [TASK, *self.inputs, *outputs, SPEC, *FIXED_TAIL]


def _csv_cell(v: Any) -> str:
    if v is None:
        return ""
    if isinstance(v, str):
        return v
    if isinstance(v, float):
        return repr(v)
    return str(v)


def table_csv(table: Table) -> str:
    buf = io.StringIO()
    writer = csv.writer(buf, lineterminator="\n")
    columns = table.columns
    writer.writerow(columns)
    for r in table.rows:
        writer.writerow([_csv_cell(r.get(c)) for c in columns])
    return buf.getvalue()


def _pandas():
    try:
        import pandas
        import pyarrow  # noqa: F401
    except ImportError:
        raise InputError("--output .parquet needs pandas and pyarrow (pip install pandas pyarrow); "
                         "or write .csv") from None
    return pandas


def check_output(path: Path | None) -> None:
    if path is None:
        return
    if path.suffix.lower() not in (".csv", ".parquet"):
        raise InputError(f"--output {path}: the sweep table is written as .csv or .parquet")
    if path.suffix.lower() == ".parquet":
        _pandas()
    directory = path.parent if str(path.parent) else Path(".")
    if not directory.is_dir():
        raise InputError(f"--output {path}: directory {directory} does not exist")


def write_table(path: Path, table: Table) -> None:
    """Write atomically (temporary file in the same folder, then os.replace)."""
    from mechsys.report.files import atomic_write

    def write(tmp: str) -> None:
        if path.suffix.lower() == ".parquet":
            pd = _pandas()
            columns = table.columns
            frame = pd.DataFrame([[r.get(c) for c in columns] for r in table.rows], columns=columns)
            frame.to_parquet(tmp, index=False)
        else:
            with open(tmp, "w", encoding="utf-8", newline="") as fh:
                fh.write(table_csv(table))

    atomic_write(path, write)


def read_table(path: Path) -> tuple[list[str], list[dict]]:
    """(columns, rows) of an existing sweep table; CSV cells stay text (written back unchanged)."""
    try:
        if path.suffix.lower() == ".parquet":
            pd = _pandas()
            frame = pd.read_parquet(path)
            columns = [str(c) for c in frame.columns]
            rows = [{k: v.item() if hasattr(v, "item") else v for k, v in rec.items()}
                    for rec in frame.to_dict("records")]
        else:
            with open(path, encoding="utf-8", newline="") as fh:
                reader = csv.reader(fh)
                columns = next(reader, [])
                rows = [dict(zip(columns, r)) for r in reader if r]
    except InputError:
        raise
    except Exception as exc:  # noqa: BLE001
        raise InputError(f"--output {path} exists but cannot be read as a sweep table ({one_line(exc)}); "
                         "remove it or choose another file") from None
    if not columns or columns[0] != TASK or not set(FIXED_TAIL) <= set(columns):
        raise InputError(f"--output {path} exists but is not a sweep table (no task/status/error/seconds "
                         "columns); remove it or choose another file")
    return columns, rows


# ===================================================================================== the sweep
#: a simulate task whose start moved by more than this (its start_moved) is counted in the summary's note
MOVED = 1e-9


@dataclass
class Summary:
    tasks: int = 0
    done: int = 0
    failed: int = 0
    skipped: int = 0
    kept: int = 0
    seconds: float = 0.0
    executor: str = "processes"
    workers: int = 1
    output: str | None = None
    errors: list[str] = field(default_factory=list)
    moved: int = 0  # simulate tasks whose start the assembly onto the constraints moved (beyond MOVED)

    def to_dict(self) -> dict:
        return {"tasks": self.tasks, "done": self.done, "failed": self.failed, "skipped": self.skipped,
                "kept": self.kept, "seconds": self.seconds, "executor": self.executor, "workers": self.workers,
                "output": self.output, "start_moved": self.moved}

    def notes(self) -> list[str]:
        """What the table's reader must know besides the errors."""
        if not self.moved:
            return []
        return [f"{self.moved} task(s) started where the assembly onto the constraints put them, not at their "
                "values (column start_moved; the start.* columns give the state they started from)"]


@dataclass
class Resume:
    rows_by_key: dict  # input key -> old row (first ok row wins, else the first)
    others: list[dict]  # old rows of tasks not in this sweep (kept at the end)


def load_resume(path: Path | None, names: list[str], model: MechanicalModel, spec: SweepSpec) -> Resume:
    """The rows of an existing --output to resume from; an InputError when it holds a sweep over other inputs, or
    rows made from another model text, `--set`, `--run` or `--option` (their `spec` differs: resumed, they kept
    the old model's results). A table without the column (written before it) is trusted as it is."""
    if path is None or not path.exists():
        return Resume({}, [])
    columns, rows = read_table(path)
    other = sorted({str(r[SPEC]) for r in rows if r.get(SPEC) not in (None, "", spec.fingerprint)})
    if other:
        raise InputError(f"--output {path} holds results made from another model file, --set, --run or --option "
                         f"(spec {', '.join(other)}; this run's is {spec.fingerprint}): remove it or choose another "
                         f"file")
    valid = set(sweepable_names(model))
    old_inputs = []
    for c in columns[1:]:
        if c not in valid:
            break
        old_inputs.append(c)
    if set(old_inputs) != set(names):
        raise InputError(f"--output {path} holds a sweep over ({', '.join(old_inputs) or 'nothing'}), "
                         f"not ({', '.join(names)}); remove it or choose another file")
    by_key: dict = {}
    order: list = []
    for r in rows:
        try:
            key = tuple(r[n] if isinstance(r[n], str) else repr(float(r[n])) for n in names)
        except (TypeError, ValueError, KeyError):
            raise InputError(f"--output {path}: a row has a non-numeric input; remove it or choose another file")
        if key not in by_key:
            order.append(key)
            by_key[key] = r
        elif by_key[key].get("status") != "ok" and r.get("status") == "ok":
            by_key[key] = r
    return Resume(by_key, [by_key[k] for k in order])


def _row(result: dict, names: list[str]) -> dict:
    row = {TASK: result["task"], **{n: float(result["values"][n]) for n in names}}
    row.update(result["outputs"])
    row.update(status=result["status"], error=result["error"], seconds=float(result["seconds"]))
    return row


def chunked(items: list, size: int) -> list[list]:
    return [items[i:i + size] for i in range(0, len(items), size)]


def chunk_size(n: int, workers: int) -> int:
    """About eight chunks per worker (progress, load balance, table writes), at most 64 tasks each."""
    return max(1, min(64, math.ceil(n / max(1, workers * 8))))


def _chunk_key(spec: SweepSpec, chunk: list) -> str:
    text = json.dumps([spec.digest, spec.sets, spec.analysis, spec.options, chunk], sort_keys=True, default=str)
    return "mechsys-sweep-" + hashlib.sha256(text.encode()).hexdigest()[:32]


def _crashed(chunk: list, exc: BaseException) -> list[dict]:
    message = f"worker failed: {one_line(exc)}"
    return [{"task": tid, "values": values, "outputs": {}, "status": "failed", "error": message, "seconds": 0.0}
            for tid, values in chunk]


def run_processes(spec: SweepSpec, chunks: list, jobs: int, on_chunk: Callable[[list[dict]], None]) -> None:
    """Local worker processes (spawned: a clean interpreter each, the current environment), or this process
    when jobs == 1."""
    payload = spec.payload()
    if jobs == 1:
        for chunk in chunks:
            on_chunk(run_chunk(payload, chunk))
        return
    import concurrent.futures as cf
    import multiprocessing

    pool = cf.ProcessPoolExecutor(max_workers=jobs, mp_context=multiprocessing.get_context("spawn"),
                                  initializer=_ignore_interrupts)
    try:
        futures = {pool.submit(run_chunk, payload, chunk): chunk for chunk in chunks}
        for fut in cf.as_completed(futures):
            try:
                results = fut.result()
            except Exception as exc:  # noqa: BLE001 - a dead worker fails its chunk, not the sweep
                results = _crashed(futures[fut], exc)
            on_chunk(results)
    except BaseException:  # Ctrl-C: stop now; the caller writes the finished tasks
        pool.shutdown(wait=False, cancel_futures=True)
        for proc in list((getattr(pool, "_processes", None) or {}).values()):
            proc.terminate()
        raise
    pool.shutdown(wait=True)


def _ignore_interrupts() -> None:
    """Worker processes leave Ctrl-C to the main process, which stops them."""
    import signal

    signal.signal(signal.SIGINT, signal.SIG_IGN)


def dask_client(scheduler: str | None, jobs: int) -> tuple[Client, LocalCluster | None, int]:
    """(client, cluster or None, workers). Dask is imported here only (an optional dependency)."""
    try:
        import logging

        from dask.distributed import Client, LocalCluster
    except ImportError:
        raise InputError("--executor dask needs Dask distributed: install mechsys[dask] "
                         "(pip install 'mechsys[dask]')") from None
    if scheduler:
        try:
            client = Client(scheduler, timeout="20s")
        except Exception as exc:  # noqa: BLE001
            raise MechsysError(f"cannot connect to the Dask scheduler at {scheduler}: {one_line(exc)}") from None
        try:
            client.wait_for_workers(1, timeout=60)
        except Exception:  # noqa: BLE001
            client.close()
            raise MechsysError(f"the Dask scheduler at {scheduler} has no workers (start some with "
                               f"`dask worker {scheduler}`)") from None
        try:
            versions = client.run(worker_version)
        except Exception as exc:  # noqa: BLE001
            client.close()
            raise MechsysError(f"the Dask workers cannot run mechsys ({one_line(exc)}): install mechsys on "
                               "every worker machine") from None
        import sys

        import mechsys

        others = sorted({v for v in versions.values() if v != mechsys.__version__})
        if others:
            sys.stderr.write(f"mechsys: warning: Dask workers run mechsys {', '.join(others)} "
                             f"(this is {mechsys.__version__}); results may differ\n")
        return client, None, max(1, len(versions))
    import warnings

    with warnings.catch_warnings():  # "port 8787 is already in use": another cluster has it, ours needs none
        warnings.filterwarnings("ignore", message=".*already in use", category=UserWarning)
        cluster = LocalCluster(n_workers=jobs, threads_per_worker=1, processes=True, dashboard_address=None,
                               silence_logs=logging.ERROR)
    return Client(cluster), cluster, jobs


def run_dask(spec: SweepSpec, chunks: list, client: Client, on_chunk: Callable[[list[dict]], None]) -> None:
    from dask.distributed import as_completed

    keys = [_chunk_key(spec, chunk) for chunk in chunks]
    futures = client.map(run_chunk, [spec.payload()] * len(chunks), chunks, key=keys, pure=True, retries=0)
    by_key = {f.key: chunk for f, chunk in zip(futures, chunks)}
    try:
        for fut in as_completed(futures):
            try:
                results = fut.result()
            except Exception as exc:  # noqa: BLE001 - a lost worker fails its chunk, not the sweep
                results = _crashed(by_key[fut.key], exc)
            on_chunk(results)
    finally:
        client.cancel(futures)


def sweep(spec: SweepSpec, names: list[str], tasks: list[dict[str, float]], resume: Resume,
          output: Path | None, executor: str = "processes", jobs: int | None = None,
          scheduler: str | None = None, progress: Callable[[int, int], None] | None = None,
          write_every: float = 1.0) -> tuple[Table, Summary]:
    """Run the tasks not finished in ``resume`` and return the tidy table (written to ``output`` as chunks
    complete, at most every ``write_every`` seconds, and at the end)."""
    t0 = time.perf_counter()
    summary = Summary(tasks=len(tasks), executor=executor, output=str(output) if output else None)
    keys = [input_key(v, names) for v in tasks]
    current = set(keys)
    old_for_task: dict[int, dict] = {}
    pending: list[tuple[int, dict]] = []
    for tid, (key, values) in enumerate(zip(keys, tasks)):
        old = resume.rows_by_key.get(key)
        if old is not None:
            old_for_task[tid] = old
        if old is not None and old.get("status") == "ok":
            summary.skipped += 1
        else:
            pending.append((tid, values))
    others = [r for r in resume.others if tuple(r[n] if isinstance(r[n], str) else repr(float(r[n]))
                                                 for n in names) not in current]
    summary.kept = len(others)
    new: dict[int, dict] = {}

    def table() -> Table:
        rows = []
        for tid in range(len(tasks)):
            if tid in new:
                rows.append(new[tid])
            elif tid in old_for_task:
                rows.append({**old_for_task[tid], TASK: tid})
        rows += [{**r, TASK: len(tasks) + k} for k, r in enumerate(others)]
        return Table(list(names), rows)

    last_write = [time.perf_counter()]

    def on_chunk(results: list[dict]) -> None:
        for res in results:
            new[res["task"]] = {**_row(res, names), SPEC: spec.fingerprint}
            if res["status"] == "ok":
                summary.done += 1
                summary.moved += float(res["outputs"].get("start_moved", 0.0)) > MOVED
            else:
                summary.failed += 1
                if len(summary.errors) < 3:
                    summary.errors.append(f"task {res['task']}: {res['error']}")
        if progress is not None:
            progress(len(results), len(pending))
        if output is not None and time.perf_counter() - last_write[0] >= write_every:
            write_table(output, table())
            last_write[0] = time.perf_counter()

    if progress is not None:
        progress(0, len(pending))
    try:
        if pending:
            if executor == "dask":
                client, cluster, workers = dask_client(scheduler, min(jobs or os.cpu_count() or 1, len(pending)))
                summary.workers = workers
                try:
                    run_dask(spec, chunked(pending, chunk_size(len(pending), workers)), client, on_chunk)
                finally:
                    client.close()
                    if cluster is not None:
                        cluster.close()
            else:
                workers = min(jobs or os.cpu_count() or 1, len(pending))
                summary.workers = workers
                run_processes(spec, chunked(pending, chunk_size(len(pending), workers)), workers, on_chunk)
    finally:
        if output is not None and (new or old_for_task or others):
            write_table(output, table())  # also after an interrupt: finished tasks are kept
    summary.seconds = time.perf_counter() - t0
    return table(), summary
