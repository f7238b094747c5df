"""Read a YAML scene into plain Python values plus the line of every value.

``yaml.safe_load`` loses line numbers and silently keeps the last of two duplicate keys; this
reader composes the node tree (``yaml.compose``) and converts it itself so that

* ``Document.lines[path]`` is the 1-based line of the value at ``path`` (a tuple of keys and
  list indices, e.g. ``("cloths", 1, "parameters", "damping")``), used in error messages;
* a duplicate key in a mapping is an error (it is nearly always a copy-paste mistake);
  YAML merge keys (``<<: *defaults``) work, the mapping's own keys overriding merged ones;
* scalars are resolved as ``yaml.safe_load`` does (``.nan``, ``.inf``, ``null``,
  ``yes``/``no`` stay YAML 1.1), plus the YAML 1.2 number forms that YAML 1.1 reads as text:
  ``1e-4``, ``1e4``, ``1.0e30``, ``2E5`` are floats (``SceneLoader``), so the schema sees
  ordinary ints, floats, bools and strings;
* absurd inputs fail fast: a document over ``MAX_DOCUMENT_BYTES`` is refused before it is
  parsed (a 50 MB file would take minutes and gigabytes to judge), an empty file says so, and
  a binary asset or recording given where a scene is expected is named with the command that
  fits it (``asset_kind``).
"""
from __future__ import annotations

import os
import pathlib
import re
from dataclasses import dataclass, field

import yaml

from magica_py.config.errors import ConfigError, Issue, format_path

Path = tuple  # tuple[str | int, ...]

# A scene document is short: rigs are generated (parts, instances) or imported (file:), clips
# are read from their files. 4 MiB is over a hundred times the largest showcase.
MAX_DOCUMENT_BYTES = 4 * 1024 * 1024


# libyaml's parser (PyYAML's C binding) when installed: the same nodes, marks and errors,
# about ten times faster than the pure-Python parser on large documents.
_SAFE_LOADER = getattr(yaml, "CSafeLoader", yaml.SafeLoader)


class SceneLoader(_SAFE_LOADER):
    """PyYAML's safe loader that also reads YAML 1.2 exponent numbers (``1e-4``, ``1e4``,
    ``1.0e30``) as floats; YAML 1.1 needs a dot and a signed exponent (``1.0e-4``) and
    otherwise returns the text ``'1e-4'``."""


for _first in "0123456789-+.":
    SceneLoader.add_implicit_resolver(
        "tag:yaml.org,2002:float",
        re.compile(r"^[-+]?(?:[0-9][0-9_]*(?:\.[0-9_]*)?|\.[0-9][0-9_]*)[eE][-+]?[0-9]+$"), [_first])


def load_yaml_value(text: str):
    """One YAML value (a ``--set`` value) with the scene's number rules."""
    return yaml.load(text, Loader=SceneLoader)  # noqa: S506 - SceneLoader is a SafeLoader


# (magic bytes or suffix) -> what the file is and the command that fits it
_ASSET_KINDS = {
    ".vrm": ("a VRM avatar", "run it directly: magica-py run {path}  (add --save-scene scene.yaml to keep "
                             "the scene it builds)"),
    ".glb": ("a glTF binary (GLB) model", "load it in a scene's rigs (rigs: - {{name: model, file: {path}}}), "
                                          "see configs/fox_run.yaml and docs/scene-format.md"),
    ".gltf": ("a glTF model", "load it in a scene's rigs (rigs: - {{name: model, file: {path}}}), "
                              "see configs/fox_run.yaml and docs/scene-format.md"),
    ".bvh": ("a BVH motion capture clip", "play it on an avatar: magica-py run AVATAR.vrm --clip {path}, "
                                          "or in a scene's animation (- {{clip: {path}, rig: ...}})"),
    ".rrd": ("a Rerun recording", "open it with: rerun {path}   or summarize it with: magica-py inspect {path}"),
}


def asset_kind(path, head: bytes) -> tuple[str, str] | None:
    """(what the file is, the command that fits) for a model, clip or recording; None for text
    that may be a scene. ``head``: the file's first bytes."""
    suffix = pathlib.Path(path).suffix.lower()
    if head[:4] == b"glTF":  # GLB container: a .vrm is a GLB with a VRM extension
        suffix = ".vrm" if suffix == ".vrm" or b'"VRM' in head else ".glb"
    elif head[:3] == b"RRF":  # Rerun's file header
        suffix = ".rrd"
    elif head.lstrip()[:9] == b"HIERARCHY":
        suffix = ".bvh"
    if suffix not in _ASSET_KINDS:
        return None
    what, command = _ASSET_KINDS[suffix]
    return what, command.format(path=path)


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
    loader = SceneLoader(text)
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
        if node is None or (isinstance(node, yaml.ScalarNode) and node.tag == "tag:yaml.org,2002:null"):
            # nothing, only comments, or an empty document ("---"): say so rather than "rigs: is required"
            raise ConfigError(source, [Issue("", "the file is empty (no YAML document in it): expected a scene "
                                                 "mapping with at least 'rigs' (docs/scene-format.md; "
                                                 "`magica-py new NAME` writes a starter scene)")])
        # aliases are expanded into copies: a recursive anchor (``&a [*a]``) or nested aliases that
        # multiply ("billion laughs": a 1 kB file of a billion values) are refused, not expanded
        budget = _Expansion(max(MIN_EXPANDED_VALUES, 2 * len(text)))
        try:
            doc.data = _convert(loader, node, (), doc.lines, issues, budget)
        except _ExpansionError as exc:
            raise ConfigError(source, [Issue(format_path(exc.path), exc.message, exc.line)]) from None
        except yaml.MarkedYAMLError as exc:   # a value PyYAML cannot construct (a bad tag, ...)
            mark = exc.problem_mark or exc.context_mark
            raise ConfigError(source, [Issue("", f"invalid YAML: {exc.problem or exc}",
                                             mark.line + 1 if mark is not None else None)]) from None
        except RecursionError:
            raise ConfigError(source, [Issue("", "the document nests too deeply (through aliases): expected a "
                                                 "scene mapping of ordinary depth")]) from None
        if issues:
            raise ConfigError(source, issues)
        return doc
    finally:
        loader.dispose()


def read_document(path: str | pathlib.Path) -> Document:
    """Read and parse a scene file; a missing or unreadable file is a ConfigError."""
    source = str(path)
    try:
        with open(path, "rb") as fh:
            size = os.fstat(fh.fileno()).st_size
            head = fh.read(4096)
            kind = asset_kind(path, head)
            if kind is not None:
                what, command = kind
                raise ConfigError(source, [Issue("", f"this is {what}, not a scene: {command}")])
            if size > MAX_DOCUMENT_BYTES:  # judged from its size: nothing parsed
                raise ConfigError(source, [Issue("", f"the scene document is {size / 1e6:.1f} MB; scene files are "
                                                     f"limited to {MAX_DOCUMENT_BYTES / 1e6:.1f} MB. Generate bones "
                                                     "with rig parts and instances, and read rigs and clips from their "
                                                     "asset files (file:, clip:) instead of writing them out "
                                                     "(docs/scene-format.md)")])
            data = head + fh.read()
    except FileNotFoundError:
        raise ConfigError(source, [Issue("", "file not found")]) from None
    except IsADirectoryError:
        raise ConfigError(source, [Issue("", "is a directory, expected a YAML scene file")]) from None
    except OSError as exc:
        raise ConfigError(source, [Issue("", f"cannot read the file: {exc}")]) from None
    try:
        text = data.decode("utf-8")
    except UnicodeDecodeError as exc:
        raise ConfigError(source, [Issue("", f"not a YAML scene: the file is not UTF-8 text (byte {exc.start}); "
                                             "expected a scene file (docs/scene-format.md)")]) from None
    return parse_text(text, source)


# A document's values after its aliases are expanded: at most twice its length in characters
# (a value takes at least two), and at least this many, so that anchors shared by many entries
# (``<<: *defaults``) always work.
MIN_EXPANDED_VALUES = 1_000_000


class _ExpansionError(Exception):
    def __init__(self, path: Path, message: str, line: int | None):
        super().__init__(message)
        self.path, self.message, self.line = path, message, line


class _Expansion:
    """The values ``_convert`` produced so far and the nodes it is inside (recursive anchors)."""

    def __init__(self, limit: int):
        self.limit = limit
        self.count = 0
        self.open: set[int] = set()

    def enter(self, node, path: Path) -> None:
        self.count += 1
        if self.count > self.limit:
            raise _ExpansionError(path, f"the document's aliases (*name) expand to more than {self.limit:,} values: "
                                        "expected a scene of ordinary size (an anchor repeated inside aliases "
                                        "that are repeated again multiplies)", node.start_mark.line + 1)
        if id(node) in self.open:
            raise _ExpansionError(path, "an alias (*name) refers to a mapping or list that contains it: a "
                                        "recursive structure cannot be a scene value", node.start_mark.line + 1)


def _convert(loader, node, path: Path, lines: dict, issues: list, budget: _Expansion | None = None) -> object:
    if budget is None:
        budget = _Expansion(MIN_EXPANDED_VALUES)
    budget.enter(node, path)
    lines[path] = node.start_mark.line + 1
    if isinstance(node, (yaml.MappingNode, yaml.SequenceNode)):
        budget.open.add(id(node))
        try:
            return _convert_collection(loader, node, path, lines, issues, budget)
        finally:
            budget.open.discard(id(node))
    return _construct_scalar(loader, node, path, issues)


def _construct_scalar(loader, node, path: Path, issues: list):
    """A scalar's value; an explicit tag whose text does not fit it (``!!float abc``,
    ``!!int 1.5``) is an issue at ``path`` (PyYAML raises a bare ValueError)."""
    try:
        return loader.construct_object(node, deep=True)
    except (ValueError, TypeError, OverflowError) as exc:
        if isinstance(exc, yaml.YAMLError):
            raise
        issues.append(Issue(format_path(path), f"cannot read {node.value!r} as {node.tag.rsplit(':', 1)[-1]}: "
                                               f"{exc}", node.start_mark.line + 1))
        return None


_MERGE = "tag:yaml.org,2002:merge"


def _flattened_pairs(node, path: Path, inside: frozenset = frozenset()) -> list:
    """(key node, value node, explicit) of a mapping node with its merge keys (``<<: *a``,
    ``<<: [*a, *b]``) expanded: merged pairs first (the earlier of several merged mappings
    wins), then the mapping's own pairs, which override them. Unlike PyYAML's
    ``flatten_mapping`` the nodes are not changed, so a mapping reached again through an alias
    is read the same way (its own keys still known as its own)."""
    if id(node) in inside:
        raise _ExpansionError(path, "a merge key (<<) merges a mapping into itself: a recursive structure "
                                    "cannot be a scene value", node.start_mark.line + 1)
    inside = inside | {id(node)}
    merged: list = []
    own: list = []
    for key_node, value_node in node.value:
        if key_node.tag != _MERGE:
            own.append((key_node, value_node, True))
            continue
        if isinstance(value_node, yaml.MappingNode):
            sources = [value_node]
        elif isinstance(value_node, yaml.SequenceNode) and all(isinstance(v, yaml.MappingNode)
                                                                for v in value_node.value):
            sources = list(value_node.value)
        else:
            raise _ExpansionError(path + ("<<",), "a merge key (<<) takes a mapping or a list of mappings "
                                                  "(<<: *defaults or <<: [*a, *b]), got "
                                                  + ("a list with other values" if isinstance(value_node, yaml.SequenceNode)
                                                     else f"the value {value_node.value!r}"),
                                  key_node.start_mark.line + 1)
        for source in reversed(sources):   # the first mapping listed wins: it comes last
            merged.extend((k, v, False) for k, v, _ in _flattened_pairs(source, path, inside))
    return merged + own


def _convert_collection(loader, node, path: Path, lines: dict, issues: list, budget: _Expansion) -> object:
    if isinstance(node, yaml.MappingNode):
        out: dict = {}
        merged: set = set()  # keys whose current value came from a merge (overridable)
        for key_node, value_node, explicit in _flattened_pairs(node, path):
            key = _construct_scalar(loader, key_node, path, issues) if isinstance(key_node, yaml.ScalarNode) \
                else loader.construct_object(key_node, deep=True)
            if not isinstance(key, str):
                if isinstance(key, (int, float, bool)) or key is None:
                    key = str(key)  # e.g. a bone named 1 in bone_attributes
                else:
                    issues.append(Issue(format_path(path), f"mapping keys must be text, got {key!r}",
                                        key_node.start_mark.line + 1))
                    continue
            if key in out and key not in merged and explicit:
                issues.append(Issue(format_path(path + (key,)), "duplicate key (it appears twice in this mapping)",
                                    key_node.start_mark.line + 1))
                continue
            if explicit:
                merged.discard(key)
            else:
                merged.add(key)
            out[key] = _convert(loader, value_node, path + (key,), lines, issues, budget)
            lines[path + (key,)] = key_node.start_mark.line + 1
        return out
    if isinstance(node, yaml.SequenceNode):
        return [_convert(loader, item, path + (i,), lines, issues, budget) for i, item in enumerate(node.value)]
    raise AssertionError(f"not a collection node: {node!r}")
