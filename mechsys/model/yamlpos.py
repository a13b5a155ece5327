"""YAML reading that remembers the line and column of every key, for file:line:col errors."""
from __future__ import annotations

from typing import Any

import yaml

from mechsys.errors import InputError

Path = tuple[Any, ...]


class PositionMap:
    """Maps key paths such as ``("links", "arm", "mass")`` to 1-based (line, column)."""

    def __init__(self) -> None:
        self.value_pos: dict[Path, tuple[int, int]] = {}
        self.key_pos: dict[Path, tuple[int, int]] = {}

    def lookup(self, path: Path, key: bool = False) -> tuple[int, int]:
        """Position of the deepest known prefix of ``path`` (the key itself when ``key``)."""
        path = tuple(path)
        while path:
            table = self.key_pos if key else self.value_pos
            if path in table:
                return table[path]
            if path in self.value_pos:
                return self.value_pos[path]
            path = path[:-1]
        return self.value_pos.get((), (1, 1))


def _mark(node: yaml.Node) -> tuple[int, int]:
    return node.start_mark.line + 1, node.start_mark.column + 1


_MAX_NODES = 200_000


class _Builder:
    def __init__(self, file: str, loader: yaml.SafeLoader) -> None:
        self.file = file
        self.loader = loader
        self.pos = PositionMap()
        self.count = 0

    def build(self, node: yaml.Node, path: Path) -> Any:
        self.count += 1
        if self.count > _MAX_NODES:
            line, col = _mark(node)
            raise InputError(f"the document is too large (more than {_MAX_NODES} YAML nodes)", self.file, line, col)
        self.pos.value_pos[path] = _mark(node)
        if isinstance(node, yaml.MappingNode):
            out: dict[Any, Any] = {}
            for key_node, value_node in node.value:
                if not isinstance(key_node, yaml.ScalarNode):
                    line, col = _mark(key_node)
                    raise InputError("mapping keys must be plain names", self.file, line, col, _dotted(path))
                key = str(key_node.value)  # raw text: YAML 1.1 would read 'on'/'yes' as booleans
                if key in out:
                    line, col = _mark(key_node)
                    raise InputError(f"duplicate key {key!r}", self.file, line, col, _dotted(path + (key,)))
                self.pos.key_pos[path + (key,)] = _mark(key_node)
                out[key] = self.build(value_node, path + (key,))
            return out
        if isinstance(node, yaml.SequenceNode):
            return [self.build(item, path + (i,)) for i, item in enumerate(node.value)]
        try:
            value = self.loader.construct_object(node, deep=True)
        except ValueError:  # e.g. an integer with thousands of digits
            line, col = _mark(node)
            raise InputError("number too large", self.file, line, col, _dotted(path)) from None
        if isinstance(value, (bytes, bytearray)) or type(value).__module__ == "datetime":
            line, col = _mark(node)
            raise InputError("unsupported YAML value type; use numbers or strings", self.file, line, col,
                             _dotted(path))
        return value


def _dotted(path: Path) -> str:
    out = ""
    for part in path:
        if isinstance(part, int):
            out += f"[{part}]"
        else:
            out += ("." if out else "") + str(part)
    return out


dotted = _dotted


def load_yaml(text: str, file: str) -> tuple[Any, PositionMap]:
    """Parse YAML text (safe subset, no tags that construct objects) into plain data and positions."""
    try:
        loader = yaml.SafeLoader(text)
    except yaml.reader.ReaderError as exc:
        line = text.count("\n", 0, exc.position) + 1
        col = exc.position - (text.rfind("\n", 0, exc.position) + 1) + 1
        raise InputError(f"character {exc.character!r} is not allowed in YAML", file, line, col) from None
    try:
        node = loader.get_single_node()
        if node is None:
            raise InputError("the file is empty; a model needs at least 'name' and 'links'", file, 1, 1)
        builder = _Builder(file, loader)
        data = builder.build(node, ())
    except yaml.MarkedYAMLError as exc:
        mark = exc.problem_mark or exc.context_mark
        if exc.context_mark is not None and "end of stream" in str(exc.problem or ""):
            mark = exc.context_mark  # an unclosed quote or bracket: point at where it opened
        line, col = (mark.line + 1, mark.column + 1) if mark else (1, 1)
        problem = exc.problem or exc.context or "invalid YAML"
        raise InputError(f"YAML syntax error: {problem}", file, line, col) from None
    except yaml.YAMLError as exc:
        raise InputError(f"YAML error: {exc}", file, 1, 1) from None
    except RecursionError:
        raise InputError("YAML nested too deeply", file, 1, 1) from None
    finally:
        loader.dispose()
    return data, builder.pos
