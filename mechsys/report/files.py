"""Atomic output files: write to a temporary file in the same folder, then rename, so nothing is half-written.

Every result, report and figure mechsys writes goes through `atomic_write`. The target must be a regular file
(or not exist yet) in a folder that exists: a directory, a device such as /dev/null or a FIFO is refused. A
symbolic link is written through: its resolved target is replaced atomically and the link is kept. Any failure
(permission, full disk, an interrupt) removes the temporary file and is reported as one line,
``cannot write FILE: reason`` (an `InputError`, exit code 2)."""
from __future__ import annotations

import os
import stat
import tempfile
from pathlib import Path
from typing import Callable

from mechsys.errors import InputError


def cannot_write(path: str | os.PathLike, reason: str) -> InputError:
    """The one-line error of an output file that cannot be written."""
    return InputError(f"cannot write {os.fspath(path)}: {reason}")


def _reason(exc: OSError) -> str:
    return (exc.strerror or str(exc) or type(exc).__name__).lower()


def output_target(path: str | os.PathLike) -> Path:
    """The regular file an output goes to (a symlink's resolved target), checked before any work is done."""
    path = Path(path)
    target = Path(os.path.realpath(path)) if path.is_symlink() else path
    try:
        mode = os.stat(target).st_mode
    except FileNotFoundError:
        mode = None
    except OSError as exc:
        raise cannot_write(path, _reason(exc)) from None
    if mode is not None and stat.S_ISDIR(mode):
        raise cannot_write(path, "it is a directory")
    if mode is not None and not stat.S_ISREG(mode):
        raise cannot_write(path, "not a regular file (a device, FIFO or socket); give a file name")
    directory = target.parent if str(target.parent) else Path(".")
    if not directory.is_dir():
        raise cannot_write(path, f"directory {directory} does not exist")
    if not os.access(directory, os.W_OK | os.X_OK):
        raise cannot_write(path, f"permission denied (directory {directory})")
    return target


def _permissions() -> int:
    umask = os.umask(0)
    os.umask(umask)
    return 0o666 & ~umask


def atomic_write(path: str | os.PathLike, write: Callable[[str], None]) -> None:
    """Call ``write(tmp_path)`` and move the result onto ``path`` (permissions follow the umask). The temporary
    file keeps the target's suffix, so writers that choose the format from the name (matplotlib) pick the right
    one. Nothing is left behind when ``write`` fails or is interrupted."""
    target = output_target(path)
    try:
        fd, tmp = tempfile.mkstemp(prefix=f".{target.name}.", suffix=target.suffix, dir=target.parent)
    except OSError as exc:
        raise cannot_write(path, _reason(exc)) from None
    try:
        os.close(fd)
        write(tmp)
        os.chmod(tmp, _permissions())
        os.replace(tmp, target)
    except OSError as exc:
        raise cannot_write(path, _reason(exc)) from None
    finally:
        if os.path.lexists(tmp):
            os.unlink(tmp)


def write_text_atomic(path: str | os.PathLike, text: str) -> None:
    atomic_write(path, lambda tmp: Path(tmp).write_text(text, encoding="utf-8", newline=""))


def write_bytes_atomic(path: str | os.PathLike, content: bytes) -> None:
    atomic_write(path, lambda tmp: Path(tmp).write_bytes(content))


FIGURE_SUFFIXES = (".png", ".svg", ".pdf", ".jpg", ".jpeg", ".eps", ".ps", ".tif", ".tiff", ".webp", ".svgz")


def check_figure_path(path: str | os.PathLike, option: str = "--plot") -> None:
    """Reject a figure file name before any work: a suffix matplotlib cannot write, or a target that is not a
    writable regular file."""
    suffix = Path(path).suffix.lower()
    if suffix not in FIGURE_SUFFIXES:
        raise InputError(f"{option} {os.fspath(path)}: unsupported figure format {suffix or '(no suffix)'!r} "
                         f"(use {', '.join(FIGURE_SUFFIXES[:3])} ...)")
    output_target(path)


def write_figure(path: str | os.PathLike, draw: Callable[[str], None], option: str = "--plot") -> None:
    """Draw a figure into a temporary file of the same suffix (``draw(tmp)`` calls savefig) and move it onto
    ``path``."""
    check_figure_path(path, option)
    atomic_write(path, draw)
