"""Code generation: a model's equations as a standalone Python, C or MATLAB/Octave package, or an FMU (`codegen`)."""
from __future__ import annotations

import os
from pathlib import Path
from typing import TYPE_CHECKING, Callable

from mechsys.codegen import c, matlab, python
from mechsys.codegen.names import mangle
from mechsys.codegen.package import Package, check_destination, derive_package, write_directory
from mechsys.errors import InputError

if TYPE_CHECKING:
    from mechsys.mechanics.model import MechanicalModel

__all__ = ["TARGETS", "FILE_TARGETS", "render", "write_package", "check_target", "check_destination",
           "derive_package", "mangle", "Package"]


TARGETS: dict[str, Callable[[Package], dict[str, str]]] = {"python": python.render, "c": c.render,
                                                          "matlab": matlab.render}
"""Target name -> the function that prints a package's files (file name -> text)."""
FILE_TARGETS = ("fmu",)
"""Targets written as one file rather than a folder: fmu (codegen/fmu.py, `write_fmu`)."""


def check_target(target: str) -> str:
    """The target's name, or an InputError naming the valid ones."""
    if target not in TARGETS and target not in FILE_TARGETS:
        raise InputError(f"unknown target {target!r}; use one of {', '.join([*TARGETS, *FILE_TARGETS])}")
    return target


def _package_target(target: str) -> str:
    """A target that writes a folder, or an InputError (fmu writes one file: mechsys.codegen.fmu.write_fmu)."""
    if check_target(target) in FILE_TARGETS:
        raise InputError(f"the {target} target writes one file, not a package folder: use "
                         f"mechsys.codegen.fmu.write_{target}")
    return target


def render(model: "MechanicalModel", target: str, method: str = "lagrange") -> dict[str, str]:
    """The files (name -> text) of ``model``'s package for ``target`` with the equations of ``method``."""
    return TARGETS[_package_target(target)](derive_package(model, method))


def write_package(model: "MechanicalModel", target: str, directory: str | os.PathLike,
                  method: str = "lagrange") -> list[str]:
    """Write ``model``'s package for ``target`` into ``directory`` (created or replaced atomically; see
    `check_destination`) and return the names of its files."""
    _package_target(target)
    check_destination(directory)
    files = render(model, target, method)
    write_directory(Path(directory), files)
    return sorted(files)
