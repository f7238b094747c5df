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
