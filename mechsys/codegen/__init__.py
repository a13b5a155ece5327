"""Code generation: a model's equations as a standalone Python, C or MATLAB/Octave package, or an FMU (`codegen`)."""
from __future__ import annotations

import os
from pathlib import Path
from typing import TYPE_CHECKING, Any, Callable

from mechsys.codegen.folder import check_destination, write_directory
from mechsys.codegen.names import mangle
from mechsys.errors import InputError

if TYPE_CHECKING:
    from mechsys.codegen.package import Package
    from mechsys.mechanics.model import MechanicalModel

__all__ = ["TARGETS", "FILE_TARGETS", "render", "write_package", "check_target", "check_destination",
           "write_directory", "derive_package", "mangle", "Package"]

FOLDER_TARGETS = ("python", "c", "matlab")
"""Targets written as a folder of files (their printers: codegen/python.py, c.py, matlab.py)."""
FILE_TARGETS = ("fmu",)
"""Targets written as one file rather than a folder: fmu (codegen/fmu.py, `write_fmu`)."""


def _printers() -> dict[str, Callable[["Package"], dict[str, str]]]:
    """Target name -> the function that prints a package's files (file name -> text)."""
    from mechsys.codegen import c, matlab, python

    return {"python": python.render, "c": c.render, "matlab": matlab.render}


def __getattr__(name: str) -> Any:
    """The parts that import sympy, on first use: a kept package (report/warm.py) is written without them.
    ``TARGETS``: the printers of the folder targets (_printers)."""
    if name == "TARGETS":
        return _printers()
    if name in ("derive_package", "Package"):
        from mechsys.codegen import package

        return getattr(package, name)
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")


def check_target(target: str) -> str:
    """The target's name, or an InputError naming the valid ones."""
    if target not in FOLDER_TARGETS and target not in FILE_TARGETS:
        raise InputError(f"unknown target {target!r}; use one of {', '.join([*FOLDER_TARGETS, *FILE_TARGETS])}")
    return target


def _package_target(target: str) -> str:
    """A target that writes a folder, or an InputError (fmu writes one file: mechsys.codegen.fmu.write_fmu)."""
    if check_target(target) in FILE_TARGETS:
        raise InputError(f"the {target} target writes one file, not a package folder: use "
                         f"mechsys.codegen.fmu.write_{target}")
    return target


def render(model: "MechanicalModel", target: str, method: str = "lagrange") -> dict[str, str]:
    """The files (name -> text) of ``model``'s package for ``target`` with the equations of ``method``."""
    from mechsys.codegen.package import derive_package

    return _printers()[_package_target(target)](derive_package(model, method))


def write_package(model: "MechanicalModel", target: str, directory: str | os.PathLike,
                  method: str = "lagrange") -> list[str]:
    """Write ``model``'s package for ``target`` into ``directory`` (created or replaced atomically; see
    `check_destination`) and return the names of its files."""
    _package_target(target)
    check_destination(directory)
    files = render(model, target, method)
    write_directory(Path(directory), files)
    return sorted(files)
