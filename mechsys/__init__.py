"""mechsys: validated model files and fast, trustworthy analyses of mechanical systems."""
from __future__ import annotations

import os
from typing import Any, Mapping

__version__ = "0.1.0"
__all__ = ["load", "__version__"]


def load(path: str | os.PathLike, overrides: Mapping[str, Any] | None = None,
         release_prescribed: bool = False) -> "MechanicalModel":
    """Load, validate and build the symbolic model of a mechsys YAML file.

    ``overrides`` maps parameter names, coordinate names (initial value) and ``der(name)`` (initial rate)
    to numbers or expression strings, like ``--set`` on the command line. With ``release_prescribed`` each
    prescribed coordinate becomes a free coordinate held by the constraint ``drive(name)``, whose multiplier
    is the driving force or torque (inverse dynamics; used by ``mechsys simulate``).
    """
    from mechsys.mechanics.model import MechanicalModel
    from mechsys.model.load import read_document

    return MechanicalModel(read_document(path, overrides, release_prescribed))


if False:  # pragma: no cover - typing only
    from mechsys.mechanics.model import MechanicalModel
