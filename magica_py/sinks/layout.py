"""Entity paths, timelines and colours of a magica_py recording (see docs/recordings.md).

One module owns every path so the writer (``rerun_sink``), the readers (``inspect``,
``resim``) and the tests agree. Paths are plain strings without a leading slash; rerun's
reader reports them with one (``/world/rig/joints``), ``reader_path`` adds it.
"""
from __future__ import annotations

import re

APPLICATION_ID = "magica_py"

# timelines: `frame` (int64 sequence) and `sim_time` (Unity scaled game time, duration)
TIMELINE_FRAME = "frame"
TIMELINE_SIM_TIME = "sim_time"

WORLD = "world"                                   # ViewCoordinates LEFT_HAND_Y_UP (static)
RIG_JOINTS = "world/rig/joints"                   # Points3D: every transform's world position
RIG_BONES = "world/rig/bones"                     # LineStrips3D: one 2-point strip per parent->child link
COLLIDER_SPHERES = "world/colliders/spheres"      # Ellipsoids3D (half_sizes = radius)
COLLIDER_CAPSULES = "world/colliders/capsules"    # Capsules3D (start, axis quaternion, length, radius)
COLLIDER_PLANES = "world/colliders/planes"        # Boxes3D: a flat square patch on the plane
CLOTHS = "world/cloths"

METRICS = "metrics"
METRIC_STEPS = "metrics/steps"                    # simulation steps this frame (max over teams)
METRIC_MAX_STRETCH = "metrics/max_edge_stretch"   # max |len/rest - 1| over proxy edges
METRIC_MAX_PENETRATION = "metrics/max_penetration"  # m, deepest particle surface inside a collider
METRIC_MAX_SPEED = "metrics/max_speed"            # m/s, display positions between frames
METRIC_PHASE_TIME = "metrics/time"                # metrics/time/<phase>: wall time per phase (ms)

EVENTS = "events"                                 # TextLog: teleports, resets, time-scale changes

# replay data: what resim needs to re-run the solver exactly (float64 AnyValues)
REPLAY = "replay"
REPLAY_SCENE = "replay/scene"                     # static: scene name, source path, YAML text, format version
REPLAY_NODES = "replay/nodes"                     # static: names of the recorded (driven) transforms
REPLAY_POSE = "replay/pose"                       # per frame: local_position/rotation/scale of those nodes
REPLAY_TIME = "replay/time"                       # per frame: every UnityTime field
REPLAY_EVENTS = "replay/events"                   # per frame with events: JSON list raised before LATE_UPDATE
REPLAY_FORMAT_VERSION = 1

# colours (RGBA uint8)
COLOR_FIXED = (230, 80, 60, 255)
COLOR_MOVE = (70, 160, 240, 255)
COLOR_INVALID = (140, 140, 140, 255)
COLOR_JOINT = (220, 220, 220, 255)
COLOR_BONE = (170, 170, 170, 255)
COLOR_EDGE = (250, 200, 60, 255)
COLOR_BASELINE = (120, 230, 120, 255)
COLOR_BASE_POSE = (200, 120, 240, 255)
COLOR_COLLIDER = (255, 140, 0, 110)
COLOR_PLANE = (120, 120, 120, 255)

_UNSAFE = re.compile(r"[^A-Za-z0-9_.\-]")


def entity_name(name: str) -> str:
    """A name usable as one entity path part (`hair#3` -> `hair_3`); never empty."""
    safe = _UNSAFE.sub("_", name)
    return safe or "_"


def cloth_path(cloth: str, part: str) -> str:
    """Entity path of one cloth's part: particles | edges | triangles | baselines | base_pose."""
    return f"{CLOTHS}/{entity_name(cloth)}/{part}"


def metric_path(key: str) -> str:
    """Entity path of a metric from ``ctx.metrics`` (`time.late_update` -> metrics/time/late_update)."""
    return METRICS + "/" + "/".join(entity_name(p) for p in key.split("."))


def reader_path(path: str) -> str:
    """The path as rerun's chunk reader spells it (leading slash)."""
    return path if path.startswith("/") else "/" + path
