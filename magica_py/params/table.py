"""The BoneCloth parameter table (docs/solver.md §F.1), one row per parameter.

Keys are MagicaCloth2's serialized names in snake_case, grouped as in its inspector
(``inertia.world_inertia``). Kinds:

* ``float``  — a number clamped to [lo, hi] by validation (out of range is an error);
* ``curve``  — a depth curve (``params.curves.Curve``): the range applies to its value;
* ``limit``  — MagicaCloth2's CheckSliderSerializeData: a number enables the limit, ``false``
  / ``off`` disables it; the simulation receives -1 for "no limit";
* ``bool``, ``enum`` (choices), ``vector3``, ``transform`` (a transform name or null).

``implemented`` is False for parameters that are accepted (so MagicaCloth2 settings carry
over) but have no effect because the feature does not exist here (self collision):
``docs/parameters.md`` says so.
"""
from __future__ import annotations

from dataclasses import dataclass


@dataclass(frozen=True)
class ParameterDef:
    key: str
    kind: str
    default: object
    lo: float | None = None
    hi: float | None = None
    units: str = ""
    ref: str = ""
    doc: str = ""
    choices: tuple[str, ...] = ()
    implemented: bool = True


def _p(key, kind, default, lo=None, hi=None, units="", ref="", doc="", choices=(), implemented=True):
    return ParameterDef(key, kind, default, lo, hi, units, ref, doc, tuple(choices), implemented)


# Curve defaults are written as YAML-shaped values and parsed by params.__init__.
PARAMETER_DEFS: tuple[ParameterDef, ...] = (
    # -- bone cloth / general
    _p("rotational_interpolation", "float", 0.5, 0, 1, "", "E.2", "How far a moving bone turns towards its children (0: follow the parent edge, 1: point at the children)."),
    _p("root_rotation", "float", 0.5, 0, 1, "", "E.2", "How far a fixed root bone turns towards its simulated children."),
    _p("update_mode", "enum", "normal", ref="A.4", doc="Frame delta source: normal (deltaTime), unity_physics (fixed updates x fixedDeltaTime), unscaled (unscaledDeltaTime). animator_linkage resolves to normal (no Animator here).",
       choices=("normal", "unity_physics", "unscaled", "animator_linkage")),
    _p("animation_pose_ratio", "float", 0.0, 0, 1, "", "D.2, D.4, E.2", "Blend of the rest shape towards the animated pose as the constraints' reference."),
    _p("normal_axis", "enum", "up", ref="D.9", doc="Bone axis used as the backstop direction.",
       choices=("right", "up", "forward", "inverse_right", "inverse_up", "inverse_forward")),
    _p("gravity", "float", 5.0, 0, 20, "m/s^2", "C.3, D.1", "Gravity acceleration magnitude (MagicaCloth2 default 5, not 9.81)."),
    _p("gravity_direction", "vector3", (0.0, -1.0, 0.0), units="unit vector", ref="C.2", doc="World gravity direction; normalized (zero if too short). Defaults to the scene's gravity direction."),
    _p("gravity_falloff", "float", 0.0, 0, 1, "", "C.3", "Reduces gravity while the cloth's center frame keeps its build orientation."),
    _p("stabilization_time_after_reset", "float", 0.1, 0, 1, "s", "C.3, H.2", "Ramp time of velocities and blend weight after a reset."),
    _p("blend_weight", "float", 1.0, 0, 1, "", "C.3, E.1, E.2", "Blend between the animated pose (0) and the simulation (1)."),
    _p("damping", "curve", 0.05, 0, 1, "per step at 90 Hz", "D.1", "Velocity damping; the job table is value x 0.2."),
    _p("radius", "curve", 0.02, 0.001, 1, "m", "D.8, D.9", "Particle collision radius over depth."),
    # -- inertia
    _p("inertia.anchor", "transform", None, ref="C.4", doc="Optional anchor transform whose motion is (partly) removed from the cloth's felt motion."),
    _p("inertia.anchor_inertia", "float", 0.0, 0, 1, "", "C.4", "How much of the anchor's motion the cloth still feels."),
    _p("inertia.world_inertia", "float", 1.0, 0, 1, "", "C.4", "Fraction of the component's world motion the particles feel (0: carried rigidly)."),
    _p("inertia.movement_inertia_smoothing", "float", 0.4, 0, 1, "", "C.4", "Per-frame smoothing of the component's velocity."),
    _p("inertia.movement_speed_limit", "limit", 5.0, 0, 10, "m/s", "C.4", "Cap on the world movement speed the cloth feels; the rest is shifted rigidly."),
    _p("inertia.rotation_speed_limit", "limit", 720.0, 0, 1440, "deg/s", "C.4", "Cap on the world rotation speed the cloth feels."),
    _p("inertia.local_inertia", "float", 1.0, 0, 1, "", "C.3", "Fraction of the center's per-step motion the particles feel."),
    _p("inertia.local_movement_speed_limit", "limit", False, 0, 10, "m/s", "C.3", "Cap on the felt per-step center speed (off by default; default value when enabled 5)."),
    _p("inertia.local_rotation_speed_limit", "limit", False, 0, 1440, "deg/s", "C.3", "Cap on the felt per-step center rotation speed (off by default; default value when enabled 720)."),
    _p("inertia.depth_inertia", "float", 0.0, 0, 1, "", "D.1", "Makes root-side particles follow the center's step motion more."),
    _p("inertia.centrifugal_acceleration", "float", 0.0, 0, 1, "", "D.10", "Centrifugal boost while the center rotates."),
    _p("inertia.particle_speed_limit", "limit", 4.0, 0, 10, "m/s", "D.10", "Cap on each particle's speed."),
    _p("inertia.teleport_mode", "enum", "none", ref="C.4", doc="What a jump beyond the teleport thresholds does: none, reset (snap to the animated pose), keep (carry the shape over).",
       choices=("none", "reset", "keep")),
    _p("inertia.teleport_distance", "float", 0.5, 0, 1e6, "m", "C.4", "Teleport distance threshold per frame."),
    _p("inertia.teleport_rotation", "float", 90.0, 0, 360, "deg", "C.4", "Teleport rotation threshold per frame."),
    # -- constraints
    _p("tether.distance_compression", "float", 0.4, 0, 1, "", "D.3", "How far a particle may approach its root (compression limit is 1 - value)."),
    _p("distance.stiffness", "curve", {"value": 1.0, "curve": [1.0, 0.5], "use_curve": False}, 0, 1, "", "D.4", "Distance constraint stiffness over depth (horizontal links get half)."),
    _p("triangle_bending.stiffness", "float", 1.0, 0, 1, "", "D.7", "Triangle bending and volume stiffness (mesh connection modes only)."),
    _p("angle_restoration.use", "bool", True, ref="D.6", doc="Restore each edge towards its rest direction."),
    _p("angle_restoration.stiffness", "curve", {"value": 0.2, "curve": [1.0, 0.2]}, 0, 1, "", "D.6", "Restoration stiffness over depth; the job table is value x 0.2."),
    _p("angle_restoration.velocity_attenuation", "float", 0.8, 0, 1, "", "D.6", "Fraction of the restoration correction not turned into velocity."),
    _p("angle_restoration.gravity_falloff", "float", 0.0, 0, 1, "", "D.6", "Weakens restoration (to 1 - value) as the cloth's center frame turns away from its build orientation against gravity (gravity_dot of C.3): no effect while the build orientation is kept, full upside down."),
    _p("angle_limit.use", "bool", False, ref="D.5", doc="Limit the angle between each edge and its rest direction."),
    _p("angle_limit.limit_angle", "curve", {"value": 60.0, "curve": [0.0, 1.0]}, 0, 180, "deg", "D.5", "Maximum angle over depth (evaluated without clamp)."),
    _p("angle_limit.stiffness", "float", 1.0, 0, 1, "", "D.5", "How far a violating edge is brought back to the limit per iteration."),
    _p("motion.use_max_distance", "bool", False, ref="D.9", doc="Keep each particle within max_distance of its animated position."),
    _p("motion.max_distance", "curve", 0.3, 0, 5, "m", "D.9", "Maximum distance from the animated pose (evaluated at depth^2)."),
    _p("motion.use_backstop", "bool", False, ref="D.9", doc="Keep particles outside a backstop sphere behind the animated pose."),
    _p("motion.backstop_radius", "float", 10.0, 0, 10, "m", "D.9", "Backstop sphere radius."),
    _p("motion.backstop_distance", "curve", 0.0, 0, 1, "m", "D.9", "Backstop offset along -normal_axis (evaluated at depth^2)."),
    _p("motion.stiffness", "float", 1.0, 0, 1, "", "D.9", "Stiffness of the motion constraint."),
    _p("collider_collision.mode", "enum", "point", ref="D.8", doc="Collider collision: none, point (particle spheres) or edge (proxy edges).",
       choices=("none", "point", "edge")),
    _p("collider_collision.friction", "float", 0.05, 0, 0.5, "", "D.8, D.10", "Dynamic and static friction against colliders."),
    # -- culling (distance culling; camera culling has no camera here)
    _p("culling.distance_culling_length", "limit", False, 0, 100, "m", "H.1", "Stop simulating beyond this distance from the reference transform (off by default; default value when enabled 30)."),
    _p("culling.distance_culling_fade_ratio", "float", 0.2, 0, 1, "", "H.1", "Fraction of the culling length over which the cloth fades to the animated pose."),
    _p("culling.distance_culling_reference", "transform", None, ref="H.1", doc="Transform the culling distance is measured from (the main camera in Unity)."),
    # -- wind (the scene's `wind:` zones, docs/scene-format.md; magica_py/wind)
    _p("wind.influence", "float", 1.0, 0, 2, "", "D.1", "Scale of every wind this cloth feels (0 switches wind off for it)."),
    _p("wind.frequency", "float", 1.0, 0, 2, "", "C.3, D.1", "Speed of the wind's phase: each zone's time advances by min((0.2 + 0.5 main/7.5) frequency, 1.5) per second."),
    _p("wind.turbulence", "float", 1.0, 0, 2, "", "D.1", "Scales the zones' turbulence: the swing of the direction (up to 45 degrees) and the gusting of the speed."),
    _p("wind.blend", "float", 0.7, 0, 1, "", "D.1", "Wave shape: 0 a sine, 1 Perlin noise (also widens the sideways swing from 0.1 to 0.5 of the vertical one)."),
    _p("wind.synchronization", "float", 0.7, 0, 1, "", "D.1", "1: every root line of the cloth moves in phase; lower values shift the phase per root line."),
    _p("wind.depth_weight", "float", 0.0, 0, 1, "", "D.1", "0: uniform along the line; 1: wind scaled by depth^2 (roots feel none)."),
    _p("wind.moving_wind", "float", 0.0, 0, 10, "", "C.4, D.1", "Wind against the cloth's own movement: speed = frame moving speed x moving_wind / scale ratio (off below 0.01)."),
    # -- beyond MagicaCloth2 (docs/parameters.md, docs/quality-mode.md)
    _p("solver.rate_mode", "enum", "magica", ref="docs/parameters.md",
       doc="magica: per-step rates tuned for 90 Hz and patched by SimulationPower (MagicaCloth2); frequency_consistent: every per-step quantity is converted by the step (rates 1-(1-k)^(90/f), retentions a^(90/f), per-step amounts x 90/f; projection stiffnesses kept as per-step strengths), so the same parameters give the same model at any frequency, up to soft projections, which stiffen towards the hard constraint as f grows (identical at 90 Hz).",
       choices=("magica", "frequency_consistent")),
    # -- quality mode (docs/quality-mode.md); "auto" = disabled in faithful mode, the measured default in quality mode (enabled/disabled, not on/off: YAML reads on/off as booleans)
    _p("solver.mode", "enum", "faithful", ref="docs/quality-mode.md",
       doc="faithful: MagicaCloth2's BoneCloth as specified (what its users tune against); quality: frequency-consistent rates, time-based smoothing and display, inextensibility and collision last (each switch below set to auto takes its quality default).",
       choices=("faithful", "quality")),
    _p("solver.time_based_smoothing", "enum", "auto", ref="docs/quality-mode.md",
       doc="enabled: movement smoothing is a time constant (exact exponential filter of the component velocity, tuned at 90 fps) and the display interpolates the last two steps in their roots' frames (one step of latency, never more stretch than the state), so the motion does not depend on the frame rate.",
       choices=("auto", "enabled", "disabled")),
    _p("solver.inextensibility", "enum", "auto", ref="docs/quality-mode.md",
       doc="End-of-step pass against stretch: none; tether (root distance clamped to rest x (1 + tether_limit)); ftl (follow-the-leader: each edge clamped to its rest length, root to tip, with the DFTL velocity correction); ftl_tether (both); iterations (distance_iterations extra distance passes); ftl_edges (distance_iterations unilateral projections of every proxy edge, horizontal ones too, then tether and FTL).",
       choices=("auto", "none", "tether", "ftl", "ftl_tether", "iterations", "ftl_edges")),
    _p("solver.tether_limit", "float", 0.02, 0, 0.1, "ratio", "docs/quality-mode.md", "Root-distance stretch the tight tether allows (0.01 = 1 %)."),
    _p("solver.distance_iterations", "float", 2, 1, 16, "passes", "docs/quality-mode.md", "Passes of inextensibility iterations / ftl_edges (an integer)."),
    _p("solver.ftl_damping", "float", 0.9, 0, 1, "", "docs/quality-mode.md", "DFTL velocity correction: fraction of a child's FTL correction removed from its parent's velocity (0: plain FTL, full damping of the stretch)."),
    _p("solver.restoration_drift", "enum", "auto", ref="docs/quality-mode.md",
       doc="enabled: the share of the angle pass's correction kept out of the velocity (the restoration's drift) is taken out of the positions from the angle pass until the inextensibility pass (tether, ftl, ftl_tether, ftl_edges) has run, so the constraints in between turn into velocity only what the step's motion stretched; then it is put back and projected by the same pass without velocity: a drift the constraints bend, never a velocity growing with the frequency.",
       choices=("auto", "enabled", "disabled")),
    _p("solver.distance_velocity", "enum", "auto", ref="docs/quality-mode.md",
       doc="attenuated: 70 % of each distance correction becomes velocity (MagicaCloth2); full: all of it (plain PBD, no artificial damping).",
       choices=("auto", "attenuated", "full")),
    _p("solver.contact_speed_limit", "limit", 2.0, 0, 10, "m/s", "docs/quality-mode.md",
       "Quality mode: a particle within the contact range of a collider (its sphere within one radius of the surface, D.8's friction range) at the end of a step moves at most this fast relative to the body point under it (a saturating kinetic friction; times the cloth's scale; false: off). Faithful mode ignores it; collision_mode none turns it off."),
    _p("solver.collision_last", "enum", "auto", ref="docs/quality-mode.md",
       doc="enabled: a final collider projection after the second distance pass and the inextensibility pass, so no particle ends a step inside a collider (a particle that started inside is carried out without its depth becoming velocity); with the time-based display, the display's push out of the colliders at this frame's pose.",
       choices=("auto", "enabled", "disabled")),
)

# Defaults a limit takes when enabled without a value (§F.1 "check (false, v)").
LIMIT_ENABLED_DEFAULTS = {
    "inertia.movement_speed_limit": 5.0,
    "inertia.rotation_speed_limit": 720.0,
    "inertia.local_movement_speed_limit": 5.0,
    "inertia.local_rotation_speed_limit": 720.0,
    "inertia.particle_speed_limit": 4.0,
    "culling.distance_culling_length": 30.0,
}

# ``float`` parameters that take whole numbers only (validated: 2.5 is an error naming the path)
INTEGER_PARAMETERS = frozenset({"solver.distance_iterations"})

PARAMETERS = {d.key: d for d in PARAMETER_DEFS}
