"""Per-team parameter table: ``params.ClothParameters`` converted to job data (docs/solver.md §F.1).

One row per team; kernels read ``prm.<field>[team]``. Conversions of §F.1 happen here once:
damping and restoration stiffness tables are multiplied by 0.2, limits arrive as -1 when off,
enums become small integers. Rewriting a row (``write_row``) is how a runtime parameter change
takes effect at the next frame without touching the simulation state.

Per-step rates (``rate_mode``): MagicaCloth2 tunes them for 90 Hz and patches other
frequencies with SimulationPower (§A.3); ``frequency_consistent`` converts every per-step
rate k with ``1 - (1 - k)^(90/f)`` instead (``step_rate`` below), every per-step retention
with ``keep^(90/f)`` (``step_keep``), every per-step amount with ``x 90/f`` (``step_share``),
and keeps the projections' stiffness as per-step strengths (``constraint_stiffness``;
docs/parameters.md, *solver.rate_mode*).
"""
from __future__ import annotations


import math

import numpy as np

from magica_py.jit import kernel
from magica_py.solver import blocks as bk
from magica_py.params import default_parameters
from magica_py.solver.fields import F64, I32, U8, allocate, make_soa
from magica_py.kernels import portable

CURVE = (16,)

TEAM_PARAMETER_FIELDS = [
    ("gravity", "team", (), F64, "m/s^2"),
    ("gravity_direction", "team", (3,), F64, "unit world direction"),
    ("gravity_falloff", "team", (), F64, ""),
    ("stabilization_time", "team", (), F64, "s"),
    ("blend_weight", "team", (), F64, ""),
    ("animation_pose_ratio", "team", (), F64, ""),
    ("rotational_interpolation", "team", (), F64, ""),
    ("root_rotation", "team", (), F64, ""),
    ("normal_axis", "team", (), I32, "0 right 1 up 2 forward 3 -right 4 -up 5 -forward"),
    ("anchor_transform", "team", (), I32, "hierarchy node or -1"),
    ("anchor_inertia", "team", (), F64, ""),
    ("world_inertia", "team", (), F64, ""),
    ("movement_smoothing", "team", (), F64, ""),
    ("movement_speed_limit", "team", (), F64, "m/s or -1"),
    ("rotation_speed_limit", "team", (), F64, "deg/s or -1"),
    ("local_inertia", "team", (), F64, ""),
    ("local_movement_speed_limit", "team", (), F64, "m/s or -1"),
    ("local_rotation_speed_limit", "team", (), F64, "deg/s or -1"),
    ("depth_inertia", "team", (), F64, ""),
    ("centrifugal_acceleration", "team", (), F64, ""),
    ("particle_speed_limit", "team", (), F64, "m/s or -1"),
    ("teleport_mode", "team", (), I32, "0 none 1 reset 2 keep"),
    ("teleport_distance", "team", (), F64, "m"),
    ("teleport_rotation", "team", (), F64, "deg"),
    ("tether_compression", "team", (), F64, ""),
    ("bending_stiffness", "team", (), F64, ""),
    ("use_restoration", "team", (), U8, ""),
    ("restoration_attenuation", "team", (), F64, ""),
    ("restoration_gravity_falloff", "team", (), F64, ""),
    ("use_angle_limit", "team", (), U8, ""),
    ("limit_stiffness", "team", (), F64, ""),
    ("use_max_distance", "team", (), U8, ""),
    ("use_backstop", "team", (), U8, ""),
    ("backstop_radius", "team", (), F64, "m"),
    ("motion_stiffness", "team", (), F64, ""),
    ("collision_mode", "team", (), I32, "0 none 1 point 2 edge"),
    ("friction", "team", (), F64, ""),
    ("culling_length", "team", (), F64, "m or -1"),
    ("culling_fade_ratio", "team", (), F64, ""),
    ("culling_reference", "team", (), I32, "hierarchy node or -1"),
    ("rate_mode", "team", (), I32, "0 magica, 1 frequency_consistent"),
    # wind (§D.1 WindParams)
    ("wind_influence", "team", (), F64, "[0,2]; <= 1e-8: the team feels no wind"),
    ("wind_frequency", "team", (), F64, "[0,2]; phase speed factor"),
    ("wind_turbulence", "team", (), F64, "[0,2]; scales the zones' turbulence"),
    ("wind_blend", "team", (), F64, "[0,1]; sine (0) to Perlin noise (1)"),
    ("wind_synchronization", "team", (), F64, "[0,1]; 1: all root lines in phase"),
    ("wind_depth_weight", "team", (), F64, "[0,1]; lerp(1, depth^2, depth_weight)"),
    ("wind_moving_wind", "team", (), F64, "[0,10]; wind from the team's own movement"),
    # quality mode (docs/quality-mode.md); all zero in faithful mode
    ("quality", "team", (), U8, "1: solver.mode quality (implies rate_mode 1)"),
    ("time_based_smoothing", "team", (), U8, "1: smoothing and display converted by the frame time"),
    ("inextensibility", "team", (), I32, "0 none, 1 tether, 2 ftl, 3 ftl_tether, 4 iterations, 5 ftl_edges"),
    ("tether_limit", "team", (), F64, "allowed root-distance stretch of the tight tether (ratio)"),
    ("distance_iterations", "team", (), I32, "extra distance passes of the iterations option"),
    ("ftl_damping", "team", (), F64, "DFTL velocity correction factor s_damp"),
    ("restoration_drift", "team", (), U8, "1: the passes do not see the restoration's kept-out drift (quality)"),
    ("distance_full_velocity", "team", (), U8, "1: distance corrections become velocity in full"),
    ("collision_last", "team", (), U8, "1: final collision projection at the end of the step"),
    ("contact_speed_limit", "team", (), F64, "m/s or -1; quality mode's speed limit relative to a touched collider"),
    # depth tables (§0.3)
    ("damping_curve", "team", CURVE, F64, "x0.2 applied"),
    ("radius_curve", "team", CURVE, F64, "m"),
    ("distance_stiffness_curve", "team", CURVE, F64, ""),
    ("restoration_stiffness_curve", "team", CURVE, F64, "x0.2 applied"),
    ("limit_angle_curve", "team", CURVE, F64, "deg"),
    ("max_distance_curve", "team", CURVE, F64, "m"),
    ("backstop_distance_curve", "team", CURVE, F64, "m"),
]
TeamParameters = make_soa("TeamParameters", TEAM_PARAMETER_FIELDS)

NORMAL_AXES = ("right", "up", "forward", "inverse_right", "inverse_up", "inverse_forward")
TELEPORT_MODES = ("none", "reset", "keep")
COLLISION_MODES = ("none", "point", "edge")
RATE_MODES = ("magica", "frequency_consistent")
SOLVER_MODES = ("faithful", "quality")
INEXTENSIBILITY = ("none", "tether", "ftl", "ftl_tether", "iterations", "ftl_edges")
# what "auto" means in quality mode (chosen by measurement, docs/quality-mode.md)
QUALITY_AUTO = {"solver.time_based_smoothing": "enabled", "solver.inextensibility": "ftl_edges",
                "solver.distance_velocity": "full", "solver.collision_last": "enabled",
                "solver.restoration_drift": "enabled"}

def curve_table(value) -> np.ndarray:
    """The 16-sample depth table of a ``Curve`` (``.samples``) or of a plain number."""
    samples = getattr(value, "samples", None)
    if samples is not None:
        return np.asarray(samples, dtype=np.float64)
    return np.full(16, float(value))


def _lookup(parameters, key):
    """``parameters[key]``, or the table's default (``params.default_parameters``) when the
    mapping lacks the key or holds None."""
    value = parameters.get(key, None) if hasattr(parameters, "get") else None
    return default_parameters()[key] if value is None else value


def _limit(value) -> float:
    if value is None or value is False:
        return -1.0
    return float(value)


def _enum(value, choices, key) -> int:
    name = str(value).lower()
    if name == "animator_linkage":
        name = "normal"
    if name not in choices:
        raise ValueError(f"parameter {key}: {value!r} is not one of {choices}")
    return choices.index(name)


def write_row(table, team: int, parameters, collision_mode: str | None = None,
              resolve_transform=None) -> None:
    """Convert one team's parameters (a mapping of dotted keys) into row ``team`` of ``table``.

    ``resolve_transform(name) -> hierarchy index`` resolves transform-valued parameters
    (anchor, culling reference); ``collision_mode`` (the cloth spec's) overrides the parameter.
    """
    g = lambda key: _lookup(parameters, key)  # noqa: E731
    resolve = resolve_transform or (lambda name: -1)
    t = team
    table.gravity[t] = float(g("gravity"))
    d = np.asarray(g("gravity_direction"), dtype=np.float64)
    n = portable.norm(d)
    table.gravity_direction[t] = d / n if n > 1e-8 else 0.0
    table.gravity_falloff[t] = float(g("gravity_falloff"))
    table.stabilization_time[t] = float(g("stabilization_time_after_reset"))
    table.blend_weight[t] = float(g("blend_weight"))
    table.animation_pose_ratio[t] = float(g("animation_pose_ratio"))
    table.rotational_interpolation[t] = float(g("rotational_interpolation"))
    table.root_rotation[t] = float(g("root_rotation"))
    table.normal_axis[t] = _enum(g("normal_axis"), NORMAL_AXES, "normal_axis")
    anchor = g("inertia.anchor")
    table.anchor_transform[t] = -1 if anchor is None else (anchor if isinstance(anchor, int) else resolve(anchor))
    table.anchor_inertia[t] = float(g("inertia.anchor_inertia"))
    table.world_inertia[t] = float(g("inertia.world_inertia"))
    table.movement_smoothing[t] = float(g("inertia.movement_inertia_smoothing"))
    table.movement_speed_limit[t] = _limit(g("inertia.movement_speed_limit"))
    table.rotation_speed_limit[t] = _limit(g("inertia.rotation_speed_limit"))
    table.local_inertia[t] = float(g("inertia.local_inertia"))
    table.local_movement_speed_limit[t] = _limit(g("inertia.local_movement_speed_limit"))
    table.local_rotation_speed_limit[t] = _limit(g("inertia.local_rotation_speed_limit"))
    table.depth_inertia[t] = float(g("inertia.depth_inertia"))
    table.centrifugal_acceleration[t] = float(g("inertia.centrifugal_acceleration"))
    table.particle_speed_limit[t] = _limit(g("inertia.particle_speed_limit"))
    table.teleport_mode[t] = _enum(g("inertia.teleport_mode"), TELEPORT_MODES, "inertia.teleport_mode")
    table.teleport_distance[t] = float(g("inertia.teleport_distance"))
    table.teleport_rotation[t] = float(g("inertia.teleport_rotation"))
    table.tether_compression[t] = float(g("tether.distance_compression"))
    table.bending_stiffness[t] = float(g("triangle_bending.stiffness"))
    table.use_restoration[t] = 1 if g("angle_restoration.use") else 0
    table.restoration_attenuation[t] = float(g("angle_restoration.velocity_attenuation"))
    table.restoration_gravity_falloff[t] = float(g("angle_restoration.gravity_falloff"))
    table.use_angle_limit[t] = 1 if g("angle_limit.use") else 0
    table.limit_stiffness[t] = float(g("angle_limit.stiffness"))
    table.use_max_distance[t] = 1 if g("motion.use_max_distance") else 0
    table.use_backstop[t] = 1 if g("motion.use_backstop") else 0
    table.backstop_radius[t] = float(g("motion.backstop_radius"))
    table.motion_stiffness[t] = float(g("motion.stiffness"))
    mode = collision_mode if collision_mode is not None else g("collider_collision.mode")
    table.collision_mode[t] = _enum(mode, COLLISION_MODES, "collision_mode")
    table.friction[t] = float(g("collider_collision.friction"))
    table.culling_length[t] = _limit(g("culling.distance_culling_length"))
    table.culling_fade_ratio[t] = float(g("culling.distance_culling_fade_ratio"))
    ref = g("culling.distance_culling_reference")
    table.culling_reference[t] = -1 if ref is None else (ref if isinstance(ref, int) else resolve(ref))
    table.rate_mode[t] = _enum(g("solver.rate_mode"), RATE_MODES, "solver.rate_mode")
    for name in ("influence", "frequency", "turbulence", "blend", "synchronization", "depth_weight", "moving_wind"):
        getattr(table, "wind_" + name)[t] = float(g("wind." + name))
    _write_quality(table, t, g)
    table.damping_curve[t] = curve_table(g("damping")) * 0.2
    table.radius_curve[t] = curve_table(g("radius"))
    table.distance_stiffness_curve[t] = curve_table(g("distance.stiffness"))
    table.restoration_stiffness_curve[t] = curve_table(g("angle_restoration.stiffness")) * 0.2
    table.limit_angle_curve[t] = curve_table(g("angle_limit.limit_angle"))
    table.max_distance_curve[t] = curve_table(g("motion.max_distance"))
    table.backstop_distance_curve[t] = curve_table(g("motion.backstop_distance"))


def _switch(g, key, quality: bool) -> str:
    """An ``auto | enabled | disabled``-style switch: ``auto`` is off ("disabled") in faithful
    mode and the measured default (``QUALITY_AUTO``) in quality mode."""
    value = str(g(key)).lower()
    if value == "auto":
        return QUALITY_AUTO[key] if quality else "disabled"
    return value


def _write_quality(table, t: int, g) -> None:
    """Quality-mode columns (docs/quality-mode.md). Faithful mode leaves them all at their "off" value,
    so its kernels take exactly the MagicaCloth2 paths."""
    quality = _enum(g("solver.mode"), SOLVER_MODES, "solver.mode") == 1
    table.quality[t] = 1 if quality else 0
    if quality:
        table.rate_mode[t] = 1  # quality mode converts every per-step rate by the step size
    table.time_based_smoothing[t] = 1 if _switch(g, "solver.time_based_smoothing", quality) == "enabled" else 0
    inext = _switch(g, "solver.inextensibility", quality)
    table.inextensibility[t] = 0 if inext == "disabled" else _enum(inext, INEXTENSIBILITY, "solver.inextensibility")
    table.tether_limit[t] = float(g("solver.tether_limit"))
    iterations = float(g("solver.distance_iterations"))
    if iterations != int(iterations):
        raise ValueError(f"parameter solver.distance_iterations: expected an integer, got {iterations!r}")
    table.distance_iterations[t] = int(iterations)
    table.ftl_damping[t] = float(g("solver.ftl_damping"))
    table.restoration_drift[t] = 1 if _switch(g, "solver.restoration_drift", quality) == "enabled" else 0
    table.distance_full_velocity[t] = 1 if _switch(g, "solver.distance_velocity", quality) == "full" else 0
    table.collision_last[t] = 1 if _switch(g, "solver.collision_last", quality) == "enabled" else 0
    table.contact_speed_limit[t] = _limit(g("solver.contact_speed_limit")) if quality else -1.0


def allocate_parameters(team_count: int):
    return allocate(TeamParameters, {"team": team_count})


# ----------------------------------------------------------------------------- packed rows
# The kernels read a block's parameters from one float64 row of ``P`` (B, PARAMETER_COUNT):
# every field of TEAM_PARAMETER_FIELDS at its column (integers exactly as float64, a (3,)
# direction in 3 columns, a curve in 16). The teams of a block share their row (it is part
# of the block key), except the transform-valued fields, which are per lane
# (``blocks.TI_ANCHOR``, ``blocks.TI_CULLING_REFERENCE``) and left out of the key.
PARAMETER_COLUMNS: dict[str, tuple[int, int]] = {}
_at = 0
for _name, _per, _shape, _dtype, _doc in TEAM_PARAMETER_FIELDS:
    _size = int(np.prod(_shape)) if _shape else 1
    PARAMETER_COLUMNS[_name] = (_at, _size)
    _at += _size
PARAMETER_COUNT = _at
del _at, _name, _per, _shape, _dtype, _doc, _size
PER_LANE_PARAMETERS = ("anchor_transform", "culling_reference")


def _column(name: str) -> int:
    return PARAMETER_COLUMNS[name][0]


PRM_GRAVITY = _column("gravity")
PRM_GRAVITY_DIRECTION = _column("gravity_direction")
PRM_GRAVITY_FALLOFF = _column("gravity_falloff")
PRM_STABILIZATION_TIME = _column("stabilization_time")
PRM_BLEND_WEIGHT = _column("blend_weight")
PRM_ANIMATION_POSE_RATIO = _column("animation_pose_ratio")
PRM_ROTATIONAL_INTERPOLATION = _column("rotational_interpolation")
PRM_ROOT_ROTATION = _column("root_rotation")
PRM_NORMAL_AXIS = _column("normal_axis")
PRM_ANCHOR_INERTIA = _column("anchor_inertia")
PRM_WORLD_INERTIA = _column("world_inertia")
PRM_MOVEMENT_SMOOTHING = _column("movement_smoothing")
PRM_MOVEMENT_SPEED_LIMIT = _column("movement_speed_limit")
PRM_ROTATION_SPEED_LIMIT = _column("rotation_speed_limit")
PRM_LOCAL_INERTIA = _column("local_inertia")
PRM_LOCAL_MOVEMENT_SPEED_LIMIT = _column("local_movement_speed_limit")
PRM_LOCAL_ROTATION_SPEED_LIMIT = _column("local_rotation_speed_limit")
PRM_DEPTH_INERTIA = _column("depth_inertia")
PRM_CENTRIFUGAL_ACCELERATION = _column("centrifugal_acceleration")
PRM_PARTICLE_SPEED_LIMIT = _column("particle_speed_limit")
PRM_TELEPORT_MODE = _column("teleport_mode")
PRM_TELEPORT_DISTANCE = _column("teleport_distance")
PRM_TELEPORT_ROTATION = _column("teleport_rotation")
PRM_TETHER_COMPRESSION = _column("tether_compression")
PRM_BENDING_STIFFNESS = _column("bending_stiffness")
PRM_USE_RESTORATION = _column("use_restoration")
PRM_RESTORATION_ATTENUATION = _column("restoration_attenuation")
PRM_RESTORATION_GRAVITY_FALLOFF = _column("restoration_gravity_falloff")
PRM_USE_ANGLE_LIMIT = _column("use_angle_limit")
PRM_LIMIT_STIFFNESS = _column("limit_stiffness")
PRM_USE_MAX_DISTANCE = _column("use_max_distance")
PRM_USE_BACKSTOP = _column("use_backstop")
PRM_BACKSTOP_RADIUS = _column("backstop_radius")
PRM_MOTION_STIFFNESS = _column("motion_stiffness")
PRM_COLLISION_MODE = _column("collision_mode")
PRM_FRICTION = _column("friction")
PRM_CULLING_LENGTH = _column("culling_length")
PRM_CULLING_FADE_RATIO = _column("culling_fade_ratio")
PRM_RATE_MODE = _column("rate_mode")
PRM_WIND_INFLUENCE = _column("wind_influence")
PRM_WIND_FREQUENCY = _column("wind_frequency")
PRM_WIND_TURBULENCE = _column("wind_turbulence")
PRM_WIND_BLEND = _column("wind_blend")
PRM_WIND_SYNCHRONIZATION = _column("wind_synchronization")
PRM_WIND_DEPTH_WEIGHT = _column("wind_depth_weight")
PRM_WIND_MOVING_WIND = _column("wind_moving_wind")
PRM_QUALITY = _column("quality")
PRM_TIME_BASED_SMOOTHING = _column("time_based_smoothing")
PRM_INEXTENSIBILITY = _column("inextensibility")
PRM_TETHER_LIMIT = _column("tether_limit")
PRM_DISTANCE_ITERATIONS = _column("distance_iterations")
PRM_FTL_DAMPING = _column("ftl_damping")
PRM_RESTORATION_DRIFT = _column("restoration_drift")
PRM_DISTANCE_FULL_VELOCITY = _column("distance_full_velocity")
PRM_COLLISION_LAST = _column("collision_last")
PRM_CONTACT_SPEED_LIMIT = _column("contact_speed_limit")
PRM_DAMPING_CURVE = _column("damping_curve")
PRM_RADIUS_CURVE = _column("radius_curve")
PRM_DISTANCE_STIFFNESS_CURVE = _column("distance_stiffness_curve")
PRM_RESTORATION_STIFFNESS_CURVE = _column("restoration_stiffness_curve")
PRM_LIMIT_ANGLE_CURVE = _column("limit_angle_curve")
PRM_MAX_DISTANCE_CURVE = _column("max_distance_curve")
PRM_BACKSTOP_DISTANCE_CURVE = _column("backstop_distance_curve")


def packed_row(table, team: int) -> np.ndarray:
    """Team ``team``'s row of ``table`` (a ``TeamParameters``) as the kernels' float64 row;
    the per-lane fields are left at 0 (they travel in ``blocks.team_ints``)."""
    row = np.zeros(PARAMETER_COUNT)
    for name, (at, size) in PARAMETER_COLUMNS.items():
        if name in PER_LANE_PARAMETERS:
            continue
        row[at:at + size] = np.asarray(getattr(table, name)[team], dtype=np.float64).reshape(size)
    return row


# ----------------------------------------------------------------------------- kernels
SQRT3 = math.sqrt(3.0)   # |(1, 1, 1)|: the length of a unit lossy scale


@kernel(inline="always")
def length_unit(quality, init_scale):
    """The cloth's own length unit (m): 1.0 in faithful mode (MagicaCloth2's lengths are world
    metres at the build scale); in quality mode the component's build scale, |lossy scale| /
    sqrt(3) (exactly 1.0 at scale 1), so that every length-like parameter (particle radius,
    speed limits, friction threshold, gravity, motion distances, teleport distance) follows
    the cloth's scale: a rig built at 0.01 behaves as the rig at 1 seen at 0.01
    (docs/parameters.md, *Scale*). ``quality``: the block's ``PRM_QUALITY``; ``init_scale``: the
    lane's build scale (``blocks.INIT_SCALE``)."""
    if quality == 0.0:
        return 1.0
    return np.sqrt(init_scale[0] * init_scale[0] + init_scale[1] * init_scale[1]
                     + init_scale[2] * init_scale[2]) / SQRT3


@kernel
def curve_at(P, b, col, depth):
    """``EvaluateCurve`` of §0.3 on the 16-sample curve at column ``col`` of block b's row of
    ``P`` (no clamp)."""
    sd = 0.0 if depth < 0.0 else (1.0 if depth > 1.0 else depth)
    i = int(sd * 15.0)
    u = (depth - i / 15.0) * 15.0
    j = i + 1 if i + 1 < 15 else 15
    return P[b, col + i] + (P[b, col + j] - P[b, col + i]) * u


@kernel
def curve_at_clamp01(P, b, col, depth):
    v = curve_at(P, b, col, depth)
    if v < 0.0:
        return 0.0
    if v > 1.0:
        return 1.0
    return v


@kernel
def step_rate(k, frequency_ratio, power, rate_mode):
    """A per-step rate at the simulation frequency: ``k * power`` (MagicaCloth2) or
    ``1 - (1 - k)^(90/f)`` (frequency-consistent; exactly k at 90 Hz)."""
    if rate_mode == 0:
        return k * power
    if frequency_ratio == 1.0:
        return k
    kk = 0.0 if k < 0.0 else (1.0 if k > 1.0 else k)
    return 1.0 - portable.pow(1.0 - kk, frequency_ratio)


@kernel
def step_keep(keep, frequency_ratio, rate_mode):
    """A per-step retention factor (e.g. friction x0.6): unchanged in MagicaCloth2 mode,
    ``keep^(90/f)`` in frequency-consistent mode."""
    if rate_mode == 0 or frequency_ratio == 1.0:
        return keep
    return portable.pow(keep, frequency_ratio)


@kernel
def step_share(share, frequency_ratio, rate_mode):
    """A per-step share of a correction that is itself about proportional to the step (e.g.
    the share of angle restoration's correction that becomes velocity, ``1 - attn``):
    unchanged in MagicaCloth2 mode, ``share * 90/f`` (clamped to [0, 1]) in
    frequency-consistent mode, so that the velocity it leaves per unit time does not depend
    on f (exactly ``share`` at 90 Hz)."""
    if rate_mode == 0 or frequency_ratio == 1.0:
        return share
    s = share * frequency_ratio
    return 1.0 if s > 1.0 else (0.0 if s < 0.0 else s)



@kernel
def constraint_stiffness(k, frequency_ratio, power, rate_mode, quality):
    """A projection's per-step stiffness (distance links, triangle bending: the share of the
    violation one pass removes, the whole correction kept as velocity): ``k * power``
    (MagicaCloth2), ``1 - (1 - k)^(90/f)`` in quality mode (``step_rate``), and ``k`` as is in
    frequency-consistent mode. Converted as a rate, a soft projection whose correction becomes
    velocity kicks the velocity by about ``-ln(1 - k) 90 C`` every step whatever the step, a
    spring that stiffens in proportion to f and whose short-horizon map does not converge (the
    character's skirt, docs/BENCHMARKS.md); a per-step strength, like the angle limit's, tends
    to the hard constraint as f grows, and the map converges to it."""
    if rate_mode != 0 and quality == 0:
        return k
    return step_rate(k, frequency_ratio, power, rate_mode)


@kernel(forceinline=False)
def particle_parameters_block(PP, PM, P, BI, b):
    """Block b's depth curves at every particle's depth, every lane (``blocks.PARTICLE_PARAMETERS``):
    the values ``curve_at`` gives, computed when the block's row or a lane changes. The columns
    go in as plain int64 (``np.int64``): one compile of ``curve_at``, not one per column
    (docs/tech-notes.md §7)."""
    g0 = BI[b, bk.BI_G0]
    for g in range(g0, g0 + BI[b, bk.BI_N]):
        for l in range(bk.lane_width(BI, b)):
            depth = PM[g, bk.DEPTH + l]
            PP[g, bk.CURVE_DAMPING + l] = curve_at(P, b, np.int64(PRM_DAMPING_CURVE), depth)
            PP[g, bk.CURVE_RADIUS + l] = curve_at(P, b, np.int64(PRM_RADIUS_CURVE), depth)
            PP[g, bk.CURVE_DISTANCE_STIFFNESS + l] = curve_at(P, b, np.int64(PRM_DISTANCE_STIFFNESS_CURVE), depth)
            PP[g, bk.CURVE_RESTORATION_STIFFNESS + l] = curve_at(P, b, np.int64(PRM_RESTORATION_STIFFNESS_CURVE), depth)
            PP[g, bk.CURVE_LIMIT_ANGLE + l] = curve_at(P, b, np.int64(PRM_LIMIT_ANGLE_CURVE), depth)
            # D.9 reads its curves at the depth squared
            PP[g, bk.CURVE_MAX_DISTANCE + l] = curve_at(P, b, np.int64(PRM_MAX_DISTANCE_CURVE), depth * depth)
            PP[g, bk.CURVE_BACKSTOP_DISTANCE + l] = curve_at(P, b, np.int64(PRM_BACKSTOP_DISTANCE_CURVE), depth * depth)


@kernel
def clamp01(v):
    """``curve_at_clamp01``'s clamp of a curve value."""
    if v < 0.0:
        return 0.0
    if v > 1.0:
        return 1.0
    return v
