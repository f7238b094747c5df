"""Read a YAML scene into plain Python values plus the line of every value.

``yaml.safe_load`` loses line numbers and silently keeps the last of two duplicate keys; this
reader composes the node tree (``yaml.compose``) and converts it itself so that

* ``Document.lines[path]`` is the 1-based line of the value at ``path`` (a tuple of keys and
  list indices, e.g. ``("cloths", 1, "parameters", "damping")``), used in error messages;
* a duplicate key in a mapping is an error (it is nearly always a copy-paste mistake);
  YAML merge keys (``<<: *defaults``) work, the mapping's own keys overriding merged ones;
* scalars are resolved exactly as ``yaml.safe_load`` does (``.nan``, ``.inf``, ``null``,
  ``yes``/``no`` stay YAML 1.1), so the schema sees ordinary ints, floats, bools and strings.
"""
from __future__ import annotations

import pathlib
from dataclasses import dataclass, field

import yaml

from magica_py.config.errors import ConfigError, Issue, format_path

Path = tuple  # tuple[str | int, ...]


@dataclass
class Document:
    """A parsed scene file: the data, where it came from and the line of each value."""

    data: object
    source: str | None = None
    lines: dict[Path, int] = field(default_factory=dict)
    overridden: dict[Path, str] = field(default_factory=dict)  # path -> the --set text
    text: str | None = None                                     # the file's text as read

    def effective_text(self) -> str:
        """The scene as YAML text: the file itself, or (after ``--set``) the overridden data."""
        if not self.overridden and self.text is not None:
            return self.text
        return yaml.safe_dump(self.data, sort_keys=False, default_flow_style=None)

    def mark_overridden(self, path: Path, text: str) -> None:
        """Forget the file lines under ``path``: its value now comes from ``--set text``."""
        path = tuple(path)
        for key in [p for p in self.lines if p[:len(path)] == path]:
            del self.lines[key]
        self.overridden[path] = text

    def override_of(self, path: Path) -> str | None:
        """The ``--set`` text that produced the value at ``path`` (or an ancestor), if any."""
        path = tuple(path)
        for k in range(len(path), -1, -1):
            if path[:k] in self.overridden:
                return self.overridden[path[:k]]
        return None

    def line(self, path: Path) -> int | None:
        """Line of ``path`` or of its nearest ancestor that has one."""
        path = tuple(path)
        if self.override_of(path) is not None:
            return None
        while True:
            if path in self.lines:
                return self.lines[path]
            if not path:
                return None
            path = path[:-1]


def parse_text(text: str, source: str | None = None) -> Document:
    """Parse YAML text; raise ConfigError (with the line) on a syntax error."""
    loader = yaml.SafeLoader(text)
    try:
        try:
            node = loader.get_single_node()
        except yaml.MarkedYAMLError as exc:
            mark = exc.problem_mark or exc.context_mark
            line = mark.line + 1 if mark is not None else None
            problem = exc.problem or str(exc)
            raise ConfigError(source, [Issue("", f"invalid YAML: {problem}", line)]) from None
        except yaml.YAMLError as exc:
            raise ConfigError(source, [Issue("", f"invalid YAML: {exc}")]) from None
        doc = Document(None, source, text=text)
        issues: list[Issue] = []
        if node is not None:
            doc.data = _convert(loader, node, (), doc.lines, issues)
        if issues:
            raise ConfigError(source, issues)
        return doc
    finally:
        loader.dispose()


def read_document(path: str | pathlib.Path) -> Document:
    """Read and parse a scene file; a missing or unreadable file is a ConfigError."""
    source = str(path)
    try:
        text = pathlib.Path(path).read_text(encoding="utf-8")
    except FileNotFoundError:
        raise ConfigError(source, [Issue("", "file not found")]) from None
    except IsADirectoryError:
        raise ConfigError(source, [Issue("", "is a directory, expected a YAML scene file")]) from None
    except (OSError, UnicodeDecodeError) as exc:
        raise ConfigError(source, [Issue("", f"cannot read the file: {exc}")]) from None
    return parse_text(text, source)


def _convert(loader, node, path: Path, lines: dict, issues: list) -> object:
    lines[path] = node.start_mark.line + 1
    if isinstance(node, yaml.MappingNode):
        explicit = {id(k) for k, _ in node.value if k.tag != "tag:yaml.org,2002:merge"}
        loader.flatten_mapping(node)  # YAML merge keys (<<: *anchor): merged pairs first
        out: dict = {}
        merged: set = set()  # keys whose current value came from a merge (overridable)
        for key_node, value_node in node.value:
            key = loader.construct_object(key_node, deep=True)
            if not isinstance(key, str):
                if isinstance(key, (int, float, bool)) or key is None:
                    key = str(key)  # e.g. a bone named 1 in bone_attributes
                else:
                    issues.append(Issue(format_path(path), f"mapping keys must be text, got {key!r}",
                                        key_node.start_mark.line + 1))
                    continue
            if key in out and key not in merged and id(key_node) in explicit:
                issues.append(Issue(format_path(path + (key,)), "duplicate key (it appears twice in this mapping)",
                                    key_node.start_mark.line + 1))
                continue
            if id(key_node) in explicit:
                merged.discard(key)
            else:
                merged.add(key)
            out[key] = _convert(loader, value_node, path + (key,), lines, issues)
            lines[path + (key,)] = key_node.start_mark.line + 1
        return out
    if isinstance(node, yaml.SequenceNode):
        return [_convert(loader, item, path + (i,), lines, issues) for i, item in enumerate(node.value)]
    return loader.construct_object(node, deep=True)
