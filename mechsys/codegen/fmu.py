"""The FMU target: an FMI 2.0 Model Exchange FMU of a model (the C target's code, an FMI wrapper, built by gcc)."""
from __future__ import annotations

import hashlib
import os
import platform
import shutil
import subprocess
import sys
import tempfile
import uuid
import xml.etree.ElementTree as ET
import zipfile
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING

import sympy as sp

from mechsys.codegen import c
from mechsys.codegen.names import mangle
from mechsys.codegen.package import Function, Package, Program, derive_package, function_body, plain
from mechsys.errors import AnalysisError, InputError
from mechsys.report.files import atomic_write, cannot_write, output_target

if TYPE_CHECKING:
    from mechsys.mechanics.model import MechanicalModel

__all__ = ["write_fmu", "check_fmu_output", "find_gcc", "check_exportable", "fmu_layout", "FmuLayout",
           "FmuSummary", "CFLAGS", "WRAPPER", "HEADERS"]

HERE = Path(__file__).resolve().parent
WRAPPER = HERE / "fmu_wrapper.c"
"""The FMI 2.0 functions, the same C for every model; it includes the generated ``fmu_model.h``."""
HEADERS = HERE / "fmi2"
"""The FMI 2.0 headers of the Modelica Association (BSD-2-Clause, as shipped by FMPy; LICENSE.txt)."""
HEADER_FILES = ("fmi2Functions.h", "fmi2FunctionTypes.h", "fmi2TypesPlatform.h")
CFLAGS = ("-O2", "-std=c99", "-fPIC", "-shared", "-fvisibility=hidden")
"""How the binary is built: only the fmi2 functions are exported (the model's own functions stay hidden)."""
ENERGIES = (("kinetic_energy", "kinetic energy T"), ("potential_energy", "potential energy V"),
            ("total_energy", "T + V"))
RESIDUAL = ("constraint_residual", "max |Phi(q, t)| of the holonomic rows and |A u + a_t| of all rows (zero on "
                                   "the constraints; the FMU projects back when it exceeds 1e-12 x (1 + max |x|))")
TOLERANCE = 1e-10
"""The relative tolerance of the DefaultExperiment (FMPy's default would be 1e-5)."""


# ----------------------------------------------------------------------------------------- checks
def check_fmu_output(path: str | os.PathLike) -> Path:
    """The file an FMU goes to: the suffix .fmu (what importers look for) and a writable place, checked before
    any work (`cannot write FILE: reason` otherwise)."""
    if Path(path).suffix != ".fmu":
        raise cannot_write(path, "an FMU file name ends in .fmu (give -o NAME.fmu)")
    return output_target(path)


def find_gcc() -> str:
    """The path of gcc, the compiler the FMU's binary is built with; an InputError (exit 2) without it."""
    found = shutil.which("gcc")
    if found is None:
        raise InputError("gcc was not found on PATH: the FMU's binary is compiled with the system C compiler gcc; "
                         "install it (Debian/Ubuntu: apt install gcc), or use --target c for the sources alone")
    return found


def platform_folder() -> tuple[str, str]:
    """The FMI 2.0 binaries folder and library suffix of this machine (linux64 .so, darwin64 .dylib)."""
    machine = platform.machine().lower()
    if sys.platform.startswith("linux") and machine in ("x86_64", "amd64"):
        return "linux64", ".so"
    if sys.platform == "darwin" and machine in ("x86_64", "arm64"):
        return "darwin64", ".dylib"
    raise InputError(f"FMI 2.0 names no binaries folder for {sys.platform} on {machine}: an FMU is built here "
                     "for x86-64 Linux (linux64) and macOS (darwin64); use --target c for the sources")


def check_exportable(model: "MechanicalModel") -> list[str]:
    """An InputError for what an FMU of this kind cannot carry without a silently wrong motion: contacts (impacts
    are velocity jumps the FMU does not implement) and events that stop the simulation. Returns the warnings for
    what it leaves out harmlessly (events that are only recorded)."""
    spec = model.doc.spec
    if spec.contacts:
        names = ", ".join(contact.name for contact in spec.contacts)
        raise InputError(f"contacts ({names}) cannot be exported to an FMU: impacts are velocity jumps this FMU "
                         "does not implement, and without them the motion would pass through the contact; use "
                         "`mechsys simulate`, or --target c for the smooth motion between impacts")
    stops = [event.name for event in spec.events if event.action == "stop"]
    if stops:
        raise InputError(f"events that stop the simulation ({', '.join(stops)}) cannot be exported to an FMU: it has "
                         "no event indicators and would run past them; use `mechsys simulate`, or remove the events")
    recorded = [event.name for event in spec.events]
    if recorded:
        return [f"events ({', '.join(recorded)}) are not exported: the FMU has no event indicators (the events "
                "only record crossings; the motion is the same)"]
    return []


# ----------------------------------------------------------------------------------------- the variables
@dataclass
class Variable:
    """One ScalarVariable of modelDescription.xml (all are Real)."""

    name: str
    causality: str
    variability: str
    initial: str | None
    start: float | None
    description: str = ""
    unit: str = ""
    derivative: int | None = None  # the 1-based index of the state this variable is the derivative of


@dataclass
class FmuLayout:
    """What the FMU exposes, in value-reference order: parameters, states x = [q; u], der(x), outputs."""

    pkg: Package
    parameters: list[Variable]
    states: list[Variable]
    derivatives: list[Variable]
    outputs: list[Variable]
    calculated_parameters: list[tuple[str, sp.Expr]]  # (code, expression of parameters), in dependency order
    calculated_states: list[tuple[int, sp.Expr]]  # (state index, expression of parameters)
    file_outputs: list[sp.Expr]  # the file's outputs, after the energies (and the residual)

    @property
    def variables(self) -> list[Variable]:
        return self.parameters + self.states + self.derivatives + self.outputs

    def index(self, variable: Variable) -> int:
        """The 1-based index of ``variable`` in ModelVariables (value reference + 1)."""
        return next(k for k, v in enumerate(self.variables) if v is variable) + 1


def _depends(expr: sp.Expr, symbols: set) -> bool:
    return bool(sp.sympify(expr).free_symbols & symbols)


def _parameters(model: "MechanicalModel", pkg: Package) -> tuple[list[Variable], list[tuple[str, sp.Expr]]]:
    """A parameter the file computes from others is a calculatedParameter that follows them (as --set does);
    the calculated ones are returned in dependency order (doc.parameter_exprs is sorted so)."""
    doc = model.doc
    symbols = set(model.parameter_symbols)
    codes = {quantity.name: quantity.code for quantity in pkg.parameters}
    calculated = [(codes[name], expr) for name, expr in doc.parameter_exprs.items() if _depends(expr, symbols)]
    dependent = {code for code, _ in calculated}
    variables = []
    for quantity in pkg.parameters:
        if quantity.code in dependent:
            note = "; ".join(x for x in (quantity.comment, f"= {quantity.expression}") if x)
            variables.append(Variable(quantity.code, "calculatedParameter", "tunable", "calculated", None, note,
                                      quantity.unit))
        else:
            variables.append(Variable(quantity.code, "parameter", "tunable", "exact", quantity.value,
                                      quantity.comment, quantity.unit))
    return variables, calculated


def _rate_unit(unit: str, power: int) -> str:
    return "" if not unit else f"{unit}/s" if power == 1 else f"{unit}/s^2"


def _states(model: "MechanicalModel", pkg: Package) -> tuple[list[Variable], list[tuple[int, sp.Expr]]]:
    """q then u: a start value that the file writes as an expression of parameters is calculated from them
    (initial="calculated"); another is exact, or approx (assembled onto the constraints) with constraint rows."""
    doc = model.doc
    symbols = set(model.parameter_symbols)
    given = "approx" if pkg.m else "exact"
    states: list[Variable] = []
    calculated: list[tuple[int, sp.Expr]] = []
    n = pkg.n
    for offset, key in ((0, "initial"), (n, "rate")):
        for i, quantity in enumerate(pkg.coordinates):
            spec = doc.spec.coordinates[quantity.name]
            expr = doc.parse(getattr(spec, key), ("coordinates", quantity.name, key), "initial")
            value = quantity.value if key == "initial" else quantity.rate
            name = quantity.code if key == "initial" else quantity.rate_code
            text = f"coordinate {quantity.name}" if key == "initial" else f"der({quantity.name})"
            if quantity.note() and key == "initial":
                text += f": {quantity.note()}"
            unit = quantity.unit if key == "initial" else _rate_unit(quantity.unit, 1)
            if _depends(expr, symbols):
                calculated.append((offset + i, expr))
                states.append(Variable(name, "local", "continuous", "calculated", None, text, unit))
            else:
                states.append(Variable(name, "local", "continuous", given, value, text, unit))
    return states, calculated


def _derivatives(pkg: Package, states: list[Variable], first_index: int) -> list[Variable]:
    out = []
    for k, state in enumerate(states):
        unit = _rate_unit(pkg.coordinates[k % pkg.n].unit, 1 + k // pkg.n)
        out.append(Variable(f"der({state.name})", "local", "continuous", "calculated", None,
                            f"time derivative of {state.name}", unit, derivative=first_index + k))
    return out


def fmu_layout(model: "MechanicalModel", pkg: Package) -> FmuLayout:
    """The FMU's variables of ``model`` (whose package is ``pkg``): names are the package's identifiers
    (names.py); outputs are the energies, the constraint residual (with constraint rows) and the file's
    `outputs:`, mangled by the same rule."""
    parameters, calculated_parameters = _parameters(model, pkg)
    states, calculated_states = _states(model, pkg)
    derivatives = _derivatives(pkg, states, len(parameters) + 1)
    fixed = list(ENERGIES) + ([RESIDUAL] if pkg.m else [])
    file_outputs = list(model.outputs)
    deferred = set(getattr(model, "deferred_quantities", {}) or {})
    forces = [name for name, expr in file_outputs if expr.free_symbols & deferred]
    if forces:
        written = list(model.doc.spec.outputs)  # the file's names (a vector output is expanded: cfB.x, cfB.y)
        bases = list(dict.fromkeys(n if n in written else n.rsplit(".", 1)[0] for n in forces))
        raise model.doc.error(("outputs", bases[0]),
                              f"{', '.join(bases)} use reaction(), constraint_force() or multiplier(): the FMU "
                              "exports outputs of the state alone, not the constraint forces of the equations' "
                              "solution; leave them out of the file for the FMU (mechsys simulate --reactions and "
                              "mechsys inverse give them)")
    taken = {v.name for v in parameters + states}
    names = mangle([name for name, _ in fixed] + [name for name, _ in file_outputs], taken)
    outputs = [Variable(names[name], "output", "continuous", "calculated", None, text) for name, text in fixed]
    outputs += [Variable(names[name], "output", "continuous", "calculated", None, f"output {plain(name)}")
                for name, _ in file_outputs]
    return FmuLayout(pkg, parameters, states, derivatives, outputs, calculated_parameters, calculated_states,
                     [expr for _, expr in file_outputs])


# ----------------------------------------------------------------------------------------- fmu_model.h
def _block(pkg: Package, args: tuple[str, ...], exprs: list[sp.Expr], targets: list[str]) -> list[str]:
    """Statements assigning ``exprs`` (functions of ``args``) to the C lvalues ``targets``, in a scope of their
    own, printed as the C target prints (one CSE, mechsys's C printer)."""
    if not exprs:
        return []
    fn = Function("fmu", args, (len(exprs),), Program.of(exprs), "")
    lines, values = function_body(pkg, fn, c.STYLE)
    return ["    {", *("    " + line for line in lines),
            *(f"        {target} = {value};" for target, value in zip(targets, values)), "    }"]


def _c_array(ctype: str, name: str, values: list[str]) -> str:
    return f"static const {ctype} {name}[{max(1, len(values))}] = {{{', '.join(values) or '0'}}};"


def _c_text(text: str) -> str:
    """A C string literal of plain text (printable ASCII, quotes and backslashes escaped)."""
    return '"' + "".join(ch if 32 <= ord(ch) < 127 and ch not in '"\\?' else f"\\x{ord(ch):02x}\"\"" for ch in text) + '"'


def _c_string(text: str) -> str:
    return '"' + "".join(ch if ch.isalnum() or ch in "_()." else f"\\x{ord(ch):02x}" for ch in text) + '"'


def model_header(layout: FmuLayout, guid: str) -> str:
    """``fmu_model.h``: the sizes, tables and model functions fmu_wrapper.c uses, over the C target's code."""
    pkg = layout.pkg
    prefix, P = pkg.prefix, pkg.prefix.upper()
    n_out = len(layout.outputs)
    settable = ["0" if v.causality == "calculatedParameter" else "1" for v in layout.parameters]
    offsets = [f"offsetof({prefix}_params, {v.name})" for v in layout.parameters]
    codes = {q.code: q for q in pkg.parameters}
    exported = [repr(float(codes[v.name].value)) for v in layout.parameters]
    fixed = [_c_text(pkg.fixed.get(codes[v.name].name, "").replace("`", "")) for v in layout.parameters]
    state_start = [repr(float(v.start)) if v.start is not None else "0.0" for v in layout.states]
    state_settable = ["0" if v.initial == "calculated" else "1" for v in layout.states]
    names = [_c_string(v.name) for v in layout.variables]
    calc_params = [line for code, expr in layout.calculated_parameters
                   for line in _block(pkg, ("p",), [expr], [f"p->{code}"])]
    calc_states = _block(pkg, ("p",), [e for _, e in layout.calculated_states],
                         [f"x[{k}]" for k, _ in layout.calculated_states])
    first = len(ENERGIES) + (1 if pkg.m else 0)
    outputs = _block(pkg, ("t", "q", "u", "a", "p"), layout.file_outputs,
                     [f"out[{first + k}]" for k in range(len(layout.file_outputs))])
    lines = [f"/* {plain(pkg.model)}: the model side of the FMU (generated by mechsys codegen --target fmu from "
             f"{plain(pkg.file)}); included once, by fmu_wrapper.c, before the FMI headers. The object-like macros "
             "come last, so that no model name (a struct field) is expanded. */",
             "#ifndef MSFMU_MODEL_H", "#define MSFMU_MODEL_H", "", "#include <stddef.h>", "",
             f'#include "{prefix}.h"', "",
             c.MATH_DEFINES, "",
             f"typedef {prefix}_params msfmu_parameters;", "",
             _c_array("size_t", "msfmu_parameter_offset", offsets),
             _c_array("int", "msfmu_parameter_settable", settable),
             _c_array("double", "msfmu_parameter_exported", exported),
             _c_array("char *const", "msfmu_parameter_fixed", fixed),
             _c_array("double", "msfmu_state_start", state_start),
             _c_array("double", "msfmu_state_guess", [repr(x) for x in pkg.start_guess]),
             _c_array("int", "msfmu_state_held", ["1" if x else "0" for x in pkg.start_held]),
             _c_array("int", "msfmu_coordinate_angle", ["1" if x else "0" for x in pkg.angles]),
             _c_array("int", "msfmu_state_settable", state_settable),
             _c_array("char *const", "msfmu_variable_name", names)]
    if pkg.holonomic_rows:
        lines.append(_c_array("int", "msfmu_holonomic_row", [str(r) for r in pkg.holonomic_rows]))
    lines += ["", "/* the parameters the file computes from others, in dependency order */",
              "static void msfmu_calculate_parameters(msfmu_parameters *p) {", "    (void)p;", *calc_params, "}", "",
              "/* the initial states the file writes as expressions of parameters */",
              "static void msfmu_calculated_states(const msfmu_parameters *p, double *x) {", "    (void)p;",
              "    (void)x;", *calc_states, "}", "",
              "/* T, V, T + V, (the constraint residual: set by the wrapper), the file's outputs */",
              "static void msfmu_outputs(double t, const double *q, const double *u, const double *a, "
              "const msfmu_parameters *p, double *out) {",
              "    (void)t; (void)q; (void)u; (void)a; (void)p;",
              f"    {prefix}_kinetic_energy(t, q, u, p, out);", f"    {prefix}_potential_energy(t, q, u, p, out + 1);",
              "    out[2] = out[0] + out[1];", *outputs, "}", "",
              f'#define MSFMU_GUID "{guid}"',
              f"#define MSFMU_NPAR {len(layout.parameters)}",
              f"#define MSFMU_NCOORD {P}_N", f"#define MSFMU_NSTATE {P}_NX", f"#define MSFMU_NROWS {P}_NC",
              f"#define MSFMU_NHOL {len(pkg.holonomic_rows)}", f"#define MSFMU_NOUT {n_out}"]
    if pkg.m:
        lines.append(f"#define MSFMU_RESIDUAL_OUTPUT {len(ENERGIES)}")
    lines += [f"#define msfmu_defaults_of_parameters() {prefix}_params_default()",
              f"#define msfmu_accelerations(t, q, u, p, a) {prefix}_accelerations((t), (q), (u), (p), (a), NULL)"]
    if pkg.m:
        lines += [f"#define msfmu_constraint_matrix(t, q, u, p, out) {prefix}_constraint_matrix((t), (q), (u), (p), "
                  "(out))",
                  f"#define msfmu_constraint_velocity(t, q, u, p, out) {prefix}_constraint_velocity((t), (q), (u), "
                  "(p), (out))"]
    if pkg.holonomic_rows:
        lines.append(f"#define msfmu_constraint_position(t, q, u, p, out) {prefix}_constraint_position((t), (q), "
                     "(u), (p), (out))")
    lines += ["", "#endif", ""]
    return "\n".join(lines)


# ----------------------------------------------------------------------------------------- modelDescription.xml
def _real(parent: ET.Element, variable: Variable, vr: int) -> None:
    attrs = {"name": variable.name, "valueReference": str(vr)}
    if variable.description:
        attrs["description"] = variable.description
    attrs.update(causality=variable.causality, variability=variable.variability)
    if variable.initial:
        attrs["initial"] = variable.initial
    scalar = ET.SubElement(parent, "ScalarVariable", attrs)
    real = {}
    if variable.unit:
        real["unit"] = variable.unit
    if variable.start is not None:
        real["start"] = repr(float(variable.start))
    if variable.derivative is not None:
        real["derivative"] = str(variable.derivative)
    ET.SubElement(scalar, "Real", real)


def model_description(layout: FmuLayout, guid: str, version: str) -> str:
    """modelDescription.xml (FMI 2.0, Model Exchange, structured names, no event indicators)."""
    pkg = layout.pkg
    root = ET.Element("fmiModelDescription", {
        "fmiVersion": "2.0", "modelName": plain(pkg.model), "guid": guid,
        "description": plain(pkg.description) or f"{plain(pkg.model)}: equations of motion from mechsys",
        "generationTool": f"mechsys {version} (codegen --target fmu, {pkg.method})",
        "variableNamingConvention": "structured", "numberOfEventIndicators": "0"})
    me = ET.SubElement(root, "ModelExchange", {
        "modelIdentifier": pkg.prefix, "needsExecutionTool": "false",
        "completedIntegratorStepNotNeeded": "false" if pkg.m else "true",
        "canBeInstantiatedOnlyOncePerProcess": "false", "canNotUseMemoryManagementFunctions": "false",
        "canGetAndSetFMUstate": "false", "canSerializeFMUstate": "false", "providesDirectionalDerivative": "false"})
    sources = ET.SubElement(me, "SourceFiles")
    for name in (f"{pkg.prefix}.c", "fmu_wrapper.c"):
        ET.SubElement(sources, "File", {"name": name})
    units = sorted({v.unit for v in layout.variables if v.unit})
    if units:
        definitions = ET.SubElement(root, "UnitDefinitions")
        for unit in units:
            ET.SubElement(definitions, "Unit", {"name": unit})
    categories = ET.SubElement(root, "LogCategories")
    for name, text in (("logEvents", "projections onto the constraints at events"),
                       ("logStatusWarning", "warnings (the initial state assembled onto the constraints)"),
                       ("logStatusError", "errors (a singular system matrix, a failed projection, misuse)")):
        ET.SubElement(categories, "Category", {"name": name, "description": text})
    ET.SubElement(root, "DefaultExperiment", {"startTime": "0.0", "tolerance": repr(TOLERANCE)})
    variables = ET.SubElement(root, "ModelVariables")
    for vr, variable in enumerate(layout.variables):
        _real(variables, variable, vr)
    structure = ET.SubElement(root, "ModelStructure")
    for tag, members in (("Outputs", layout.outputs), ("Derivatives", layout.derivatives),
                         ("InitialUnknowns", [v for v in layout.variables if v.initial in ("approx", "calculated")
                                              or v.causality == "output"])):
        if members:
            element = ET.SubElement(structure, tag)
            for variable in members:
                ET.SubElement(element, "Unknown", {"index": str(layout.index(variable))})
    ET.indent(root, "  ")
    return '<?xml version="1.0" encoding="UTF-8"?>\n' + ET.tostring(root, encoding="unicode") + "\n"


# ----------------------------------------------------------------------------------------- build and write
@dataclass
class FmuSummary:
    """What `write_fmu` wrote: the FMU's file, its model identifier, platform and counts, and the warnings."""

    path: Path
    identifier: str
    platform: str
    states: int
    parameters: int
    outputs: int
    warnings: list[str]

    def line(self) -> str:
        return (f"wrote {self.path}: FMI 2.0 Model Exchange FMU {self.identifier} ({self.platform}), "
                f"{self.states} states, {self.parameters} parameters, {self.outputs} outputs")


def _guid(texts: list[str]) -> str:
    digest = hashlib.sha256("\0".join(texts).encode("utf-8")).digest()
    return "{" + str(uuid.UUID(bytes=digest[:16])) + "}"


def fmu_files(model: "MechanicalModel", pkg: Package) -> tuple[FmuLayout, dict[str, str]]:
    """The layout and the text files of the FMU (archive name -> text), everything but the binary."""
    from mechsys import __version__

    layout = fmu_layout(model, pkg)
    c_files = c.render(pkg)
    wrapper = WRAPPER.read_text(encoding="utf-8")
    headers = {name: (HEADERS / name).read_text(encoding="utf-8") for name in HEADER_FILES}
    sources = {pkg.prefix + ".h": c_files[pkg.prefix + ".h"], pkg.prefix + ".c": c_files[pkg.prefix + ".c"],
               "fmu_wrapper.c": wrapper, **headers}
    guid = _guid([model_description(layout, "", __version__), model_header(layout, ""), *sources.values()])
    files = {"modelDescription.xml": model_description(layout, guid, __version__),
             "sources/fmu_model.h": model_header(layout, guid),
             **{f"sources/{name}": text for name, text in sources.items()},
             "documentation/licenses/fmi2-headers.txt": (HEADERS / "LICENSE.txt").read_text(encoding="utf-8")}
    return layout, files


def compile_binary(gcc: str, sources: Path, prefix: str, library: Path) -> None:
    """Build the FMU's shared library from ``sources`` with gcc; AnalysisError with gcc's first error line."""
    command = [gcc, *CFLAGS, "-o", str(library), "fmu_wrapper.c", f"{prefix}.c", "-lm"]
    proc = subprocess.run(command, cwd=sources, capture_output=True, text=True)
    if proc.returncode != 0:
        errors = [line for line in proc.stderr.splitlines() if "error" in line] or proc.stderr.splitlines() or [""]
        raise AnalysisError(f"gcc could not build the FMU's binary (exit {proc.returncode}): {errors[0].strip()}")


def _zip(archive: str, folder: Path) -> None:
    """The FMU archive of ``folder``'s files, in a fixed order with fixed time stamps (reproducible)."""
    with zipfile.ZipFile(archive, "w", zipfile.ZIP_DEFLATED) as zf:
        for path in sorted(p for p in folder.rglob("*") if p.is_file()):
            info = zipfile.ZipInfo(path.relative_to(folder).as_posix(), date_time=(1980, 1, 1, 0, 0, 0))
            info.compress_type = zipfile.ZIP_DEFLATED
            info.external_attr = (0o755 if path.suffix in (".so", ".dylib") else 0o644) << 16
            zf.writestr(info, path.read_bytes())


def write_fmu(model: "MechanicalModel", path: str | os.PathLike, method: str = "lagrange") -> FmuSummary:
    """Write ``model`` as an FMI 2.0 Model Exchange FMU to ``path`` (NAME.fmu): modelDescription.xml, the C
    sources (the C target's code, fmu_model.h, fmu_wrapper.c, the FMI headers) and the binary for this platform
    built by gcc. Built in a temporary folder and moved onto ``path`` in one rename. InputError (exit 2) for a
    bad path, a missing gcc, contacts and stopping events; AnalysisError (exit 1) when the model cannot be solved
    for its accelerations or gcc fails."""
    check_fmu_output(path)
    gcc = find_gcc()
    folder, suffix = platform_folder()
    warnings = check_exportable(model)
    pkg = derive_package(model, method)
    layout, files = fmu_files(model, pkg)
    with tempfile.TemporaryDirectory(prefix="mechsys-fmu-") as tmp:
        root = Path(tmp) / "fmu"
        for name, text in files.items():
            target = root / name
            target.parent.mkdir(parents=True, exist_ok=True)
            target.write_text(text, encoding="utf-8", newline="\n")
        binaries = root / "binaries" / folder
        binaries.mkdir(parents=True)
        compile_binary(gcc, root / "sources", pkg.prefix, binaries / f"{pkg.prefix}{suffix}")
        atomic_write(path, lambda archive: _zip(archive, root))
    return FmuSummary(Path(path), pkg.prefix, folder, len(layout.states), len(layout.parameters),
                      len(layout.outputs), warnings)
