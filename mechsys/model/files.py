"""Reading model files: regular files only, bounded in size, UTF-8; imports nothing heavy (the warm path uses it)."""
from __future__ import annotations

import os
import stat

from mechsys.errors import InputError

MAX_MODEL_BYTES = 10 * 1024 * 1024  # model files are text of a few kB; a larger "model" is a mistake


def _open_model(file: str) -> int:
    """A read-only descriptor of a regular file; never blocks (a FIFO is opened non-blocking, then refused)."""
    try:
        fd = os.open(file, os.O_RDONLY | getattr(os, "O_NONBLOCK", 0))
    except FileNotFoundError:
        raise InputError(f"{file}: no such file") from None
    except IsADirectoryError:
        raise InputError(f"{file}: is a directory, expected a model file") from None
    except OSError as exc:
        raise InputError(f"{file}: cannot read: {(exc.strerror or str(exc)).lower()}") from None
    info = os.fstat(fd)
    problem = ("is a directory, expected a model file" if stat.S_ISDIR(info.st_mode) else
               "cannot read: not a regular file (a device, FIFO or socket)" if not stat.S_ISREG(info.st_mode) else
               f"cannot read: larger than {MAX_MODEL_BYTES // 2**20} MB (the limit of a model file)"
               if info.st_size > MAX_MODEL_BYTES else None)
    if problem:
        os.close(fd)
        raise InputError(f"{file}: {problem}")
    return fd


def read_model_text(path: str | os.PathLike) -> str:
    """The text of a model file (UTF-8, at most MAX_MODEL_BYTES), or a one-line InputError: missing, a directory,
    not a regular file (FIFO, device), too large, unreadable, not UTF-8."""
    file = os.fspath(path)
    fd = _open_model(file)
    try:
        with os.fdopen(fd, encoding="utf-8") as fh:
            text = fh.read(MAX_MODEL_BYTES + 1)
    except UnicodeDecodeError:
        raise InputError("the file is not UTF-8 text", file, 1, 1) from None
    except OSError as exc:
        raise InputError(f"{file}: cannot read: {(exc.strerror or str(exc)).lower()}") from None
    if len(text) > MAX_MODEL_BYTES:
        raise InputError(f"{file}: cannot read: larger than {MAX_MODEL_BYTES // 2**20} MB (the limit of a model "
                         "file)")
    return text
