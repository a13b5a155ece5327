"""Fuzzing the model reader: mutate the bundled systems/*.yaml at the text level and at the data level, then
``mechsys.load`` (and derive the equations when loading succeeded). The only exception ever allowed is
``mechsys.errors.InputError``, positioned in the file (``FILE:LINE:COL: ...``, one line).

Each example runs in a forked child with a time limit, so a hang (e.g. sympy computing a gigantic integer) is
reported as a failure instead of stalling the suite; the child inherits the parent's warmed-up imports and sympy
caches, so this costs a few milliseconds per example.
"""
from __future__ import annotations

import functools
import json
import os
import re
import signal
import time
import traceback
from pathlib import Path
from typing import Any

import pytest
import yaml
from hypothesis import HealthCheck, Phase, given, note, seed, settings
from hypothesis import strategies as st

import fuzzing as fz

ROOT = Path(__file__).resolve().parents[1]
SYSTEMS = ROOT / "systems"
ERROR_LINE = re.compile(r"^.+:\d+:\d+: .*$")
EXAMPLE_TIMEOUT = 30.0  # seconds for one load + derivation in the child
MAX_DERIVE_COORDINATES = 8

# ----------------------------------------------------------------------------------------- vocabulary
FUNCTIONS = ["sin", "cos", "tan", "asin", "acos", "atan", "atan2", "sinh", "cosh", "tanh", "exp", "log", "sqrt",
             "abs", "sign", "min", "max", "der"]
OPERATORS = ["+", "-", "*", "/", "**", "^", "(", ")", ",", "(", ")"]
NUMBERS = ["0", "1", "2", "3", "0.5", "1e3", "2.5e-3", ".5", "1.", "007", "1e999"]
JUNK_NAMES = ["t", "pi", "ground", "com", "origin", "gg", "nosuch", "_", "__import__", "__class__", "lambda", "open",
              "os", "eval", "é"]
JUNK_CHARS = [".", "'", '"', "[", "]", "{", "}", ":", ";", "%", "=", "==", "<", "!", "@", "#", "&", "|", "~", "`",
              "\\", "$", "?", "\t", "\n", " ", ""]
# literals that are valid YAML/expressions but not usable numbers (Python refuses int('9' * 5000) by default)
HUGE_LITERALS = ["9" * 5000, "-" + "1" * 4400, "1e999", "-1e999", ".inf", "-.inf", ".nan", "1e308*1e308", "0**-1",
                 "log(0)", "(-8)**(1/3)", "sqrt(-1)"]
KEYS = ["name", "description", "parameters", "coordinates", "ground", "links", "constraints", "forces", "type",
        "parent", "origin", "axis", "axes", "coordinate", "coordinates", "mass", "center_of_mass", "inertia",
        "inertia_about", "shape", "points", "particle", "joint", "initial", "rate", "prescribed", "angle", "xx",
        "yy", "zz", "xy", "xz", "yz", "rod", "disk", "cylinder", "sphere", "box", "radius", "length", "size",
        "steps", "rotate", "translate", "expression", "through", "direction", "normal", "frame", "link",
        "contact", "on", "components", "acceleration", "at", "value", "reaction", "between", "stiffness",
        "free_length", "coefficient", "free_angle", "sequence", "revolute", "prismatic", "cylindrical",
        "universal", "spherical", "planar", "fixed", "free", "transform", "holonomic", "nonholonomic",
        "point_on_point", "point_on_line", "point_on_plane", "rolling", "gravity", "force", "torque", "spring",
        "damper", "actuator", "torsional_spring", "torsional_damper", "generalized_force", "dissipation",
        "potential", "x", "y", "z", "-x", "-z", "zyx", "xyz"]
YAML_CHARS = "abcxyz_019 .,:-[]{}#&*!|>'\"%@`?\t\n\\é\u2028\x85\x00\ufeff"


class _Loader(yaml.SafeLoader):
    """SafeLoader that reads only true/false as booleans, so keys such as ``on:`` stay text (as in mechsys)."""


_Loader.yaml_implicit_resolvers = {
    first: [(tag, rx) for tag, rx in resolvers if tag != "tag:yaml.org,2002:bool"]
    for first, resolvers in yaml.SafeLoader.yaml_implicit_resolvers.items()
}
_Loader.add_implicit_resolver("tag:yaml.org,2002:bool", re.compile(r"^(?:true|True|TRUE|false|False|FALSE)$"),
                              list("tTfF"))


def system_files() -> list[Path]:
    """The bundled models, globbed at test time (the directory grows while the project is written)."""
    files = sorted(SYSTEMS.glob("*.yaml"))
    assert files, f"no model files in {SYSTEMS}"
    return files


def names_of(data: Any) -> list[str]:
    """Parameter, coordinate and link names (and named points) of a parsed model, for realistic mutations."""
    out: list[str] = []
    if isinstance(data, dict):
        for section in ("parameters", "coordinates", "links"):
            if isinstance(data.get(section), dict):
                out += [str(k) for k in data[section]]
        links = data.get("links")
        if isinstance(links, dict):
            for link, spec in links.items():
                if isinstance(spec, dict) and isinstance(spec.get("points"), dict):
                    out += [f"{link}.{p}" for p in spec["points"]]
                out += [f"{link}.com"]
    return out or ["q"]


# ----------------------------------------------------------------------------------------- strategies
def expressions(names: list[str]) -> st.SearchStrategy[str]:
    token = st.one_of(st.sampled_from(names), st.sampled_from(FUNCTIONS), st.sampled_from(OPERATORS),
                      st.sampled_from(names), st.sampled_from(OPERATORS), st.sampled_from(NUMBERS),
                      st.sampled_from(JUNK_NAMES), st.sampled_from(JUNK_CHARS))
    joiner = st.sampled_from(["", " "])
    return st.builds(lambda toks, sep: sep.join(toks), st.lists(token, min_size=1, max_size=12), joiner)


def scalars(names: list[str]) -> st.SearchStrategy[Any]:
    return st.one_of(
        st.none(), st.booleans(), st.integers(-10**6, 10**6), st.integers(), st.floats(),
        st.text(max_size=12), st.sampled_from(names), st.sampled_from(KEYS), expressions(names),
    )


def values(names: list[str]) -> st.SearchStrategy[Any]:
    scalar = scalars(names)
    return st.one_of(
        scalar, scalar, scalar,
        st.lists(scalar, max_size=5),
        st.dictionaries(st.one_of(st.sampled_from(KEYS), st.text(max_size=8)), scalar, max_size=3),
    )


def misspell(word: str) -> st.SearchStrategy[str]:
    """A near miss of ``word``: one character dropped, doubled, swapped or changed."""
    if not word:
        return st.just("x")
    pos = st.integers(0, len(word) - 1)
    return st.one_of(
        pos.map(lambda i: word[:i] + word[i + 1:]),
        pos.map(lambda i: word[:i] + word[i] + word[i:]),
        pos.map(lambda i: word[:i] + word[i + 1:i + 2] + word[i:i + 1] + word[i + 2:]),
        st.tuples(pos, st.sampled_from("aeiouxyz_.0")).map(lambda a: word[:a[0]] + a[1] + word[a[0] + 1:]),
    )


# ----------------------------------------------------------------------------------------- data-level mutations
def all_paths(node: Any, prefix: tuple = ()) -> list[tuple]:
    out = [prefix]
    if isinstance(node, dict):
        for k, v in node.items():
            out += all_paths(v, prefix + (k,))
    elif isinstance(node, list):
        for i, v in enumerate(node):
            out += all_paths(v, prefix + (i,))
    return out


def get(node: Any, path: tuple) -> Any:
    for part in path:
        node = node[part]
    return node


def mutate_data(data: Any, draw, names: list[str]) -> tuple[Any, str]:
    """Apply one random structural mutation; returns the new data and a description."""
    paths = all_paths(data)
    leaves = [p for p in paths if p and not isinstance(get(data, p), (dict, list))]
    op = draw(st.sampled_from(["delete", "rename", "replace", "replace", "expression", "expression", "tweak",
                               "tweak", "insert", "misspell", "misspell", "empty", "wrap"]))
    # expression-like mutations go to scalars, so that they survive the schema and reach the parser and builder
    path = draw(st.sampled_from(leaves if op in ("expression", "tweak", "misspell") and leaves else paths))
    if path == ():
        if op in ("delete", "rename", "misspell"):
            op = "replace"
        if op == "replace":
            return draw(values(names)), "replace the whole document"
    parent = get(data, path[:-1]) if path else None
    key = path[-1] if path else None
    value = get(data, path)
    if op == "delete":
        del parent[key]
        return data, f"delete {path}"
    if op == "rename":
        if isinstance(parent, dict):
            new_key = draw(st.one_of(st.sampled_from(KEYS), misspell(str(key)), st.text(max_size=8),
                                     st.sampled_from(names)))
            items = [(new_key if k == key else k, v) for k, v in parent.items()]
            parent.clear()
            parent.update(items)
            return data, f"rename key {path} -> {new_key!r}"
        op = "replace"
    if op == "misspell" and isinstance(value, str):
        new = draw(misspell(value))
        parent[key] = new
        return data, f"misspell {path}: {value!r} -> {new!r}"
    if op == "tweak" and path:
        # splice a token or a short expression into the existing text of a scalar
        text = str(value)
        pos = draw(st.integers(0, len(text)))
        piece = draw(st.one_of(st.sampled_from(OPERATORS + NUMBERS + FUNCTIONS + names), st.sampled_from(JUNK_NAMES),
                               st.sampled_from(JUNK_CHARS),
                               expressions(names).map(lambda e: f"*({e})")))
        parent[key] = text[:pos] + piece + text[pos:]
        return data, f"tweak {path}: {value!r} -> {parent[key]!r}"
    if op == "expression":
        new = draw(expressions(names))
        if path:
            parent[key] = new
        else:
            data = new
        return data, f"expression at {path}: {new!r}"
    if op == "insert":
        target = value if isinstance(value, (dict, list)) else parent
        if isinstance(target, dict):
            new_key = draw(st.one_of(st.sampled_from(KEYS), st.sampled_from(names), st.text(max_size=8)))
            new_value = draw(values(names))
            target[new_key] = new_value
            return data, f"insert {new_key!r}: {new_value!r} near {path}"
        if isinstance(target, list):
            new_value = draw(values(names))
            target.insert(draw(st.integers(0, len(target))), new_value)
            return data, f"insert list item {new_value!r} near {path}"
        op = "replace"
    if op == "empty" and path:
        new = type(value)() if isinstance(value, (dict, list, str)) else None
        parent[key] = new
        return data, f"empty {path}: {new!r}"
    if op == "wrap" and path:
        parent[key] = [value]
        return data, f"wrap {path} in a list"
    new = draw(values(names))
    if path:
        parent[key] = new
    else:
        data = new
    return data, f"replace {path} with {new!r}"


# ----------------------------------------------------------------------------------------- text-level mutations
def mutate_text(text: str, draw, names: list[str]) -> tuple[str, str]:
    lines = text.splitlines(keepends=True) or [""]
    n = len(lines)
    # Mostly hit the model itself, not the long comment headers of the bundled files.
    content = [k for k, line in enumerate(lines) if line.strip() and not line.lstrip().startswith("#")] or [0]
    pick_line = st.one_of(st.sampled_from(content), st.sampled_from(content), st.integers(0, n - 1))
    op = draw(st.sampled_from(["truncate", "swap", "duplicate", "delete", "insert", "char", "indent", "word"]))
    i = draw(pick_line)
    line_start = sum(len(line) for line in lines[:i])
    if op == "truncate":
        pos = line_start + draw(st.integers(0, len(lines[i])))
        return text[:pos], f"truncate at {pos} (line {i + 1})"
    if op == "swap":
        j = draw(pick_line)
        lines[i], lines[j] = lines[j], lines[i]
        return "".join(lines), f"swap lines {i + 1} and {j + 1}"
    if op == "duplicate":
        lines.insert(i, lines[i])
        return "".join(lines), f"duplicate line {i + 1}"
    if op == "delete":
        del lines[i]
        return "".join(lines), f"delete line {i + 1}"
    if op == "insert":
        pos = line_start + draw(st.integers(0, len(lines[i])))
        junk = draw(st.one_of(st.text(alphabet=YAML_CHARS, max_size=12), expressions(names),
                              st.sampled_from(KEYS).map(lambda k: f"{k}: ")))
        return text[:pos] + junk + text[pos:], f"insert {junk!r} at {pos}"
    if op == "char":
        if not text:
            return draw(st.text(alphabet=YAML_CHARS, max_size=5)), "replace empty text"
        pos = min(line_start + draw(st.integers(0, max(len(lines[i]) - 1, 0))), len(text) - 1)
        ch = draw(st.sampled_from(YAML_CHARS))
        return text[:pos] + ch + text[pos + 1:], f"set char {pos} to {ch!r}"
    if op == "indent":
        prefix = draw(st.sampled_from([" ", "  ", "\t", "   "]))
        if draw(st.booleans()):
            lines[i] = prefix + lines[i]
            return "".join(lines), f"indent line {i + 1} with {prefix!r}"
        lines[i] = lines[i][len(prefix):] if lines[i].startswith(prefix) else lines[i].lstrip(" ")
        return "".join(lines), f"dedent line {i + 1}"
    # word: replace one identifier-like word of a line by another or a near miss
    words = list(re.finditer(r"[A-Za-z_][A-Za-z_0-9]*", lines[i]))
    if not words:
        lines.insert(i, draw(expressions(names)) + "\n")
        return "".join(lines), f"insert an expression line before {i + 1}"
    m = draw(st.sampled_from(words))
    new = draw(st.one_of(misspell(m.group()), st.sampled_from(names), st.sampled_from(KEYS),
                         expressions(names), st.sampled_from(HUGE_LITERALS)))
    lines[i] = lines[i][:m.start()] + new + lines[i][m.end():]
    return "".join(lines), f"line {i + 1}: {m.group()!r} -> {new!r}"


@st.composite
def mutants(draw, files: list[Path]) -> tuple[Path, str, list[str]]:
    base = draw(st.sampled_from(files))
    text = base.read_text(encoding="utf-8")
    try:
        data = yaml.load(text, Loader=_Loader)  # noqa: S506 - a SafeLoader subclass
    except yaml.YAMLError:
        data = None
    names = names_of(data)
    steps: list[str] = []
    # mostly a single mutation, so that errors deep in the pipeline are not masked by earlier ones
    data_ops = draw(st.sampled_from([0, 1, 1, 1, 2, 3])) if isinstance(data, dict) else 0
    text_ops = draw(st.sampled_from([0, 0, 0, 1] if data_ops else [1, 1, 2]))
    if data_ops:
        for _ in range(data_ops):
            data, what = mutate_data(data, draw, names)
            steps.append(what)
        style = draw(st.sampled_from([None, False, True]))
        text = yaml.safe_dump(data, sort_keys=False, allow_unicode=True, default_flow_style=style)
    for _ in range(text_ops):
        text, what = mutate_text(text, draw, names)
        steps.append(what)
    return base, text, steps


# ----------------------------------------------------------------------------------------- the check
def check_file(path: Path) -> dict:
    """Load (and derive if that worked); classify the outcome. Runs in the forked child."""
    import mechsys
    from mechsys.errors import InputError

    stage = "load"
    try:
        model = mechsys.load(path)
        if len(model.coordinates) <= MAX_DERIVE_COORDINATES:
            stage = "equations"
            model.equations("lagrange")
        return {"outcome": "ok"}
    except InputError as exc:
        text = str(exc)
        problems = []
        if len(text.splitlines()) != 1:  # also \r, \x85, \u2028... which terminals and editors break on
            problems.append("str() is not one line")
        if exc.file != str(path):
            problems.append(f"file is {exc.file!r}, expected {str(path)!r}")
        elif not ERROR_LINE.match(text):
            problems.append("str() does not match FILE:LINE:COL: ...")
        if problems:
            return {"outcome": "bad-input-error", "stage": stage, "message": text, "problems": problems}
        return {"outcome": "input-error", "message": text}
    except BaseException as exc:  # noqa: BLE001 - that is what we are looking for
        return {"outcome": "other-exception", "stage": stage, "type": f"{type(exc).__module__}.{type(exc).__name__}",
                "message": str(exc)[:2000], "traceback": traceback.format_exc()[-6000:]}


def run_forked(path: Path, timeout: float) -> dict:
    """``check_file`` in a forked child; a hang or a crash of the child becomes an outcome too."""
    read_fd, write_fd = os.pipe()
    pid = os.fork()
    if pid == 0:  # child
        code = 0
        try:
            os.close(read_fd)
            signal.signal(signal.SIGINT, signal.SIG_DFL)
            payload = json.dumps(check_file(path)).encode()
            with os.fdopen(write_fd, "wb") as fh:
                fh.write(payload)
        except BaseException:  # noqa: BLE001
            code = 3
        finally:
            os._exit(code)
    os.close(write_fd)
    start = time.monotonic()
    status = None
    while True:
        done, status = os.waitpid(pid, os.WNOHANG)
        if done:
            break
        if time.monotonic() - start > timeout:
            os.kill(pid, signal.SIGKILL)
            os.waitpid(pid, 0)
            os.close(read_fd)
            return {"outcome": "hang", "seconds": timeout}
        time.sleep(0.002)
    with os.fdopen(read_fd, "rb") as fh:
        raw = fh.read()
    if not raw:
        return {"outcome": "child-crashed", "status": status}
    return json.loads(raw)


@functools.lru_cache(maxsize=None)
def warm_up() -> None:
    """Import everything and derive the unmutated models once in the parent, so forked children start warm."""
    import mechsys

    for path in system_files():
        try:
            model = mechsys.load(path)
            if len(model.coordinates) <= MAX_DERIVE_COORDINATES:
                model.equations("lagrange")
        except Exception:  # noqa: BLE001 - a model being written right now may be broken; the fuzz decides
            pass


@pytest.fixture(scope="module")
def workdir(tmp_path_factory: pytest.TempPathFactory) -> Path:
    return tmp_path_factory.mktemp("fuzz")


def fuzz_once(data: st.DataObject, workdir: Path) -> None:
    warm_up()
    base, text, steps = data.draw(mutants(system_files()), label="mutant")
    path = workdir / f"{base.stem}.yaml"
    path.write_text(text, encoding="utf-8", errors="surrogatepass")
    result = run_forked(path, EXAMPLE_TIMEOUT)
    note(f"outcome: {result}")
    if result["outcome"] in ("ok", "input-error"):
        return
    excerpt = text if len(text) < 3000 else text[:3000] + "\n...[truncated]"
    detail = json.dumps(result, indent=2)
    pytest.fail(f"{base.name} mutated by {steps}: {result['outcome']}\n{detail}\n--- mutated file ---\n{excerpt}",
                pytrace=False)


COMMON = dict(deadline=None, derandomize=True, database=None, print_blob=False,
              phases=[Phase.explicit, Phase.generate],  # no shrinking: hangs would make it very slow
              suppress_health_check=[HealthCheck.too_slow, HealthCheck.data_too_large,
                                     HealthCheck.function_scoped_fixture, HealthCheck.filter_too_much])


@settings(max_examples=150, **COMMON)
@given(data=st.data())
def test_fuzz_model_files_fast(data: st.DataObject, workdir: Path) -> None:
    fuzz_once(data, workdir)


SLOW_SEED, SLOW_HOW = fz.fuzz_seed()  # fixed by default; CI draws a new one every run (tests/fuzzing.py)


@pytest.mark.slow
@seed(SLOW_SEED)
@settings(max_examples=350, **{**COMMON, "derandomize": False})  # about 55 s in CI; the seed rotates every run
@given(data=st.data())
def test_fuzz_model_files_slow(data: st.DataObject, workdir: Path) -> None:
    note(f"seed {SLOW_SEED} ({SLOW_HOW}): MECHSYS_FUZZ_SEED={SLOW_SEED} reproduces this run")
    fuzz_once(data, workdir)
