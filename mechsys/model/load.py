"""Read a model file: YAML with positions, pydantic validation, --set overrides, symbols and parameters."""
from __future__ import annotations

import difflib
import os
import re
from dataclasses import dataclass, field
from typing import Any, Mapping

import pydantic
import sympy as sp

from mechsys.errors import InputError
from mechsys.model.expressions import RESERVED, ExpressionError, Quantities, names_in, parse_expression
from mechsys.model.files import read_model_text
from mechsys.model.schema import System
from mechsys.model.yamlpos import Path, PositionMap, dotted, load_yaml

T = sp.Symbol("t", real=True)


def rate_symbol(name: str) -> sp.Symbol:
    """The symbol printed as ``der(name)``: the rate of coordinate ``name``."""
    return sp.Symbol(f"der({name})", real=True)


def accel_symbol(name: str) -> sp.Symbol:
    return sp.Symbol(f"der(der({name}))", real=True)


@dataclass
class Document:
    """A validated model file with everything needed to report positioned errors and parse expressions."""

    file: str
    spec: System
    raw: dict
    positions: PositionMap
    parameters: dict[str, sp.Symbol] = field(default_factory=dict)
    parameter_exprs: dict[str, sp.Expr] = field(default_factory=dict)
    parameter_values: dict[str, float] = field(default_factory=dict)
    coords: dict[str, sp.Symbol] = field(default_factory=dict)  # free coordinates
    rates: dict[str, sp.Symbol] = field(default_factory=dict)
    accels: dict[str, sp.Symbol] = field(default_factory=dict)
    prescribed: dict[str, sp.Expr] = field(default_factory=dict)  # name -> expression of t
    initial: dict[str, float] = field(default_factory=dict)
    initial_rate: dict[str, float] = field(default_factory=dict)
    overridden: dict[tuple, str] = field(default_factory=dict)  # key path -> the --set text that replaced it
    released: dict[str, sp.Expr] = field(default_factory=dict)  # prescribed coordinates turned into drive constraints

    # ------------------------------------------------------------------------------------- errors
    def error(self, path: Path, message: str, key: bool = False) -> InputError:
        if tuple(path) in self.overridden:
            return InputError(f"--set {_shorten(self.overridden[tuple(path)])}: {message}")
        line, col = self.positions.lookup(path, key=key)
        return InputError(message, self.file, line, col, dotted(path))

    # ------------------------------------------------------------------------------------- parsing
    def parse(self, value: Any, path: Path, kind: str = "kinematic", extra: dict | None = None,
              quantities: Quantities | None = None) -> sp.Expr:
        """Parse an expression at ``path``. ``kind``: 'parameter' (parameters only), 'initial' (parameters),
        'prescribed' (parameters and t), 'kinematic' (+ coordinates), 'force' (+ rates); ``quantities``: the
        built-in functions of `outputs:` (mechanics/quantities.py)."""
        # parameters only: the mapping itself (no copy per call, which made N parameters cost N**2)
        symbols: Mapping[str, sp.Expr] = self.parameters
        if kind in ("prescribed", "kinematic", "force") or extra:
            symbols = dict(self.parameters)
        rates = None
        if kind in ("prescribed", "kinematic", "force"):
            symbols["t"] = T
        if kind in ("kinematic", "force"):
            symbols.update(self.coords)
            symbols.update(self.prescribed)
        if kind == "force":
            rates = dict(self.rates)
            rates.update({n: sp.diff(e, T) for n, e in self.prescribed.items()})
        if extra:
            symbols.update(extra)  # a copy: see above
        try:
            return parse_expression(value, symbols, rates, quantities)
        except ExpressionError as exc:
            if path in self.overridden:
                raise InputError(f"--set {_shorten(self.overridden[path])}: {exc.message}") from None
            line, col = self.positions.lookup(path)
            if isinstance(value, str):
                col += _offset_in_scalar(self.raw_text_line(line), value, exc.column)
            raise InputError(exc.message, self.file, line, col, dotted(path)) from None

    def parse_vec(self, values: list, path: Path, kind: str = "kinematic") -> sp.Matrix:
        return sp.Matrix([self.parse(v, path + (i,), kind) for i, v in enumerate(values)])

    def raw_text_line(self, line: int) -> str:
        lines = self._text.splitlines()
        return lines[line - 1] if 0 < line <= len(lines) else ""

    _text: str = ""

    @property
    def text(self) -> str:
        """The file's text as it was read for this document (what cache keys of its results must hash)."""
        return self._text

    # ------------------------------------------------------------------------------------- lookups
    def suggest(self, name: str, options: list[str]) -> str:
        close = difflib.get_close_matches(name, options, n=1)
        return f" (did you mean {close[0]!r}?)" if close else ""

    def numeric_parameters(self) -> dict[sp.Symbol, float]:
        return {self.parameters[k]: v for k, v in self.parameter_values.items()}


def _shorten(text: str, limit: int = 80) -> str:
    """A --set item as echoed in a message: at most ``limit`` characters (an expression may have 4000)."""
    return text if len(text) <= limit else text[:limit - 3] + "..."


def _offset_in_scalar(line_text: str, value: str, column: int) -> int:
    """Column offset of character ``column`` of ``value`` within its (possibly quoted) YAML scalar."""
    idx = line_text.find(value)
    quoted = idx > 0 and line_text[idx - 1] in "\"'"
    return column + (1 if quoted else 0)


# ----------------------------------------------------------------------------------------- pydantic errors
def _model_at(loc: tuple, data: Any) -> type[pydantic.BaseModel] | None:
    """The pydantic model class that owns the last element of ``loc`` (for did-you-mean suggestions)."""
    import typing

    current: Any = System
    value: Any = data
    for part in loc[:-1]:
        current = _unwrap(current, value)
        if current is None:
            return None
        if isinstance(current, type) and issubclass(current, pydantic.BaseModel):
            fld = current.model_fields.get(part)
            if fld is None:
                return None
            current = fld.annotation
            value = value.get(part) if isinstance(value, dict) else None
        else:
            origin = typing.get_origin(current)
            args = typing.get_args(current)
            if origin is dict:
                current = args[1]
                value = value.get(part) if isinstance(value, dict) else None
            elif origin is list:
                current = args[0]
                value = value[part] if isinstance(value, list) and isinstance(part, int) and part < len(value) else None
            else:
                return None
    current = _unwrap(current, value)
    if isinstance(current, type) and issubclass(current, pydantic.BaseModel):
        return current
    return None


def _unwrap(tp: Any, value: Any) -> Any:
    """Strip Annotated/Optional/discriminated unions, choosing the member named by value['type']."""
    import types
    import typing

    for _ in range(10):
        origin = typing.get_origin(tp)
        if origin is typing.Annotated:
            tp = typing.get_args(tp)[0]
            continue
        if origin in (typing.Union, types.UnionType):
            members = [a for a in typing.get_args(tp) if a is not type(None)]
            models = [a for a in members if isinstance(a, type) and issubclass(a, pydantic.BaseModel)]
            if len(models) == 1:
                tp = models[0]
                continue
            tag = value.get("type") if isinstance(value, dict) else None
            for m in models:
                fld = m.model_fields.get("type")
                if fld is not None and tag in typing.get_args(fld.annotation):
                    return m
            if models:
                return None
            tp = members[0] if len(members) == 1 else tp
            return tp
        return tp
    return tp


def _clean_loc(loc: tuple, data: Any) -> tuple:
    """Drop discriminator tags and type names that pydantic inserts into error locations."""
    out: list = []
    value = data
    for part in loc:
        if part == "[key]":
            out.append(part)
            break
        if isinstance(value, dict) and part not in value and isinstance(part, str) and (
            value.get("type") == part or part in ("str", "int", "float", "list[...]", "function-after")
            or re.match(r"^(list|dict|literal|union)\[", part) or part.startswith("lax-")):
            continue
        if isinstance(value, list) and not isinstance(part, int):
            continue
        if isinstance(value, (str, int, float)) and not isinstance(value, bool):
            # pydantic tried union members: 'int', 'float', 'str' under a scalar
            continue
        out.append(part)
        if isinstance(value, dict):
            value = value.get(part)
        elif isinstance(value, list) and isinstance(part, int) and part < len(value):
            value = value[part]
        else:
            value = None
    return tuple(out)


_TYPE_WORDS = {
    "dict_type": "expected a mapping (key: value)",
    "list_type": "expected a list",
    "string_type": "expected a text value",
    "bool_type": "expected true or false",
    "bool_parsing": "expected true or false",
    "model_type": "expected a mapping (key: value)",
    "model_attributes_type": "expected a mapping (key: value)",
}


def _pydantic_to_input_error(exc: pydantic.ValidationError, data: Any, pos: PositionMap, file: str) -> InputError:
    errors = exc.errors()
    # Prefer the most specific error: unknown keys and missing keys first, then the deepest location.
    def rank(err: dict) -> tuple:
        kind = err["type"]
        order = {"extra_forbidden": 0, "missing": 1, "union_tag_invalid": 2, "literal_error": 3}.get(kind, 4)
        return (order, -len(err["loc"]))

    err = sorted(errors, key=rank)[0]
    loc = _clean_loc(tuple(err["loc"]), data)
    kind = err["type"]
    if kind == "extra_forbidden":
        key = loc[-1]
        model = _model_at(loc, data)
        options = list(model.model_fields) if model else []
        hint = ""
        close = difflib.get_close_matches(str(key), options, n=1)
        if close:
            hint = f" (did you mean {close[0]!r}?)"
        elif options:
            hint = f" (allowed: {', '.join(options)})"
        line, col = pos.lookup(loc, key=True)
        return InputError(f"unknown key {key!r}{hint}", file, line, col, dotted(loc))
    if kind == "missing":
        line, col = pos.lookup(loc[:-1])
        return InputError(f"missing required key {loc[-1]!r}", file, line, col, dotted(loc))
    if kind in ("union_tag_invalid", "union_tag_not_found"):
        ctx = err.get("ctx", {})
        expected = ctx.get("expected_tags", "")
        tag = ctx.get("tag")
        if kind == "union_tag_not_found":
            import typing

            from mechsys.model import schema

            union = {"forces": schema.ForceSpec, "constraints": schema.Constraint}.get(loc[0], schema.Joint)
            tags = [typing.get_args(m.model_fields["type"].annotation)[0]
                    for m in typing.get_args(typing.get_args(union)[0])]
            line, col = pos.lookup(loc)
            return InputError(f"missing 'type' (one of {', '.join(repr(t) for t in tags)})", file, line, col,
                              dotted(loc))
        options = [s.strip().strip("'") for s in str(expected).split(",")]
        hint = difflib.get_close_matches(str(tag), options, n=1)
        extra = f" (did you mean {hint[0]!r}?)" if hint else f" (one of {expected})"
        line, col = pos.lookup(loc + ("type",))
        return InputError(f"unknown type {tag!r}{extra}", file, line, col, dotted(loc + ("type",)))
    if "[key]" in loc:
        key_path = loc[:loc.index("[key]")]
        line, col = pos.lookup(key_path, key=True)
        return InputError(f"invalid name {key_path[-1]!r}: use letters, digits and '_', not starting with a digit",
                          file, line, col, dotted(key_path))
    if kind == "value_error":
        line, col = pos.lookup(loc)
        return InputError(err["msg"].removeprefix("Value error, "), file, line, col, dotted(loc))
    message = _TYPE_WORDS.get(kind, err["msg"])
    if kind == "literal_error":
        message = f"{err['msg'].replace('Input should be', 'expected')}"
    elif kind in ("too_short", "too_long") and isinstance(err.get("input"), list):
        message = err["msg"].replace("List should", "expected a list that should")
    elif kind in ("int_type", "float_type", "int_parsing", "float_parsing", "string_type") or (
            kind.endswith("_type") and "expected" not in message):
        message = f"wrong type: {err['msg']}"
    line, col = pos.lookup(loc)
    return InputError(message, file, line, col, dotted(loc))


# ----------------------------------------------------------------------------------------- overrides
_SET = re.compile(r"^\s*(der\(\s*(?P<rate>[A-Za-z_][A-Za-z_0-9]*)\s*\)|(?P<name>[A-Za-z_][A-Za-z_0-9]*))\s*$")


def parse_assignments(items: list[str] | None) -> dict[str, str]:
    """Turn ``["m=2", "der(beta)=0"]`` into a dict; an item without '=' is an input error."""
    out: dict[str, str] = {}
    for item in items or []:
        if "=" not in item:
            raise InputError(f"--set {item!r}: expected NAME=VALUE")
        key, value = item.split("=", 1)
        if not _SET.match(key) or not value.strip():
            raise InputError(f"--set {item!r}: expected NAME=VALUE or der(NAME)=VALUE")
        out[key.replace(" ", "")] = value.strip()
    return out


def _apply_overrides(data: dict, overrides: Mapping[str, Any]) -> dict[tuple, str]:
    """Write --set values into the raw data; return the key paths they replaced (for error messages).
    Text values stay text, so the expression parser reads decimals exactly."""
    params = data.setdefault("parameters", {})
    coords = data.get("coordinates", {})
    if not isinstance(params, dict) or not isinstance(coords, dict):
        return {}
    replaced: dict[tuple, str] = {}
    for key, value in overrides.items():
        m = _SET.match(key)
        if not m:
            raise InputError(f"--set {key!r}: expected NAME or der(NAME)")
        if m.group("rate"):
            name = m.group("rate")
            if name not in coords:
                raise InputError(f"--set der({name}): unknown coordinate{_hint(name, list(coords))}")
            path: tuple = ("coordinates", name, "rate")
        elif m.group("name") in params:
            path = ("parameters", m.group("name"))
        elif m.group("name") in coords:
            path = ("coordinates", m.group("name"), "initial")
        else:
            name = m.group("name")
            raise InputError(f"--set {name}: unknown parameter or coordinate{_hint(name, list(params) + list(coords))}")
        if len(path) == 3:
            entry = coords[path[1]] if isinstance(coords[path[1]], dict) else {}
            entry[path[2]] = value
            coords[path[1]] = entry
        else:
            params[path[1]] = value
        replaced[path] = f"{key}={value}"
    return replaced


def _hint(name: str, options: list[str]) -> str:
    close = difflib.get_close_matches(name, options, n=1)
    return f" (did you mean {close[0]!r}?)" if close else ""


# ----------------------------------------------------------------------------------------- entry point
def read_document(path: str | os.PathLike, overrides: Mapping[str, Any] | None = None,
                  release_prescribed: bool = False) -> Document:
    """Read and validate a model file, resolve parameters and coordinates; raise InputError on bad input.
    ``release_prescribed`` turns each prescribed coordinate into a free one held by q - p(t) = 0 (its
    multiplier is then the driving force: inverse dynamics)."""
    file = os.fspath(path)
    text = read_model_text(file)
    data, pos = load_yaml(text, file)
    if not isinstance(data, dict):
        raise InputError("a model file must be a mapping with keys such as 'name' and 'links'", file, 1, 1)
    replaced = _apply_overrides(data, overrides) if overrides else {}
    try:
        spec = System.model_validate(data)
    except pydantic.ValidationError as exc:
        raise _pydantic_to_input_error(exc, data, pos, file) from None
    doc = Document(file=file, spec=spec, raw=data, positions=pos, overridden=replaced)
    doc._text = text
    _resolve_symbols(doc, release_prescribed)
    return doc


def _resolve_symbols(doc: Document, release_prescribed: bool = False) -> None:
    spec = doc.spec
    for name in spec.parameters:
        if name in RESERVED:
            raise doc.error(("parameters", name), f"{name!r} is a reserved name", key=True)
    for name in spec.coordinates:
        if name in RESERVED:
            raise doc.error(("coordinates", name), f"{name!r} is a reserved name", key=True)
        if name in spec.parameters:
            raise doc.error(("coordinates", name), f"{name!r} is both a parameter and a coordinate", key=True)
    doc.parameters = {n: sp.Symbol(n, real=True) for n in spec.parameters}
    _resolve_parameters(doc)
    for name, c in spec.coordinates.items():
        if c.prescribed is not None:
            for key in ("initial", "rate"):
                if key in c.model_fields_set:
                    raise doc.error(("coordinates", name, key),
                                    f"a prescribed coordinate has no free {key}: its motion is given by 'prescribed'",
                                    key=True)
            motion = doc.parse(c.prescribed, ("coordinates", name, "prescribed"), "prescribed")
            if not release_prescribed:
                doc.prescribed[name] = motion
                continue
            # inverse dynamics: a free coordinate held on q - p(t) = 0, whose multiplier is the driving force
            doc.released[name] = motion
            doc.coords[name] = sp.Symbol(name, real=True)
            doc.rates[name] = rate_symbol(name)
            doc.accels[name] = accel_symbol(name)
            path = ("coordinates", name, "prescribed")
            doc.initial[name] = _real(doc, motion.xreplace({T: 0}), path, " at t = 0")
            doc.initial_rate[name] = _real(doc, sp.diff(motion, T).xreplace({T: 0}), path, " (its rate) at t = 0")
        else:
            doc.coords[name] = sp.Symbol(name, real=True)
            doc.rates[name] = rate_symbol(name)
            doc.accels[name] = accel_symbol(name)
            doc.initial[name] = _numeric(doc, c.initial, ("coordinates", name, "initial"))
            doc.initial_rate[name] = _numeric(doc, c.rate, ("coordinates", name, "rate"))


def _numeric(doc: Document, value: Any, path: Path) -> float:
    return _real(doc, doc.parse(value, path, "initial"), path)


def _real(doc: Document, expr: sp.Expr, path: Path, where: str = "") -> float:
    """``expr`` with the file's parameter values: a finite real number, or an input error at ``path``."""
    try:
        used = expr.free_symbols
        values = {doc.parameters[n]: sp.Float(v) for n, v in doc.parameter_values.items() if doc.parameters[n] in used}
        out = complex(sp.sympify(expr.xreplace(values)).evalf())
    except (TypeError, ValueError):
        raise doc.error(path, f"does not evaluate to a number{where}") from None
    if abs(out.imag) > 1e-12 * max(1.0, abs(out.real)) or out.real != out.real or abs(out.real) == float("inf"):
        raise doc.error(path, f"does not evaluate to a finite real number{where}")
    return out.real


def _resolve_parameters(doc: Document) -> None:
    """Sort the parameters so each comes after the ones it uses (a cycle is an error: ``a -> b -> a``), parse
    them and evaluate them to floats. Linear in the number of parameters: an iterative depth-first search (no
    recursion limit on long chains) and each expression evaluated with the numeric values of its own
    dependencies only (sympy Floats, never Python floats: ``m1: m2`` is the Float of m2, not a float)."""
    spec = doc.spec
    known = set(spec.parameters)
    deps = {n: sorted(names_in(v) & known) for n, v in spec.parameters.items()}
    order: list[str] = []
    state: dict[str, int] = {}  # 1: on the current path, 2: done
    for root in spec.parameters:
        if root in state:
            continue
        state[root] = 1
        path = [root]
        stack = [iter(deps[root])]
        while stack:
            d = next(stack[-1], None)
            if d is None:
                stack.pop()
                done = path.pop()
                state[done] = 2
                order.append(done)
            elif state.get(d) == 1:
                cycle = path[path.index(d):] + [d]
                raise doc.error(("parameters", d), f"parameters form a cycle: {' -> '.join(cycle)}")
            elif d not in state:
                state[d] = 1
                path.append(d)
                stack.append(iter(deps[d]))
    values: dict[str, sp.Float] = {}
    for n in order:
        expr = doc.parse(spec.parameters[n], ("parameters", n), "parameter")
        doc.parameter_exprs[n] = expr
        try:
            val = complex(sp.sympify(expr.xreplace({doc.parameters[d]: values[d] for d in deps[n]})).evalf())
        except (TypeError, ValueError):
            raise doc.error(("parameters", n), "does not evaluate to a number") from None
        if abs(val.imag) > 1e-12 * max(1.0, abs(val.real)) or val.real != val.real or abs(val.real) == float("inf"):
            raise doc.error(("parameters", n), "does not evaluate to a finite real number")
        values[n] = sp.Float(val.real)
        doc.parameter_values[n] = val.real
