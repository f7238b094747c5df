"""YAML scene file -> validated ``Scene``.

Pipeline (every stage collects all its problems; the first stage with problems stops the
load with one ``ConfigError`` listing them):

1. ``document.read_document``: YAML -> plain values + line of every value;
2. ``overrides.apply_overrides``: ``--set PATH=VALUE`` (so overrides are validated too);
3. ``schema.check_document``: structure, types, ranges, exactly-one-of groups, defaults;
4. ``resolve_document`` (this module): rigs expanded into bones (``scene.rigs``), names
   checked (duplicates, unknown parents with a did-you-mean, cycles), instanced rigs
   replicated together with every collider / animation entry / cloth that names their
   bones, root-bone and collider globs expanded, cloth parameters resolved
   (``params.resolve_parameters``), parameter events checked against their cloth;
5. ``build_scene``: ``TransformHierarchy``, ``ColliderSet``, ``Animation``, ``ClothSpec``s.

Public entry points: ``load_scene(path, overrides=())``, ``load_scene_text(text, ...)``,
``validate_file(path, overrides=())`` (stages 1-4, returns the ``ResolvedScene``).

Instancing rule: a name that is a bone of an instanced rig (``hips`` of a rig with
``instances: {count: 100}``) means "this bone in every instance"; an entry naming such bones
is replicated once per instance with names ``hips#<i>`` and its own name suffixed the same
way (cloth ``skirt`` -> ``skirt#0`` .. ``skirt#99``). A name written with its instance
(``hips#3``) means only that bone and is not replicated. An entry may name bones of at most
one instanced rig.
"""
from __future__ import annotations

import pathlib

from magica_py.config.checker import Checker
from magica_py.config.document import Document, parse_text, read_document
from magica_py.config.errors import ConfigError, Issue
from magica_py.config.overrides import apply_overrides
from magica_py.config.resolve import ResolvedScene, resolve_document
from magica_py.config.schema import check_document
from magica_py.jit import stage_policy

__all__ = ["load_scene", "load_scene_text", "validate_file", "validate_document", "load_document", "build_scene",
           "ResolvedScene"]


# ----------------------------------------------------------------------------- entry points
def load_document(path, overrides=()) -> Document:
    doc = read_document(path)
    if overrides:
        apply_overrides(doc, overrides)
    return doc


def validate_document(doc: Document) -> ResolvedScene:
    c = Checker(doc)
    normalized = check_document(c, doc.data)
    structural = len(c.issues)
    try:  # cross references are checked even after structural errors: report everything at once
        resolved = resolve_document(c, normalized, doc.source)
    except Exception:
        if not structural:
            raise
        del c.issues[structural:]  # the partial data confused resolution: keep the primary errors
    c.raise_if_any()
    return resolved


def validate_file(path, overrides=()) -> ResolvedScene:
    """Stages 1-4: a ``ResolvedScene`` or a ConfigError listing every problem."""
    return validate_document(load_document(path, overrides))


def load_scene(path, overrides=()):
    """Read, validate and build the scene file at ``path`` (``--set`` strings in ``overrides``)."""
    doc = load_document(path, overrides)
    resolved = validate_document(doc)
    return build_scene(resolved, pathlib.Path(path), doc.effective_text(), overrides)


def load_scene_text(text: str, overrides=(), source: str = "<text>"):
    """Like ``load_scene`` for YAML text (tests, notebooks)."""
    doc = parse_text(text, source)
    if overrides:
        apply_overrides(doc, overrides)
    return build_scene(validate_document(doc), None, doc.effective_text(), overrides)


# ----------------------------------------------------------------------------- build
def build_scene(resolved: ResolvedScene, source: pathlib.Path | None, text: str | None = None, overrides=()):
    """Construct the runtime objects of a resolved scene (``overrides``: the ``--set`` strings
    it was loaded with, kept on the scene for recordings and ``resim``)."""
    from magica_py.scene.colliders import ColliderSet
    from magica_py.scene.hierarchy import HierarchyError, TransformHierarchy
    from magica_py.scene.scene import ClothSpec, FrozenMapping, OutputSpec, RigInfo, Scene, SceneSettings

    src = resolved.source
    try:
        hierarchy = TransformHierarchy(resolved.bones)
    except HierarchyError as exc:  # the checks above should have caught it: report, don't crash
        raise ConfigError(src, [_issue("rigs", str(exc))]) from None
    colliders = ColliderSet.from_specs(resolved.colliders, hierarchy)
    animation = _build_animation(resolved, hierarchy, src)
    settings = SceneSettings(**resolved.settings)
    cloths = [ClothSpec(name=cl["name"], root_bones=tuple(hierarchy.index(n) for n in cl["root_bones"]),
                        component=hierarchy.index(cl["component"]), connection_mode=cl["connection_mode"],
                        parameters=cl["parameters"], colliders=tuple(cl["colliders"]),
                        collision_mode=cl["collision_mode"],
                        bone_attributes=FrozenMapping({hierarchy.index(b): a for b, a in cl["bone_attributes"].items()}),
                        instance=cl["instance"], preset=cl["preset"], document_path=cl["document_path"])
              for cl in resolved.cloths]
    out = resolved.output
    output = OutputSpec(rrd=pathlib.Path(out["rrd"]) if out["rrd"] else None, log=FrozenMapping(dict(out["log"])))
    rigs = [RigInfo(r["name"], tuple(hierarchy.index(roots[0]) for roots in r["roots"] if roots),
                    r["nodes_per_instance"], r["instances"]) for r in resolved.rigs]
    from magica_py.wind.zones import WindZoneSpec

    wind = tuple(WindZoneSpec.from_resolved(z, hierarchy) for z in resolved.wind)
    return Scene(name=settings.name, source=source, settings=settings, hierarchy=hierarchy,
                 colliders=colliders, animation=animation, cloths=cloths, output=output, rigs=rigs,
                 collider_names=list(colliders.names), source_text=text,
                 overrides=tuple(str(o) for o in overrides), wind=wind)


def _issue(path: str, message: str) -> Issue:
    return Issue(path, message)


def _build_animation(resolved: ResolvedScene, hierarchy, source):
    """``scene.animation.Animation`` from the resolved entries (None when the module is absent
    and the scene has no animation)."""
    try:
        from magica_py.scene import animation as animation_module
    except ImportError:
        if resolved.animation:
            raise ConfigError(source, [_issue("animation", "this installation has no animation module "
                                                           "(magica_py.scene.animation)")]) from None
        return None
    stage_policy()   # a bad MAGICA_STAGES is the environment's error, not the document's: raised as is
    try:
        return animation_module.Animation.from_specs(resolved.animation, hierarchy)
    except ValueError as exc:
        raise ConfigError(source, [_issue("animation", str(exc))]) from None
