"""``--set dotted.key=value`` overrides, applied to the parsed document before validation.

Syntax: ``PATH=VALUE``. PATH is a dotted path with list indices in brackets or as a dotted
number; in a list, a word selects the element whose ``name`` is that word (for ``parts``
entries, the name inside the generator), so these are equivalent::

    cloths[0].parameters.damping=0.2
    cloths.0.parameters.damping=0.2
    cloths.tail.parameters.damping=0.2

A generator part selected by name is entered directly: ``rigs.character.parts.skirt.strands=8``
is ``rigs[0].parts[<i>].skirt.strands=8``.

VALUE is parsed as YAML (``0.2`` is a number, ``true`` a bool, ``[0, -1, 0]`` a list,
``null`` None, ``tail`` text). Missing mapping keys are created, so an override can add a
key the file does not have (but never replaces a number or text by a mapping); unknown keys are then reported by the validation like any other.
Because overrides are applied before validation, an out-of-range override is reported with
its document path exactly as if it were in the file (tagged ``(from --set ...)``).
"""
from __future__ import annotations

import re

import yaml

from magica_py.config.document import Document, load_yaml_value
from magica_py.config.errors import ConfigError, Issue, format_path

_TOKEN = re.compile(r"([^.\[\]]+)|\[(-?\d+)\]")


def parse_override(text: str) -> tuple[list[str | int], object]:
    """Split ``a.b[0].c=value`` into (["a", "b", 0, "c"], parsed value); ValueError if malformed."""
    if "=" not in text:
        raise ValueError(f"override {text!r}: expected PATH=VALUE, e.g. scene.fps=30")
    raw_path, raw_value = text.split("=", 1)
    raw_path = raw_path.strip()
    if not raw_path:
        raise ValueError(f"override {text!r}: the path before '=' is empty")
    tokens: list[str | int] = []
    pos = 0
    while pos < len(raw_path):
        if raw_path[pos] == "." and tokens:
            pos += 1
        m = _TOKEN.match(raw_path, pos)
        if m is None:
            raise ValueError(f"override {text!r}: cannot parse the path at {raw_path[pos:]!r}")
        tokens.append(m.group(1) if m.group(1) is not None else int(m.group(2)))
        pos = m.end()
    try:
        value = load_yaml_value(raw_value) if raw_value.strip() else None
    except yaml.YAMLError as exc:
        raise ValueError(f"override {text!r}: the value is not valid YAML ({exc})") from None
    except (ValueError, TypeError, OverflowError) as exc:   # an explicit tag that does not fit: !!float abc
        raise ValueError(f"override {text!r}: the value cannot be read ({exc})") from None
    return tokens, value


def _element_name(item) -> str | None:
    if not isinstance(item, dict):
        return None
    if isinstance(item.get("name"), str):
        return item["name"]
    if len(item) == 1:  # a generator part: {chain: {name: tail, ...}}
        inner = next(iter(item.values()))
        if isinstance(inner, dict) and isinstance(inner.get("name"), str):
            return inner["name"]
    return None


def apply_overrides(doc: Document, overrides) -> None:
    """Apply ``PATH=VALUE`` strings to ``doc.data`` in order; all bad overrides are reported."""
    issues: list[Issue] = []
    for text in overrides:
        try:
            tokens, value = parse_override(text)
        except ValueError as exc:
            issues.append(Issue("", str(exc)))
            continue
        if doc.data is None:
            doc.data = {}
        problem = _set(doc, tokens, value, text)
        if problem:
            issues.append(problem)
    if issues:
        raise ConfigError(doc.source, issues)


def _set(doc: Document, tokens: list, value, text: str) -> Issue | None:
    node = doc.data
    path: list = []
    for k, token in enumerate(tokens):
        last = k == len(tokens) - 1
        if isinstance(node, list):
            if isinstance(token, str) and token.lstrip("-").isdigit():
                token = int(token)
            selected_by_name = isinstance(token, str)
            if isinstance(token, str):
                names = [_element_name(item) for item in node]
                if token not in names:
                    known = ", ".join(repr(n) for n in names if n) or "none"
                    return Issue(format_path(path), f"--set {text}: no element named {token!r} in this list "
                                                    f"(names: {known})")
                token = names.index(token)
            if not -len(node) <= token < len(node):
                return Issue(format_path(path), f"--set {text}: index {token} is out of range "
                                                f"(the list has {len(node)} elements)")
            token %= len(node)
            item = node[token]
            nxt = tokens[k + 1] if not last else None
            if (selected_by_name and isinstance(item, dict) and "name" not in item and len(item) == 1
                    and nxt is not None and nxt not in item):
                # a generator part selected by its inner name: parts.skirt.strands means parts[i].skirt.strands
                kind = next(iter(item))
                path.extend([token, kind])
                node = item[kind]
                continue
        elif isinstance(node, dict):
            token = str(token)
            if not last and node.get(token) is None:
                node[token] = {}  # create missing mappings on the way
            elif not last and not isinstance(node[token], (dict, list)):
                return Issue(format_path(path + [token]), f"--set {text}: cannot descend into the "
                                                          f"{type(node[token]).__name__} value {node[token]!r}")
        else:
            return Issue(format_path(path), f"--set {text}: cannot descend into a {type(node).__name__} value")
        path.append(token)
        if last:
            node[token] = value
        else:
            node = node[token]
    doc.mark_overridden(tuple(path), text)
    return None
