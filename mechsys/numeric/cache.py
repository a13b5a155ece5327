"""On-disk cache of derived data and compiled libraries: keyed by all they depend on, signed, checked before use.

Trust model (docs/simulate.md, "The cache"):

- **Key.** An entry's key covers the model's structure with the order of every mapping (parameters,
  coordinates, links, ...: generated code reads parameters and states by position), the value-dependent
  structural decisions the builder made (`Kinematics.decisions`: a constraint row found identically zero with the
  file's values), the released prescribed coordinates, the mechsys version and a fingerprint of the code that
  derives and generates. Parameter and initial values are not part of it: they are inputs of the compiled code.
- **Folder.** `MECHSYS_CACHE` chooses it (default: the user cache folder; `off` disables the cache). It is
  created 0700; a folder that is not owned by the user or is writable by group or others is not used (the run
  goes on uncached).
- **Entries.** Each file must be a regular file owned by the user and not writable by others, and carry an
  HMAC-SHA256 made with a per-user secret key (`$XDG_CONFIG_HOME/mechsys/cache.key`, created 0600, kept outside
  the cache folder): an entry copied in from elsewhere (another user, a CI cache restored from another branch)
  or damaged is ignored and rebuilt, never loaded. Generated Python source read back is further restricted to
  arithmetic (`runtime.check_source`) before it is compiled, and a shared library is loaded only when the bytes
  on disk carry a valid signature.
- Entries are written atomically (temporary file, then rename)."""
from __future__ import annotations

import hashlib
import hmac
import json
import os
import stat
import tempfile
from pathlib import Path
from typing import TYPE_CHECKING, Any, Optional

if TYPE_CHECKING:
    from mechsys.mechanics.model import MechanicalModel

MAX_ENTRY_BYTES = 512 * 1024 * 1024  # nothing the cache writes is larger; a larger file is not read
_MAGIC = b"mechsys-cache-1 "


def cache_dir() -> Path | None:
    """The configured cache folder (not checked or created), or None when the cache is off."""
    value = os.environ.get("MECHSYS_CACHE")
    if value and value.lower() in ("off", "0", "none", "false"):
        return None
    if value:
        return Path(value)
    base = os.environ.get("XDG_CACHE_HOME") or os.path.join(os.path.expanduser("~"), ".cache")
    return Path(base) / "mechsys"


def _private(st: os.stat_result) -> bool:
    """Owned by this user and writable by nobody else."""
    return (not hasattr(os, "getuid") or st.st_uid == os.getuid()) and not st.st_mode & 0o022


def usable_dir() -> Path | None:
    """The cache folder, created 0700 when missing; None when the cache is off, cannot be created, is not owned
    by this user or is writable by others, or no signing key can be had (the run then goes on uncached)."""
    folder = cache_dir()
    if folder is None or _secret() is None:
        return None
    try:
        folder.mkdir(mode=0o700, parents=True, exist_ok=True)
        st = folder.stat()
    except OSError:
        return None
    return folder if stat.S_ISDIR(st.st_mode) and _private(st) else None


def read_private(path: Path, limit: int = MAX_ENTRY_BYTES) -> bytes | None:
    """The bytes of ``path`` when it is a regular file (not a link) owned by this user, not writable by others
    and at most ``limit`` bytes; None otherwise."""
    try:
        fd = os.open(path, os.O_RDONLY | getattr(os, "O_NOFOLLOW", 0))
    except OSError:
        return None
    with os.fdopen(fd, "rb") as fh:
        st = os.fstat(fh.fileno())
        if not stat.S_ISREG(st.st_mode) or not _private(st) or st.st_size > limit:
            return None
        return fh.read(limit + 1)


_SECRET: dict[str, bytes] = {}


def _key_file() -> Path:
    base = os.environ.get("XDG_CONFIG_HOME") or os.path.join(os.path.expanduser("~"), ".config")
    return Path(base) / "mechsys" / "cache.key"


def _secret() -> bytes | None:
    """The per-user signing key (32 random bytes, file mode 0600), created on first use; None if unavailable."""
    path = _key_file()
    if str(path) in _SECRET:
        return _SECRET[str(path)]
    data = read_private(path, 64)
    if data is None or len(data) != 32:
        try:
            path.parent.mkdir(mode=0o700, parents=True, exist_ok=True)
            fd = os.open(path, os.O_WRONLY | os.O_CREAT | os.O_EXCL | getattr(os, "O_NOFOLLOW", 0), 0o600)
            with os.fdopen(fd, "wb") as fh:
                fh.write(os.urandom(32))
        except FileExistsError:
            pass  # another process made it first (or a bad one is in the way: then it is checked below)
        except OSError:
            return None
        data = read_private(path, 64)
        if data is None or len(data) != 32 or os.stat(path).st_mode & 0o077:
            return None
    _SECRET[str(path)] = data
    return data


def sign(data: bytes) -> str:
    """HMAC-SHA256 of ``data`` under the user's key (callers reach it only through `usable_dir`, which needs one)."""
    secret = _secret()
    if secret is None:
        raise OSError("no cache signing key")  # never sign with an empty key; callers treat OSError as uncached
    return hmac.new(secret, data, hashlib.sha256).hexdigest()


def _verified(blob: bytes | None) -> bytes | None:
    """The payload of a signed blob (magic, hex MAC, newline, payload) when the MAC is right."""
    if not blob or not blob.startswith(_MAGIC) or _secret() is None:
        return None
    head, _, payload = blob[len(_MAGIC):].partition(b"\n")
    return payload if hmac.compare_digest(head.decode("ascii", "replace"), sign(payload)) else None


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
        files += [root / "analysis" / name for name in ("motion/simulate.py", "motion/reactions.py",
                                                        "equilibrium/nonholonomic.py", "equilibrium/charts.py",
                                                        "equilibrium/equilibria.py", "equilibrium/linearize.py",
                                                        "info.py")]
        for f in files:
            digest.update(f.read_bytes())
        _FINGERPRINT = digest.hexdigest()[:16]
    return _FINGERPRINT


def _ordered(value: Any) -> Any:
    """JSON-ready copy that keeps the order of every mapping (as [key, value] pairs)."""
    if isinstance(value, dict):
        return {"{}": [[str(k), _ordered(v)] for k, v in value.items()]}
    if isinstance(value, (list, tuple)):
        return [_ordered(v) for v in value]
    return value if isinstance(value, (int, float, bool)) or value is None else str(value)


def _structure(raw: dict) -> dict:
    """The model data without parameter values, initial values, names and descriptions; order kept."""
    data = json.loads(json.dumps(raw, default=str))
    data.pop("name", None)
    data.pop("description", None)
    data.pop("expect", None)  # expectations are read by `check`, never by generated code
    params = data.get("parameters")
    data["parameters"] = list(params) if isinstance(params, dict) else []
    coords = data.get("coordinates", {})
    if isinstance(coords, dict):
        for c in coords.values():
            if isinstance(c, dict):
                c.pop("initial", None)
                c.pop("rate", None)
    return data


def model_key(model: MechanicalModel, what: str) -> str:
    """Key of a cache entry ``what`` for this model: structure in file order, decisions, code version."""
    from mechsys import __version__

    payload = {"version": __version__, "code": code_fingerprint(), "what": what,
               "structure": _ordered(_structure(model.doc.raw)),
               "coordinates": list(model.coordinates),
               "parameters": [str(s) for s in model.parameter_symbols],
               "decisions": [[what_, kind, outcome] for what_, kind, _e, outcome in model.kin.decisions],
               "released": list(model.doc.released)}
    return hashlib.sha256(json.dumps(payload).encode()).hexdigest()[:32]


def load(key: str) -> dict | None:
    """A verified entry, or None (missing, foreign, damaged or unsigned entries are ignored)."""
    folder = usable_dir()
    if folder is None:
        return None
    payload = _verified(read_private(folder / f"{key}.json"))
    try:
        data = json.loads(payload) if payload is not None else None
    except ValueError:
        return None
    return data if isinstance(data, dict) else None


def _write_atomic(folder: Path, name: str, data: bytes) -> None:
    fd, tmp = tempfile.mkstemp(dir=folder, prefix=f".{name}.")
    try:
        with os.fdopen(fd, "wb") as fh:
            fh.write(data)
        os.replace(tmp, folder / name)
    except BaseException:
        Path(tmp).unlink(missing_ok=True)
        raise


def store(key: str, payload: dict) -> None:
    """Sign and write an entry; a read-only, full or unsafe cache folder only costs speed."""
    folder = usable_dir()
    if folder is None:
        return
    body = json.dumps(payload).encode()
    # an entry larger than MAX_ENTRY_BYTES is never read back: not signed and written for nothing (the 40-link
    # chain's Lagrange equations printed as JSON: 985 MB)
    if len(_MAGIC) + 65 + len(body) > MAX_ENTRY_BYTES:  # 65: the hex signature and its newline
        return
    try:
        _write_atomic(folder, f"{key}.json", _MAGIC + sign(body).encode() + b"\n" + body)
    except OSError:
        pass


def library(key: str) -> Optional[Path]:
    """The cached shared library ``key`` when its bytes carry a valid signature; None otherwise."""
    folder = usable_dir()
    if folder is None:
        return None
    path = folder / f"{key}.so"
    data = read_private(path)
    signature = read_private(folder / f"{key}.so.sig", 4096)
    if data is None or signature is None or not hmac.compare_digest(signature, sign(data).encode()):
        return None
    return path


def store_library(key: str, built: Path) -> Optional[Path]:
    """Copy a freshly built library into the cache with its signature; its cached path, or None when the cache
    is off or cannot be written."""
    folder = usable_dir()
    if folder is None:
        return None
    try:
        data = built.read_bytes()
        _write_atomic(folder, f"{key}.so", data)
        _write_atomic(folder, f"{key}.so.sig", sign(data).encode())
    except OSError:
        return None
    return folder / f"{key}.so"
