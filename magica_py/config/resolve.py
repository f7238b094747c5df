"""Stage 4 of loading a scene: names resolved, rigs and instances expanded, references checked.

``resolve_document(checker, normalized, source)`` turns the schema's ``NormalizedScene`` into
a ``ResolvedScene`` of plain values with final names, recording every problem on the
checker:

* rigs expanded into bones (``scene.rigs`` generators and placement), duplicate names,
  unknown parents (did-you-mean) and parent cycles reported;
* static nodes created for colliders without a transform (``scene.colliders``);
* instanced rigs replicated together with every collider / animation entry / cloth that
  names their bones (see ``config.load``'s docstring for the rule);
* root-bone, collider and bone-attribute globs expanded (hierarchy order), components
  defaulted, bones claimed by two cloths reported;
* cloth parameters resolved with ``params.resolve_parameters`` one key at a time, so every
  bad key is reported; ``set_parameter`` events checked against their cloth.
"""
from __future__ import annotations

import fnmatch
import pathlib
from dataclasses import dataclass, field

from magica_py.config.checker import REQUIRED, Checker
from magica_py.config.errors import did_you_mean, format_path
from magica_py.config.schema import DRIVER_FIELDS, PART_FIELDS, NormalizedScene
from magica_py.scene.hierarchy import BoneSpec


# More bones than this is a mistake (a count with extra zeros), not a scene: the crowd
# showcase has 5,000; half a million already takes gigabytes to build and minutes per frame.
MAX_BONES = 500_000


def instance_name(name: str, i: int) -> str:
    from magica_py.scene.rigs import instance_name as rig_instance_name

    return rig_instance_name(name, i)


def static_node_name(collider: str) -> str:
    from magica_py.scene.colliders import static_transform_name

    return static_transform_name(collider)


# ----------------------------------------------------------------------------- names
@dataclass
class Ref:
    """A resolved name: one node (``rig is None``) or a bone of every instance of ``rig``."""

    name: str
    rig: int | None = None

    def in_instance(self, i: int | None) -> str:
        return self.name if self.rig is None or i is None else instance_name(self.name, i)


@dataclass
class NameTable:
    """Every transform of the scene, before (base) and after (final) instancing."""

    base_bones: list[BoneSpec] = field(default_factory=list)   # rigs before instancing + static nodes
    base_rig: dict[str, int | None] = field(default_factory=dict)  # base name -> instanced rig or None
    final: set[str] = field(default_factory=set)               # names of the hierarchy's nodes
    instance_counts: dict[int, int] = field(default_factory=dict)  # instanced rig -> count
    base_order: list[str] = field(default_factory=list)         # base names, hierarchy (DFS) order
    children: dict[str | None, list[str]] = field(default_factory=dict)
    definition: dict[str, tuple] = field(default_factory=dict)  # base name -> document path
    def resolve(self, name: str) -> Ref | None:
        if name in self.base_rig:
            return Ref(name, self.base_rig[name])
        if name in self.final:
            return Ref(name, None)
        return None

    def suggestions(self) -> list[str]:
        return list(self.base_rig) + [n for n in self.final if n not in self.base_rig][:2000]

    def match(self, pattern: str) -> list[str]:
        """Base names matching a glob, in hierarchy order (final names if it names an instance)."""
        if "#" in pattern:  # instance names: instance by instance, each in hierarchy order
            position = {n: k for k, n in enumerate(self.base_order)}
            found = []
            for n in self.final:
                if fnmatch.fnmatchcase(n, pattern):
                    base, _, index = n.rpartition("#")
                    found.append((int(index) if index.isdigit() else -1, position.get(base, -1), n))
            return [n for _, _, n in sorted(found)]
        return [n for n in self.base_order if fnmatch.fnmatchcase(n, pattern)]

    def subtree(self, name: str) -> list[str]:
        """Names of ``name``'s subtree (pre-order): base names, or instance names for a bone
        named with its instance (``skirt_0_0#2``)."""
        if name not in self.base_rig and "#" in name:
            base, _, index = name.rpartition("#")
            if base in self.base_rig and index.isdigit():
                return [instance_name(n, int(index)) for n in self.subtree(base)]
        out, stack, seen = [], [name], set()
        while stack:
            n = stack.pop()
            if n in seen:   # a duplicate bone name (reported) lists its children twice: 2^depth paths
                continue
            seen.add(n)
            out.append(n)
            stack.extend(reversed(self.children.get(n, [])))
        return out


@dataclass
class ResolvedScene:
    """Everything checked and expanded, still as plain values (no numba-backed objects)."""

    source: str | None
    settings: dict
    bones: list[BoneSpec]                      # final bones, instances expanded, static nodes added
    rigs: list[dict]                           # name, instances, roots (final names per instance), nodes
    colliders: list[dict]                      # colliders.ColliderSet.from_specs entries (final names)
    animation: list[dict]                      # animation entries in YAML shape (final names)
    cloths: list[dict]                         # name, root_bones, component, ... (final names)
    output: dict
    normalized: NormalizedScene | None = None
    wind: list[dict] = field(default_factory=list)   # wind zones (final transform names)


# ----------------------------------------------------------------------------- resolution
def resolve_document(c: Checker, n: NormalizedScene, source: str | None) -> ResolvedScene:
    settings = dict(n.settings)
    if settings.get("name") is None:
        settings["name"] = pathlib.Path(source).stem if source and not source.startswith("<") else "scene"
    table = NameTable()
    bones, rigs = _expand_rigs(c, n.rigs, table)
    static = _static_collider_nodes(c, n.colliders, table)
    bones.extend(static)
    _check_unique(c, bones, n)
    _check_cycles(c, table)
    table.base_order = _dfs_order(table)
    phases = _instance_phases(n.rigs, settings["seed"])
    colliders, collider_groups = _resolve_colliders(c, n.colliders, table)
    cloths = _resolve_cloths(c, n.cloths, table, colliders, collider_groups, settings)
    declared = {cl["name"] for cl in n.cloths if cl["name"] is not None}
    wind = _resolve_wind(c, n.wind, table)
    animation = _resolve_animation(c, n.animation, table, phases, cloths, declared,
                                   {z["name"] for z in n.wind if z["name"] is not None})
    return ResolvedScene(source, settings, bones, rigs, colliders, animation, cloths, n.output, n, wind)


def _expand_rigs(c: Checker, rigs: list[dict], table: NameTable):
    from magica_py.scene import rigs as rig_module

    final_bones: list[BoneSpec] = []
    rig_infos = []
    for r, rig in enumerate(rigs):
        path = rig["path"]
        base: list[BoneSpec] = []
        where: dict[str, tuple] = {}
        for b in rig["bones"]:
            if b["name"] is None:
                continue
            base.append(BoneSpec(b["name"], b["parent"], b["position"], b["rotation"], b["scale"]))
            where[b["name"]] = b["path"]
        for part in rig["parts"]:
            required = [k for k, f in PART_FIELDS[part["kind"]].items() if f.default is REQUIRED]
            if any(part["params"][k] is None for k in required):
                continue  # already reported by the schema
            params = {k: v for k, v in part["params"].items() if v is not None}
            planned = len(final_bones) + len(base) + int(params.get("strands", 1)) * int(params["bones"])
            if planned > MAX_BONES:  # refused before a single bone is generated
                c.error(part["path"], f"this {part['kind']} would bring the scene to {planned:,} bones; a scene "
                                      f"is limited to {MAX_BONES:,} bones")
                continue
            try:
                generated = rig_module.part_bones({part["kind"]: params})
            except (ValueError, TypeError) as exc:
                c.error(part["path"], f"cannot generate the {part['kind']}: {exc}")
                continue
            for g in generated:
                where.setdefault(g.name, part["path"])
            base.extend(generated)
        own = {b.name for b in base}
        for b in base:  # parents: this rig's bones, or (non-instanced rig) any earlier bone
            if b.parent is not None and b.parent not in own:
                p = where[b.name]
                key = "parent"
                if b.parent in table.base_rig or b.parent in table.final:
                    if rig["instances"] is None or table.base_rig.get(b.parent) is None:
                        continue
                    c.error(p + (key,), f"bone {b.name!r}: parent {b.parent!r} belongs to an instanced rig; "
                                        "a rig can only hang under bones of itself or of a non-instanced rig")
                    continue
                c.error(p + (key,), f"unknown parent {b.parent!r} of {b.name!r}"
                                    f"{did_you_mean(b.parent, list(own) + list(table.base_rig))}")
        for name, p in where.items():
            table.definition.setdefault(name, p)
        rig_module.place_roots(base, rig["position"], rig["rotation"])
        inst = rig["instances"]
        count = inst["count"] if inst else 1
        if inst and len(final_bones) + len(base) * count > MAX_BONES:
            c.error(path + ("instances", "count"), f"{count:,} instances of {len(base):,} bones would make "
                                                   f"{len(final_bones) + len(base) * count:,} bones; a scene is "
                                                   f"limited to {MAX_BONES:,} bones")
            inst, count = None, 1  # keep checking the rest of the scene on one copy
            rig["instances"] = None  # (the phase table below must not build a row per instance)
        for b in base:
            table.base_bones.append(b)
            table.base_rig.setdefault(b.name, r if inst else None)
            table.children.setdefault(b.parent, []).append(b.name)
        if inst:
            table.instance_counts[r] = count
            try:
                final = rig_module.instance_rig(base, count, inst["spacing"], inst["columns"] or None,
                                                inst["row_spacing"])
            except ValueError as exc:
                c.error(path + ("instances",), str(exc))
                final = []
        else:
            final = list(base)
        table.final.update(b.name for b in final)
        roots = [b.name for b in base if b.parent not in own]
        rig_infos.append({"name": rig["name"], "instances": count, "nodes_per_instance": len(base),
                          "roots": [[instance_name(n, i) if inst else n for n in roots] for i in range(count)]})
        final_bones.extend(final)
    return final_bones, rig_infos


def _static_collider_nodes(c: Checker, colliders: list[dict], table: NameTable) -> list[BoneSpec]:
    out = []
    for col in colliders:
        if col["transform"] is None and col["name"] is not None:
            pose = col["static_pose"]
            b = BoneSpec(static_node_name(col["name"]), None, pose["position"], pose["rotation"],
                         tags={"collider": col["name"]})
            out.append(b)
            table.final.add(b.name)
            table.base_rig.setdefault(b.name, None)
            table.base_bones.append(b)
            table.children.setdefault(None, []).append(b.name)
    return out


def _check_unique(c: Checker, bones: list[BoneSpec], n: NormalizedScene) -> None:
    first: dict[str, int] = {}
    paths = _bone_definition_paths(n)
    parts = [(part["params"]["name"], part["path"] + ("name",)) for rig in n.rigs for part in rig["parts"]
             if isinstance(part["params"].get("name"), str)]
    for b in bones:
        if b.name in first:
            where = _definition_path(b.name, paths, parts)
            c.error(where, f"duplicate transform name {b.name!r}: every bone, generated bone and "
                           "static collider node needs a unique name")
        first.setdefault(b.name, 1)
    names: dict[str, tuple] = {}
    for key, items in (("cloths", n.cloths), ("colliders", n.colliders), ("rigs", n.rigs)):
        names.clear()
        for item in items:
            if item["name"] is None:
                continue
            if item["name"] in names:
                c.error(item["path"] + ("name",), f"duplicate {key[:-1]} name {item['name']!r} "
                                                  f"(also {format_path(names[item['name']])})")
            names.setdefault(item["name"], item["path"])


def _definition_path(name: str, paths: dict, parts: list) -> tuple:
    """Where the bone ``name`` is defined: an explicit bone's or static collider's ``name``, or
    the ``name`` of the generator part that made it (``tail_3`` -> the chain ``tail``, the
    later part when two make the same names); an instance's copy (``hips#2``) is its rig's bone."""
    base = name.split("#", 1)[0]
    if base in paths:
        return paths[base]
    for part_name, path in reversed(parts):
        if base.startswith(part_name + "_"):
            return path
    return ()


def _bone_definition_paths(n: NormalizedScene) -> dict[str, tuple]:
    out: dict[str, tuple] = {}
    for rig in n.rigs:
        for b in rig["bones"]:
            if b["name"] in out:
                out[b["name"]] = b["path"] + ("name",)  # the second definition is the duplicate
            out.setdefault(b["name"], b["path"] + ("name",))
        for part in rig["parts"]:
            out.setdefault(part["params"]["name"], part["path"] + ("name",))
    for col in n.colliders:
        out.setdefault(static_node_name(col["name"] or ""), col["path"] + ("name",))
    return out


def _check_cycles(c: Checker, table: NameTable) -> None:
    """Bones whose parent chain never reaches a root (explicit bones only can do this)."""
    parent = {b.name: b.parent for b in table.base_bones}
    state: dict[str, int] = {}  # 1 = on the current walk, 2 = reaches a root
    for start in parent:
        walk = []
        node = start
        while node is not None and node in parent and state.get(node) is None:
            state[node] = 1
            walk.append(node)
            node = parent[node]
        if node is not None and state.get(node) == 1:  # closed a loop in this walk
            loop = walk[walk.index(node):]
            c.error(table.definition.get(loop[0], ("rigs",)) + ("parent",),
                    f"bone parents form a cycle: {' -> '.join(loop + [node])}")
        for w in walk:
            state[w] = 2


def _dfs_order(table: NameTable) -> list[str]:
    out, seen = [], set()
    parents = {b.name: b.parent for b in table.base_bones}
    roots = [b.name for b in table.base_bones if b.parent is None or b.parent not in parents]
    stack = list(reversed(roots))
    while stack:
        name = stack.pop()
        if name in seen:
            continue
        seen.add(name)
        out.append(name)
        stack.extend(reversed(table.children.get(name, [])))
    return out


def _instance_phases(rigs: list[dict], seed: int) -> dict[int, list[float]]:
    """Animation time offset (s) of each instance of each instanced rig
    (``animation.instance_phase_offset``: index x phase_offset + seeded jitter)."""
    from magica_py.scene.animation import instance_phase_offset

    out = {}
    for r, rig in enumerate(rigs):
        inst = rig["instances"]
        if inst:
            out[r] = [instance_phase_offset(i, inst["phase_offset"], inst["phase_jitter"], seed + r)
                      for i in range(inst["count"])]
    return out


def _ref(c: Checker, table: NameTable, name: str | None, path: tuple, what: str = "transform") -> Ref | None:
    if name is None:
        return None
    ref = table.resolve(name)
    if ref is None:
        c.error(path, f"unknown {what} {name!r}{did_you_mean(name, table.suggestions())}")
    return ref


def _instancing(c: Checker, refs: list[Ref | None], path: tuple, table: NameTable) -> int | None:
    rigs = sorted({r.rig for r in refs if r is not None and r.rig is not None})
    if len(rigs) > 1:
        c.error(path, f"names bones of {len(rigs)} different instanced rigs; an entry may name bones of "
                      "at most one instanced rig (or name instances explicitly, e.g. hips#3)")
    return rigs[0] if rigs else None


def _instances(rig: int | None, table: NameTable) -> list[int | None]:
    return [None] if rig is None else list(range(table.instance_counts[rig]))


def _suffix(name: str, i: int | None) -> str:
    return name if i is None else instance_name(name, i)


# ----------------------------------------------------------------------------- colliders
def _resolve_colliders(c: Checker, colliders: list[dict], table: NameTable):
    out: list[dict] = []
    groups: dict[str, list[tuple[int | None, int]]] = {}  # base name -> [(instance, index in out)]
    for col in colliders:
        path = col["path"]
        ref = _ref(c, table, col["transform"], path + ("transform",)) if col["transform"] else None
        rig = ref.rig if ref is not None else None
        for i in _instances(rig, table):
            name = _suffix(col["name"], i)
            entry = {"name": name, "center": col["center"], col["shape"]: dict(col["params"])}
            entry["transform"] = ref.in_instance(i) if ref is not None else static_node_name(col["name"])
            groups.setdefault(col["name"], []).append((i, len(out)))
            out.append(entry)
    return out, groups


# ----------------------------------------------------------------------------- cloths
def _resolve_cloths(c: Checker, cloths: list[dict], table: NameTable, colliders: list[dict],
                    collider_groups: dict, settings: dict) -> list[dict]:
    out = []
    owner_of_bone: dict[str, str] = {}
    for k, cloth in enumerate(cloths):
        path = cloth["path"]
        roots: list[str] = []
        refs: list[Ref] = []
        for j, pattern in enumerate(cloth["root_bones"]):
            matches = table.match(pattern)
            if not matches:
                hint = did_you_mean(pattern, table.base_order) if not any(ch in pattern for ch in "*?[") else ""
                c.error(path + ("root_bones", j), f"no bone matches {pattern!r}{hint}")
            for m in matches:
                if m not in roots:
                    roots.append(m)
                    refs.append(table.resolve(m))
        component = _ref(c, table, cloth["component"], path + ("component",))
        rig = _instancing(c, refs + [component], path + ("root_bones",), table)
        attributes = _resolve_bone_attributes(c, cloth, roots, table)
        collider_names = _match_colliders(c, cloth, collider_groups)
        parameters = _resolve_parameters(c, cloth, settings, table)
        if not roots or parameters is None:
            continue
        _check_overlap(c, cloth, roots, table, owner_of_bone)
        parent_of = {b.name: b.parent for b in table.base_bones}
        for i in _instances(rig, table):
            def inst(name):
                ref = table.resolve(name)
                return ref.in_instance(i) if ref is not None else name

            root_names = [inst(r) for r in roots]
            if component is not None:
                component_name = component.in_instance(i)
            else:
                component_name = _default_component(roots[0], root_names[0], parent_of, inst)
            indices = []
            for base_name in collider_names:
                for inst_i, index in collider_groups[base_name]:
                    # an instance's cloth uses its own copy of a replicated collider; a cloth
                    # outside the instanced rig collides with every copy
                    if inst_i is None or i is None or inst_i == i:
                        indices.append(index)
            params = parameters
            changes = {key: inst(params[key]) for key in ("inertia.anchor", "culling.distance_culling_reference")
                       if params.get(key) is not None}
            if changes and i is not None:
                params = params.with_changes(changes, format_path(path + ("parameters",)))
            out.append({"name": _suffix(cloth["name"], i), "root_bones": root_names, "component": component_name,
                        "connection_mode": cloth["connection"], "parameters": params,
                        "colliders": indices, "collision_mode": params["collider_collision.mode"],
                        "bone_attributes": {inst(b): a for b, a in attributes.items()},
                        "instance": i, "preset": cloth["preset"], "base_name": cloth["name"],
                        "document_path": format_path(path)})
    return out


def _default_component(root: str, root_name: str, parent_of: dict, inst) -> str:
    """The first root's parent (the root itself when it has none); ``hips#3`` for a root
    named with its instance (``tail_0#3``)."""
    if root in parent_of:
        parent = parent_of[root]
        return inst(parent) if parent is not None else root_name
    base, _, index = root.rpartition("#")
    parent = parent_of.get(base)
    if parent is None or not index.isdigit():
        return root_name
    return instance_name(parent, int(index))


def _resolve_bone_attributes(c: Checker, cloth: dict, roots: list[str], table: NameTable) -> dict[str, str]:
    simulated = []
    for r in roots:
        simulated.extend(table.subtree(r))
    out = {}
    for pattern, attribute in cloth["bone_attributes"].items():
        if attribute is None:
            continue
        matches = [n for n in simulated if fnmatch.fnmatchcase(n, pattern)]
        if not matches:
            c.error(cloth["path"] + ("bone_attributes", pattern),
                    f"no bone of this cloth matches {pattern!r}{did_you_mean(pattern, simulated)}")
        for m in matches:
            out[m] = attribute
    return out


def _match_colliders(c: Checker, cloth: dict, groups: dict) -> list[str]:
    names: list[str] = []
    for j, pattern in enumerate(cloth["colliders"]):
        matches = [n for n in groups if fnmatch.fnmatchcase(n, pattern)]
        if not matches:
            c.error(cloth["path"] + ("colliders", j), f"unknown collider {pattern!r}{did_you_mean(pattern, groups)}")
        names.extend(m for m in matches if m not in names)
    return names


def _check_overlap(c: Checker, cloth: dict, roots: list[str], table: NameTable, owner: dict) -> None:
    """A bone simulated by two cloths would be written twice per frame."""
    reported = set()
    for r in roots:
        for name in table.subtree(r):
            other = owner.get(name)
            if other is not None and other != cloth["name"] and other not in reported:
                c.error(cloth["path"] + ("root_bones",), f"bone {name!r} is already simulated by cloth {other!r}; "
                                                         "two cloths cannot move the same bones")
                reported.add(other)
            owner.setdefault(name, cloth["name"])


def _parse_param_path(text: str) -> tuple:
    from magica_py.config.overrides import parse_override

    try:
        tokens, _ = parse_override(text + "=0")
        return tuple(tokens)
    except ValueError:
        return ()


def _param_error(c: Checker, exc, fallback: tuple) -> None:
    path = _parse_param_path(exc.path) or fallback
    c.error(path, exc.message)


def _resolve_parameters(c: Checker, cloth: dict, settings: dict, table: NameTable):
    """``params.resolve_parameters`` with every bad key reported (one call per key)."""
    from magica_py import params as P

    path = cloth["path"]
    where = format_path(path + ("parameters",))
    try:
        base = P.resolve_parameters(cloth["preset"], {"update_mode": settings["update_mode"]}, where,
                                    preset_where=format_path(path + ("preset",)),
                                    gravity_direction=settings["gravity"])
    except P.ParameterError as exc:
        _param_error(c, exc, path + ("preset",))
        base = P.resolve_parameters(None, {"update_mode": settings["update_mode"]}, where,
                                    gravity_direction=settings["gravity"])
    changes: dict = {}
    ok = True

    def visit(node: dict, prefix: str, doc_path: tuple):
        nonlocal ok
        for name, value in node.items():
            key = prefix + str(name)
            sub = doc_path + (name,)
            is_group = any(k.startswith(key + ".") for k in P.PARAMETERS)
            if key not in P.PARAMETERS and isinstance(value, dict) and is_group:
                visit(value, key + ".", sub)
                continue
            try:
                flat = P.flatten_overrides({key: value}, where)
                base.with_changes(flat, where)
                changes.update(flat)
            except P.ParameterError as exc:
                ok = False
                _param_error(c, exc, sub)

    visit(cloth["parameters"], "", path + ("parameters",))
    mode = cloth["collision_mode"]
    if mode is not None:
        given = changes.get("collider_collision.mode")
        if given is not None and str(given).lower() != mode:
            c.error(path + ("collision_mode",), f"collision_mode {mode!r} contradicts "
                                                f"parameters.collider_collision.mode {given!r}")
            ok = False
        changes["collider_collision.mode"] = mode
    for key in ("inertia.anchor", "culling.distance_culling_reference"):
        name = changes.get(key)
        if isinstance(name, str) and table.resolve(name) is None:
            c.error(path + ("parameters",) + tuple(key.split(".")),
                    f"unknown transform {name!r}{did_you_mean(name, table.suggestions())}")
            ok = False
    if not ok:
        return None
    return base.with_changes(changes, where)


# ----------------------------------------------------------------------------- wind
def _resolve_wind(c: Checker, zones: list[dict], table: NameTable) -> list[dict]:
    """Wind zones with their transform resolved (a bone of an instanced rig: its first
    instance, or name one with ``bone#i``); zone names unique."""
    out, seen = [], set()
    for z in zones:
        if z["name"] in seen:
            c.error(z["path"] + ("name",), f"duplicate wind zone name {z['name']!r}")
            continue
        seen.add(z["name"])
        transform = None
        if z["transform"] is not None:
            ref = _ref(c, table, z["transform"], z["path"] + ("transform",))
            if ref is None:
                continue
            transform = ref.in_instance(0 if ref.rig is not None else None)
        out.append(dict(z, transform=transform))
    return out


# ----------------------------------------------------------------------------- animation
def _resolve_animation(c: Checker, entries: list[dict], table: NameTable, phases: dict,
                       cloths: list[dict], declared: set[str], wind_zones: set[str] = frozenset()) -> list[dict]:
    cloth_by_base: dict[str, list[dict]] = {}
    for cl in cloths:  # by YAML name (every instance) and by instance name (skirt#3)
        cloth_by_base.setdefault(cl["base_name"], []).append(cl)
        if cl["instance"] is not None:
            cloth_by_base[cl["name"]] = [cl]
    out = []
    for e in entries:
        path, kind, params = e["path"], e["kind"], e["params"]
        if kind in DRIVER_FIELDS:
            ref = _ref(c, table, e["target"], path + ("target",))
            if ref is None:
                continue
            for i in _instances(ref.rig, table):
                offset = e["phase_offset"] + (float(phases[ref.rig][i]) if i is not None else 0.0)
                out.append({"target": ref.in_instance(i), kind: _driver_params(kind, params),
                            "start": e["start"], "end": e["end"], "phase_offset": offset, "fade": e["fade"]})
        elif kind == "teleport":
            ref = _ref(c, table, params["target"], path + ("teleport", "target"))
            if ref is None:
                continue
            for i in _instances(ref.rig, table):
                body = {"target": ref.in_instance(i)}
                if params["position"] is not None:
                    body["position"] = list(params["position"])
                if params["rotation"] is not None:
                    body["rotation"] = list(params["rotation"])
                out.append({"at": e["at"], "teleport": body})
        elif kind == "time_scale":
            out.append({"at": e["at"], "time_scale": params["value"]})
        elif kind == "wind":
            if params["zone"] not in wind_zones:
                c.error(path + ("wind", "zone"),
                        f"unknown wind zone {params['zone']!r}{did_you_mean(params['zone'], sorted(wind_zones))}")
                continue
            out.append({"at": e["at"], "wind": {k: params[k] for k in ("zone", "enabled", "main")}})
        else:  # set_parameter
            targets = cloth_by_base.get(params["cloth"])
            if targets is None and params["cloth"] in declared:
                continue  # the cloth itself is invalid and already reported
            if targets is None:
                known = sorted(declared)
                c.error(path + ("set_parameter", "cloth"),
                        f"unknown cloth {params['cloth']!r}{did_you_mean(params['cloth'], known)}")
                continue
            if not _check_parameter_change(c, params, targets[0], path):
                continue
            for cl in targets:
                out.append({"at": e["at"], "set_parameter": {"cloth": cl["name"], "key": params["key"],
                                                             "value": params["value"]}})
    return out


def _driver_params(kind: str, params: dict) -> dict:
    body = {k: (list(v) if isinstance(v, tuple) else v) for k, v in params.items() if kind != "keyframes" or k != "keys"}
    if kind == "keyframes":
        body["keys"] = [{k: (list(v) if isinstance(v, tuple) else v) for k, v in key.items() if v is not None}
                        for key in params["keys"]]
    return {k: v for k, v in body.items() if v is not None}


def _check_parameter_change(c: Checker, params: dict, cloth: dict, path: tuple) -> bool:
    from magica_py import params as P

    key = params["key"]
    if key is None:
        return False
    try:
        cloth["parameters"].with_changes({key: params["value"]}, "set_parameter")
    except P.ParameterError as exc:
        unknown = exc.message.startswith("unknown parameter")
        c.error(path + ("set_parameter", "key" if unknown else "value"), exc.message)
        return False
    return True
