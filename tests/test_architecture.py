"""The code's own rules (DEVELOPERS.md, docs/architecture.md): the tree reads as the pipeline, no import circles,
a one-line purpose atop every module, type hints on every public function. Read from the source, nothing runs."""
from __future__ import annotations

import ast
from pathlib import Path

from tests.helpers import ROOT

PACKAGE = ROOT / "mechsys"

#: the pipeline, upstream first (docs/architecture.md section 1); codegen, like report, turns results into files
STAGES = ["errors", "model", "mechanics", "numeric", "analysis", "report", "codegen", "cli"]

#: modules a stage may import from a later stage, and why (each import of them sits inside the function that needs
#: it, so loading the earlier stage does not load the later one)
SHARED = {
    "mechsys.numeric.cache": "the signed on-disk cache: the derivation cache of mechanics/ keeps its entries there",
    "mechsys.numeric.lambdify": "mechanics/ decides autonomy and cyclic coordinates numerically, at random states",
    "mechsys.report.notebook": "Jupyter display hooks of models and results (_repr_markdown_, to_dataframe)",
    "mechsys.report.files": "atomic writing of the files an analysis writes as it goes (a sweep's table)",
    "mechsys.report.printing": "expressions as text where an analysis reports one (check's messages)",
}


def _modules() -> dict[str, ast.Module]:
    out = {}
    for path in sorted(PACKAGE.rglob("*.py")):
        name = ".".join(path.relative_to(ROOT).with_suffix("").parts).removesuffix(".__init__")
        out[name] = ast.parse(path.read_text(encoding="utf-8"), str(path))
    return out


MODULES = _modules()


def _stage(module: str) -> str | None:
    parts = module.split(".")
    return parts[1] if len(parts) > 1 and parts[1] in STAGES else None


def _imports(tree: ast.Module, module_level: bool) -> list[tuple[int, str]]:
    """(line, imported mechsys module) of a module's imports: all of them, or those run at import time (not inside
    functions or `if TYPE_CHECKING:` blocks)."""
    found = []
    nodes = tree.body if module_level else list(ast.walk(tree))
    for node in nodes:
        if isinstance(node, ast.ImportFrom) and node.module and node.module.startswith("mechsys"):
            # `from package import module` imports the module (and the package's empty __init__)
            names = [f"{node.module}.{a.name}" for a in node.names]
            found += [(node.lineno, n) for n in names if n in MODULES] or [(node.lineno, node.module)]
        elif isinstance(node, ast.Import):
            found += [(node.lineno, a.name) for a in node.names if a.name.startswith("mechsys")]
    return [(line, m) for line, m in found if m in MODULES]


def test_the_tree_reads_as_the_pipeline():
    """No stage imports a later one (model -> mechanics -> numeric -> analysis -> report -> codegen -> cli),
    except the shared helpers named in SHARED."""
    backwards = []
    for module, tree in MODULES.items():
        here = _stage(module)
        for line, imported in _imports(tree, module_level=False):
            there = _stage(imported)
            if here and there and STAGES.index(there) > STAGES.index(here) and imported not in SHARED:
                backwards.append(f"{module}:{line} imports {imported}")
    assert not backwards, "\n".join(backwards)


def test_shared_helpers_are_imported_only_where_used():
    """The later-stage helpers an earlier stage uses are imported inside the functions that use them."""
    eager = [f"{module}:{line} imports {imported}" for module, tree in MODULES.items() if _stage(module)
             for line, imported in _imports(tree, module_level=True)
             if _stage(imported) and STAGES.index(_stage(imported)) > STAGES.index(_stage(module))]
    assert not eager, "\n".join(eager)


def test_no_import_circles():
    """The modules' import-time imports form no circle (a circle breaks on the first import of its other end)."""
    graph = {m: {i for _line, i in _imports(tree, module_level=True) if i != m} for m, tree in MODULES.items()}
    state: dict[str, int] = {}  # 1: on the current path, 2: done

    def walk(start: str) -> list[str] | None:
        path, stack = [start], [iter(sorted(graph[start]))]
        state[start] = 1
        while stack:
            nxt = next(stack[-1], None)
            if nxt is None:
                state[path.pop()] = 2
                stack.pop()
            elif state.get(nxt) == 1:
                return path[path.index(nxt):] + [nxt]
            elif nxt not in state:
                state[nxt] = 1
                path.append(nxt)
                stack.append(iter(sorted(graph[nxt])))
        return None

    for module in sorted(graph):
        if module not in state:
            circle = walk(module)
            assert circle is None, " -> ".join(circle)


def test_every_module_says_what_it_is_for():
    """A docstring atop every module whose first line says its purpose."""
    missing = [m for m, tree in MODULES.items() if not (ast.get_docstring(tree) or "").strip()]
    assert not missing, missing


def test_public_functions_have_type_hints():
    """Every parameter (but self and cls) and the return of every public function and method is annotated."""
    unhinted = []
    for module, tree in MODULES.items():
        scopes = [(tree.body, "")] + [(c.body, c.name + ".") for c in tree.body
                                       if isinstance(c, ast.ClassDef) and not c.name.startswith("_")]
        for body, prefix in scopes:
            for f in body:
                if not isinstance(f, (ast.FunctionDef, ast.AsyncFunctionDef)) or f.name.startswith("_"):
                    continue
                args = f.args.posonlyargs + f.args.args + f.args.kwonlyargs
                args += [a for a in (f.args.vararg, f.args.kwarg) if a is not None]
                if f.returns is None or any(a.annotation is None for a in args if a.arg not in ("self", "cls")):
                    unhinted.append(f"{module}.{prefix}{f.name}")
    assert not unhinted, unhinted
