"""``magica-py new NAME [--template ponytail|tail|skirt|crowd]``: a commented starter scene.

The templates live in ``magica_py/templates/<template>.yaml`` (package data). ``{name}`` in a
template becomes the scene name (the file name without ``.yaml``) and ``{file}`` the file
written, so the header's commands and ``output.rrd`` fit the new file. Each template runs as
it is (tests/test_starter.py runs all of them).
"""
from __future__ import annotations

import argparse
import pathlib
import re
import sys

from magica_py import atomic

TEMPLATES = {
    "ponytail": "a ponytail on a head that nods and turns, with a skull collider",
    "tail": "a tail on a creature running in a circle",
    "skirt": "a skirt on walking hips, colliding with the thighs",
    "crowd": "25 instanced characters with ponytails, each on its own clock",
}
DEFAULT_TEMPLATE = "ponytail"
_NAME = re.compile(r"^[A-Za-z0-9_][A-Za-z0-9_.-]*$")


def template_text(template: str) -> str:
    """The raw text of a template (``{name}`` / ``{file}`` not yet filled in)."""
    if template not in TEMPLATES:
        raise ValueError(f"unknown template {template!r}; expected one of: {', '.join(TEMPLATES)}")
    return (pathlib.Path(__file__).parent / "templates" / f"{template}.yaml").read_text(encoding="utf-8")


def starter_text(template: str, name: str, file: str) -> str:
    """The template filled in for scene ``name`` written to ``file``."""
    return template_text(template).replace("{name}", name).replace("{file}", file)


def target_path(name: str) -> pathlib.Path:
    """``NAME`` -> ``NAME.yaml``; ``path/to/NAME.yaml`` stays as given."""
    path = pathlib.Path(name)
    return path if path.suffix.lower() in (".yaml", ".yml") else path.with_name(path.name + ".yaml")


def write_starter(name: str, template: str = DEFAULT_TEMPLATE, force: bool = False) -> pathlib.Path:
    """Write the starter scene; returns its path. ValueError for a bad name, an unknown
    template or an existing file (unless ``force``)."""
    path = target_path(name)
    stem = path.stem
    if not _NAME.match(stem):
        raise ValueError(f"{name!r}: a scene name is letters, digits, '_', '-' and '.', starting with a letter, "
                         "digit or '_' (it names the recording file too)")
    text = starter_text(template, stem, path.as_posix())
    if path.exists() and not force:
        raise ValueError(f"{path} already exists; choose another name or add --force to replace it")
    if path.is_dir():
        raise ValueError(f"{path} is a folder")
    path.parent.mkdir(parents=True, exist_ok=True)
    atomic.write_text(path, text)
    return path


def main_new(argv=None) -> int:
    parser = argparse.ArgumentParser(
        prog="magica-py new", description="Write a commented starter scene that runs as it is.",
        epilog="templates:\n" + "\n".join(f"  {k:<9} {v}" for k, v in TEMPLATES.items()),
        formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("name", metavar="NAME", help="scene name; writes NAME.yaml (or the .yaml path given)")
    parser.add_argument("--template", "-t", choices=list(TEMPLATES), default=DEFAULT_TEMPLATE,
                        help=f"what the scene shows (default: {DEFAULT_TEMPLATE})")
    parser.add_argument("--force", action="store_true", help="replace an existing file")
    try:
        args = parser.parse_args(argv)
    except SystemExit as exc:
        return int(exc.code or 0)
    try:
        path = write_starter(args.name, args.template, args.force)
    except (ValueError, OSError) as exc:
        print(f"magica-py new: error: {exc}", file=sys.stderr)
        return 2
    print(f"wrote {path} ({args.template}: {TEMPLATES[args.template]})\n"
          f"  run it:             magica-py run {path}\n"
          f"  tune it live:       magica-py watch {path}   (re-runs on every save)")
    return 0
