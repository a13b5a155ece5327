"""What every code-generation target shares: the derived functions as CSE'd programs, names, README, output."""
from __future__ import annotations

import re
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Callable, Sequence

import sympy as sp

from mechsys.codegen.folder import MARKER, check_destination, write_directory  # noqa: F401 (used from here)
from mechsys.codegen.names import MODULES, mangle
from mechsys.errors import AnalysisError, InputError
from mechsys.mechanics.products import product
from mechsys.numeric.cse import cse
from mechsys.numeric.lambdify import ForwardProgram, compile_program, differentiate_program, shared_program
from mechsys.numeric.runtime import call_generated

if TYPE_CHECKING:
    from mechsys.mechanics.model import MechanicalModel


MAX_PREFIX = 40  # leaves room for "_constraint_velocity" and the like within 63 characters (MATLAB)

# the functions of a package (constraint functions only with constraint rows); the C and MATLAB names carry the
# model's prefix, which model names may not take
STATE_ARGS = ("t", "q", "u", "p")
FUNCTIONS = ("mass_matrix", "forcing", "constraint_matrix", "constraint_rhs", "constraint_position",
             "constraint_velocity", "kinetic_energy", "potential_energy", "residual_jacobian", "system_matrix",
             "accelerations", "rhs", "linearize", "params", "params_default", "initial_state", "example")


@dataclass
class StepFacts:
    """What is known of the steps of the functions cut from one CSE, each step's found once (not once per function
    and per question: sympy keeps neither): its free symbols, and the classes of the functions it applies."""

    free: dict = field(default_factory=dict)
    kinds: dict = field(default_factory=dict)


@dataclass
class Program:
    """Straight-line code: temporaries assigned in order, then the outputs, in terms of inputs and temporaries."""

    assignments: list[tuple[sp.Symbol, sp.Expr]]
    outputs: list[sp.Expr]
    facts: StepFacts = field(default_factory=StepFacts, compare=False, repr=False)

    @classmethod
    def of(cls, exprs: Sequence[sp.Expr]) -> "Program":
        """``exprs`` after one common-subexpression elimination over all of them."""
        replacements, reduced = cse([sp.sympify(e) for e in exprs], order="none")
        return cls(list(replacements), list(reduced))

    @classmethod
    def part(cls, program: "ForwardProgram", outputs: Sequence[sp.Expr], facts: StepFacts | None = None) -> "Program":
        """``outputs`` (in terms of ``program``'s temporaries) with the temporaries of ``program`` they need: one
        function of a package from the CSE all of them share (``facts``: what is known of its steps so far)."""
        steps = [(program.symbols[name], value) for name, value in program.values + program.derivatives]
        return cls(steps, list(outputs), StepFacts() if facts is None else facts).pruned()

    def _free(self, expr: sp.Expr) -> set:
        found = self.facts.free.get(expr)
        if found is None:
            found = self.facts.free[expr] = sp.sympify(expr).free_symbols
        return found

    def _kinds(self, expr: sp.Expr) -> frozenset:
        found = self.facts.kinds.get(expr)
        if found is None:
            kinds, stack = set(), [sp.sympify(expr)]
            while stack:  # iterative: a long chain's outputs are deep sums of products
                node = stack.pop()
                if isinstance(node, sp.Function):
                    kinds.add(type(node))
                stack.extend(node.args)
            found = self.facts.kinds[expr] = frozenset(kinds)
        return found

    def applies(self, kind: type) -> bool:
        """Whether a step or an output applies the function ``kind`` (such as sp.re or sp.Heaviside)."""
        return any(kind in self._kinds(e) for e in [v for _, v in self.assignments] + self.outputs)

    def pruned(self) -> "Program":
        """Without the temporaries no output needs."""
        needed: set = set().union(*(self._free(e) for e in self.outputs))
        kept = []
        for sym, value in reversed(self.assignments):
            if sym in needed:
                kept.append((sym, value))
                needed |= self._free(value)
        return Program(kept[::-1], self.outputs, self.facts)

    def inputs(self) -> set:
        """The symbols the program reads (not its own temporaries)."""
        assigned = {s for s, _ in self.assignments}
        used = set().union(*(self._free(v) for _, v in self.assignments), *(self._free(e) for e in self.outputs))
        return used - assigned


@dataclass
class Function:
    """One generated function of the model: a name, its argument vectors, the shape of its result, its program."""

    name: str
    args: tuple[str, ...]
    shape: tuple[int, ...]  # () a scalar, (r,) a vector, (r, c) a matrix (row-major outputs)
    program: Program
    summary: str


@dataclass
class Quantity:
    """A coordinate or a parameter as the README and the code name it."""

    name: str  # as in the model file
    code: str  # the identifier (names.py)
    value: float  # default (parameters) or initial value (coordinates; assembled onto the constraints)
    unit: str = ""
    comment: str = ""
    expression: str = ""  # a parameter given as an expression of others
    rate_code: str = ""  # coordinates: the identifier of der(name)
    rate: float = 0.0  # coordinates: the initial rate

    def note(self) -> str:
        """The comment and the unit, for a comment in code."""
        return " ".join(x for x in (self.comment, f"[{self.unit}]" if self.unit else "") if x)


@dataclass
class Package:
    """Everything a target prints: model facts, identifiers and the derived functions."""

    model: str
    prefix: str
    file: str
    method: str
    description: str
    coordinates: list[Quantity]
    parameters: list[Quantity]
    constraints: list[tuple[str, str]]  # (name, holonomic | nonholonomic) per row
    functions: dict[str, Function]
    inputs: dict[sp.Symbol, tuple[str, int, str]]  # symbol -> (argument vector, index, identifier)
    prescribed: list[tuple[str, str]] = field(default_factory=list)  # (coordinate, expression of t)
    notes: list[str] = field(default_factory=list)
    version: str = ""
    #: parameter name -> why it fixes the structure of this export (a constraint row or a contact that vanishes
    #: at its value and was left out): another value needs another export (`--set`)
    fixed: dict[str, str] = field(default_factory=dict)
    #: x = [q; u] as the file (and --set) give them, before assembly, and which of them --set gave (held by the
    #: assembly): the FMU assembles a start from them as `mechsys simulate` does
    start_guess: list[float] = field(default_factory=list)
    start_held: list[bool] = field(default_factory=list)
    angles: list[bool] = field(default_factory=list)  # which coordinates are angles (turns of them are one position)

    @property
    def n(self) -> int:
        return len(self.coordinates)

    @property
    def m(self) -> int:
        return len(self.constraints)

    @property
    def holonomic_rows(self) -> list[int]:
        return [i for i, (_, kind) in enumerate(self.constraints) if kind == "holonomic"]

    def state_codes(self) -> list[str]:
        """The identifiers of the state x = [q; u], in order."""
        return [c.code for c in self.coordinates] + [c.rate_code for c in self.coordinates]

    def initial_state(self) -> list[float]:
        return [c.value for c in self.coordinates] + [c.rate for c in self.coordinates]


@dataclass
class Style:
    """How a target spells the parts of a generated function body."""

    printer: Callable[[dict], object]  # symbol -> identifier map -> a sympy code printer
    bind: Callable[[str, int, str], str]  # (argument vector, index, identifier) -> statement binding a local
    element: Callable[[str, int], str]  # (argument vector, index) -> an element read in place
    assign: Callable[[str, str], str]  # (temporary, expression) -> statement


_VECTORS = ("t", "q", "u", "a", "lam", "p")


def function_body(pkg: Package, fn: Function, style: Style) -> tuple[list[str], list[str]]:
    """The statements of a generated function (bindings of the inputs it reads, in argument order, then its
    temporaries ``cse0``, ``cse1``, ...) and its printed outputs. Multipliers are read in place (``lam[0]``)."""
    names: dict = {}
    lines = []
    used = fn.program.inputs()
    unknown = [s for s in used if s not in pkg.inputs]
    if unknown:
        raise AnalysisError(f"{fn.name} depends on {', '.join(sorted(map(str, unknown)))}, which is not an argument")
    for sym in sorted(used, key=lambda s: (_VECTORS.index(pkg.inputs[s][0]), pkg.inputs[s][1])):
        vector, index, code = pkg.inputs[sym]
        if vector == "t":
            names[sym] = "t"
        elif vector == "lam":
            names[sym] = style.element(vector, index)
        else:
            names[sym] = code
            lines.append(style.bind(vector, index, code))
    for k, (sym, _) in enumerate(fn.program.assignments):
        names[sym] = f"cse{k}"
    printer = style.printer(names)
    printer.no_re = not fn.program.applies(sp.re)  # LeanDoprint: no statement to look through for re(...)
    steps = fn.program.applies(sp.Heaviside)
    lines += [style.assign(names[sym], printer.doprint(_without_steps(value, steps))) for sym, value in
              fn.program.assignments]
    return lines, [printer.doprint(_without_steps(sp.sympify(e), steps)) for e in fn.program.outputs]


def _without_steps(expr: sp.Expr, steps: bool = True) -> sp.Expr:
    """Heaviside(x, h0) (the derivative of min and max) written with sign(x), which every target prints: sympy's
    printers turn it into a Piecewise whose conditions may hold booleans that C cannot print. ``steps`` False: the
    program has none (nothing to look for)."""
    def step(x: sp.Expr, h0: sp.Expr = sp.S.Half) -> sp.Expr:
        s = sp.sign(x)
        return (1 + s) / 2 if h0 == sp.S.Half else s ** 2 * (1 + s) / 2 + h0 * (1 - s ** 2)

    return expr.replace(sp.Heaviside, step) if steps and expr.has(sp.Heaviside) else expr


def plain(text: str) -> str:
    """Free text (the model's name, description, a file comment) made safe in a comment or docstring of every
    target: one printable line without backslashes, double quotes or a C comment's end."""
    text = "".join(c if c.isprintable() else " " for c in text)
    return text.replace("\\", "/").replace('"', "'").replace("*/", "* /")


# ----------------------------------------------------------------------------------------- the file's comments
def _comment(line: str) -> str:
    """The YAML comment of a line (a ``#`` at the start or after white space, outside quotes)."""
    quote = None
    for i, ch in enumerate(line):
        if quote:
            quote = None if ch == quote else quote
        elif ch in "'\"":
            quote = ch
        elif ch == "#" and (i == 0 or line[i - 1].isspace()):
            return line[i + 1:].strip()
    return ""


def _annotations(doc, section: str) -> dict[str, tuple[str, str]]:
    """(unit, comment) per name of a section ('parameters', 'coordinates') from the comment on its key's line
    (``m1: 1.0  # rod mass [kg]`` -> ``("kg", "rod mass")``); a line that holds several names gives none."""
    lines: dict[int, list[str]] = {}
    for name in doc.raw.get(section) or {}:
        lines.setdefault(doc.positions.lookup((section, name), key=True)[0], []).append(name)
    out = {}
    for line, names in lines.items():
        text = _comment(doc.raw_text_line(line))
        if len(names) != 1 or not text:
            continue
        unit = re.search(r"\[([^\]]+)\]", text)
        comment = re.sub(r"\s*\[[^\]]+\]\s*", " ", text).strip(" ,;:-")
        out[names[0]] = (plain(unit.group(1).strip()) if unit else "", plain(comment))
    return out


# ----------------------------------------------------------------------------------------- derivation
def derive_package(model: "MechanicalModel", method: str = "lagrange") -> Package:
    """What a generated package of ``model`` contains, derived once for every target: the model's M, f, constraint
    rows, energies and the Jacobian the linearization needs, each as a CSE'd `Program`; the coordinates and
    parameters with their identifiers (names.py), defaults and the units the file's comments state. A target module
    (python.py, c.py, matlab.py) prints it. InputError for an unknown method or a model without free coordinates,
    AnalysisError when the equations cannot be solved for the accelerations at the file's initial state."""
    from mechsys import __version__
    from mechsys.mechanics.model import METHODS
    from mechsys.report.printing import to_text

    if method not in METHODS:
        raise InputError(f"unknown method {method!r}; use one of {', '.join(METHODS)}")
    if not model.q:
        raise InputError("the model has no free coordinates: there is no motion to generate code for")
    eq = model.equations(method)
    doc = model.doc
    prefix = mangle([model.name], MODULES)[model.name][:MAX_PREFIX]
    functions = {f"{prefix}_{name}" for name in FUNCTIONS} | {prefix}
    functions |= {f"{prefix.upper()}_{macro}" for macro in ("H", "N", "NX", "NC", "NK")}  # the C header's macros
    params = [s.name for s in model.parameter_symbols]
    codes = mangle(params + model.coordinates + [s.name for s in model.u] + [s.name for s in model.a], functions)
    units = {**_annotations(doc, "parameters"), **_annotations(doc, "coordinates")}
    raw = doc.raw.get("parameters") or {}
    parameters = [Quantity(n, codes[n], model.parameters[n], *units.get(n, ("", "")),
                           expression=_expression(raw.get(n))) for n in params]
    coordinates = []
    q0, u0, moved = _initial_state(model)
    for k, (name, u) in enumerate(zip(model.coordinates, model.u)):
        unit, comment = units.get(name, ("", ""))
        coordinates.append(Quantity(name, codes[name], float(q0[k]), unit or ("rad" if model.angles[name] else ""),
                                    comment, rate_code=codes[u.name], rate=float(u0[k])))
    rows = [(c.name, c.kind) for c in model.kin.constraints]
    lam = [sp.Dummy(f"lam{i}") for i in range(len(rows))]
    inputs = {model.t: ("t", 0, "t")}
    for vector, symbols in (("q", model.q), ("u", model.u), ("a", model.a), ("lam", lam),
                            ("p", model.parameter_symbols)):
        inputs.update({s: (vector, i, codes.get(s.name, "")) for i, s in enumerate(symbols)})
    pkg = Package(plain(model.name), prefix, plain(Path(doc.file).name), method, plain(doc.spec.description or ""),
                  coordinates, parameters, rows, {}, inputs, [(n, to_text(e)) for n, e in model.prescribed.items()],
                  _notes(model, moved), __version__)
    pkg.fixed = fixed_parameters(model)
    from mechsys.analysis.motion.simulate import file_state, held_start

    pkg.start_guess = [float(x) for part in file_state(model) for x in part]
    pkg.start_held = [bool(x) for part in held_start(model) for x in part]
    pkg.angles = [bool(model.angles[name]) for name in model.coordinates]
    n, m = len(model.q), len(rows)

    def add(name: str, args: tuple[str, ...], shape: tuple[int, ...], program: Program, summary: str) -> None:
        pkg.functions[name] = Function(name, args, shape, program, summary)

    # M, f, A and b from one CSE (real temporaries: the Jacobian below differentiates it), each function the part
    # of it that its outputs need; the Jacobian of the residual by forward differentiation of that CSE, with the
    # entries of M, f, A and b as temporaries there (their derivatives then temporaries too; the bicycle's
    # Jacobian: 3 % fewer operations)
    wrt = [*model.q, *model.u]
    blocks = [list(eq.M), list(eq.f)] + ([list(eq.A), list(eq.b)] if m else [])
    shared = shared_program([e for block in blocks for e in block],
                            [model.t, *model.q, *model.u, *model.parameter_symbols], wrt)
    _check_regular(model, shared, n, m, pkg.initial_state())
    named = ForwardProgram(shared.args, list(shared.values), [], dict(shared.symbols), [], [])
    as_named = []  # each output of the CSE, or its temporary in ``named``
    for k, e in enumerate(shared.outputs):
        if not e.is_Atom:
            named.symbols[f"o{k}"] = sym = sp.Dummy(f"o{k}", real=True)
            named.values.append((f"o{k}", e))
            e = sym
        as_named.append(e)
    parts, entries, start = [], [], 0
    for block in blocks:
        parts.append(shared.outputs[start:start + len(block)])
        entries.append(as_named[start:start + len(block)])
        start += len(block)
    facts = StepFacts()  # what is known of the CSE's steps, for every function cut from it
    add("mass_matrix", STATE_ARGS, (n, n), Program.part(shared, parts[0], facts), "mass matrix M")
    add("forcing", STATE_ARGS, (n,), Program.part(shared, parts[1], facts), "forcing f (M q'' = f + A^T lam)")
    a = sp.Matrix(model.a)
    residual = list(product(sp.Matrix(n, n, entries[0]), a) - sp.Matrix(entries[1]))
    if m:
        holonomic = model.holonomic_constraints
        A = sp.Matrix(m, n, entries[2])
        add("constraint_matrix", STATE_ARGS, (m, n), Program.part(shared, parts[2], facts),
            "constraint matrix A (A q'' = b)")
        add("constraint_rhs", STATE_ARGS, (m,), Program.part(shared, parts[3], facts),
            "constraint right-hand side b")
        add("constraint_velocity", STATE_ARGS, (m,), Program.of(list(model.constraint_velocity)),
            "velocity-level constraints A q' + a_t (zero on a consistent motion)")
        if len(holonomic):
            add("constraint_position", STATE_ARGS, (len(holonomic),), Program.of(list(holonomic)),
                "position-level constraints Phi of the holonomic rows (zero on a consistent motion)")
        residual = [r - e for r, e in zip(residual, product(A.T, sp.Matrix(lam)))]
        residual += list(product(A, a) - sp.Matrix(entries[3]))
    add("kinetic_energy", STATE_ARGS, (), Program.of([eq.T]), "kinetic energy T")
    add("potential_energy", STATE_ARGS, (), Program.of([eq.V]), "potential energy V")
    named.outputs = residual
    jac = differentiate_program(named, wrt)
    add("residual_jacobian", ("t", "q", "u", "a", "lam", "p"), (n + m, 2 * n), Program.part(jac, jac.jacobian, facts),
        "Jacobian d[M q'' - f - A^T lam; A q'' - b]/d[q, q'] at given q'' and lam (exact, symbolic)")
    return pkg


def fixed_parameters(model: "MechanicalModel") -> dict[str, str]:
    """The parameters that fix the structure of an export, and why: those in a constraint row (or a contact's
    normal velocity, a rolling frame's turning) that vanishes identically at the file's values and was left out
    (mechanics/build.py's decisions), and the parameters a calculated one among them is computed from. With other
    values that row may not vanish: the exported code would leave a constraint out, silently (a cart on a rail
    along [1, h, 0] pinned to a cart on x: exported at h = 0, the pin's y row is gone, and at h = 0.3 the carts
    moved where the pin locks them)."""
    names = {s: s.name for s in model.parameter_symbols}
    exprs = model.doc.parameter_exprs
    out: dict[str, str] = {}
    for what, kind, expr, outcome in model.kin.decisions:
        if kind != "zero" or not outcome:
            continue
        found = [names[s] for s in sorted(sp.sympify(expr).free_symbols, key=str) if s in names]
        stack = list(found)
        while stack:  # a calculated parameter follows the ones it is computed from
            name = stack.pop()
            depends = [str(x) for x in sp.sympify(exprs.get(name, 0)).free_symbols if str(x) in model.parameters]
            stack += [x for x in depends if x not in found]
            found += [x for x in depends if x not in found]
        for name in found:
            out.setdefault(name, f"`{what}` is identically zero at the exported values, which decides the "
                                 "exported structure")
    return out


def _expression(value: object) -> str:
    """A parameter's text in the file when it is an expression rather than a number."""
    if not isinstance(value, str):
        return ""
    try:
        float(value)
    except ValueError:
        return plain(value)
    return ""


def _initial_state(model: "MechanicalModel") -> tuple[list[float], list[float], list[str]]:
    """The package's initial state (q0, u0) and the coordinates and rates assembly moved: with constraint rows,
    the file's values assembled onto them as `mechsys simulate` starts (Gauss-Newton on Phi, then the
    minimum-norm change of u), so the generated examples start on the loop; AnalysisError when that fails. Before,
    a four-bar with a guessed coupler angle started its exported example 0.2 m off its loop (exit 0)."""
    from mechsys.analysis.motion.simulate import check_on_manifold, file_state, initial_state

    q_file, u_file = file_state(model)
    if not model.kin.constraints:
        return list(q_file), list(u_file), []
    c, p, y0 = initial_state(model)
    n = len(model.q)
    q0, u0 = y0[:n], y0[n:]
    check_on_manifold(c, p, 0.0, q0, u0)
    moved = [name for k, name in enumerate(model.coordinates)
             if abs(q0[k] - q_file[k]) > 1e-12 * (1 + abs(q_file[k]))]
    moved += [f"der({name})" for k, name in enumerate(model.coordinates)
              if abs(u0[k] - u_file[k]) > 1e-12 * (1 + abs(u_file[k]))]
    return [float(x) for x in q0], [float(x) for x in u0], moved


def _check_regular(model: "MechanicalModel", shared: "ForwardProgram", n: int, m: int, state: list[float]) -> None:
    """AnalysisError when [[M, -A^T], [A, 0]] (M without constraints) is singular at the package's initial state
    ``state`` = [q; u], as `mechsys simulate` refuses it: the generated accelerations would fail (or, in MATLAB, be
    Inf) from the start. ``shared``: the CSE of M, f, A and b (derive_package's), evaluated there."""
    import numpy as np

    values = (0.0, *state, *[model.parameters[s.name] for s in model.parameter_symbols])
    out = np.asarray(call_generated(compile_program(shared), values, len(shared.outputs)), dtype=float)
    from mechsys.numeric import saddle

    M = out[:n * n].reshape(n, n)
    A = out[n * n + n:n * n + n + m * n].reshape(m, n)
    if saddle.condition(M, A) < saddle.SINGULAR:  # balanced: a MEMS four-bar is as regular as one in metres
        return
    if not m:
        raise AnalysisError("the mass matrix is singular at the file's initial state: a coordinate, or a combination "
                            "of them, carries no mass or inertia (make it prescribed, or give it mass or inertia), "
                            "so the generated accelerations would fail")
    raise AnalysisError("[[M, -A^T], [A, 0]] is singular at the file's initial state (redundant constraints, a "
                        "singular configuration, or a coordinate without mass), so the generated accelerations "
                        "would fail; change the initial state (--set) or the constraints")


def _notes(model: "MechanicalModel", moved: Sequence[str] = ()) -> list[str]:
    """What the package leaves out or changed, so that nobody takes it for the whole model file."""
    spec = model.doc.spec
    notes = []
    if moved:
        notes.append(f"the initial state is the file's assembled onto the constraints, as `mechsys simulate` starts "
                     f"(moved: {', '.join(moved)})")
    if spec.contacts:
        notes.append(f"contacts ({', '.join(c.name for c in spec.contacts)}): impacts are not exported; the "
                     "functions give the smooth motion between impacts (`mechsys simulate` handles the impacts)")
    if spec.events:
        notes.append(f"events ({', '.join(e.name for e in spec.events)}): not exported (no event functions)")
    return notes


# ----------------------------------------------------------------------------------------- README
def readme(pkg: Package, target: str, signatures: Sequence[tuple[str, str]], usage: str) -> str:
    """The package's README.md: what it is, the state order, the parameters, the functions and how to run them."""
    n = pkg.n
    out = [MARKER, f"# {pkg.model}: equations of motion ({target})", ""]
    out += [f"Generated by `mechsys codegen` (mechsys {pkg.version}) from `{pkg.file}` with the {pkg.method} "
            "formulation. The code does not need mechsys.", ""]
    if pkg.description:
        out += [f"> {pkg.description}", ""]
    out += ["## Equations", "",
            "    M(t, q, u, p) q'' = f(t, q, u, p)" + (" + A(t, q, u, p)^T lam" if pkg.m else ""),
            *(["    A(t, q, u, p) q'' = b(t, q, u, p)"] if pkg.m else []), "",
            f"q are the {n} coordinates, u = q' their rates, p the parameters; the state is x = [q; u] "
            f"({2 * n} values) and `rhs(t, x, p)` returns x' = [u; q''].", ""]
    if pkg.m:
        out += [f"With {pkg.m} constraint rows, q'' and the multipliers lam solve [[M, -A^T], [A, 0]] [q''; lam] = "
                "[f; b] (the constraints at acceleration level, index 1). The state must start on the constraints "
                "(`constraint_position` and `constraint_velocity` are zero there); a long integration drifts off "
                "them unless it projects back.", ""]
    out += ["## State order", "", "| index | coordinate | code name | rate (code name) | unit | initial | rate |",
            "|---|---|---|---|---|---|---|"]
    for i, c in enumerate(pkg.coordinates):
        out.append(f"| {i} | `{c.name}` | `{c.code}` | `{c.rate_code}` (index {n + i}) | {_cell(c.unit)} | "
                   f"{c.value!r} | {c.rate!r} |")
    out += ["", "Indices count from 0 (MATLAB: add 1).", ""]
    if pkg.prescribed:
        out += ["Prescribed coordinates are not states: their motions are functions of t inside the code.", ""]
        out += [f"- `{name}` = `{text}`" for name, text in pkg.prescribed] + [""]
    out += ["## Parameters", "", "| code name | file name | default | unit | comment |", "|---|---|---|---|---|"]
    for p in pkg.parameters:
        note = "; ".join(x for x in (p.comment, f"the file gives `{p.expression}`" if p.expression else "") if x)
        out.append(f"| `{p.code}` | `{p.name}` | {p.value!r} | {_cell(p.unit)} | {_cell(note)} |")
    if not pkg.parameters:
        out.append("| | | | | the model has no parameters |")
    out += ["", "Defaults are the file's values (with `--set` applied). A parameter the file computes from others is "
            "exported as its value: changing one parameter does not update it.", ""]
    if pkg.fixed:
        out += ["### Fixed by this export", "",
                "These parameters decide the structure of the exported equations: at their values a constraint row "
                "(or a contact) vanishes and is left out. With other values it may not vanish, and the code would "
                "silently leave it out. Export again with `mechsys codegen --set NAME=VALUE` to change them. The "
                "Python package's `params()` and the FMU's `fmi2SetReal` refuse another value; C and MATLAB callers "
                "must keep these values.", ""]
        out += [f"- `{name}`: {why}" for name, why in pkg.fixed.items()] + [""]
    if pkg.m:
        out += ["## Constraint rows", "", "| row | name | kind |", "|---|---|---|"]
        out += [f"| {i} | `{name}` | {kind} |" for i, (name, kind) in enumerate(pkg.constraints)]
        if pkg.holonomic_rows != list(range(pkg.m)):
            out += ["", f"`constraint_position` returns the holonomic rows {pkg.holonomic_rows} only."]
        out.append("")
    out += ["## Functions", ""] + [f"- `{sig}`: {text}" for sig, text in signatures] + [""]
    out += ["## Linearization", "",
            "`linearize` returns A = d rhs/dx (2n x 2n) and B = d rhs/d tau (2n x n), where tau is a generalized "
            "force added to f on every coordinate (the model file declares no inputs: B is the input matrix of "
            "joint forces and torques). Both are exact: the derivatives of M, f, A and b are symbolic "
            "(`residual_jacobian`), and only the linear solves are numeric, no finite differences. "
            + ("For constrained models A includes the directions off the constraint manifold." if pkg.m else ""), ""]
    if pkg.notes:
        out += ["## Not exported", ""] + [f"- {note}" for note in pkg.notes] + [""]
    out += ["## Use", "", usage.strip(), "",
            "## Names", "",
            "Names of the model file that are not identifiers in Python, C and MATLAB at once are mangled by one "
            "rule (`mechsys/codegen/names.py`, docs/codegen.md): `der(q)` -> `der_q`, reserved words get a trailing "
            "`_` (`lambda` -> `lambda_`), collisions take `_2`, `_3`, ... The tables above give every name.", ""]
    return "\n".join(out)


def _cell(text: str) -> str:
    """Text for a Markdown table cell."""
    return text.replace("|", "\\|")


# ----------------------------------------------------------------------------------------- output
