"""Helpers of tests/test_fuzz_cli.py: mutate VALID bundled models so that most mutants stay valid, drive the real
``mechsys`` CLI in subprocesses through the on-disk cache (cold, warm, off) and classify every outcome.

Nothing here imports mechsys: the CLI is always a separate process (``python -m mechsys``), so a crash, a hang
or a stale cache entry shows up exactly as a user would see it. A `simulate` past its timeout is run again with a
small step budget: ending then (a result or one reasoned line) makes it slow, not stuck (BOUNDED_STEPS).

Environment:

- ``MECHSYS_FUZZ_SEED=N``   reproduce the examples of seed N (the failure message prints it);
- ``MECHSYS_FUZZ_ONLY=K,L`` run only these example numbers of the seed;
- ``CI=true`` or ``MECHSYS_FUZZ_ROTATE=1``: a new seed from the clock on every run (printed on failure);
- ``MECHSYS_FUZZ_LOG=DIR``  write every mutant and every subprocess output (command, exit code, stdout,
  stderr) to DIR, one file per run, so that ``grep -c "internal error" DIR/*`` can be reported;
- ``MECHSYS_FUZZ_JOBS=N``   examples run concurrently (default 2).
"""
from __future__ import annotations

import copy
import io
import json
import math
import os
import random
import re
import subprocess
import sys
import time
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import yaml

ROOT = Path(__file__).resolve().parents[1]
SYSTEMS = ROOT / "systems"
DATA = ROOT / "tests" / "data"
DEFAULT_SEED = 20240521

# seconds a command may take on a loaded 2-core machine before it counts as a hang
TIMEOUTS = {"info": 90, "derive": 120, "equilibria": 180, "modes": 180, "simulate": 120, "collide": 90,
            "inverse": 90, "codegen": 120}
# models whose equilibria/modes take 10-30 s already unmutated (slow suite only), and over 40 s (never)
SLOW_ANALYSIS = {"torque_free_body", "newton_cradle", "winch_gear"}
VERY_SLOW_ANALYSIS = {"friction_sphere_3d", "two_free_bodies"}
COMPARE_RTOL, COMPARE_ATOL = 1e-9, 1e-12

# keys whose string values are names or tags, never expressions
NAME_KEYS = {"name", "description", "type", "parent", "coordinate", "coordinates", "on", "link", "between", "frame",
             "sequence", "inertia_about", "points", "through", "axis", "axes", "analysis", "output", "contact",
             "bodies", "links", "of", "at_point", "point", "body", "joint", "method"}
IDENT = re.compile(r"[A-Za-z_][A-Za-z_0-9]*")


# ------------------------------------------------------------------------------------------------- seeds
def fuzz_seed() -> tuple[int, str]:
    """The seed of this run and how it was chosen."""
    env = os.environ.get("MECHSYS_FUZZ_SEED", "").strip()
    if env:
        return int(env), "from MECHSYS_FUZZ_SEED"
    rotate = (os.environ.get("CI", "").strip().lower() in ("1", "true", "yes")
              or os.environ.get("MECHSYS_FUZZ_ROTATE", "").strip().lower() in ("1", "true", "yes"))
    if rotate:
        return int(time.strftime("%Y%m%d%H%M%S")), "rotating (CI / MECHSYS_FUZZ_ROTATE), from the clock"
    return DEFAULT_SEED, "fixed default"


def selected_examples(count: int) -> list[int]:
    only = os.environ.get("MECHSYS_FUZZ_ONLY", "").strip()
    if only:
        return [int(x) for x in only.split(",") if x.strip()]
    return list(range(count)) if count >= 0 else []


# ------------------------------------------------------------------------------------------------- models
class Loader(yaml.SafeLoader):
    """``yaml.safe_load`` that reads only true/false as booleans, so keys such as ``on:`` stay text (as in
    mechsys; a plain safe_load would turn ``on`` into True)."""


Loader.yaml_implicit_resolvers = {
    first: [(tag, rx) for tag, rx in resolvers if tag != "tag:yaml.org,2002:bool"]
    for first, resolvers in yaml.SafeLoader.yaml_implicit_resolvers.items()
}
Loader.add_implicit_resolver("tag:yaml.org,2002:bool", re.compile(r"^(?:true|True|TRUE|false|False|FALSE)$"),
                             list("tTfF"))


def safe_load(text: str) -> Any:
    return yaml.load(text, Loader=Loader)  # noqa: S506 - a SafeLoader subclass


@dataclass(frozen=True)
class BaseModel:
    path: Path
    data: dict
    contacts: bool
    loops: bool

    @property
    def stem(self) -> str:
        return self.path.stem


#: Bundled models too expensive to mutate many times in CI (the bicycle: a minute of derivation per mutant);
#: tests/test_bicycle.py and tests/test_nonholonomic.py cover them, and the reader fuzz still reads them.
EXPENSIVE = frozenset({"bicycle"})


def load_bases(files: list[Path] | None = None) -> list[BaseModel]:
    if files is None:
        files = [f for f in sorted(SYSTEMS.glob("*.yaml")) + sorted(DATA.glob("*.yaml")) if f.stem not in EXPENSIVE]
    out = []
    for f in files:
        try:
            data = safe_load(f.read_text(encoding="utf-8"))
        except yaml.YAMLError:
            continue
        if not isinstance(data, dict) or not isinstance(data.get("parameters", {}), dict):
            continue
        out.append(BaseModel(f, data, bool(data.get("contacts")), bool(data.get("constraints"))))
    return out


def dump(data: dict) -> str:
    return yaml.safe_dump(data, sort_keys=False, allow_unicode=True, default_flow_style=None, width=200)


def number(v: Any) -> float | None:
    if isinstance(v, bool):
        return None
    if isinstance(v, (int, float)):
        return float(v)
    return None


def fmt(x: float) -> str:
    return repr(float(x)) if math.isfinite(x) else str(x)


# ------------------------------------------------------------------------------------------------- mutations
def _leaves(node: Any, path: tuple = ()):
    """(path, value) of every scalar leaf."""
    if isinstance(node, dict):
        for k, v in node.items():
            yield from _leaves(v, path + (k,))
    elif isinstance(node, list):
        for i, v in enumerate(node):
            yield from _leaves(v, path + (i,))
    else:
        yield path, node


def _get(data: Any, path: tuple) -> Any:
    for k in path:
        data = data[k]
    return data


def _set(data: Any, path: tuple, value: Any) -> None:
    _get(data, path[:-1])[path[-1]] = value


def _key_of(path: tuple) -> Any:
    """The nearest mapping key of a path (skipping list indices)."""
    for k in reversed(path):
        if isinstance(k, str):
            return k
    return None


def _expression_leaves(data: dict, params: list[str]) -> list[tuple]:
    """Paths of leaves that are expressions (parameter values, masses, vectors, force values, gaps...)."""
    out = []
    for path, v in _leaves(data):
        if not path or path[0] in ("expect", "name", "description"):
            continue
        if _key_of(path) in NAME_KEYS and path[0] != "parameters":
            continue
        if path[0] == "coordinates" and len(path) == 2:
            continue
        if isinstance(v, str) and (set(IDENT.findall(v)) & set(params) or re.search(r"[0-9()*/+-]", v)):
            out.append(path)
        elif number(v) is not None and path[0] != "expect":
            out.append(path)
    return out


def _rename_everywhere(data: dict, old: str, new: str, include_names: bool) -> None:
    pattern = re.compile(rf"(?<![A-Za-z_0-9.]){re.escape(old)}(?![A-Za-z_0-9])")
    for path, v in list(_leaves(data)):
        if not isinstance(v, str) or not path or path[0] in ("name", "description"):
            continue
        if _key_of(path) in ("type", "name", "description", "axis", "axes", "sequence", "inertia_about"):
            continue
        if not include_names and _key_of(path) in NAME_KEYS and path[0] != "parameters":
            continue
        _set(data, path, pattern.sub(new, v))


def _reorder(rng: random.Random, seq: list) -> tuple[list, str]:
    if len(seq) > 2 and rng.random() < 0.5:
        new = seq[:]
        while new == seq:
            rng.shuffle(new)
        return new, "shuffle"
    return seq[::-1], "reverse"


class Mutator:
    """Small, mostly meaning-preserving or physically plausible edits of a valid model's data."""

    def __init__(self, data: dict, rng: random.Random):
        self.data = data
        self.rng = rng

    # helpers
    @property
    def params(self) -> list[str]:
        p = self.data.get("parameters")
        return list(p) if isinstance(p, dict) else []

    @property
    def coords(self) -> dict:
        c = self.data.get("coordinates")
        return c if isinstance(c, dict) else {}

    def free_coords(self) -> list[str]:
        return [n for n, c in self.coords.items() if not (isinstance(c, dict) and "prescribed" in c)]

    # operations: each returns a description, or None when it does not apply
    def param_value(self) -> str | None:
        if not self.params:
            return None
        rng, params = self.rng, self.data["parameters"]
        p = rng.choice(self.params)
        v = params[p]
        x = number(v)
        kind = rng.choice(["scale", "scale", "scale", "sign", "zero", "tiny", "huge", "alias", "alias", "expr"])
        if kind == "scale":
            f = rng.choice([0.5, 2, 10, 0.1, 1.1, 0.9, 3])
            new: Any = x * f if x is not None else f"({v})*{f}"
        elif kind == "sign":
            new = -x if x is not None else f"-({v})"
        elif kind == "zero":
            new = 0
        elif kind == "tiny":
            new = rng.choice([1e-9, 1e-12, 1e-300])
        elif kind == "huge":
            new = rng.choice([1e9, 1e15, 1e200])
        elif kind == "alias":
            others = [q for q in self.params if q != p]
            if not others:
                return None
            new = rng.choice(others)
        else:
            new = f"{v} + 0" if rng.random() < 0.5 else f"1*({v})"
        params[p] = new
        return f"parameters.{p}: {v!r} -> {new!r} ({kind})"

    def reorder(self) -> str | None:
        rng = self.rng
        sections = [k for k in ("parameters", "coordinates", "links", "forces", "contacts", "constraints")
                    if isinstance(self.data.get(k), (dict, list)) and len(self.data[k]) > 1]
        if not sections:
            return None
        s = rng.choice(sections + ["parameters", "coordinates"] * 2 if "parameters" in sections else sections)
        if s not in sections:
            s = rng.choice(sections)
        block = self.data[s]
        if isinstance(block, dict):
            keys, how = _reorder(rng, list(block))
            self.data[s] = {k: block[k] for k in keys}
            return f"{how} the {s} mapping: {keys}"
        items, how = _reorder(rng, list(block))
        self.data[s] = items
        return f"{how} the {s} list"

    def initial_state(self) -> str | None:
        free = self.free_coords()
        if not free:
            return None
        rng = self.rng
        c = rng.choice(free)
        spec = self.coords[c]
        if not isinstance(spec, dict):
            spec = self.coords[c] = {}
        key = rng.choice(["initial", "rate"])
        old = spec.get(key, 0)
        x = number(old)
        if key == "initial":
            choices = [0, 0.1, -0.3, 1.0, 3.14159, "pi/2", (x + 0.01) if x is not None else f"({old}) + 0.01"]
        else:
            choices = [0, 1, -2.5, 10, 0.01, -0.5, (x * 2) if x is not None else f"2*({old})"]
        new = rng.choice(choices)
        spec[key] = new
        return f"coordinates.{c}.{key}: {old!r} -> {new!r}"

    def drop_optional(self) -> str | None:
        cands: list[tuple] = []
        if "description" in self.data:
            cands.append(("description",))
        for n, c in self.coords.items():
            if isinstance(c, dict):
                cands += [("coordinates", n, k) for k in ("initial", "rate", "angle") if k in c]
        links = self.data.get("links") if isinstance(self.data.get("links"), dict) else {}
        for n, link in links.items():
            if isinstance(link, dict):
                cands += [("links", n, k) for k in ("center_of_mass", "inertia_about") if k in link]
                if isinstance(link.get("joint"), dict) and "origin" in link["joint"]:
                    cands.append(("links", n, "joint", "origin"))
        for s in ("forces", "contacts"):
            if isinstance(self.data.get(s), list):
                cands += [(s, i) for i in range(len(self.data[s]))]
                for i, item in enumerate(self.data[s]):
                    if isinstance(item, dict):
                        cands += [(s, i, k) for k in ("restitution", "friction") if k in item]
        if not cands:
            return None
        path = self.rng.choice(cands)
        parent = _get(self.data, path[:-1])
        del parent[path[-1]]
        return f"drop {'.'.join(map(str, path))}"

    def duplicate(self) -> str | None:
        rng = self.rng
        cands = [s for s in ("forces", "contacts") if isinstance(self.data.get(s), list) and self.data[s]]
        if self.params:
            cands.append("parameters")
        if not cands:
            return None
        s = rng.choice(cands)
        if s == "parameters":
            p = rng.choice(self.params)
            new = f"{p}_dup"
            if new in self.data["parameters"]:
                return None
            self.data["parameters"][new] = copy.deepcopy(self.data["parameters"][p])
            return f"duplicate parameter {p} as an unused {new}"
        i = rng.randrange(len(self.data[s]))
        item = copy.deepcopy(self.data[s][i])
        if isinstance(item, dict) and "name" in item:
            item["name"] = f"{item['name']}_dup"
        self.data[s].insert(i + 1, item)
        return f"duplicate {s}[{i}]"

    def perturb_expression(self) -> str | None:
        leaves = _expression_leaves(self.data, self.params)
        if not leaves:
            return None
        rng = self.rng
        path = rng.choice(leaves)
        old = _get(self.data, path)
        kind = rng.choice(["plus0", "times1", "swap", "swap", "minus0"])
        s = str(old)
        if kind == "swap":
            names = [n for n in IDENT.findall(s) if n in self.params]
            others = self.params
            if not names or len(others) < 2:
                kind = "plus0"
            else:
                a = rng.choice(names)
                b = rng.choice([o for o in others if o != a])
                new: Any = re.sub(rf"(?<![A-Za-z_0-9.]){re.escape(a)}(?![A-Za-z_0-9])", b, s, count=1)
        if kind == "plus0":
            new = f"{s} + 0"
        elif kind == "times1":
            new = f"({s})*1"
        elif kind == "minus0":
            new = f"{s} - 0.0"
        _set(self.data, path, new)
        return f"{'.'.join(map(str, path))}: {old!r} -> {new!r}"

    def joint_axis(self) -> str | None:
        links = self.data.get("links") if isinstance(self.data.get("links"), dict) else {}
        cands = [n for n, link in links.items() if isinstance(link, dict) and isinstance(link.get("joint"), dict)
                 and "axis" in link["joint"]]
        if not cands:
            return None
        n = self.rng.choice(cands)
        joint = links[n]["joint"]
        old = joint["axis"]
        new = self.rng.choice([a for a in ("x", "y", "z", "-z", "-x", [0, 0, 1], [0, 1, 1], [1, 0, 0])
                               if a != old])
        joint["axis"] = new
        return f"links.{n}.joint.axis: {old!r} -> {new!r}"

    def rename_parameter(self) -> str | None:
        if not self.params:
            return None
        p = self.rng.choice(self.params)
        new = f"{p}_r"
        if new in self.params:
            return None
        self.data["parameters"] = {(new if k == p else k): v for k, v in self.data["parameters"].items()}
        _rename_everywhere(self.data, p, new, include_names=False)
        return f"rename parameter {p} -> {new} everywhere"

    def rename_coordinate(self) -> str | None:
        free = list(self.coords)
        if not free:
            return None
        c = self.rng.choice(free)
        new = f"{c}_r"
        if new in self.coords or new in self.params:
            return None
        self.data["coordinates"] = {(new if k == c else k): v for k, v in self.coords.items()}
        _rename_everywhere(self.data, c, new, include_names=True)
        return f"rename coordinate {c} -> {new} everywhere"

    def vector_component(self) -> str | None:
        cands = [p for p in _expression_leaves(self.data, self.params)
                 if _key_of(p) in ("origin", "center_of_mass", "acceleration") and isinstance(p[-1], int)]
        if not cands:
            return None
        path = self.rng.choice(cands)
        old = _get(self.data, path)
        x = number(old)
        new: Any = (x + self.rng.choice([0.01, -0.05, 0.2])) if x is not None else f"{old} + 0.01"
        _set(self.data, path, new)
        return f"{'.'.join(map(str, path))}: {old!r} -> {new!r}"

    OPS: list[tuple[str, int]] = [("param_value", 6), ("reorder", 4), ("initial_state", 3), ("drop_optional", 2),
                                  ("duplicate", 1), ("perturb_expression", 3), ("joint_axis", 1),
                                  ("rename_parameter", 1), ("rename_coordinate", 1), ("vector_component", 1)]

    def mutate(self, count: int) -> list[str]:
        steps = []
        names = [n for n, _ in self.OPS]
        weights = [w for _, w in self.OPS]
        tries = 0
        while len(steps) < count and tries < 50:
            tries += 1
            op = self.rng.choices(names, weights)[0]
            what = getattr(self, op)()
            if what:
                steps.append(what)
        return steps


def make_mutant(base: BaseModel, rng: random.Random) -> tuple[dict, list[str]]:
    data = copy.deepcopy(base.data)
    data.pop("expect", None)  # `mechsys check` only; its names would turn renames into input errors
    steps = Mutator(data, rng).mutate(rng.choice([1, 1, 2, 2, 3]))
    return data, steps


# ------------------------------------------------------------------------------------------------- commands
@dataclass
class Command:
    name: str
    args: list[str]          # after the command name and the file; `{out}` is replaced by a per-run output file
    timeout: float
    modes: tuple[str, ...]   # "cold", "warm", "off"

    def argv(self, model: Path, out: Path | None) -> list[str]:
        args = [str(out) if a == "{out}" else a for a in self.args]
        return [sys.executable, "-m", "mechsys", self.name, str(model), *args]

    def pretty(self, model: str = "mutant.yaml") -> str:
        out = "OUT" if self.name == "codegen" else "OUT.csv"
        return " ".join(["mechsys", self.name, model] + [a.replace("{out}", out) for a in self.args])


def set_options(rng: random.Random, data: dict) -> list[str]:
    """Zero to two random `--set` options: parameters, initial values, rates, sometimes odd or invalid values."""
    params = data.get("parameters") if isinstance(data.get("parameters"), dict) else {}
    coords = data.get("coordinates") if isinstance(data.get("coordinates"), dict) else {}
    free = [n for n, c in coords.items() if not (isinstance(c, dict) and "prescribed" in c)]
    out: list[str] = []
    for _ in range(rng.choice([0, 0, 1, 1, 2])):
        kind = rng.choice(["param"] * 8 + ["initial"] * 2 + ["rate"] * 2 + ["odd"])
        if kind == "param" and params:
            p = rng.choice(list(params))
            x = number(params[p])
            values = ["0", "-1", "1e-9", "1e9", "2.5", rng.choice(["nan", "inf", "1e400", "0**-1"])]
            values += [n for n in params if n != p][:3]
            if x is not None:
                values += [fmt(1.1 * x)] * 3 + [fmt(0.5 * x), fmt(-x)]
            out += ["--set", f"{p}={rng.choice(values)}"]
        elif kind == "initial" and free:
            out += ["--set", f"{rng.choice(free)}={rng.choice(['0', '0.2', '-1', 'pi/4', '1e3', '0.5*pi'])}"]
        elif kind == "rate" and free:
            out += ["--set", f"der({rng.choice(free)})={rng.choice(['0', '1.5', '-3', '100', '-0.01'])}"]
        elif kind == "odd":
            out += ["--set", rng.choice(["nosuch=1", "der(nosuch)=0", "=3", "g", "g=", "1x=2"])]
    return out


def simulate_args(rng: random.Random) -> list[str]:
    """Valid random options; in about one run of seven, one of them invalid (nan, -1, 0, inf, an unknown method)."""
    opts = {"--t-end": "0.1", "--method": rng.choice(["auto"] * 2 + ["native"] * 2 + ["DOP853", "RK45", "Radau"])}
    if rng.random() < 0.4:
        opts["--rtol"] = rng.choice(["1e-8", "1e-6", "1e-12", "1e-10", "1e-4"])
    if rng.random() < 0.2:
        opts["--atol"] = rng.choice(["1e-9", "1e-6", "1e-14"])
    if rng.random() < 0.3:
        opts["--dt"] = rng.choice(["0.01", "0.025", "0.2", "0.0999"])
    if rng.random() < 0.15:
        key = rng.choice(["--t-end", "--method", "--rtol", "--rtol", "--atol", "--dt", "--dt", "--max-steps"])
        opts[key] = rng.choice({"--t-end": ["0", "-1", "nan"], "--method": ["bogus", "lsoda"],
                                "--max-steps": ["0", "10"], "--rtol": ["0", "-1", "nan", "inf", "1"],
                                "--atol": ["0", "-1", "nan"], "--dt": ["0", "-1", "nan", "inf"]}[key])
    return [x for kv in opts.items() for x in kv] + ["-o", "{out}"]


def _analysis_command(rng: random.Random, name: str, sets: list[str]) -> Command:
    extra: list[str] = []
    if name == "derive":
        extra = ["-m", rng.choice(["lagrange", "kane"])] + (["--check"] if rng.random() < 0.2 else [])
        extra += ["--subexpressions", "named"] if rng.random() < 0.3 else []
    elif name == "equilibria" and rng.random() < 0.25:
        extra = [rng.choice(["--linearize", "--hurwitz"])]
    elif name == "modes" and rng.random() < 0.25:
        extra = [rng.choice(["--state-space", "--frf=0:20:5"])]
    elif name == "collide" and rng.random() < 0.2:
        extra = ["--percussion"]
    elif name == "inverse" and rng.random() < 0.5:
        extra = ["--at", rng.choice(["0.3", "2", "-1"])]
    elif name == "codegen":  # a package folder ({out}), compared file by file between cold and warm
        return Command(name, ["-t", rng.choice(["python", "c", "matlab"]), "-m", rng.choice(["lagrange", "kane"]),
                              "-o", "{out}"] + sets, TIMEOUTS[name], ("cold", "warm"))
    return Command(name, ["-f", "json"] + extra + sets, TIMEOUTS[name], ("cold", "warm"))


def plan_commands(rng: random.Random, base: BaseModel, data: dict, slow: bool) -> list[Command]:
    """A simulation (cold, warm, off) and one other command (cold, warm); in the slow suite a cheap command
    (info or derive) and an analysis (equilibria, modes or collide) besides the simulation."""
    sets = set_options(rng, data)
    analyses = []
    if base.stem not in VERY_SLOW_ANALYSIS and (slow or base.stem not in SLOW_ANALYSIS):
        analyses += ["equilibria", "modes"]
    if base.contacts:
        analyses += ["collide", "collide"]
    analyses.append("inverse")
    simulate = Command("simulate", simulate_args(rng) + sets, TIMEOUTS["simulate"], ("cold", "warm", "off"))
    if not slow:
        return [simulate, _analysis_command(rng, rng.choice(["info", "derive", "codegen"] + analyses), sets)]
    cmds = [_analysis_command(rng, rng.choice(["info", "derive", "codegen"]), sets), simulate]
    if analyses:
        cmds.append(_analysis_command(rng, rng.choice(analyses), sets))
    return cmds


# ------------------------------------------------------------------------------------------------- running
@dataclass
class Run:
    label: str
    argv: list[str]
    cache: str
    rc: int | None
    stdout: str
    stderr: str
    seconds: float
    timed_out: bool
    output: Path | None = None


def run_cli(argv: list[str], cache: str, timeout: float, cwd: Path, label: str, output: Path | None = None) -> Run:
    env = dict(os.environ)
    env["MECHSYS_CACHE"] = cache
    env.pop("MECHSYS_DEBUG", None)
    env["COLUMNS"] = "100"
    t0 = time.monotonic()
    try:
        p = subprocess.run(argv, cwd=cwd, env=env, capture_output=True, text=True, timeout=timeout,
                           stdin=subprocess.DEVNULL, errors="replace")
        rc, out, err, timed_out = p.returncode, p.stdout, p.stderr, False
    except subprocess.TimeoutExpired as exc:
        def text(b):
            return b.decode(errors="replace") if isinstance(b, bytes) else (b or "")
        rc, out, err, timed_out = None, text(exc.stdout), text(exc.stderr), True
    return Run(label, argv, cache, rc, out, err, time.monotonic() - t0, timed_out, output)


def log_run(log_dir: Path | None, name: str, run: Run) -> None:
    if log_dir is None:
        return
    log_dir.mkdir(parents=True, exist_ok=True)
    head = (f"# {' '.join(run.argv)}\n# MECHSYS_CACHE={run.cache}\n# exit code: {run.rc}"
            f"{' (TIMEOUT)' if run.timed_out else ''}\n# seconds: {run.seconds:.2f}\n")
    (log_dir / f"{name}.txt").write_text(f"{head}--- stdout ---\n{run.stdout}--- stderr ---\n{run.stderr}",
                                         encoding="utf-8")


def log_dir() -> Path | None:
    v = os.environ.get("MECHSYS_FUZZ_LOG", "").strip()
    return Path(v) if v else None


def run_problems(run: Run) -> list[str]:
    """The contract of every run: exit 0; or exit 1/2 with exactly one non-empty stderr line; never a traceback,
    an internal error, a signal or a hang."""
    if run.timed_out:
        return [f"timeout: still running after {run.seconds:.0f} s"]
    problems = []
    both = run.stdout + run.stderr
    if "internal error" in both.lower():
        problems.append("internal error")
    if "Traceback" in both:
        problems.append("traceback in the output")
    if run.rc is not None and run.rc < 0:
        problems.append(f"killed by signal {-run.rc}")
    elif run.rc in (1, 2):
        lines = [ln for ln in run.stderr.splitlines() if ln.strip()]
        if len(lines) != 1:
            problems.append(f"exit {run.rc} with {len(lines)} stderr lines (expected one)")
        elif len(lines[0].strip()) < 16 or not (lines[0].startswith("mechsys: ") or re.match(r"^.+:\d+:\d+: ",
                                                                                              lines[0])):
            problems.append(f"exit {run.rc} without a reasoned message")
    elif run.rc != 0:
        problems.append(f"unexpected exit code {run.rc}")
    return problems


#: A `simulate` that outlives its timeout is run again with this step budget: a run whose work the budget bounds
#: (a stiff undamped spring on scipy's Radau legitimately takes minutes) must then end within BOUNDED_TIMEOUT, with
#: a result or one reasoned line; a run that still does not end is stuck somewhere the budget does not reach.
BOUNDED_STEPS = "2000"
BOUNDED_TIMEOUT = 90


def bounded_rerun(cmd: Command, model: Path, cache: str, cwd: Path, out: Path | None) -> Run:
    """The same command with --max-steps BOUNDED_STEPS (replacing the command's own budget)."""
    args = list(cmd.args)
    if "--max-steps" in args:
        args[args.index("--max-steps") + 1] = BOUNDED_STEPS
    else:
        args += ["--max-steps", BOUNDED_STEPS]
    return run_cli(Command(cmd.name, args, BOUNDED_TIMEOUT, cmd.modes).argv(model, out), cache, BOUNDED_TIMEOUT,
                   cwd, f"{cmd.name}/bounded", out)


def first_error_line(run: Run) -> str:
    if run.timed_out:
        return f"(timeout after {run.seconds:.0f} s)"
    lines = [ln for ln in run.stderr.splitlines() if ln.strip()]
    if not lines:
        return "(no stderr)"
    for ln in lines:
        if "internal error" in ln or "Error" in ln:
            return ln.strip()[:400]
    return lines[-1].strip()[:400]


# ------------------------------------------------------------------------------------------------- comparing
def read_csv(path: Path) -> tuple[list[str], np.ndarray]:
    text = path.read_text(encoding="utf-8")
    header, _, body = text.partition("\n")
    names = header.strip().split(",")
    arr = np.loadtxt(io.StringIO(body), delimiter=",", ndmin=2) if body.strip() else np.zeros((0, len(names)))
    return names, arr


def compare_folders(a: Path, b: Path) -> str | None:
    """None when the two folders hold the same files, byte for byte (a generated package: the same code on every
    run, kept or not), else the first difference."""
    files_a, files_b = sorted(f.name for f in a.iterdir()), sorted(f.name for f in b.iterdir())
    if files_a != files_b:
        return f"files differ: {files_a} vs {files_b}"
    for name in files_a:
        if (a / name).read_bytes() != (b / name).read_bytes():
            return f"{name} differs"
    return None


def compare_tables(a: tuple[list[str], np.ndarray], b: tuple[list[str], np.ndarray], rtol: float = COMPARE_RTOL,
                   atol: float = COMPARE_ATOL, by_name: bool = False) -> str | None:
    """None when equal (to tolerance), else a short description of the first difference."""
    na, A = a
    nb, B = b
    if by_name:
        if sorted(na) != sorted(nb):
            return f"columns differ: {na} vs {nb}"
        B = B[:, [nb.index(n) for n in na]]
    elif na != nb:
        return f"columns differ: {na} vs {nb}"
    if A.shape != B.shape:
        return f"shapes differ: {A.shape} vs {B.shape}"
    close = np.isclose(A, B, rtol=rtol, atol=atol, equal_nan=True)
    if close.all():
        return None
    worst = []
    for j in np.where(~close.all(axis=0))[0][:4]:
        i = int(np.where(~close[:, j])[0][-1])
        worst.append(f"{na[j]} at row {i} (t={A[i, 0]:.6g}): {A[i, j]:.9g} vs {B[i, j]:.9g}")
    return "; ".join(worst)


def _json_close(a: Any, b: Any, path: str = "") -> str | None:
    if isinstance(a, dict) and isinstance(b, dict):
        if list(a) != list(b):
            return f"{path or '.'}: keys {list(a)} vs {list(b)}"
        for k in a:
            d = _json_close(a[k], b[k], f"{path}.{k}")
            if d:
                return d
        return None
    if isinstance(a, list) and isinstance(b, list):
        if len(a) != len(b):
            return f"{path}: lengths {len(a)} vs {len(b)}"
        for i, (x, y) in enumerate(zip(a, b)):
            d = _json_close(x, y, f"{path}[{i}]")
            if d:
                return d
        return None
    if isinstance(a, (int, float)) and isinstance(b, (int, float)) and not isinstance(a, bool):
        if math.isclose(a, b, rel_tol=COMPARE_RTOL, abs_tol=COMPARE_ATOL) or (a != a and b != b):
            return None
        return f"{path}: {a!r} vs {b!r}"
    return None if a == b else f"{path}: {a!r} vs {b!r}"


def compare_stdout(a: str, b: str) -> str | None:
    if a == b:
        return None
    try:
        return _json_close(json.loads(a), json.loads(b)) or None
    except ValueError:
        lines = [(x, y) for x, y in zip(a.splitlines(), b.splitlines()) if x != y]
        return f"text differs: {lines[:1]}"


# ------------------------------------------------------------------------------------------------- one example
@dataclass
class Failure:
    example: int
    base: str
    steps: list[str]
    command: str
    mode: str
    rc: int | None
    problem: str
    message: str
    mutant: str
    mutant_path: Path
    stderr: str = ""

    def key(self) -> str:
        """What makes two failures 'the same' for the summary: the command and the message without numbers."""
        msg = re.sub(r"[-+]?\d[\d.e+-]*", "N", self.message)
        msg = re.sub(r"/\S+", "PATH", msg)
        return f"{self.command.split()[1]} | {self.problem.split(':')[0]} | {msg[:160]}"

    def report(self) -> str:
        return (f"[example {self.example}] {self.base} mutated by {self.steps}\n"
                f"  $ {self.command}   ({self.mode})\n  exit {self.rc}: {self.problem}\n  {self.message}\n"
                + (f"  stderr:\n    " + "\n    ".join(self.stderr.splitlines()[:12]) + "\n" if self.stderr
                   and "stderr lines" in self.problem else "")
                + f"  mutant: {self.mutant_path}")


@dataclass
class ExampleResult:
    index: int
    failures: list[Failure] = field(default_factory=list)
    outcomes: list[str] = field(default_factory=list)
    seconds: float = 0.0


def run_example(index: int, seed: int, bases: list[BaseModel], workdir: Path, slow: bool,
                logs: Path | None, tag: str) -> ExampleResult:
    t0 = time.monotonic()
    rng = random.Random(f"mechsys-fuzz-cli:{seed}:{index}")
    base = rng.choice(bases)
    data, steps = make_mutant(base, rng)
    folder = workdir / f"ex{index:03d}"
    folder.mkdir(parents=True, exist_ok=True)
    model = folder / f"{base.stem}.yaml"
    text = f"# {base.path.relative_to(ROOT)} mutated by: {steps}\n" + dump(data)
    model.write_text(text, encoding="utf-8")
    name = f"{tag}-s{seed}-ex{index:03d}-{base.stem}"
    if logs is not None:
        logs.mkdir(parents=True, exist_ok=True)
        (logs / f"{name}-model.yaml").write_text(text, encoding="utf-8")
    result = ExampleResult(index)

    def fail(cmd: Command, mode: str, run: Run | None, problem: str, message: str | None = None) -> None:
        result.failures.append(Failure(index, str(base.path.relative_to(ROOT)), steps, cmd.pretty(model.name), mode,
                                       run.rc if run else None, problem,
                                       message if message is not None else first_error_line(run), text, model,
                                       run.stderr[-3000:] if run else ""))

    for k, cmd in enumerate(plan_commands(rng, base, data, slow)):
        runs: dict[str, Run] = {}
        cache = folder / f"cache{k}-{cmd.name}"
        for mode in cmd.modes:
            suffix = "" if cmd.name == "codegen" else ".csv"  # codegen writes a folder
            out = folder / f"{cmd.name}{k}-{mode}{suffix}" if "{out}" in cmd.args else None
            run = run_cli(cmd.argv(model, out), "off" if mode == "off" else str(cache), cmd.timeout, folder,
                          f"{cmd.name}/{mode}", out)
            runs[mode] = run
            log_run(logs, f"{name}-{k}-{cmd.name}-{mode}", run)
            if run.timed_out and cmd.name == "simulate":
                bounded = bounded_rerun(cmd, model, "off" if mode == "off" else str(cache), folder, out)
                log_run(logs, f"{name}-{k}-{cmd.name}-{mode}-bounded", bounded)
                problems = run_problems(bounded)
                if not problems:  # slow, not stuck: the other modes would only be as slow
                    result.outcomes.append(f"{cmd.name}/{mode}:slow")
                    break
                for problem in problems:
                    fail(cmd, mode, bounded, f"timeout after {run.seconds:.0f} s, and with --max-steps "
                                             f"{BOUNDED_STEPS}: {problem}")
                continue
            result.outcomes.append(f"{cmd.name}/{mode}:{run.rc}")
            for problem in run_problems(run):
                fail(cmd, mode, run, problem)
        cold = runs["cold"]
        for mode, run in runs.items():
            if mode == "cold" or run.timed_out or cold.timed_out:
                continue
            if run.rc != cold.rc:
                fail(cmd, mode, run, f"exit code {run.rc} ({mode}) differs from {cold.rc} (cold)",
                     f"cold: {first_error_line(cold) if cold.rc else 'ok'} / {mode}: "
                     f"{first_error_line(run) if run.rc else 'ok'}")
                continue
            if run.rc != 0:
                continue
            if cold.output is not None:
                if not (cold.output.exists() and run.output and run.output.exists()):
                    fail(cmd, mode, run, "exit 0 but no result file", "")
                    continue
                diff = compare_folders(cold.output, run.output) if cold.output.is_dir() else \
                    compare_tables(read_csv(cold.output), read_csv(run.output))
                if diff:
                    fail(cmd, mode, run, f"{mode} result differs from the cold one", diff)
            else:
                diff = compare_stdout(cold.stdout, run.stdout)
                if diff:
                    fail(cmd, mode, run, f"{mode} stdout differs from the cold one", diff[:400])
    result.seconds = time.monotonic() - t0
    return result


def run_examples(count: int, workdir: Path, slow: bool, tag: str,
                 offset: int = 0) -> tuple[int, str, list[ExampleResult], float]:
    seed, how = fuzz_seed()
    bases = load_bases()
    logs = log_dir()
    jobs = max(1, int(os.environ.get("MECHSYS_FUZZ_JOBS", "2")))
    t0 = time.monotonic()
    indices = [offset + i for i in range(count)]
    only = selected_examples(-1)
    if only:  # MECHSYS_FUZZ_ONLY: the example numbers printed in a failure message
        indices = only
    with ThreadPoolExecutor(max_workers=jobs) as pool:
        results = list(pool.map(lambda i: run_example(i, seed, bases, workdir, slow, logs, tag), indices))
    return seed, how, results, time.monotonic() - t0


def summarize(seed: int, how: str, results: list[ExampleResult], seconds: float, test: str) -> str | None:
    failures = [f for r in results for f in r.failures]
    if not failures:
        return None
    groups: dict[str, list[Failure]] = {}
    for f in failures:
        groups.setdefault(f.key(), []).append(f)
    lines = [f"{len(failures)} problem(s) in {len({f.example for f in failures})} of {len(results)} examples, "
             f"{len(groups)} distinct; seed {seed} ({how}), {seconds:.0f} s.",
             f"Reproduce: MECHSYS_FUZZ_SEED={seed} [MECHSYS_FUZZ_ONLY=K] python -m pytest tests/test_fuzz_cli.py "
             f"-k {test}", ""]
    for key, fs in groups.items():
        lines.append(f"=== {key}  (x{len(fs)})")
        lines.append(fs[0].report())
        lines.append("")
    first = failures[0]
    lines.append(f"--- mutant of example {first.example} ---\n{first.mutant[:3000]}")
    return "\n".join(lines)


# ------------------------------------------------------------------------------------------------- reordering
def reversed_copy(data: dict) -> dict:
    """The same model with its parameters and its coordinates mappings in reverse order."""
    new = copy.deepcopy(data)
    for key in ("parameters", "coordinates"):
        if isinstance(new.get(key), dict):
            new[key] = dict(reversed(list(new[key].items())))
    return new  # nothing else changes (not even `expect`, which an older cache key included)


def scaled_set(data: dict) -> tuple[str, str]:
    """`NAME=VALUE` setting the first non-zero parameter to 1.1x its value (a model without parameters: the
    first coordinate's initial value), and a label for it."""
    for k, v in (data.get("parameters") or {}).items():
        x = number(v)
        if x is not None and x != 0:
            return f"{k}={fmt(1.1 * x)}", f"--set {k}=1.1x"
        if x is None:
            return f"{k}=1.1*({v})", f"--set {k}=1.1x"
    for k, c in (data.get("coordinates") or {}).items():
        if isinstance(c, dict) and "prescribed" not in c:
            v = c.get("initial", 0)
            x = number(v)
            return (f"{k}={fmt(1.1 * x) if x is not None else f'1.1*({v})'}" if v != 0 else f"{k}=0.1",
                    f"--set {k} (initial)")
    raise AssertionError("a model without parameters and free coordinates")
