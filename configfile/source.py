"""Safe YAML loading that remembers where every key came from.

Bench profiles and test plans are data written by people; when a value is
wrong the error must name the file, the line and the key. PyYAML's safe
loader drops positions, so documents are composed into nodes first (which keep
their marks) and converted here. Only the safe constructors run: no tags that
build Python objects, no code from a file is ever evaluated.
"""
from __future__ import annotations

import re
from dataclasses import field
from pathlib import Path
from typing import Any

import yaml
import yaml.constructor

from configfile.dataclass_methods import dataclass

KeyPath = tuple[Any, ...]


class ConfigError(ValueError):
    """A bad value in a YAML file, located by file, line and key path."""

    def __init__(self, message: str, source: str | None = None, line: int | None = None,
                 key: str | None = None):
        self.message = message
        self.source = source
        self.line = line
        self.key = key
        where = source or "<input>"
        if line is not None:
            where += f":{line}"
        if key:
            where += f": key '{key}'"
        super().__init__(f"{where}: {message}")


def format_key(path: KeyPath) -> str:
    """('steps', 2, 'check') -> 'steps[2].check'."""
    text = ""
    for part in path:
        if isinstance(part, int):
            text += f"[{part}]"
        else:
            text += ("." if text else "") + str(part)
    return text


@dataclass
class YamlDocument:
    """Plain data (dicts, lists, scalars) plus the line of every key path."""

    data: Any
    source: str
    lines: dict[KeyPath, int] = field(default_factory=dict)

    def line_of(self, path: KeyPath) -> int | None:
        """Line (1-based) of the key path, or of its closest located parent."""
        path = tuple(path)
        while path:
            if path in self.lines:
                return self.lines[path]
            path = path[:-1]
        return self.lines.get(())

    def error(self, path: KeyPath, message: str) -> ConfigError:
        return ConfigError(message, self.source, self.line_of(path), format_key(path) or None)


class _Constructor(yaml.constructor.SafeConstructor):
    pass


def _convert(node: yaml.Node, path: KeyPath, lines: dict[KeyPath, int], source: str,
             constructor: _Constructor) -> Any:
    lines.setdefault(path, node.start_mark.line + 1)
    if isinstance(node, yaml.MappingNode):
        result: dict[Any, Any] = {}
        for key_node, value_node in node.value:
            if key_node.tag == "tag:yaml.org,2002:merge":
                raise ConfigError("YAML merge keys (<<) are not supported", source,
                                  key_node.start_mark.line + 1, format_key(path) or None)
            key = constructor.construct_object(key_node, deep=True)
            if not isinstance(key, (str, int, float, bool)):
                raise ConfigError("mapping keys must be scalars", source,
                                  key_node.start_mark.line + 1, format_key(path) or None)
            if key in result:
                raise ConfigError("duplicate key", source, key_node.start_mark.line + 1,
                                  format_key(path + (key,)))
            lines[path + (key,)] = key_node.start_mark.line + 1
            result[key] = _convert(value_node, path + (key,), lines, source, constructor)
        return result
    if isinstance(node, yaml.SequenceNode):
        return [_convert(item, path + (i,), lines, source, constructor)
                for i, item in enumerate(node.value)]
    return constructor.construct_object(node, deep=True)


# libyaml's safe loader, when PyYAML was built with it: its nodes carry the same marks and its
# constructors are the same Python ones, and it composes a bench profile ~30 times faster than
# the pure-Python loader (9 ms of `hil run`'s start-up for the default profile).
_C_LOADER = getattr(yaml, "CSafeLoader", None)
# libyaml takes some documents that the pure-Python loader refuses or reads otherwise: a tab
# inside a line, a '?' inside a plain scalar of a flow collection ({a: 0.?2}), a tag ('!', a
# tag of nothing is '' there and None here), a byte-order mark, a '#' right after a block
# scalar's indicators ('|#'). A document with any of them goes to the pure-Python loader,
# which refuses it, or reads it, as before (tests/test_yaml_source.py holds the two to the
# same results on the repository's files and on mutants of them).
_PURE_ONLY = re.compile("[\t?!\ufeff]|[|>][-+0-9]*#")


def _compose(text: str) -> yaml.Node | None:
    """The document's node tree. A document libyaml refuses is composed again by the
    pure-Python loader, so an error names the same problem and line as before."""
    if _C_LOADER is not None and not _PURE_ONLY.search(text):
        try:
            return yaml.compose(text, Loader=_C_LOADER)
        except yaml.YAMLError:
            pass
    return yaml.compose(text, Loader=yaml.SafeLoader)


def parse_yaml(text: str, source: str = "<string>") -> YamlDocument:
    """Parses one YAML document with the safe loader, keeping key lines."""
    try:
        node = _compose(text)
    except yaml.YAMLError as exc:
        mark = getattr(exc, "problem_mark", None)
        line = mark.line + 1 if mark is not None else None
        problem = getattr(exc, "problem", None) or str(exc)
        raise ConfigError(f"not valid YAML: {problem}", source, line) from None
    if node is None:
        return YamlDocument({}, source, {(): 1})
    lines: dict[KeyPath, int] = {}
    constructor = _Constructor()
    try:
        data = _convert(node, (), lines, source, constructor)
    except yaml.constructor.ConstructorError as exc:
        mark = exc.problem_mark
        raise ConfigError(f"unsupported YAML: {exc.problem}", source,
                          mark.line + 1 if mark else None) from None
    return YamlDocument(data, source, lines)


def load_yaml(path: str | Path) -> YamlDocument:
    """Reads and parses a YAML file; a missing or unreadable file is a ConfigError."""
    path = Path(path)
    try:
        text = path.read_text(encoding="utf-8")
    except OSError as exc:
        raise ConfigError(f"cannot read file: {exc.strerror}", str(path)) from None
    except UnicodeDecodeError:
        raise ConfigError("file is not UTF-8 text", str(path)) from None
    return parse_yaml(text, str(path))
