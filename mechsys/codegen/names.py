"""Name mangling of the code generator: model names to identifiers valid in Python, C and MATLAB at once."""
from __future__ import annotations

import hashlib
import keyword
import re
import sys
import unicodedata
from typing import Iterable, Sequence

__all__ = ["mangle", "identifier", "RESERVED", "MODULES", "TEMPORARY", "MAX_LENGTH"]

MAX_LENGTH = 63
TEMPORARY = re.compile(r"cse\d+")
"""Names of the common subexpressions in generated code (``cse0``, ``cse1``, ...)."""

_PYTHON = set(keyword.kwlist) | set(keyword.softkwlist) | {"None", "True", "False"}
_C = {
    "auto", "break", "case", "char", "const", "continue", "default", "do", "double", "else", "enum", "extern",
    "float", "for", "goto", "if", "inline", "int", "long", "register", "restrict", "return", "short", "signed",
    "sizeof", "static", "struct", "switch", "typedef", "union", "unsigned", "void", "volatile", "while", "_Alignas",
    "_Alignof", "_Atomic", "_Bool", "_Complex", "_Generic", "_Imaginary", "_Noreturn", "_Static_assert",
    "_Thread_local", "bool", "true", "false", "NULL",
}
_MATLAB = {
    "break", "case", "catch", "classdef", "continue", "else", "elseif", "end", "for", "function", "global", "if",
    "otherwise", "parfor", "persistent", "return", "spmd", "switch", "try", "while", "pi", "Inf", "inf", "NaN", "nan",
    "nargin", "nargout", "varargin", "varargout",
}
# what the printed expressions call: sympy's Python (math.*), C99 and Octave printers
_FUNCTIONS = {
    "math", "numpy", "abs", "fabs", "sign", "copysign", "min", "max", "fmin", "fmax", "mod", "fmod", "floor",
    "pow", "sqrt", "exp", "log", "sin", "cos", "tan", "asin", "acos", "atan", "atan2", "sinh", "cosh", "tanh",
    "zeros",
}
# object-like macros of the C headers the generated code includes (math.h, stdio.h, stdlib.h, string.h): a struct
# field of that name would be macro-expanded
_MACROS = {
    "M_E", "M_LOG2E", "M_LOG10E", "M_LN2", "M_LN10", "M_PI", "M_PI_2", "M_PI_4", "M_1_PI", "M_2_PI", "M_2_SQRTPI",
    "M_SQRT2", "M_SQRT1_2", "HUGE_VAL", "HUGE_VALF", "HUGE_VALL", "INFINITY", "NAN", "FP_INFINITE", "FP_NAN",
    "FP_NORMAL", "FP_SUBNORMAL", "FP_ZERO", "FP_ILOGB0", "FP_ILOGBNAN", "FP_FAST_FMA", "FP_FAST_FMAF",
    "FP_FAST_FMAL", "MATH_ERRNO", "MATH_ERREXCEPT", "math_errhandling", "EOF", "BUFSIZ", "FILENAME_MAX",
    "FOPEN_MAX", "L_tmpnam", "SEEK_CUR", "SEEK_END", "SEEK_SET", "TMP_MAX", "stdin", "stdout", "stderr", "errno",
    "EXIT_FAILURE", "EXIT_SUCCESS", "MB_CUR_MAX", "RAND_MAX", "NULL",
}
# the arguments of the generated functions (the only other names their bodies use)
_ARGUMENTS = {"t", "q", "u", "x", "p", "a", "lam", "out"}
RESERVED: frozenset[str] = frozenset(_PYTHON | _C | _MATLAB | _FUNCTIONS | _MACROS | _ARGUMENTS)
"""Identifiers no model name may take: keywords of Python, C and MATLAB and the names generated code uses."""

MODULES: frozenset[str] = frozenset(sys.stdlib_module_names) | {"numpy", "scipy", "example"}
"""Module names a Python package's file may not take (it would shadow them for its own imports)."""


_SPELLING = {"LAMDA": "LAMBDA"}  # Unicode's spelling of the letter's name


def _characters(name: str) -> Iterable[str | None]:
    """The identifier text of each character, None for a separator (rule 1)."""
    for ch in name:
        if ch.isascii() and (ch.isalnum() or ch == "_"):
            yield ch
            continue
        uname = unicodedata.name(ch, "")
        if uname.startswith("GREEK ") and " LETTER " in uname:
            words = [w for w in uname.split(" LETTER ", 1)[1].split() if w not in ("FINAL", "ARCHAIC")]
            word = _SPELLING.get(words[0], words[0]).lower()
            yield word.capitalize() if "CAPITAL" in uname else word
            continue
        base = unicodedata.normalize("NFKD", ch).encode("ascii", "ignore").decode("ascii")
        yield base if base and (base.isalnum() or base == "_") else None


def identifier(name: str, reserved: frozenset[str] | set[str] = RESERVED) -> str:
    """The identifier of one name by rules 1 to 4 (collisions among several names are `mangle`'s)."""
    parts: list[str] = []
    separated = False
    for text in _characters(name):
        if text is None:
            separated = True
            continue
        if separated and parts:
            parts.append("_")
        separated = False
        parts.append(text)
    ident = "".join(parts)
    if not ident[:1].isalpha():
        ident = "v" + ident
    if len(ident) > MAX_LENGTH:
        digest = hashlib.sha256(name.encode("utf-8")).hexdigest()[:8]
        ident = f"{ident[:MAX_LENGTH - 9]}_{digest}"
    if ident in reserved or ident in RESERVED or TEMPORARY.fullmatch(ident):
        ident += "_"
    return ident


def mangle(names: Sequence[str], reserved: Iterable[str] = ()) -> dict[str, str]:
    """Identifiers for ``names`` (distinct strings), valid in Python, C and MATLAB and distinct from each other, from
    the reserved words and from ``reserved``. The one rule of every generated package (docs/codegen.md repeats it):

    1. Characters: ASCII letters, digits and ``_`` stay; a Greek letter becomes its English name (``α`` -> ``alpha``,
       ``Ω`` -> ``Omega``); another letter with an ASCII base loses its accent (``é`` -> ``e``); every other run of
       characters is a separator and becomes one ``_`` (``der(q)`` -> ``der_q``, ``der(der(q))`` -> ``der_der_q``),
       except at the ends, where it is dropped.
    2. An identifier must start with a letter (MATLAB): otherwise ``v`` is put in front (``_k`` -> ``v_k``; nothing
       left at all -> ``v``).
    3. At most 63 characters (MATLAB's ``namelengthmax``): a longer one keeps 54 and gets ``_`` and 8 hexadecimal
       digits of the SHA-256 of the original name.
    4. A reserved word of Python, C or MATLAB, a name the generated code itself uses (``RESERVED``), a name in
       ``reserved`` (the package's function names) or a temporary's name (``cse`` and digits) gets a trailing ``_``
       (``lambda`` -> ``lambda_``, ``end`` -> ``end_``, ``int`` -> ``int_``).
    5. Collisions: a name already valid keeps its identifier; the others, in the order given, take ``_2``, ``_3``,
       ... when their identifier is taken (a parameter ``der_q`` keeps ``der_q``, the rate ``der(q)`` becomes
       ``der_q_2``).

    Deterministic: the result depends only on the names, their order and ``reserved``. The same identifier serves
    every target, so a parameter has one name in the Python dict, the C struct and the MATLAB struct."""
    extra = frozenset(reserved)
    candidates = {name: identifier(name, extra) for name in names}
    taken = set(extra)
    out: dict[str, str] = {}
    for name in names:  # names that are already valid identifiers keep them
        if candidates[name] == name and name not in taken:
            out[name] = name
            taken.add(name)
    for name in names:
        if name in out:
            continue
        ident, k = candidates[name], 2
        while ident in taken:
            ident = f"{candidates[name][:MAX_LENGTH - 1 - len(str(k))]}_{k}"
            k += 1
        out[name] = ident
        taken.add(ident)
    return out
