"""On-disk cache of generated code, keyed by the model's structure and the mechsys version.

Parameter values and initial values are not part of the key: they are inputs of the compiled code, so
`--set` and sweeps reuse the cache. `MECHSYS_CACHE` chooses the folder (default: the user cache folder);
`MECHSYS_CACHE=off` disables it. Entries are written atomically; a damaged entry is ignored."""
from __future__ import annotations

import hashlib
import json
import os
import tempfile
from pathlib import Path


def cache_dir() -> Path | None:
    value = os.environ.get("MECHSYS_CACHE")
    if value and value.lower() in ("off", "0", "none", "false"):
        return None
    if value:
        return Path(value)
    base = os.environ.get("XDG_CACHE_HOME") or os.path.join(os.path.expanduser("~"), ".cache")
    return Path(base) / "mechsys"


def _structure(raw: dict) -> dict:
    """The model data without parameter values, initial values, names and descriptions."""
    data = json.loads(json.dumps(raw, default=str))
    data.pop("name", None)
    data.pop("description", None)
    data["parameters"] = sorted(data.get("parameters", {})) if isinstance(data.get("parameters"), dict) else []
    coords = data.get("coordinates", {})
    if isinstance(coords, dict):
        for c in coords.values():
            if isinstance(c, dict):
                c.pop("initial", None)
                c.pop("rate", None)
    return data


_FINGERPRINT: str | None = None


def code_fingerprint() -> str:
    """Hash of the code that derives and generates (so a development change never reuses stale entries)."""
    global _FINGERPRINT
    if _FINGERPRINT is None:
        root = Path(__file__).resolve().parents[1]
        digest = hashlib.sha256()
        files = [f for sub in ("model", "mechanics", "numeric") for f in sorted((root / sub).glob("*.py"))]
        files += sorted((root / "numeric").glob("*.c"))  # the native integrator template
        # the analyses that generate code of their own define what their entries hold
        files += [root / "analysis" / name for name in ("simulate.py", "reactions.py")]
        for f in files:
            digest.update(f.read_bytes())
        _FINGERPRINT = digest.hexdigest()[:16]
    return _FINGERPRINT


def model_key(model, what: str) -> str:
    from mechsys import __version__

    payload = {"version": __version__, "code": code_fingerprint(), "what": what,
               "structure": _structure(model.doc.raw),
               "released": sorted(model.doc.released)}
    return hashlib.sha256(json.dumps(payload, sort_keys=True).encode()).hexdigest()[:32]


def load(key: str) -> dict | None:
    folder = cache_dir()
    if folder is None:
        return None
    try:
        return json.loads((folder / f"{key}.json").read_text(encoding="utf-8"))
    except (OSError, ValueError):
        return None


def store(key: str, payload: dict) -> None:
    folder = cache_dir()
    if folder is None:
        return
    try:
        folder.mkdir(parents=True, exist_ok=True)
        fd, tmp = tempfile.mkstemp(dir=folder, prefix=f".{key}.")
        with os.fdopen(fd, "w", encoding="utf-8") as fh:
            json.dump(payload, fh)
        os.replace(tmp, folder / f"{key}.json")
    except OSError:
        pass  # a read-only or full cache folder only costs speed
