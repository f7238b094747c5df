"""Scene files: YAML format v1 -> validated ``Scene`` (see docs/scene-format.md).

``load_scene(path, overrides=())`` is the entry point; every problem of a file is reported at
once in a ``ConfigError`` (file, line, document path, what was expected).
"""
from __future__ import annotations

from magica_py.config.errors import ConfigError, Issue

__all__ = ["ConfigError", "Issue", "load_scene", "load_scene_text", "validate_file"]


def load_scene(path, overrides=()):
    """Read, validate and build a scene file (``overrides``: ``--set`` strings)."""
    from magica_py.config.load import load_scene as _load

    return _load(path, overrides)


def load_scene_text(text: str, overrides=(), source: str = "<text>"):
    from magica_py.config.load import load_scene_text as _load

    return _load(text, overrides, source)


def validate_file(path, overrides=()):
    """Check a scene file completely without building it; returns the ResolvedScene."""
    from magica_py.config.load import validate_file as _validate

    return _validate(path, overrides)
