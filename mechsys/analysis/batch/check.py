"""`mechsys check`: find model files, run their expectations in parallel, compare with tolerances, report."""
from __future__ import annotations

import json
import math
import os
import time
from concurrent.futures import ProcessPoolExecutor
from dataclasses import asdict, dataclass
from pathlib import Path

import yaml

from mechsys.analysis.batch.tasks import option_problem
from mechsys.errors import InputError


@dataclass
class CheckResult:
    file: str
    name: str
    status: str  # "pass", "fail", "error"
    measured: str
    expected: str
    message: str = ""
    seconds: float = 0.0

    def to_dict(self) -> dict:
        return asdict(self)


def discover(paths: list[str]) -> list[tuple[str, list[dict]]]:
    """Model files under the paths with their expectations (from `expect:` or a sibling FILE.check.yaml)."""
    files: list[Path] = []
    for raw in paths:
        p = Path(raw)
        if p.is_dir():
            files += sorted(x for x in p.rglob("*.yaml") if not x.name.endswith(".check.yaml"))
        elif p.is_file():
            files.append(p)
        else:
            raise InputError(f"{raw}: no such file or directory")
    out = []
    for f in files:
        from mechsys.model.load import read_document

        doc = read_document(f)  # validates the model and its expect section (InputError -> exit 2)
        expectations = [e.model_dump() for e in doc.spec.expect]
        for i, e in enumerate(expectations):
            for key, value in e["options"].items():
                why = option_problem(e["analysis"], key, value)
                if why:
                    raise doc.error(("expect", i, "options", key), why, key=True)
        sibling = f.with_name(f.stem + ".check.yaml")
        if sibling.exists():
            expectations += _sibling_expectations(sibling)
        if expectations:
            out.append((str(f), expectations))
    return out


def _sibling_expectations(path: Path) -> list[dict]:
    from pydantic import ValidationError

    from mechsys.model.schema import Expectation

    try:
        data = yaml.safe_load(path.read_text(encoding="utf-8")) or {}
    except yaml.YAMLError as exc:
        raise InputError(f"YAML syntax error: {exc}", str(path), 1, 1) from None
    if not isinstance(data, dict) or not isinstance(data.get("expect"), list):
        raise InputError("a check file needs an 'expect:' list", str(path), 1, 1)
    out = []
    for i, item in enumerate(data["expect"]):
        try:
            out.append(Expectation.model_validate(item).model_dump())
        except ValidationError as exc:
            err = exc.errors()[0]
            raise InputError(f"{'.'.join(map(str, err['loc']))}: {err['msg']}", str(path), 1, 1,
                             f"expect[{i}]") from None
        for key, value in out[-1]["options"].items():
            why = option_problem(out[-1]["analysis"], key, value)
            if why:
                raise InputError(why, str(path), 1, 1, f"expect[{i}].options.{key}")
    return out


def _task_key(e: dict) -> str:
    return json.dumps([e["analysis"], e["set"], e["options"]], sort_keys=True, default=str)


def run_group(file: str, expectations: list[dict]) -> list[dict]:
    """Run one analysis (file, analysis, set, options) once and evaluate every expectation that uses it."""
    from mechsys.analysis.batch.tasks import run_task

    first = expectations[0]
    t0 = time.perf_counter()
    try:
        outputs = run_task(file, first["analysis"], {k: str(v) for k, v in first["set"].items()}, first["options"])
        error = None
    except Exception as exc:  # noqa: BLE001 - reported per check
        outputs, error = {}, f"{type(exc).__name__}: {exc}".splitlines()[0]
    seconds = time.perf_counter() - t0
    results = []
    for e in expectations:
        if error is not None:
            results.append(CheckResult(file, e["name"], "error", "", _expected_text(e), error, seconds).to_dict())
            continue
        try:
            status, measured, message = evaluate(e, outputs, file)
        except Exception as exc:  # noqa: BLE001
            status, measured, message = "error", "", f"{type(exc).__name__}: {exc}".splitlines()[0]
        results.append(CheckResult(file, e["name"], status, measured, _expected_text(e), message, seconds).to_dict())
    return results


def _expected_text(e: dict) -> str:
    if e.get("equilibrium") is not None:
        text = "an equilibrium at " + ", ".join(f"{k} = {v}" for k, v in e["equilibrium"].items())
        return text + (f" ({e['stability']})" if e.get("stability") else "") + _tol(e)
    if e.get("expression") is not None:
        return f"{e['output']} = {e['expression']}"
    parts = []
    if e.get("value") is not None:
        parts.append(f"{e['output']} = {e['value']}{_tol(e)}")
    if e.get("min") is not None:
        parts.append(f"{e['output']} >= {e['min']}")
    if e.get("max") is not None:
        parts.append(f"{e['output']} <= {e['max']}")
    return "; ".join(parts)


def _tol(e: dict) -> str:
    """The tolerance as _close applies it: the larger of the absolute and the relative one."""
    if e.get("tolerance") and e.get("rel_tolerance"):
        return f" ± max({e['tolerance']}, {e['rel_tolerance']} relative)"
    if e.get("tolerance"):
        return f" ± {e['tolerance']}"
    if e.get("rel_tolerance"):
        return f" ± {e['rel_tolerance']} (relative)"
    return ""


def _close(measured: float, e: dict) -> bool:
    target = float(e["value"])
    tol = max(float(e.get("tolerance") or 0.0), float(e.get("rel_tolerance") or 0.0) * abs(target))
    return abs(measured - target) <= tol if tol > 0 else measured == target


def evaluate(e: dict, outputs: dict, file: str) -> tuple[str, str, str]:
    """(status, measured, message) of one expectation against an analysis' outputs."""
    if e.get("equilibrium") is not None:
        return _evaluate_equilibrium(e, outputs)
    key = e.get("output")
    if key is None:
        return "error", "", "an expectation needs 'output' (or 'equilibrium')"
    if key not in outputs:
        known = ", ".join(sorted(outputs)[:12])
        return "fail", "(absent)", f"no output {key!r} (outputs: {known}{', ...' if len(outputs) > 12 else ''})"
    measured = outputs[key]
    if e.get("expression") is not None:
        return _evaluate_expression(e, measured, file)
    note = ""
    if isinstance(e.get("value"), str) and not isinstance(measured, (str, bool)):
        try:  # a closed form in the parameters: value: 5/14*g*sin(alpha)
            target = _value_of(e, file)
        except InputError as exc:
            return "error", f"{float(measured):.10g}", f"value {e['value']!r}: {exc.message}"
        e, note = {**e, "value": target}, f"value {e['value']} = {target:.10g}"
    elif isinstance(measured, (str, bool)) or isinstance(e.get("value"), (str, bool)):
        ok = str(measured) == str(e.get("value"))
        return ("pass" if ok else "fail"), str(measured), ""
    value = float(measured)
    ok = not math.isnan(value)
    if e.get("value") is not None:
        ok = ok and _close(value, e)
    if e.get("min") is not None:
        ok = ok and value >= float(e["min"])
    if e.get("max") is not None:
        ok = ok and value <= float(e["max"])
    return ("pass" if ok else "fail"), f"{value:.10g}", note


def _value_of(e: dict, file: str) -> float:
    """An expectation's value written as an expression of the parameters (the whitelist parser), at the file's
    values with the expectation's `set` applied."""
    from mechsys.model.load import read_document

    doc = read_document(file, {k: str(v) for k, v in e["set"].items()})
    expr = doc.parse(e["value"], ("expect",), "parameter").xreplace(doc.numeric_parameters())
    if not expr.is_number or not expr.is_real:
        raise InputError(f"not a real number with the parameter values ({expr})", file, 1, 1)
    return float(expr)


def _evaluate_equilibrium(e: dict, outputs: dict) -> tuple[str, str, str]:
    count = int(outputs.get("count", 0))
    tols = {name: float(e["tolerance"]) if e.get("tolerance") else _default_tolerance(name, t, outputs)
            for name, t in e["equilibrium"].items()}
    for k in range(1, count + 1):
        values = {name: outputs.get(f"eq{k}.{name}") for name in e["equilibrium"]}
        if all(v is not None and abs(float(v) - float(t)) <= tols[name] for (name, t), v in
               zip(e["equilibrium"].items(), values.values())):
            stability = outputs.get(f"eq{k}.stability")
            measured = ", ".join(f"{n} = {float(v):.10g}" for n, v in values.items()) + f" ({stability})"
            if e.get("stability") and stability != e["stability"]:
                return "fail", measured, f"verdict {stability!r}, expected {e['stability']!r}"
            return "pass", measured, ""
    found = "; ".join(", ".join(f"{n} = {outputs.get(f'eq{k}.{n}')}" for n in e["equilibrium"])
                      for k in range(1, count + 1))
    return "fail", found or "(none)", "no equilibrium within the tolerance"


def _default_tolerance(name: str, expected: float, outputs: dict) -> float:
    """1e-6 times the size of the coordinate among the rests found and the value expected, at most 1: 1e-6 at
    ordinary units; a MEMS model's rests of 1e-6 m are told apart (an expected 1.2e-6 matched the rest at 1.0e-6,
    and passed)."""
    sizes = [abs(float(outputs[f"eq{k}.{name}"])) for k in range(1, int(outputs.get("count", 0)) + 1)
             if outputs.get(f"eq{k}.{name}") is not None]
    size = min(1.0, max([abs(float(expected)), *sizes]))
    return 1e-6 * size if size > 0 else 1e-6


def _evaluate_expression(e: dict, measured, file: str) -> tuple[str, str, str]:
    """Compare a derived expression with the expected one numerically at random states (and parameter values)."""
    import sympy as sp

    import mechsys
    from mechsys.model.expressions import parse_expression

    model = mechsys.load(file, {k: str(v) for k, v in e["set"].items()})
    symbols = {**model.doc.parameters, **model.doc.coords, **model.doc.prescribed, "t": model.t}
    expected = parse_expression(e["expression"], symbols, model.doc.rates)
    worst = _relative_difference(model, sp.sympify(measured), expected)
    tol = float(e.get("rel_tolerance") or 1e-9)
    from mechsys.report.printing import to_text

    return ("pass" if worst <= tol else "fail"), to_text(measured)[:200], f"max relative difference {worst:.2e}"


def _relative_difference(model, measured, expected) -> float:
    """max |a - b| / max(|a|, |b|) over 5 random states (t in [0, 2], coordinates and rates in [-2, 2], the file's
    parameter values), each value at 60 digits (dag.precise; machine floats for a node it does not evaluate): the
    entry's own size is the scale, whatever the units (a MEMS rod's M = 3e-18 against a floor of 1 passed any
    expected value, 0 included), and cancellation in either form stays far below any tolerance. Two expressions
    that vanish at every state differ by 0."""
    import numpy as np

    from mechsys.mechanics.dag import precise
    from mechsys.numeric.lambdify import compile_exprs

    args = [model.t, *model.q, *model.u, *model.parameter_symbols]
    p = [model.parameters[s.name] for s in model.parameter_symbols]
    rng = np.random.default_rng(0)
    states = [[rng.uniform(0, 2), *rng.uniform(-2, 2, 2 * len(model.q)), *p] for _ in range(5)]
    difference = measured - expected
    rows = []
    for state in states:
        values = dict(zip(args, map(float, state)))
        row = [precise(x, values, 60) for x in (difference, measured, expected)]
        if None in row:
            fn = compile_exprs([measured, expected], args)
            a, b = (float(v) for v in fn(*state))
            row = [abs(a - b), abs(a), abs(b)]
        rows.append(row)
    scale = max(max(a, b) for _, a, b in rows)
    worst = max(d for d, _, _ in rows)
    return worst / scale if scale > 0 else (0.0 if worst == 0 else float("inf"))


def run_checks(paths: list[str], jobs: int | None = None) -> list[dict]:
    """All expectations under the paths, grouped per analysis run and executed on local processes."""
    groups: list[tuple[str, list[dict]]] = []
    for file, expectations in discover(paths):
        by_task: dict[str, list[dict]] = {}
        for e in expectations:
            by_task.setdefault(_task_key(e), []).append(e)
        groups += [(file, es) for es in by_task.values()]
    if not groups:
        return []
    workers = max(1, min(jobs or os.cpu_count() or 1, len(groups)))
    if workers == 1:
        nested = [run_group(f, es) for f, es in groups]
    else:
        with ProcessPoolExecutor(max_workers=workers) as pool:
            nested = list(pool.map(run_group, [f for f, _ in groups], [es for _, es in groups]))
    return [r for rs in nested for r in rs]


def junit_xml(results: list[dict]) -> str:
    """JUnit XML: one testsuite per model file, one testcase per expectation."""
    from xml.sax.saxutils import escape, quoteattr

    by_file: dict[str, list[dict]] = {}
    for r in results:
        by_file.setdefault(r["file"], []).append(r)
    lines = ['<?xml version="1.0" encoding="UTF-8"?>',
             f'<testsuites tests="{len(results)}" failures="{sum(r["status"] == "fail" for r in results)}" '
             f'errors="{sum(r["status"] == "error" for r in results)}">']
    for file, rs in by_file.items():
        lines.append(f'  <testsuite name={quoteattr(file)} tests="{len(rs)}" '
                     f'failures="{sum(r["status"] == "fail" for r in rs)}" '
                     f'errors="{sum(r["status"] == "error" for r in rs)}">')
        for r in rs:
            head = f'    <testcase classname={quoteattr(file)} name={quoteattr(r["name"])} time="{r["seconds"]:.3f}"'
            if r["status"] == "pass":
                lines.append(head + "/>")
                continue
            tag = "failure" if r["status"] == "fail" else "error"
            text = f"measured {r['measured']}; expected {r['expected']}. {r['message']}"
            lines += [head + ">", f'      <{tag} message={quoteattr(text)}>{escape(text)}</{tag}>', "    </testcase>"]
        lines.append("  </testsuite>")
    lines.append("</testsuites>")
    return "\n".join(lines) + "\n"
