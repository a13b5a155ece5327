"""Warm outputs of `derive`, `info`, `equilibria`, `modes` and `codegen`: kept by the file's bytes and the options,
so a repeated command prints (or writes) without sympy (no import, no model build: a second `derive` of the
bicycle in a third of a second).

What is kept is data: derive's printed text, the files of a generated package (text; not an FMU, which gcc builds),
info's facts (analysis/facts.py `Info`, rendered again in the format asked), the tables and JSON payload of
`equilibria` and `modes` (rendered again, so a text table fits the terminal). The key is the file's bytes, the
command, every option that shapes the output (the `--set` assignments in their order), mechsys's version, the source
of the whole package and the versions of sympy, numpy and scipy (a printer or a rank decision may change with them),
and for the numeric commands the C compilers used (none, or MECHSYS_NATIVE=off: the Python path, whose last digits
may differ; and the quick compiler of the straight-line programs). Entries are signed like every cache entry
(numeric/cache.py) and checked for their shape. An output is kept only when the model was loaded from the text its
key hashed (`loaded`: a file saved during the command keeps nothing). Commands that fail, that verify or draw
(`derive --check`, `equilibria --verify`, `--plot`) and runs with the cache off are never stored or read. Imports
nothing heavy."""
from __future__ import annotations

import hashlib
import json
from pathlib import Path
from typing import TYPE_CHECKING, Any

from mechsys.numeric import cache

if TYPE_CHECKING:
    from mechsys.analysis.facts import Info

_SOURCE: list[str] = []
#: key -> (the file, the text its key hashed); a key whose file was then loaded with other text is never stored
_HASHED: dict[str, tuple[str, str]] = {}
_STALE: set[str] = set()


def package_fingerprint() -> str:
    """Hash of every source file of mechsys (Python and C) and of the libraries that print and decide."""
    if not _SOURCE:
        from importlib.metadata import PackageNotFoundError, version

        root = Path(__file__).resolve().parents[1]
        digest = hashlib.sha256()
        for f in sorted(root.rglob("*.py")) + sorted(root.rglob("*.c")):
            digest.update(str(f.relative_to(root)).encode() + b"\0" + f.read_bytes())
        for lib in ("sympy", "numpy", "scipy"):
            try:
                digest.update(f"{lib}={version(lib)}".encode())
            except PackageNotFoundError:
                digest.update(f"{lib}=?".encode())
        _SOURCE.append(digest.hexdigest()[:16])
    return _SOURCE[0]


def output_key(command: str, path: Path, options: dict[str, Any]) -> str | None:
    """The key of ``command``'s output for this file's content and options; None when the cache is off or the
    file cannot be read (the full path then reports why)."""
    if cache.cache_dir() is None:
        return None
    from mechsys import __version__
    from mechsys.errors import InputError
    from mechsys.model.files import read_model_text

    try:
        text = read_model_text(path)
    except InputError:
        return None
    payload = json.dumps({"command": command, "options": options, "version": __version__,
                          "code": package_fingerprint()}, sort_keys=True)
    digest = hashlib.sha256(text.encode("utf-8"))
    digest.update(b"\0" + payload.encode())
    key = digest.hexdigest()[:32]
    _HASHED[key] = (str(Path(path).resolve()), text)
    return key


def loaded(path: Path, text: str) -> None:
    """The command's model was read from ``path`` with this text: a key made from other text of the same file (saved
    between the key and the load) must not keep this output, which is the new text's."""
    where = str(Path(path).resolve())
    _STALE.update(key for key, (file, hashed) in _HASHED.items() if file == where and hashed != text)


def _storable(key: str | None) -> bool:
    return key is not None and key not in _STALE


def load_text(key: str | None) -> str | None:
    """A kept text output, or None."""
    entry = cache.load(key) if key is not None else None
    text = entry.get("text") if entry is not None else None
    return text if isinstance(text, str) else None


def store_text(key: str | None, text: str) -> None:
    if _storable(key):
        cache.store(key, {"text": text})


def load_files(key: str | None) -> dict[str, str] | None:
    """Kept files of a generated package (name -> text), or None when missing or not of that shape."""
    entry = cache.load(key) if key is not None else None
    files = entry.get("files") if entry is not None else None
    if not isinstance(files, dict) or not files or not all(
            isinstance(k, str) and isinstance(v, str) and k and "/" not in k and "\0" not in k and k not in (".", "..")
            for k, v in files.items()):
        return None
    return files


def store_files(key: str | None, files: dict[str, str]) -> None:
    if _storable(key):
        cache.store(key, {"files": dict(files)})


def load_info(key: str | None) -> Info | None:
    """Kept `info` facts (an Info), or None when missing or not of Info's shape."""
    entry = cache.load(key) if key is not None else None
    facts = entry.get("info") if entry is not None else None
    if not isinstance(facts, dict):
        return None
    from mechsys.analysis.facts import Info

    try:
        return Info.from_dict(facts)
    except (TypeError, ValueError, KeyError):
        return None


def numeric_path() -> dict[str, Any]:
    """What decides the numeric path of an analysis (an option of its key): the C compiler (None: the Python
    path) and the quick compiler of the straight-line programs."""
    from mechsys.numeric import native

    return {"compiler": native.compiler(), "quick": native.quick_compiler()}


def _cell(x: Any) -> Any:
    """A table cell as JSON data (ValueError for what would not read back as the same cell)."""
    if x is None or isinstance(x, (bool, str)):
        return x
    if isinstance(x, complex):
        return {"complex": [float(x.real), float(x.imag)]}
    if isinstance(x, float):
        return float(x)
    if isinstance(x, int) and type(x) is int:
        return x
    raise ValueError(f"a table cell of type {type(x).__name__}")


def _uncell(x: Any) -> Any:
    if isinstance(x, dict):
        re, im = x["complex"]
        return complex(float(re), float(im))
    if x is None or isinstance(x, (bool, str, int, float)):
        return x
    raise ValueError("not a table cell")


def store_tables(key: str | None, tables: list, payload: Any) -> None:
    """Keep the tables and the JSON payload that were printed (their cells and the payload as JSON data)."""
    if not _storable(key):
        return
    from mechsys.report.tables import _json_default

    try:
        data = [{"title": str(t.title), "columns": [str(c) for c in t.columns], "notes": [str(n) for n in t.notes],
                 "rows": [[_cell(c) for c in row] for row in t.rows]} for t in tables]
        plain = json.loads(json.dumps(payload, default=_json_default))
    except (TypeError, ValueError):
        return
    cache.store(key, {"tables": data, "payload": plain})


def load_tables(key: str | None) -> tuple[list, Any] | None:
    """Kept (tables, payload), or None when missing or not of that shape."""
    entry = cache.load(key) if key is not None else None
    if entry is None or not isinstance(entry.get("tables"), list):
        return None
    from mechsys.report.tables import Table

    try:
        tables = []
        for t in entry["tables"]:
            if not (isinstance(t["title"], str) and all(isinstance(c, str) for c in t["columns"] + t["notes"])):
                return None
            tables.append(Table(t["title"], list(t["columns"]), [[_uncell(c) for c in row] for row in t["rows"]],
                                list(t["notes"])))
    except (KeyError, TypeError, ValueError):
        return None
    return tables, entry.get("payload")


def store_info(key: str | None, info: Info) -> None:
    """Keep the facts, when they are plain JSON data that reads back to the same Info."""
    if not _storable(key):
        return
    facts = info.to_dict()
    try:
        if json.loads(json.dumps(facts)) != facts:
            return
    except (TypeError, ValueError):  # e.g. a numpy number among them
        return
    cache.store(key, {"info": facts})
