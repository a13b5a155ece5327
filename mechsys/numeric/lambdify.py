"""Compile symbolic expressions to Python callables: common-subexpression elimination, then plain source code.

sympy.lambdify walks the whole (unshared) expression tree several times to find symbols and functions, which
dominates for the long expressions of a chain; here CSE runs once and only its small results are printed."""
from __future__ import annotations

import math
from collections import OrderedDict
from dataclasses import dataclass
from typing import Callable, Iterator, Sequence

import sympy as sp
from sympy.printing.pycode import PythonCodePrinter

from mechsys.mechanics.dag import FreeSymbols
from mechsys.mechanics.differentiate import Differentiator
from mechsys.numeric.cse import cse
from mechsys.numeric.runtime import StateFunction, function_from_source, matrix_from_source

__all__ = ["generate_source", "shared_cse", "compile_exprs", "matrix_source", "compile_matrix", "function_from_source",
           "matrix_from_source", "StateFunction", "value_and_jacobian_sources", "value_and_jacobian_program",
           "ForwardProgram", "shared_program", "differentiate_program", "compile_program"]


class LeanDoprint:
    """A sympy code printer with two of sympy's costs cut, the same text: doprint rewrites re(...) of an
    UnevaluatedExpr only where the expression has an re(...) (sympy's does it with a replace over the whole
    expression for every statement printed, which walks and rebuilds each one: a quarter of the printing time of
    a long chain's generated package), and a sum's terms are put in sympy's print order by ordered_terms.
    ``no_re``: the caller knows that nothing it prints has an re(...) (codegen's Program.applies)."""

    no_re = False

    def _handle_UnevaluatedExpr(self, expr):
        return super()._handle_UnevaluatedExpr(expr) if not self.no_re and expr.has(sp.re) else expr

    def _as_ordered_terms(self, expr, order=None):
        if (order or self.order) is None and expr.is_Add:
            return ordered_terms(expr)
        return super()._as_ordered_terms(expr, order=order)


_COMPLEX: dict[tuple, complex] = {}  # (type, number) -> complex(number): sympy evaluates each one through evalf


def _complex(number: sp.Expr) -> complex:
    key = (type(number), number)
    value = _COMPLEX.get(key)
    if value is None:
        if len(_COMPLEX) > 10_000:
            _COMPLEX.clear()
        value = _COMPLEX[key] = complex(number)
    return value


def ordered_terms(expr: sp.Add) -> list[sp.Expr]:
    """expr.as_ordered_terms() (sympy's print order of a sum's terms, the default order), with the numbers'
    complex values remembered: Expr.as_terms converts every term's coefficient by evalf (half of the C and MATLAB
    targets' printing time on a long chain). The same list (tests/test_numeric.py compares the two)."""
    from sympy.core.exprtools import decompose_power
    from sympy.core.sorting import default_sort_key

    terms = sp.Add.make_args(expr)
    if len(terms) == 2 and any(isinstance(t, (sp.Number, sp.NumberSymbol)) for t in terms) \
            and any(t.is_Mul for t in terms) or any(t.is_Order for t in terms):
        return expr.as_ordered_terms()  # its special case of a number and a negative product; O() terms
    key, reverse = expr._parse_order(None)
    gens, parts = set(), []
    for term in terms:  # Expr.as_terms
        coeff, rest = term.as_coeff_Mul()
        coeff = _complex(coeff)
        cpart, ncpart = {}, []
        if rest is not sp.S.One:
            for factor in sp.Mul.make_args(rest):
                if factor.is_number:
                    try:
                        coeff *= _complex(factor)
                    except (TypeError, ValueError):
                        pass
                    else:
                        continue
                if factor.is_commutative:
                    base, exp = decompose_power(factor)
                    cpart[base] = exp
                    gens.add(base)
                else:
                    ncpart.append(factor)
        parts.append((term, ((coeff.real, coeff.imag), cpart, tuple(ncpart))))
    index = {g: i for i, g in enumerate(sorted(gens, key=default_sort_key))}
    data = []
    for term, (coeff, cpart, ncpart) in parts:
        monom = [0] * len(index)
        for base, exp in cpart.items():
            monom[index[base]] = exp
        data.append((term, (coeff, tuple(monom), ncpart)))
    return [term for term, _ in sorted(data, key=key, reverse=reverse)]


class _Printer(LeanDoprint, PythonCodePrinter):
    """Python source with positional argument names a0, a1, ... for the input symbols. Sums, products, powers and
    numbers are printed directly, in the expression's own argument order and fully parenthesized (sympy's
    printer orders the terms of every sum and weighs precedence: most of a generated source's printing time);
    everything else by sympy's printer. Rationals print as a quotient of exact integers and Floats as their
    double's repr, so the numbers are the expression's own to the last bit."""

    def __init__(self, names: dict[sp.Symbol, str]) -> None:
        super().__init__({"fully_qualified_modules": True, "inline": True, "allow_unknown_functions": False})
        self._names = names

    def _print_Symbol(self, expr: sp.Symbol) -> str:
        return self._names.get(expr) or super()._print_Symbol(expr)

    _print_Dummy = _print_Symbol

    def _operand(self, e: sp.Basic) -> str:
        """``e`` printed as an operand of +, * or /: parenthesized unless printed here (sympy prints Mod as
        ``a % b`` and Piecewise as ``x if c else y``, which bind differently)."""
        text = self._print(e)
        return text if e.is_Symbol or e.is_Number or e.is_Add or e.is_Mul or e.is_Pow else f"({text})"

    def _print_Add(self, expr: sp.Add, order=None) -> str:
        return "(" + " + ".join(self._operand(a) for a in expr.args) + ")"

    def _print_Mul(self, expr: sp.Mul) -> str:
        num, den = [], []
        for a in expr.args:
            if a.is_Pow and a.exp.is_Integer and a.exp < 0:
                den.append(self._operand(a.base) if a.exp == -1 else self._operand(sp.Pow(a.base, -a.exp)))
            elif a.is_Rational and not a.is_Integer:
                num.append(str(a.p))
                den.append(str(a.q))
            else:
                num.append(self._operand(a))
        top = "*".join(num) if num else "1"
        return f"({top}/({'*'.join(den)}))" if den else f"({top})"

    def _print_Pow(self, expr: sp.Pow, rational=False) -> str:
        base, exp = expr.args
        if exp == sp.S.Half:
            return f"math.sqrt({self._print(base)})"
        if exp == -sp.S.Half:
            return f"(1/math.sqrt({self._print(base)}))"
        if exp.is_Integer:
            return f"({self._print(base)})**{int(exp)}" if exp > 0 else f"({self._print(base)})**({int(exp)})"
        return f"({self._print(base)})**({self._print(exp)})"

    def _print_Integer(self, expr: sp.Integer) -> str:
        value = int(expr)
        return f"({value})" if value < 0 else str(value)

    def _print_Rational(self, expr: sp.Rational) -> str:
        return f"({expr.p}/{expr.q})"

    def _print_Float(self, expr: sp.Float) -> str:
        value = float(expr)
        return f"({value!r})" if math.isfinite(value) else super()._print_Float(expr)

    def _print_NegativeInfinity(self, expr: sp.Expr) -> str:
        return "(-math.inf)"  # sympy's float('-inf'): generated code holds no strings (runtime.check_source)

    def _print_DiracDelta(self, expr: sp.Expr) -> str:
        # derivative of sign(x) in |x| (e.g. a 1-D spring length): zero except at the singular point itself
        return "0.0"


#: The latest CSE results by (expressions, light): one command may compile the same expressions twice (the
#: cyclic test's shifted M and A, then `info`'s; a first `simulate` prints the staged equations and the constraint
#: rows as Python and as C), and CSE is the costly part. The result is a function of the key.
_RECENT: OrderedDict[tuple, tuple[list, list]] = OrderedDict()
_RECENT_SIZE = 16


def shared_cse(exprs: Sequence[sp.Expr], light: bool = False) -> tuple[list, list]:
    """sympy's cse of ``exprs`` (``light``: light_cse's), (replacements, reduced), memoized on the expressions:
    the Python and the C code generators print the same result."""
    exprs = [sp.sympify(e) for e in exprs]
    key = (tuple(exprs), light)
    out = _RECENT.get(key)
    if out is None:
        out = _RECENT[key] = light_cse(exprs) if light else cse(exprs, order="none")
        if len(_RECENT) > _RECENT_SIZE:
            _RECENT.popitem(last=False)
    return out


def generate_source(exprs: Sequence[sp.Expr], args: Sequence[sp.Symbol], light: bool = False) -> str:
    """Python source of ``_f(a0, a1, ...)`` returning ``exprs`` (shared subexpressions computed once). ``light``:
    for code evaluated a few times only (light_cse)."""
    names = {a: f"a{i}" for i, a in enumerate(args)}
    replacements, reduced = shared_cse(exprs, light)
    for k, (sym, _) in enumerate(replacements):
        names[sym] = f"x{k}"
    printer = _Printer(names)
    lines = [f"def _f({', '.join(names[a] for a in args)}):"]
    lines += [f"    {names[sym]} = {printer.doprint(value)}" for sym, value in replacements]
    lines.append("    return [" + ", ".join(printer.doprint(e) for e in reduced) + "]")
    return "\n".join(lines)


def light_cse(exprs: list[sp.Expr], symbols: Iterator[sp.Symbol] | None = None) -> tuple[list, list]:
    """sympy's cse without its search for common sub-sums and sub-products (opt_cse): only the shared subtrees
    become temporaries. The bicycle's M, f, A, b: 0.25 s instead of 0.8 s, with a quarter more operations; for
    code that runs a few times (info's ranks, the cyclic test), not in a loop. sympy's full cse where its internal
    tree_cse is not importable."""
    try:
        from sympy.simplify.cse_main import tree_cse
    except ImportError:  # pragma: no cover - another sympy layout
        return sp.cse(exprs, symbols=symbols, order="none")
    from mechsys.numeric.cse import interned

    # (tree_cse skips the names the inputs use)
    return tree_cse(interned(exprs), symbols if symbols is not None else sp.numbered_symbols("x"), None, "none")


@dataclass
class ForwardProgram:
    """Straight-line code for some expressions and their Jacobian (value_and_jacobian_program): the shared
    subexpressions ``x{k}``, the derivatives ``d{k}_{j}`` of those the Jacobian needs, the outputs, and the
    Jacobian rows. Printed as Python (value_and_jacobian_sources) or C (numeric/native.py)."""

    args: list  # the input symbols, printed a0, a1, ... (Python) or a[0], a[1], ... (C)
    values: list  # (name, expression) of the shared subexpressions, in order
    derivatives: list  # (name, expression) of their derivatives, in order (after all values)
    symbols: dict  # the Symbol standing for each name of values and derivatives
    outputs: list  # the expressions, in terms of the names
    jacobian: list  # the Jacobian of the first ``rows`` outputs, row by row (0 where it vanishes)


def value_and_jacobian_program(exprs: Sequence[sp.Expr], args: Sequence[sp.Symbol], wrt: Sequence[sp.Symbol],
                               rows: int | None = None) -> ForwardProgram:
    """``exprs`` and their Jacobian with respect to ``wrt`` from one CSE: forward-mode differentiation of the
    CSE graph, each shared subexpression differentiated once by the chain rule through its (small) defining
    expression. Exact like sympy's ``jacobian`` but without re-differentiating whole unshared trees (the bicycle:
    seconds instead of a minute). ``rows``: only the first ``rows`` expressions are differentiated (all by
    default). Derivatives of subexpressions are generated on demand, so those only the undifferentiated outputs
    use cost nothing."""
    return differentiate_program(shared_program(exprs, args, wrt), wrt, rows)


def shared_program(exprs: Sequence[sp.Expr], args: Sequence[sp.Symbol],
                   wrt: Sequence[sp.Symbol] = (), light: bool = False) -> ForwardProgram:
    """The values part of a ForwardProgram: one CSE of ``exprs`` (no derivatives yet: differentiate_program forms
    them symbolically, numeric/tangents.py prints them straight to C). ``light``: light_cse's (derived equations
    are DAGs whose sharing it keeps: the bicycle's steady-motion pieces, 0.24 s instead of 0.75 s, with 4 % more
    C and 10 % more time per call)."""
    exprs = [sp.sympify(e) for e in exprs]
    # real temporaries, as every input is: abs(x) then differentiates to sign(x), not to re/im/Derivative terms;
    # none equal to an input (a real coordinate named x4 is the symbol x4 with real=True). The inputs' names by
    # FreeSymbols: free_symbols walks every path of a DAG (the bicycle's pieces: 0.47 s instead of 0.02 s)
    taken = set(FreeSymbols().of_all(exprs)).union(args, wrt)
    names = sp.numbered_symbols("x", real=True, exclude=taken)
    replacements, reduced = light_cse(exprs, names) if light else cse(exprs, symbols=names, order="none")
    program = ForwardProgram(list(args), [], [], {}, list(reduced), [])
    for k, (sym, value) in enumerate(replacements):
        program.symbols[f"x{k}"] = sym
        program.values.append((f"x{k}", value))
    return program


def needed_values(program: ForwardProgram, rows: int | None) -> set[str]:
    """Names of the subexpressions the first ``rows`` outputs depend on (those their Jacobian differentiates)."""
    name_of = {sym: name for name, sym in program.symbols.items()}
    value_of = dict(program.values)
    needed: set[str] = set()
    todo = [s for e in program.outputs[:rows] for s in sp.sympify(e).free_symbols if s in name_of]
    while todo:
        name = name_of[todo.pop()]
        if name in needed:
            continue
        needed.add(name)
        todo += [s for s in value_of[name].free_symbols if s in name_of and name_of[s] not in needed]
    return needed


def _plain(term: sp.Expr) -> bool:
    """A term that a sum can hold as it is (not a number, not itself a sum)."""
    return not (term.is_Number or term.is_Add)


def _times(factor: sp.Expr, tangent: sp.Expr) -> sp.Expr:
    """factor * tangent for a derivative's term: a temporary ``tangent`` (a symbol) appended to ``factor``'s own
    factors, unsorted (sympy's Mul sorts its factors by comparing them: most of the time of a long chain's
    Jacobian); a number through sympy's Mul."""
    if not tangent.is_Symbol or factor.is_Number:
        return factor * tangent
    return sp.Mul._from_args((*factor.args, tangent) if factor.is_Mul else (factor, tangent))


def differentiate_program(program: ForwardProgram, wrt: Sequence[sp.Symbol], rows: int | None = None) -> ForwardProgram:
    """``program`` (shared_program's) with the symbolic derivatives of its values and the Jacobian of its first
    ``rows`` outputs with respect to ``wrt`` (a new program; ``program`` is left as it is). A derivative that is
    a number or a symbol gets no temporary (it is used in place), one equal to an earlier derivative reuses that
    one's, and a partial derivative reads the subexpressions it shares with the program from their temporaries
    (d cos(x)/dx = -sin(x) reads the temporary of sin(x))."""
    program = ForwardProgram(program.args, list(program.values), [], dict(program.symbols), program.outputs, [])
    reduced = program.outputs
    column = {w: j for j, w in enumerate(wrt)}
    ONE = sp.S.One
    deriv: dict[sp.Basic, dict[int, sp.Expr]] = {w: {j: ONE} for w, j in column.items()}
    values = {program.symbols[name]: value for name, value in program.values}
    known = {value: sym for sym, value in values.items()}  # a subexpression -> its temporary
    order = [program.symbols[name] for name, _ in program.values]
    index = {sym: k for k, sym in enumerate(order)}
    rank = {**column, **{sym: len(wrt) + k for k, sym in enumerate(order)}}
    needed = {program.symbols[name] for name in needed_values(program, rows)}

    diff = Differentiator()  # sympy's diff, each subexpression once

    def chain(value: sp.Expr) -> dict[int, sp.Expr]:
        terms: dict[int, list[sp.Expr]] = {}
        # a sum's partial derivatives term by term, each term by its own symbols (not the whole sum by every
        # symbol of the sum: mostly zero terms), summed per symbol before the chain rule multiplies (a distributed
        # product costs operations in the code and gcc's register allocation time on large Jacobians)
        partials: dict[sp.Basic, list[sp.Expr]] = {}
        for term in value.args if value.is_Add else (value,):
            for s in diff.free(term):
                if s in deriv:
                    partial = diff(term, s)
                    if partial != 0:
                        partials.setdefault(s, []).append(partial)
        # in program order, not in the set's (whose order changes with the process's string hashing): the
        # generated code is the same on every run
        for s in sorted(partials, key=rank.__getitem__):
            partial = sp.Add(*partials[s])
            if partial == 0:
                continue
            if not partial.is_Atom:
                partial = partial.xreplace(known)
            for j, dsj in deriv[s].items():
                terms.setdefault(j, []).append(partial if dsj is ONE else dsj if partial is ONE
                                               else _times(partial, dsj))
        # one Add per entry: adding term by term flattened the growing sum again at every term (quadratic)
        out = {j: sp.Add(*t) if len(t) < 3 or any(not _plain(e) for e in t) else sp.Add._from_args(t)
               for j, t in terms.items()}
        return {j: e for j, e in out.items() if e != 0}

    for sym in order:
        if sym not in needed:
            continue
        k = index[sym]
        parts = chain(values[sym])
        if parts:
            own = {}
            for j, e in parts.items():
                d = e if e.is_Atom else known.get(e)
                if d is None:
                    d = sp.Dummy(f"d{k}_{j}", real=True)  # never equal to an input
                    program.symbols[f"d{k}_{j}"] = d
                    program.derivatives.append((f"d{k}_{j}", e))
                    known[e] = d
                own[j] = d
            deriv[sym] = own
    for e in reduced[:rows]:
        row = chain(e)
        program.jacobian += [row.get(j, sp.Integer(0)) for j in range(len(wrt))]
    return program


def value_and_jacobian_sources(exprs: Sequence[sp.Expr], args: Sequence[sp.Symbol], wrt: Sequence[sp.Symbol],
                               rows: int | None = None,
                               program: ForwardProgram | None = None) -> tuple[str, str]:
    """Python sources of ``_f(a0, a1, ...)`` returning ``exprs`` (first), and ``exprs`` followed by their Jacobian
    with respect to ``wrt`` row by row (second): value_and_jacobian_program printed (or ``program`` when given)."""
    program = program or value_and_jacobian_program(exprs, args, wrt, rows)
    names = {a: f"a{i}" for i, a in enumerate(program.args)}
    names.update({sym: name for name, sym in program.symbols.items()})
    printer = _Printer(names)
    plain = [f"def _f({', '.join(names[a] for a in program.args)}):"]
    plain += [f"    {name} = {printer.doprint(value)}" for name, value in program.values]
    lines = plain + [f"    {name} = {printer.doprint(value)}" for name, value in program.derivatives]
    outputs = [printer.doprint(e) for e in program.outputs]
    jacobian = [printer.doprint(e) if e != 0 else "0.0" for e in program.jacobian]
    plain = plain + ["    return [" + ", ".join(outputs) + "]"]
    lines.append("    return [" + ", ".join(outputs + jacobian) + "]")
    return "\n".join(plain), "\n".join(lines)


def compile_program(program: ForwardProgram) -> Callable[..., list[float]]:
    """A function of ``program.args`` returning ``program``'s outputs as floats (its values; no derivatives)."""
    return function_from_source(value_and_jacobian_sources((), program.args, (), program=program)[0])


def compile_exprs(exprs: Sequence[sp.Expr], args: Sequence[sp.Symbol]) -> Callable[..., list[float]]:
    """A function of ``args`` returning the list of ``exprs`` as floats (shared subexpressions computed once)."""
    return function_from_source(generate_source(exprs, args))


def matrix_source(expr: sp.Matrix, t: sp.Symbol, q: Sequence[sp.Symbol], u: Sequence[sp.Symbol],
                  params: Sequence[sp.Symbol], light: bool = False) -> dict:
    """Cacheable description of a compiled matrix: shape and generated source (``light``: generate_source's)."""
    expr = sp.Matrix(expr)
    empty = expr.shape[0] == 0 or expr.shape[1] == 0
    return {"shape": list(expr.shape),
            "source": None if empty else generate_source(list(expr), [t, *q, *u, *params], light)}


def compile_matrix(expr: sp.Matrix, t: sp.Symbol, q: Sequence[sp.Symbol], u: Sequence[sp.Symbol],
                   params: Sequence[sp.Symbol], light: bool = False) -> StateFunction:
    """A function of (t, q..., u..., p...) for ``expr`` (a Matrix), entries row by row."""
    return matrix_from_source(matrix_source(expr, t, q, u, params, light))
