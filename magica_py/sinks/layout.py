"""Entity paths, timelines, units and colours of a magica_py recording (see docs/recordings.md).

One module owns every path so the writer (``rerun_sink``), the readers (``inspect``,
``resim``) and the tests agree. Paths are plain strings without a leading slash; rerun's
reader reports them with one (``/world/rig/joints``), ``reader_path`` adds it.

Display frame: Unity (and the scene files) are left-handed, X right, Y up, Z forward. Rerun's
viewer only draws right-handed frames, so everything under ``/world`` is written with X
negated (``DISPLAY_MIRROR``) and ``/world`` carries ``ViewCoordinates.LUF`` (X left, Y up,
Z forward: right-handed). A right turn in the scene is a right turn on screen. ``/metrics``
and ``/replay`` stay in scene units and handedness; ``readback.Recording`` undoes the mirror
(negating a float32 is exact, so read-back stays bit for bit).

Instanced rigs (a crowd): every entity of instance ``i`` of rig ``R`` lives under
``world/R_i/`` (``world/character_17/cloths/skirt/particles``) so that hovering a particle
names its character; entities of the non-instanced part keep the plain paths below.
"""
from __future__ import annotations

import re

# timelines: `frame` (int64 sequence) and `sim_time` (Unity scaled game time, duration)
TIMELINE_FRAME = "frame"
TIMELINE_SIM_TIME = "sim_time"

WORLD = "world"                                   # ViewCoordinates LUF + the mirror note (static)
DISPLAY_MIRROR = (-1.0, 1.0, 1.0)                 # scene -> display: x' = -x (exact in float32)
FOCUS = "world/focus"                             # Points3D, 2 invisible corners: box of the characters (camera target)
ROOT_LINKS = "world/root_links"                   # LineStrips3D: stem links from a rig root to its first branch (hidden)
RIG = "rig"
RIG_JOINTS = "world/rig/joints"                   # Points3D: world position of every transform but cloth bones
RIG_BONES = "world/rig/bones"                     # LineStrips3D: one 2-point strip per parent->child link
COLLIDERS = "world/colliders"                     # world/colliders/<name>: Transform3D + shape in its frame
CLOTHS = "world/cloths"

METRICS = "metrics"
# the quality metrics, with their unit in the name (the plots are titled the same way)
METRIC_MAX_STRETCH = "metrics/quality/max_edge_stretch_pct"     # %, max |len/rest - 1| over proxy edges
METRIC_MAX_PENETRATION = "metrics/quality/max_penetration_mm"   # mm, deepest particle surface inside a collider
METRIC_MAX_SPEED = "metrics/motion/max_speed_m_per_s"           # m/s, display positions between frames
METRIC_STEPS = "metrics/solver/steps_per_frame"                 # simulation steps this frame (max over teams)
METRIC_PHASE_TIME = "metrics/time"                              # metrics/time/<phase>_ms: wall time per phase
# ctx.metrics keys (seconds) shown in milliseconds, and the other known keys with their unit
SECONDS_METRICS = ("time.", "cloth.kernel", "cloth.propagate")
COUNT_METRICS = ("cloth.steps", "cloth.simulation_steps", "frame.fixed_updates")

EVENTS = "events"                                 # TextLog: teleports, resets, time-scale changes

# replay data: what resim needs to re-run the solver exactly (float64 AnyValues, scene frame)
REPLAY = "replay"
REPLAY_SCENE = "replay/scene"                     # static: scene name, source path, YAML text, format version
REPLAY_NODES = "replay/nodes"                     # static: names of the recorded (driven) transforms
REPLAY_POSE = "replay/pose"                       # per frame: local_position/rotation/scale of those nodes
REPLAY_TIME = "replay/time"                       # per frame: every UnityTime field
REPLAY_EVENTS = "replay/events"                   # per frame with events: JSON list raised before LATE_UPDATE
REPLAY_FORMAT_VERSION = 1

# MagicaCloth2 caps collider radii at 0.5 m: bigger ones are drawn as wireframes (authoring quirks)
OVERSIZED_COLLIDER_RADIUS = 0.5

# colours (RGBA uint8)
COLOR_FIXED = (230, 80, 60, 255)
COLOR_MOVE = (70, 160, 240, 255)
COLOR_INVALID = (140, 140, 140, 255)
COLOR_JOINT = (220, 220, 220, 255)
COLOR_BONE = (170, 170, 170, 255)
COLOR_ROOT_LINK = (90, 90, 90, 160)
COLOR_EDGE = (250, 200, 60, 255)
COLOR_BASELINE = (120, 230, 120, 255)
COLOR_BASE_POSE = (200, 120, 240, 255)
COLOR_COLLIDER = (255, 140, 0, 70)
COLOR_COLLIDER_OVERSIZED = (170, 140, 220, 180)   # violet wireframe
COLOR_PLANE = (150, 150, 150, 120)
COLOR_GRID = (110, 110, 110, 90)
# plot series: one clearly different hue each
COLOR_SERIES = {
    METRIC_MAX_STRETCH: (250, 200, 60, 255),       # amber
    METRIC_MAX_PENETRATION: (240, 80, 60, 255),    # red
    METRIC_MAX_SPEED: (80, 200, 240, 255),         # cyan
    METRIC_STEPS: (200, 200, 200, 255),            # grey
}
COLOR_PHASES = {
    "restore": (120, 140, 255, 255),               # blue
    "fixed_update": (90, 210, 110, 255),           # green
    "update": (255, 160, 40, 255),                 # orange
    "late_update": (230, 70, 200, 255),            # magenta
    "render_write": (240, 240, 90, 255),           # yellow
}
COLOR_OTHER_SERIES = ((160, 120, 240, 255), (120, 230, 200, 255), (240, 130, 130, 255), (190, 190, 90, 255))

_UNSAFE = re.compile(r"[^A-Za-z0-9_.\-]")


def entity_name(name: str) -> str:
    """A name usable as one entity path part (`hair#3` -> `hair_3`); never empty."""
    safe = _UNSAFE.sub("_", name)
    return safe or "_"


def base_name(name: str) -> str:
    """A name without its instance suffix (`skirt#17` -> `skirt`)."""
    return name.split("#")[0]


def group_root(group: str = "") -> str:
    """`world` for the non-instanced part, `world/<group>` for one instance of a rig."""
    return WORLD if not group else f"{WORLD}/{entity_name(group)}"


def cloth_path(cloth: str, part: str, group: str = "") -> str:
    """Entity path of one cloth's part: particles | edges | triangles | baselines | base_pose."""
    return f"{group_root(group)}/cloths/{entity_name(cloth)}/{part}"


def rig_path(part: str, group: str = "") -> str:
    """`world/rig/joints`, `world/character_17/rig/bones`..."""
    return f"{group_root(group)}/{RIG}/{part}"


def collider_path(name: str, group: str = "") -> str:
    return f"{group_root(group)}/colliders/{entity_name(base_name(name))}"


def metric_path(key: str) -> str:
    """Entity path of a metric from ``ctx.metrics``, unit in the name:
    `time.late_update` -> metrics/time/late_update_ms, `cloth.kernel` -> metrics/time/cloth_kernel_ms,
    `cloth.steps` -> metrics/counts/cloth/steps_count; other keys -> metrics/other/<a>/<b> (unit unknown)."""
    parts = [entity_name(p) for p in key.split(".")]
    if key.startswith("time."):
        return METRIC_PHASE_TIME + "/" + "/".join(parts[1:]) + "_ms"
    if key in SECONDS_METRICS:
        return METRIC_PHASE_TIME + "/" + "_".join(parts) + "_ms"
    if key in COUNT_METRICS:
        return METRICS + "/counts/" + "/".join(parts) + "_count"
    return METRICS + "/other/" + "/".join(parts)


def metric_scale(key: str) -> float:
    """Factor from the ``ctx.metrics`` value to the logged one (seconds -> milliseconds)."""
    return 1000.0 if key.startswith("time.") or key in SECONDS_METRICS else 1.0


def series_label(path: str) -> str:
    """The legend text of a metric: its last path part with the unit spelled out."""
    leaf = path.rsplit("/", 1)[-1]
    for suffix, unit in (("_pct", " (%)"), ("_mm", " (mm)"), ("_m_per_s", " (m/s)"), ("_ms", " (ms)"),
                         ("_count", " (count)")):
        if leaf.endswith(suffix):
            return leaf[: -len(suffix)].replace("_", " ") + unit
    if path == METRIC_STEPS:
        return "steps per frame (count)"
    return leaf.replace("_", " ")


def reader_path(path: str) -> str:
    """The path as rerun's chunk reader spells it (leading slash)."""
    return path if path.startswith("/") else "/" + path
