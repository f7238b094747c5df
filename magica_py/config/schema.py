"""Scene format v1: the structure of every section, checked and normalized.

``check_document(checker, data)`` returns a ``NormalizedScene`` of plain values (dicts with
every default filled in, quaternions normalized, Euler angles converted, enum values lower
case) and records every structural problem on the checker. Names are not resolved here:
``load.py`` expands rigs, instances and globs and checks the cross references.

The field tables (``PART_FIELDS``, ``DRIVER_FIELDS``, ``SHAPE_FIELDS``, ...) are the single
description of each mapping: the validation reads them and ``docs/scene-format.md`` lists
them; ``tests/test_config_schema.py`` checks that every table key is documented.
"""
from __future__ import annotations

from dataclasses import dataclass, field

from magica_py.config.checker import ANY, NON_NEGATIVE, POSITIVE, REQUIRED, Checker, Range, euler_to_quaternion

FORMAT_VERSION = 1
TOP_LEVEL_KEYS = ("version", "scene", "rigs", "animation", "colliders", "cloths", "wind", "output")
UPDATE_MODES = ("normal", "unity_physics", "unscaled")
TIMING_MODES = ("exact", "faithful", "faithful32")  # runtime.team_time
CONNECTION_MODES = ("line", "automatic_mesh", "sequential_loop_mesh", "sequential_non_loop_mesh")
COLLISION_MODES = ("none", "point", "edge")
BONE_ATTRIBUTES = ("fixed", "move", "invalid")
CLOTH_TYPES = ("bone_cloth",)
AXES = ("x", "y", "z")


@dataclass(frozen=True)
class Field:
    """One key of a mapping: kind (number, int, bool, text, choice, vec3, dir3, name), default
    (REQUIRED if it must be given), numeric range, enum choices and a one-line doc."""

    kind: str
    default: object = REQUIRED
    rng: Range = ANY
    choices: tuple = ()
    doc: str = ""


def F(kind, default=REQUIRED, rng=ANY, choices=(), doc=""):
    return Field(kind, default, rng, tuple(choices), doc)


DEGREES_360 = Range(-360.0, 360.0)
COUNT = Range(1)

# -- rigs --------------------------------------------------------------------------------
# Keys and defaults follow the generators of magica_py.scene.rigs (chain, fan, skirt, sheet).
_STRAND_COMMON = {
    "curl": F("number", 0.0, DEGREES_360, doc="bend per bone about the bone's +X (degrees)"),
    "position": F("vec3", (0.0, 0.0, 0.0), doc="root position in the parent's space (m)"),
}
PART_FIELDS: dict[str, dict[str, Field]] = {
    "chain": {
        "name": F("name", doc="bones are named <name>_0 .. <name>_<bones-1>"),
        "parent": F("name", doc="bone the chain hangs from"),
        "bones": F("int", REQUIRED, COUNT, doc="number of bones"),
        "length": F("number", REQUIRED, POSITIVE, doc="total length, first bone to last (m)"),
        "direction": F("dir3", (0.0, -1.0, 0.0), doc="direction of the first segment in the parent's space"),
        **_STRAND_COMMON,
        "curl_axis": F("dir3", None, doc="curl axis in the parent's space (default: the bone's +X)"),
    },
    "fan": {
        "name": F("name", doc="strand s, bone b is named <name>_<s>_<b>"),
        "parent": F("name", doc="bone the strands hang from (e.g. the head)"),
        "strands": F("int", REQUIRED, COUNT, doc="number of strands"),
        "bones": F("int", REQUIRED, COUNT, doc="bones per strand"),
        "length": F("number", REQUIRED, POSITIVE, doc="strand length (m)"),
        "spread": F("number", 120.0, Range(0.0, 360.0), doc="angle covered by the strand roots about the axis (degrees)"),
        "tilt": F("number", 30.0, Range(-90.0, 90.0), doc="outward tilt of each strand from the axis (degrees)"),
        "radius": F("number", 0.08, NON_NEGATIVE, doc="radius of the root arc (m)"),
        "axis": F("dir3", (0.0, -1.0, 0.0), doc="direction the strands hang along (parent space)"),
        "facing": F("dir3", (0.0, 0.0, -1.0), doc="azimuth 0 of the fan (parent space; default the back of the head)"),
        **_STRAND_COMMON,
    },
    "skirt": {
        "name": F("name", doc="strand s, bone b is named <name>_<s>_<b>"),
        "parent": F("name", doc="bone the skirt hangs from (usually the hips)"),
        "strands": F("int", 12, COUNT, doc="strands evenly around the ring"),
        "bones": F("int", 4, COUNT, doc="bones per strand"),
        "radius": F("number", 0.15, POSITIVE, doc="ring radius (m)"),
        "length": F("number", 0.4, POSITIVE, doc="strand length (m)"),
        "flare": F("number", 20.0, Range(-90.0, 90.0), doc="outward angle of each strand from the axis (degrees)"),
        "axis": F("dir3", (0.0, -1.0, 0.0), doc="direction the strands hang along (parent space)"),
        "facing": F("dir3", (0.0, 0.0, 1.0), doc="azimuth of strand 0 (parent space; default the front)"),
        **_STRAND_COMMON,
    },
    "sheet": {
        "name": F("name", doc="strand s, bone b is named <name>_<s>_<b>"),
        "parent": F("name", doc="bone the sheet hangs from (e.g. the chest for a cape)"),
        "strands": F("int", REQUIRED, COUNT, doc="parallel strands side by side"),
        "bones": F("int", REQUIRED, COUNT, doc="bones per strand"),
        "length": F("number", REQUIRED, POSITIVE, doc="strand length (m)"),
        "width": F("number", REQUIRED, NON_NEGATIVE, doc="distance from the first strand root to the last (m)"),
        "direction": F("dir3", (0.0, -1.0, 0.0), doc="direction every strand runs along (parent space)"),
        "across": F("dir3", (1.0, 0.0, 0.0), doc="direction the strand roots are spaced along (not parallel to direction)"),
        **_STRAND_COMMON,
    },
}

INSTANCE_FIELDS = {
    "count": F("int", REQUIRED, COUNT, doc="number of copies of the rig"),
    "spacing": F("vec3", (1.0, 0.0, 0.0), doc="offset between neighbouring copies in a row (m)"),
    # bounded like count (a scene has at most 500,000 bones): numpy indexes the grid with C longs
    "columns": F("int", 0, Range(0, 500_000), doc="copies per row; 0 = all in one row"),
    "row_spacing": F("vec3", None, doc="offset between rows (m); default: spacing turned 90 degrees about Y"),
    "phase_offset": F("number", 0.0, NON_NEGATIVE, doc="animation time offset per instance index (s)"),
    "phase_jitter": F("number", 0.0, NON_NEGATIVE, doc="extra random offset in [0, phase_jitter) per instance (s), seeded by scene.seed"),
}

# -- animation ---------------------------------------------------------------------------
# The keys and meanings follow magica_py.scene.animation (``_driver_params``, ``INTERPOLATIONS``):
# tests/test_config_schema.py checks that both sides accept the same keys and choices.
KEYFRAME_INTERPOLATIONS = ("linear", "step", "smooth", "cubic")
# The periodic drivers' angles, rates and amplitudes: far beyond any motion a rig makes, and
# within the range where the angles' sine and cosine stay exact to round-off (an angle of 1e300
# degrees or a period of 1e-200 s made NaN transforms)
DRIVER_ANGLE = Range(-1e6, 1e6)          # degrees (phases, amplitudes about an axis)
DRIVER_AMPLITUDE = Range(-1e6, 1e6)      # m or degrees
DRIVER_FREQUENCY = Range(0.0, 1000.0, low_open=True)   # Hz
SPIN_SPEED = Range(-1e6, 1e6)            # degrees/s
MIN_ORBIT_PERIOD = 1e-3                  # s (either sign)
DRIVER_FIELDS: dict[str, dict[str, Field]] = {
    "keyframes": {
        "interpolation": F("choice", "linear", choices=KEYFRAME_INTERPOLATIONS,
                           doc="linear (slerp for rotations), step, smooth (each segment eased in and out) "
                               "or cubic (Catmull-Rom through the keys; rotations slerp linearly)"),
        "loop": F("bool", False, doc="repeat after the last key (else hold the last key)"),
        "keys": F("keys", doc="list of {time, position?, rotation|euler?, scale?} (local pose)"),
    },
    "orbit": {
        "center": F("vec3", (0.0, 0.0, 0.0), doc="circle centre in the parent's space (m)"),
        "radius": F("number", REQUIRED, POSITIVE, doc="circle radius (m)"),
        "period": F("number", REQUIRED, doc="time for one revolution (s), at least 0.001 s either way; negative runs the "
                                             "circle backwards"),
        "axis": F("dir3", (0.0, 1.0, 0.0), doc="axis of the circle in the parent's space: a positive rotation about it "
                                                "(clockwise seen from the axis tip, Unity is left-handed), as spin"),
        "phase": F("number", 0.0, DRIVER_ANGLE, doc="start angle (degrees)"),
        "face_path": F("bool", False, doc="also rotate the target so it faces along the path"),
    },
    "oscillate": {
        "property": F("choice", "position", choices=("position", "rotation"), doc="what oscillates"),
        "axis": F("dir3", (0.0, 1.0, 0.0), doc="direction in the parent's space (position) or rotation axis in the "
                                                "node's own local axes (rotation)"),
        "amplitude": F("number", REQUIRED, DRIVER_AMPLITUDE, doc="m for position, degrees for rotation"),
        "frequency": F("number", REQUIRED, DRIVER_FREQUENCY, doc="Hz"),
        "phase": F("number", 0.0, DRIVER_ANGLE, doc="degrees"),
    },
    "spin": {
        "axis": F("dir3", (0.0, 1.0, 0.0), doc="rotation axis in the node's own local axes"),
        "speed": F("number", REQUIRED, SPIN_SPEED, doc="angular speed (degrees/s)"),
    },
    "walk": {
        "speed": F("number", 0.0, NON_NEGATIVE, doc="forward speed (m/s); 0 = walk on the spot"),
        "stride_frequency": F("number", 1.8, DRIVER_FREQUENCY,
                              doc="strides per second (Hz); a stride is one gait cycle of two steps"),
        "bob": F("number", 0.03, Range(0.0, 1e6), doc="bob amplitude along up (m), once per step: twice per stride"),
        "sway": F("number", 4.0, Range(0.0, 1e6), doc="roll amplitude about the node's local +Z (degrees), once per stride"),
        "lateral": F("number", 0.0, Range(0.0, 1e6), doc="side-to-side shift amplitude along up x direction (m), "
                                                      "once per stride"),
        "twist": F("number", 0.0, Range(0.0, 1e6), doc="yaw amplitude about the node's local +Y (degrees), once per stride"),
        "direction": F("dir3", (0.0, 0.0, 1.0), doc="forward direction in the parent's space"),
        "up": F("dir3", (0.0, 1.0, 0.0), doc="bob direction in the parent's space (not parallel to direction)"),
    },
}
DRIVER_COMMON = {
    "target": F("name", doc="transform driven"),
    "start": F("number", 0.0, NON_NEGATIVE, doc="driver active from this time (s)"),
    "end": F("number", None, NON_NEGATIVE, doc="... until this time (s); null = forever"),
    "phase_offset": F("number", 0.0, doc="time offset added to the driver's clock (s)"),
    "fade": F("number", 0.0, NON_NEGATIVE, doc="periodic drivers fade in/out over this time inside [start, end] (s)"),
}
EVENT_KINDS = ("teleport", "time_scale", "set_parameter", "wind")
EVENT_FIELDS = {
    "teleport": {"target": F("name", doc="transform moved"),
                 "position": F("vec3", None, doc="new world position (m); null keeps it"),
                 "rotation": F("quat", None, doc="new world rotation [x,y,z,w] (or euler: [x,y,z] degrees)")},
    "set_parameter": {"cloth": F("name", doc="cloth name"),
                      "key": F("text", doc="parameter key (dotted)"),
                      "value": F("any", doc="new value, validated like cloths[].parameters")},
    "wind": {"zone": F("name", doc="wind zone name (wind[].name)"),
             "enabled": F("bool", None, doc="switch the zone on (true) or off (false); null keeps it"),
             "main": F("number", None, Range(0.0, 30.0), doc="new main wind speed (m/s); null keeps it")},
}

# -- colliders ---------------------------------------------------------------------------
MIN_COLLIDER_SIZE = Range(0.001)
SHAPE_FIELDS: dict[str, dict[str, Field]] = {
    "sphere": {"radius": F("number", REQUIRED, MIN_COLLIDER_SIZE, doc="radius (m)")},
    "capsule": {
        "radius": F("number", REQUIRED, MIN_COLLIDER_SIZE, doc="start radius (m)"),
        "end_radius": F("number", None, MIN_COLLIDER_SIZE, doc="end radius (m); default: radius"),
        "length": F("number", REQUIRED, NON_NEGATIVE, doc="length tip to tip (m)"),
        "direction": F("choice", "y", choices=AXES, doc="local axis x, y or z"),
        "reverse": F("bool", False, doc="reverse the axis"),
        "aligned_on_center": F("bool", True, doc="centred on the transform (else starts at it)"),
    },
    "plane": {},
}
SHAPES = tuple(SHAPE_FIELDS)

OUTPUT_LOG_FIELDS = {
    "skeleton": F("bool", True, doc="rig joints and bones"),
    "particles": F("bool", True, doc="cloth particles coloured by attribute"),
    "edges": F("bool", True, doc="proxy edges"),
    "triangles": F("bool", True, doc="proxy triangles (mesh connection modes)"),
    "baselines": F("bool", False, doc="baseline chains"),
    "base_pose": F("bool", False, doc="the animated base pose the solver reads"),
    "colliders": F("bool", True, doc="collider shapes"),
    "metrics": F("bool", True, doc="time series: steps, phase wall times, stretch, speed"),
    "events": F("bool", True, doc="teleports, time-scale changes, parameter changes, wind changes"),
    "replay": F("bool", True, doc="animated local poses and frame times, what `magica-py resim` needs"),
}


@dataclass
class NormalizedScene:
    """Plain, checked values of every section (names still unresolved)."""

    settings: dict = field(default_factory=dict)
    rigs: list = field(default_factory=list)
    animation: list = field(default_factory=list)
    colliders: list = field(default_factory=list)
    cloths: list = field(default_factory=list)
    wind: list = field(default_factory=list)
    output: dict = field(default_factory=dict)


# ----------------------------------------------------------------------------- readers
def read_fields(c: Checker, value, path: tuple, spec: dict[str, Field], *, extra=()) -> dict | None:
    """Check a mapping against a field table; unknown keys reported; defaults filled in."""
    m = c.mapping(value, path, list(spec) + list(extra))
    if m is None:
        return None
    out = {}
    for key, f in spec.items():
        out[key] = read_field(c, m, key, path, f)
    return out


def read_field(c: Checker, m: dict, key: str, path: tuple, f: Field):
    kind = f.kind
    if kind in ("number", "int"):
        return c.number(m, key, path, f.default, f.rng, integer=kind == "int")
    if kind == "bool":
        return c.boolean(m, key, path, f.default)
    if kind == "text":
        return c.text(m, key, path, f.default)
    if kind == "name":
        return c.text(m, key, path, f.default, what="a name")
    if kind == "choice":
        return c.choice(m, key, path, f.choices, f.default)
    if kind == "vec3":
        return c.vector(m, key, path, 3, f.default, f.rng)
    if kind == "dir3":
        return c.direction(m, key, path, f.default)
    if kind == "any":
        if key not in m:
            c.error(path, f"missing {key!r}")
        return m.get(key)
    raise AssertionError(f"field kind {kind} is read by its section")


def check_document(c: Checker, data) -> NormalizedScene:
    out = NormalizedScene()
    root = c.mapping(data, (), TOP_LEVEL_KEYS, what="a mapping with the sections " + ", ".join(TOP_LEVEL_KEYS))
    if root is None:
        return out
    version = root.get("version", FORMAT_VERSION)
    if version != FORMAT_VERSION or isinstance(version, bool):
        c.error(("version",), f"unsupported format version {version!r}: this magica_py reads version {FORMAT_VERSION}")
    out.settings = check_settings(c, root.get("scene"), ("scene",))
    from magica_py.config import imports

    out.rigs = _section(c, root, "rigs", 1, lambda item, p: [check_rig(c, item, p)])
    out.animation = _section(c, root, "animation", 0, lambda item, p: (
        [check_animation_entry(c, e, p) for e in imports.import_clip_entries(c, item, p, out.rigs)]
        if isinstance(item, dict) and "clip" in item else [check_animation_entry(c, item, p)]))
    out.colliders = _section(c, root, "colliders", 0, lambda item, p: [check_collider(c, item, p)])

    def cloth_entries(item, p):
        if not (isinstance(item, dict) and "from_vrm" in item):
            return [check_cloth(c, item, p)]
        colliders, cloths = imports.import_vrm_sections(c, item, p, out.rigs)
        out.colliders.extend(k for k in (check_collider(c, e, p) for e in colliders) if k is not None)
        return [check_cloth(c, e, p) for e in cloths]

    out.cloths = _section(c, root, "cloths", 0, cloth_entries)
    out.wind = _section(c, root, "wind", 0, lambda item, p: [check_wind_zone(c, item, p)])
    out.output = check_output(c, root.get("output"), ("output",))
    return out


def _section(c: Checker, root: dict, key: str, min_length: int, check) -> list:
    """Check every entry of a list section; ``check(item, path)`` returns normalized entries
    (several when the entry imports a file)."""
    out = []
    for i, item in enumerate(c.sequence(root, key, (), min_length=min_length)):
        out.extend(e for e in check(item, (key, i)) if e is not None)
    return out


# ----------------------------------------------------------------------------- scene
SETTINGS_KEYS = ("name", "fps", "frame_times", "frame_times_cycle", "clock", "frames", "duration", "time_scale", "update_mode",
                 "simulation_frequency", "max_steps_per_frame", "global_time_scale", "fixed_delta_time",
                 "maximum_delta_time",
                 "gravity", "timing", "seed", "threads")


def check_settings(c: Checker, value, path: tuple) -> dict:
    m = c.mapping(value, path, SETTINGS_KEYS) or {}
    s: dict = {"name": c.text(m, "name", path, None, what="a scene name")}
    source = c.exactly_one(m, ("fps", "frame_times", "clock"), path, required=False) or "fps"
    s["fps"] = c.number(m, "fps", path, 60.0 if source == "fps" else None, Range(0.0, 10000.0, low_open=True),
                        units="frames/s")
    s["frame_times"] = None
    if source == "frame_times":
        times = c.sequence(m, "frame_times", path, min_length=1)
        checked = [c.number({i: t}, i, path + ("frame_times",), REQUIRED, Range(0.0, 10.0, low_open=True), units="s")
                   for i, t in enumerate(times)]
        s["frame_times"] = tuple(t for t in checked if t is not None)
    s["frame_times_cycle"] = c.boolean(m, "frame_times_cycle", path, True)
    if s["frame_times"] and not s["frame_times_cycle"] and isinstance(m.get("frames"), int) \
            and m["frames"] > len(s["frame_times"]):
        c.error(path + ("frames",), f"expected at most {len(s['frame_times'])} frames: frame_times is not "
                                    f"cycled (frame_times_cycle: false) and has {len(s['frame_times'])} entries")
    s["clock"] = c.choice(m, "clock", path, ("realtime",), None)
    length = c.exactly_one(m, ("frames", "duration"), path, required=False) or "frames"
    s["frames"] = c.integer(m, "frames", path, 600 if length == "frames" else None, COUNT)
    s["duration"] = c.number(m, "duration", path, None, POSITIVE, units="s")
    s["time_scale"] = c.number(m, "time_scale", path, 1.0, Range(0.0, 100.0))
    s["update_mode"] = c.choice(m, "update_mode", path, UPDATE_MODES, "normal")
    s["simulation_frequency"] = c.integer(m, "simulation_frequency", path, 90, Range(30, 150))
    s["max_steps_per_frame"] = c.integer(m, "max_steps_per_frame", path, 3, Range(1, 5))
    s["global_time_scale"] = c.number(m, "global_time_scale", path, 1.0, Range(0.0, 1.0))
    s["fixed_delta_time"] = c.number(m, "fixed_delta_time", path, 0.02, Range(0.0001, 10.0), units="s")
    s["maximum_delta_time"] = c.number(m, "maximum_delta_time", path, 1.0 / 3.0, Range(0.0001, 10.0), units="s")
    if s["maximum_delta_time"] < s["fixed_delta_time"]:
        c.error(path + ("maximum_delta_time",), f"expected maximum_delta_time >= fixed_delta_time "
                                                f"({s['fixed_delta_time']:g} s), got {s['maximum_delta_time']:g}")
    s["gravity"] = c.direction(m, "gravity", path, (0.0, -1.0, 0.0))
    s["timing"] = c.choice(m, "timing", path, TIMING_MODES, "exact")
    s["seed"] = c.integer(m, "seed", path, 0, Range(0, 2**63 - 1))
    threads = m.get("threads", "auto")
    if threads != "auto" and (isinstance(threads, bool) or not isinstance(threads, int) or not 1 <= threads <= 1024):
        c.error(path + ("threads",), f"expected 'auto' or an integer in [1, 1024] (threads the cloth frame uses), "
                                     f"got {threads!r}")
        threads = "auto"
    s["threads"] = threads
    return s


# ----------------------------------------------------------------------------- rigs
def check_pose(c: Checker, m: dict, path: tuple, *, scale: bool = True) -> dict:
    pose = {"position": c.vector(m, "position", path, 3, (0.0, 0.0, 0.0)),
            "rotation": c.rotation(m, path)}
    if scale:
        s = c.vector(m, "scale", path, 3, (1.0, 1.0, 1.0))
        if any(abs(x) < 1e-6 for x in s):
            c.error(path + ("scale",), f"expected non-zero scale components, got {list(s)}")
            s = (1.0, 1.0, 1.0)
        pose["scale"] = s
    return pose


def check_rig(c: Checker, value, path: tuple) -> dict | None:
    from magica_py.config import imports

    m = c.mapping(value, path, ("name", "position", "rotation", "euler", "bones", "parts", "instances")
                  + imports.RIG_FILE_KEYS)
    if m is None:
        return None
    rig = {"name": c.text(m, "name", path, what="a rig name"), **check_pose(c, m, path, scale=False)}
    rig["bones"] = []
    rig["file"] = rig["prefix"] = None
    rig["humanoid"], rig["unit_scale"] = {}, 1.0
    if "file" in m:
        imported = imports.import_rig(c, m, path)
        if imported is not None:
            rig["bones"], rig["humanoid"], rig["unit_scale"] = (imported["bones"], imported["humanoid"],
                                                                imported["unit_scale"])
        rig["file"], rig["prefix"] = m.get("file"), m.get("prefix") or ""
    for i, b in enumerate(c.sequence(m, "bones", path)):
        bp = path + ("bones", i)
        bm = c.mapping(b, bp, ("name", "parent", "position", "rotation", "euler", "scale"))
        if bm is None:
            continue
        rig["bones"].append({"name": _defined_name(c, bm, bp, "a bone name"),
                             "parent": c.text(bm, "parent", bp, None, what="a bone name or null"),
                             "path": bp, **check_pose(c, bm, bp)})
    rig["parts"] = []
    for i, p in enumerate(c.sequence(m, "parts", path)):
        pp = path + ("parts", i)
        pm = c.mapping(p, pp, PART_FIELDS, what="a mapping with one generator: chain, fan, skirt or sheet")
        if pm is None:
            continue
        kind = c.exactly_one(pm, tuple(PART_FIELDS), pp)
        if kind is None:
            continue
        params = read_fields(c, pm[kind], pp + (kind,), PART_FIELDS[kind])
        if params is not None and isinstance(pm[kind], dict):
            params["name"] = _defined_name(c, pm[kind], pp + (kind,), "a name") if params.get("name") else None
        if params is not None:
            rig["parts"].append({"kind": kind, "params": params, "path": pp + (kind,)})
    rig["instances"] = None
    if m.get("instances") is not None:
        rig["instances"] = read_fields(c, m["instances"], path + ("instances",), INSTANCE_FIELDS)
    if not m.get("bones") and not m.get("parts") and not m.get("file"):
        c.error(path, "a rig needs bones, parts and/or a file")
    rig["path"] = path
    return rig


def _defined_name(c: Checker, m: dict, path: tuple, what: str):
    """The name a bone or a generator part defines: text without '#', which separates an
    instance's number from its rig's bone name (``hips#2``) in every reference."""
    name = c.text(m, "name", path, what=what)
    if name is not None and "#" in name:
        c.error(path + ("name",), f"{name!r}: a name cannot contain '#', which names a rig instance's copy "
                                  "(hips#2 is instance 2's hips)")
        return None
    return name


# ----------------------------------------------------------------------------- animation
def check_animation_entry(c: Checker, value, path: tuple) -> dict | None:
    kinds = tuple(DRIVER_FIELDS) + EVENT_KINDS
    m = c.mapping(value, path, kinds + tuple(DRIVER_COMMON) + ("at",),
                  what="a driver {target: ..., <kind>: {...}} or an event {at: ..., <event>: ...}")
    if m is None:
        return None
    kind = c.exactly_one(m, kinds, path)
    if kind is None:
        return None
    entry: dict = {"kind": kind, "path": path}
    if kind in DRIVER_FIELDS:
        if "at" in m:
            c.error(path + ("at",), f"'at' belongs to events ({', '.join(EVENT_KINDS)}); "
                                    f"a {kind} driver is timed with start/end")
        for key, f in DRIVER_COMMON.items():
            entry[key] = read_field(c, m, key, path, f)
        if entry["end"] is not None and entry["end"] <= entry["start"]:
            c.error(path + ("end",), f"expected end > start ({entry['start']:g} s), got {entry['end']:g}")
        kp = path + (kind,)
        if kind == "keyframes":
            params = read_fields(c, m[kind], kp, {k: f for k, f in DRIVER_FIELDS[kind].items() if k != "keys"},
                                 extra=("keys",))
            if params is not None:
                params["keys"] = check_keys(c, m[kind], kp)
        else:
            params = read_fields(c, m[kind], kp, DRIVER_FIELDS[kind])
        if kind == "orbit" and params and not abs(params["period"]) >= MIN_ORBIT_PERIOD:
            c.error(kp + ("period",), f"expected a period of at least {MIN_ORBIT_PERIOD:g} s either way, got "
                                      f"{params['period']:g} (a negative one runs the circle backwards)")
            return None
        if kind == "walk" and params and params["direction"] and params["up"]:
            d, u = params["direction"], params["up"]
            if abs(sum(a * b for a, b in zip(d, u))) > 1 - 1e-9:
                c.error(kp + ("up",), f"expected 'up' not parallel to 'direction' {list(d)}")
        if params is None:
            return None
        entry["params"] = params
        return entry
    # events
    for key in DRIVER_COMMON:
        if key in m:
            c.error(path + (key,), f"{key!r} is not used by a {kind} event (events take 'at')")
    entry["at"] = c.number(m, "at", path, REQUIRED, NON_NEGATIVE, units="s")
    if kind == "time_scale":
        entry["params"] = {"value": c.number(m, "time_scale", path, REQUIRED, Range(0.0, 100.0))}
    elif kind == "teleport":
        tp = path + ("teleport",)
        tm = c.mapping(m["teleport"], tp, ("target", "position", "rotation", "euler"))
        if tm is None:
            return None
        has_rotation = "rotation" in tm or "euler" in tm
        entry["params"] = {"target": c.text(tm, "target", tp, what="a transform name"),
                           "position": c.vector(tm, "position", tp, 3, None),
                           "rotation": c.rotation(tm, tp) if has_rotation else None}
        if entry["params"]["position"] is None and not has_rotation:
            c.error(tp, "expected a position and/or a rotation (or euler) to teleport to")
    elif kind == "wind":
        params = read_fields(c, m["wind"], path + ("wind",), EVENT_FIELDS["wind"])
        if params is None:
            return None
        if params["enabled"] is None and params["main"] is None:
            c.error(path + ("wind",), "expected 'enabled' and/or 'main' to change on the zone")
        entry["params"] = params
    else:
        params = read_fields(c, m["set_parameter"], path + ("set_parameter",), EVENT_FIELDS["set_parameter"])
        if params is None:
            return None
        entry["params"] = params
    return entry


def check_keys(c: Checker, m: dict, path: tuple) -> list[dict]:
    keys = []
    last_time = None
    for i, k in enumerate(c.sequence(m, "keys", path, min_length=1)):
        kp = path + ("keys", i)
        km = c.mapping(k, kp, ("time", "position", "rotation", "euler", "scale"))
        if km is None:
            continue
        t = c.number(km, "time", kp, REQUIRED, NON_NEGATIVE, units="s")
        if t is not None and last_time is not None and t <= last_time:
            c.error(kp + ("time",), f"key times must increase: expected > {last_time:g}, got {t:g}")
        last_time = t if t is not None else last_time
        key = {"time": t,
               "position": c.vector(km, "position", kp, 3, None),
               "rotation": c.rotation(km, kp) if ("rotation" in km or "euler" in km) else None,
               "scale": c.vector(km, "scale", kp, 3, None)}
        if not any(km.get(k) is not None for k in ("position", "rotation", "euler", "scale")):
            c.error(kp, "a key needs at least one of position, rotation (or euler), scale")
        keys.append(key)
    return keys


# ----------------------------------------------------------------------------- colliders
def check_collider(c: Checker, value, path: tuple) -> dict | None:
    m = c.mapping(value, path, ("name", "transform", "position", "rotation", "euler", "center") + SHAPES)
    if m is None:
        return None
    col = {"name": c.text(m, "name", path, what="a collider name"),
           "transform": c.text(m, "transform", path, None, what="a transform name"),
           "center": c.vector(m, "center", path, 3, (0.0, 0.0, 0.0)), "path": path}
    if col["transform"] is not None and any(k in m for k in ("position", "rotation", "euler")):
        key = next(k for k in ("position", "rotation", "euler") if k in m)
        c.error(path + (key,), "a collider with a transform takes its pose from it: give 'center' "
                               "(local offset) instead, or drop 'transform' for a static collider")
    col["static_pose"] = check_pose(c, m, path, scale=False)
    shape = c.exactly_one(m, SHAPES, path)
    col["shape"] = shape
    col["params"] = read_fields(c, m[shape], path + (shape,), SHAPE_FIELDS[shape]) if shape else None
    if shape == "capsule" and col["params"] is not None and col["params"]["end_radius"] is None:
        col["params"]["end_radius"] = col["params"]["radius"]
    return col if col["params"] is not None else None


# -- wind --------------------------------------------------------------------------------
# MagicaCloth2's MagicaWindZone (docs/solver.md §C, §D.1; magica_py/wind). Mode names: ours, or
# MagicaCloth2's (GlobalDirection, SphereDirection, BoxDirection, SphereRadial).
WIND_MODES = ("global", "sphere", "box", "radial")
WIND_MODE_ALIASES = {"global_direction": "global", "sphere_direction": "sphere", "box_direction": "box",
                     "sphere_radial": "radial"}
WIND_ZONE_FIELDS = {
    "name": F("name", doc="unique zone name (wind events refer to it)"),
    "mode": F("choice", "global", choices=WIND_MODES + tuple(WIND_MODE_ALIASES),
              doc="global (everywhere, no area), sphere or box (directional wind inside the area), "
                  "radial (blows away from the sphere's centre)"),
    "transform": F("name", None, doc="bone the zone follows; position / rotation then offset it in the bone's "
                                     "space; omitted: a fixed world pose"),
    "radius": F("number", None, POSITIVE, doc="sphere and radial zones: radius (m), default 10"),
    "size": F("vec3", None, POSITIVE, doc="box zones: edge lengths along the zone's local x, y, z (m), default [10, 10, 10]"),
    "main": F("number", 5.0, Range(0.0, 30.0), doc="main wind speed (m/s)"),
    "turbulence": F("number", 1.0, Range(0.0, 1.0), doc="turbulence: direction swing and speed gusts"),
    "direction": F("dir3", None, doc="wind direction in the zone's local space (default [0, 0, 1])"),
    "direction_angles": F("vec2", None, Range(-180.0, 180.0), doc="or MagicaCloth2's directionAngleX / Y (degrees): "
                                                                  "Euler(x, y, 0) applied to local +Z"),
    "addition": F("bool", False, doc="additive zone: felt on top of the area zone (at most 3 per cloth)"),
    "enabled": F("bool", True, doc="whether the zone blows from the start (wind events switch it)"),
    "attenuation": F("curve", None, doc="radial zones: strength over distance / radius (a depth-curve value, "
                                        "default MagicaCloth2's ease-in-out from 1 to 0)"),
}
WIND_ZONE_KEYS = tuple(WIND_ZONE_FIELDS) + ("position", "rotation", "euler")


def check_wind_zone(c: Checker, value, path: tuple) -> dict | None:
    """One ``wind:`` entry, normalized: mode canonical, local direction a unit vector, the
    attenuation a ``params.curves.Curve``; keys that do not belong to the mode are errors."""
    from magica_py.params.curves import Curve

    m = c.mapping(value, path, WIND_ZONE_KEYS)
    if m is None:
        return None
    zone = {key: read_field(c, m, key, path, f) for key, f in WIND_ZONE_FIELDS.items()
            if f.kind not in ("vec2", "curve")}
    zone["path"] = path
    mode = WIND_MODE_ALIASES.get(zone["mode"], zone["mode"])
    zone["mode"] = mode
    zone.update(check_pose(c, m, path, scale=False))
    belongs = {"radius": ("sphere", "radial"), "size": ("box",), "attenuation": ("radial",),
               "direction": ("global", "sphere", "box"), "direction_angles": ("global", "sphere", "box")}
    for key, modes in belongs.items():
        if m.get(key) is not None and mode not in modes:
            c.error(path + (key,), f"{key!r} is not used by a {mode} zone (it belongs to {' and '.join(modes)} zones)")
    zone["radius"] = 10.0 if zone["radius"] is None else zone["radius"]
    zone["size"] = (10.0, 10.0, 10.0) if zone["size"] is None else zone["size"]
    which = c.exactly_one(m, ("direction", "direction_angles"), path, required=False)
    if which == "direction_angles":
        angles = c.vector(m, "direction_angles", path, 2, None, Range(-180.0, 180.0),
                          what="[x, y] angles in degrees")
        zone["direction"] = (0.0, 0.0, 1.0)
        if angles is not None:
            from magica_py.kernels.math3d import q_rotate

            q = euler_to_quaternion((angles[0], angles[1], 0.0))
            zone["direction"] = tuple(float(x) for x in q_rotate(q, (0.0, 0.0, 1.0)))
    elif zone["direction"] is None:
        zone["direction"] = (0.0, 0.0, 1.0)
    zone["attenuation"] = Curve.hermite(1.0, (1.0, 0.0), (0.0, 0.0))   # AnimationCurve.EaseInOut(0, 1, 1, 0)
    if m.get("attenuation") is not None:
        try:
            zone["attenuation"] = Curve.parse(m["attenuation"], "attenuation")
        except ValueError as exc:   # "attenuation.curve: expected ..." -> path ...attenuation.curve
            where, _, message = str(exc).partition(": ")
            inner = where[len("attenuation"):].lstrip(".")
            c.error(path + ("attenuation",) + ((inner,) if inner else ()), message)
    return zone


# ----------------------------------------------------------------------------- cloths
CLOTH_KEYS = ("name", "type", "root_bones", "component", "connection", "preset", "parameters", "colliders",
              "collision_mode", "bone_attributes")


def check_cloth(c: Checker, value, path: tuple) -> dict | None:
    m = c.mapping(value, path, CLOTH_KEYS)
    if m is None:
        return None
    cloth = {"name": c.text(m, "name", path, what="a cloth name"),
             "type": c.choice(m, "type", path, CLOTH_TYPES, "bone_cloth"),
             "root_bones": c.names(m, "root_bones", path, min_length=1),
             "component": c.text(m, "component", path, None, what="a transform name"),
             "connection": c.choice(m, "connection", path, CONNECTION_MODES, "line"),
             "preset": c.text(m, "preset", path, None, what="a preset name"),
             "parameters": {} if m.get("parameters") is None else m["parameters"],   # [] or 0 is a mistake
             "colliders": c.names(m, "colliders", path),
             "collision_mode": c.choice(m, "collision_mode", path, COLLISION_MODES, None),
             "bone_attributes": {}, "path": path}
    if not isinstance(cloth["parameters"], dict):
        c.error(path + ("parameters",), f"expected a mapping of parameter names to values, got {m['parameters']!r}")
        cloth["parameters"] = {}
    attrs = m.get("bone_attributes")
    if attrs is not None and not isinstance(attrs, dict):
        c.error(path + ("bone_attributes",), f"expected a mapping bone name (or glob) -> "
                                             f"{' | '.join(BONE_ATTRIBUTES)}, got {attrs!r}")
    elif attrs:
        for name in attrs:
            cloth["bone_attributes"][name] = c.choice(attrs, name, path + ("bone_attributes",), BONE_ATTRIBUTES)
    return cloth


# ----------------------------------------------------------------------------- output
def check_output(c: Checker, value, path: tuple) -> dict:
    m = c.mapping(value, path, ("rrd", "log")) or {}
    out = {"rrd": c.text(m, "rrd", path, None, what="a file path ending in .rrd")}
    if out["rrd"] is not None and not out["rrd"].endswith(".rrd"):
        c.error(path + ("rrd",), f"expected a file path ending in .rrd, got {out['rrd']!r}")
    out["log"] = read_fields(c, m.get("log"), path + ("log",), OUTPUT_LOG_FIELDS) or \
        {k: f.default for k, f in OUTPUT_LOG_FIELDS.items()}
    return out
