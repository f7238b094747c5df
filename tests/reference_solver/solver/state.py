"""Simulation state: preallocated structure-of-arrays for every team at once (docs/solver.md §D.0, §C, §G).

Three tables, all float64 / int32 / uint8, world space, metres and seconds:

* ``ParticleState`` (one row per particle of every team; a team owns the contiguous rows
  ``team_particle_start[t] : + team_particle_count[t]`` of the solver model; plus a
  per-triangle scratch for E.3 sized like the model's triangle pool);
* ``TeamState`` (one row per team: center, inertia, flags, weights);
* ``ColliderState`` (one row per collider *slot*: colliders are per team, §G.3, so a
  collider shared by two cloths is simulated as two slots).

A step never allocates: every buffer a kernel needs is a field here.
"""
from __future__ import annotations

from reference_solver.solver.fields import F64, I32, U8, allocate, grow, make_soa, reset_rows

V3 = (3,)
Q4 = (4,)
WIND_SLOTS = (4,)   # one area (or global) zone and up to three additive zones (§C, TeamWindData)

PARTICLE_FIELDS = [
    # animated pose (C.1 writes position/rotation each frame; E.1 overwrites position with the display)
    ("position", "particle", V3, F64, "m; base pose skinned this frame (C.1), then display position (E.1)"),
    ("rotation", "particle", Q4, F64, "xyzw; base rotation (C.1), then simulated rotation (E.2/E.3)"),
    ("base_pos_buffer", "particle", V3, F64, "m; animated pose of this frame kept for E.2 (E.1)"),
    ("base_rot_buffer", "particle", Q4, F64, "xyzw; animated rotation of this frame kept for E.2 (E.1)"),
    # simulation state (D.0)
    ("next_pos", "particle", V3, F64, "m; prediction being corrected within a step"),
    ("old_pos", "particle", V3, F64, "m; final position of the previous step (D.10)"),
    ("velocity_pos", "particle", V3, F64, "m; reference position for the end-of-step velocity"),
    ("velocity", "particle", V3, F64, "m/s; velocity carried to the next step (D.10)"),
    ("real_velocity", "particle", V3, F64, "m/s; (next - old)/dt of the last step (D.10)"),
    ("base_pos", "particle", V3, F64, "m; animated pose interpolated at this step (D.1)"),
    ("base_rot", "particle", Q4, F64, "xyzw; animated rotation interpolated at this step (D.1)"),
    ("old_position", "particle", V3, F64, "m; animated pose of the last frame that ran steps (E.1)"),
    ("old_rotation", "particle", Q4, F64, "xyzw; same, rotation (E.1)"),
    ("disp_pos", "particle", V3, F64, "m; display position (E.1)"),
    # quality display (display.py): the last two step states in their display frame (the
    # particle's fixed root, or the team center), written at the end of each step (D.10)
    ("display_local", "particle", V3, F64, "m; state of the last step in its display frame (D.10)"),
    ("display_prev_local", "particle", V3, F64, "m; state of the step before it, same frame (D.10)"),
    ("display_history", "particle", (), U8, "0-2: step states recorded since the last reset (C.5 sets 0)"),
    ("friction", "particle", (), F64, "[0,1]; collision friction, decays x0.6 per step (D.8, D.10)"),
    ("static_friction", "particle", (), F64, "[0,1]; static friction ramp (D.10)"),
    ("collision_normal", "particle", V3, F64, "unit or 0; contact normal of the last step (D.8)"),
    ("step_basic_pos", "particle", V3, F64, "m; rest reference of this step (D.2)"),
    ("step_basic_rot", "particle", Q4, F64, "xyzw; rest reference rotation of this step (D.2)"),
    # angle constraint buffers (D.5/D.6), zeroed after the routine
    ("angle_length", "particle", (), F64, "m; segment length when the angle routine starts"),
    ("angle_local_pos", "particle", V3, F64, "unit; rest edge direction in the parent's frame"),
    ("angle_local_rot", "particle", Q4, F64, "xyzw; rest rotation relative to the parent"),
    ("angle_rest_vector", "particle", V3, F64, "m; rest edge vector in world space (restoration)"),
    ("angle_inverse_mass", "particle", (), F64, "1/(1 + 3 friction) of this angle pass (per step)"),
    ("angle_rest_length", "particle", (), F64, "m; |angle_rest_vector| (restoration, per step)"),
    ("angle_rest_direction", "particle", V3, F64, "unit; angle_rest_vector / its length (restoration, per step)"),
    ("angle_rotation", "particle", Q4, F64, "xyzw; working rotation of the limit pass"),
    ("angle_limit", "particle", (), F64, "rad; limit angle at the particle's depth (per step)"),
    ("angle_limit_cos", "particle", (), F64, "cos of angle_limit: the no-violation test without acos"),
    ("angle_restoration_k", "particle", (), F64, "restoration stiffness of this step (curve, rate, gravity factor)"),
    # fixed-point accumulators of bending and edge collision (§0.2; 1 unit = 1e-6 m)
    ("accum_vector", "particle", V3, F64, "1e-6 m integer units summed as float64 (exact below 2^53)"),
    ("accum_count", "particle", (), I32, "number of contributions"),
    ("bend_inverse_mass", "particle", (), F64, "inverse mass of this bending pass (D.7, per step)"),
    ("accum_friction", "particle", (), F64, "edge collision recorded friction (fixed-point max)"),
    ("accum_normal", "particle", V3, F64, "edge collision normal sum"),
    # transform data (E.4)
    ("transform_position", "particle", V3, F64, "m; world position written to the bone (E.4)"),
    ("transform_rotation", "particle", Q4, F64, "xyzw; world rotation written to the bone (E.4)"),
    # per-triangle scratch of E.3 (one row per triangle of the model's triangle pool)
    ("triangle_normal", "triangle", V3, F64, "unit or 0; display normal of each triangle (E.3, per frame)"),
    ("triangle_tangent", "triangle", V3, F64, "unit; display uv tangent of each triangle (E.3, per frame)"),
    # scratch of quality mode's edge projection (quality.edge_projection_team, per step): one
    # row per particle / per edge of the model's pools
    ("projection_inverse_mass", "particle", (), F64, "inverse mass of the edge projection (0: fixed)"),
    ("projection_gather", "particle", V3, F64, "W J^T p of the projection's conjugate gradients"),
    ("projection_contact", "particle", V3, F64, "unit or 0; direction collision last pushed it this step"),
    ("quality_drift", "particle", V3, F64, "m; the angle pass's share of this step's correction kept out of the velocity (restoration drift)"),
    ("edge_normal", "edge", V3, F64, "unit direction a -> b of a stretched edge, 0 otherwise"),
    ("edge_lambda", "edge", (), F64, "m; the edge projection's multiplier"),
    ("edge_residual", "edge", (), F64, "m; conjugate-gradient residual"),
    ("edge_direction", "edge", (), F64, "m; conjugate-gradient search direction"),
    ("edge_product", "edge", (), F64, "m; (J W J^T + compliance) times the search direction"),
    ("edge_diagonal", "edge", (), F64, "the edge's diagonal entry of J W J^T + compliance"),
    ("edge_compliance", "edge", (), F64, "the edge's compliance times (w_a + w_b)"),
    ("edge_active", "edge", (), I32, "the stretched edges of a team, listed from its first edge row"),
]
ParticleState = make_soa("ParticleState", PARTICLE_FIELDS)

TEAM_FIELDS = [
    # flags (A.7 clears reset, keep_teleport, inertia_shift, running at the end of a frame)
    ("reset", "team", (), U8, "1: snap particles to the base pose this frame (C.5)"),
    ("time_reset", "team", (), U8, "1: time counters were reset (build, ResetCloth)"),
    ("keep_teleport", "team", (), U8, "1: carry the shape rigidly with the component this frame"),
    ("inertia_shift", "team", (), U8, "1: a frame shift is applied this frame (C.4/C.5)"),
    ("running", "team", (), U8, "1: the team runs at least one step this frame"),
    ("active", "team", (), U8, "1: simulated this frame (enabled, not culled, not scale-suspended)"),
    ("enabled", "team", (), U8, "1: component enabled (slot in use)"),
    ("culled", "team", (), U8, "1: distance culled"),
    ("scale_suspended", "team", (), U8, "1: component scale below 1e-6 (A.4)"),
    ("guard_code", "team", (), I32, "0 ok, 1 non-finite, 2 speed bound exceeded (guards.py)"),
    ("collider_start", "team", (), I32, "first collider slot of the team"),
    ("collider_count", "team", (), I32, "collider slots of the team"),
    # component pose (C.2)
    ("component_pos", "team", V3, F64, "m; component world position read this frame"),
    ("component_rot", "team", Q4, F64, "xyzw"),
    ("component_scale", "team", V3, F64, "lossy scale"),
    ("old_component_pos", "team", V3, F64, "m; last frame's component position (shift pivot)"),
    ("old_component_rot", "team", Q4, F64, "xyzw"),
    ("old_component_scale", "team", V3, F64, ""),
    ("component_scale_ratio", "team", (), F64, "|scale|/|init scale|"),
    # center (C.2, C.3)
    ("frame_world_pos", "team", V3, F64, "m; center of this frame"),
    ("frame_world_rot", "team", Q4, F64, "xyzw"),
    ("frame_world_scale", "team", V3, F64, ""),
    ("old_frame_world_pos", "team", V3, F64, "m; center of the last frame that ran steps"),
    ("old_frame_world_rot", "team", Q4, F64, ""),
    ("old_frame_world_scale", "team", V3, F64, ""),
    ("now_world_pos", "team", V3, F64, "m; center interpolated at this step"),
    ("now_world_rot", "team", Q4, F64, ""),
    ("old_world_pos", "team", V3, F64, "m; center at the previous step"),
    ("old_world_rot", "team", Q4, F64, ""),
    ("step_vector", "team", V3, F64, "m; center motion of this step"),
    ("step_rotation", "team", Q4, F64, "center rotation of this step"),
    ("inertia_vector", "team", V3, F64, "m; part of step_vector removed rigidly (C.3)"),
    ("inertia_rotation", "team", Q4, F64, ""),
    ("step_move_inertia_ratio", "team", (), F64, "C.3 m"),
    ("step_rotation_inertia_ratio", "team", (), F64, "C.3 r"),
    ("angular_velocity", "team", (), F64, "rad/s of the center this step"),
    ("rotation_axis", "team", V3, F64, "unit axis of the center rotation this step, or 0"),
    ("scale_ratio", "team", (), F64, "max(|scale|/|init scale|, 1e-6) at this step"),
    ("length_unit", "team", (), F64, "m; the cloth's length unit (parameters.length_unit; C.2 writes it; 1 faithful)"),
    ("gravity_dot", "team", (), F64, "C.3"),
    ("gravity_ratio", "team", (), F64, "C.3"),
    ("velocity_weight", "team", (), F64, "stabilisation ramp after a reset [0,1]"),
    ("blend_weight", "team", (), F64, "[0,1] display blend (C.3, H.3)"),
    ("distance_weight", "team", (), F64, "[0,1] distance-culling fade (H.1)"),
    ("smoothing_velocity", "team", V3, F64, "m/s; smoothed component velocity (C.4)"),
    ("frame_shift_vector", "team", V3, F64, "m; rigid shift of this frame (C.4)"),
    ("frame_shift_rotation", "team", Q4, F64, ""),
    ("frame_moving_speed", "team", (), F64, "m/s (C.4 wind bookkeeping)"),
    ("frame_moving_direction", "team", V3, F64, "unit or 0; direction of frame_moving_speed (C.4)"),
    # anchor (C.4.1)
    ("anchor_pos", "team", V3, F64, "m; anchor pose of this frame"),
    ("anchor_rot", "team", Q4, F64, ""),
    ("old_anchor_rot", "team", Q4, F64, ""),
    ("anchor_component_local_pos", "team", V3, F64, "component position in anchor space"),
    ("anchor_valid", "team", (), U8, "1: anchor pose stored"),
    # external force (D.1), applied on every step of the next frame that runs
    ("external_force", "team", V3, F64, "m/s^2 impact force direction * speed"),
    ("external_force_mode", "team", (), I32, "0 none, 1 add, 2 add w/o depth, 3 change, 4 change w/o depth"),
    # wind (§C team selection, §D.1; magica_py/wind): the zones a team feels this frame, written
    # once per frame by wind.selection.select_team_wind, phases advanced per step by wind_team
    ("wind_zone_count", "team", (), I32, "zones felt this frame (<= WIND_SLOTS: one area zone + 3 additive)"),
    ("wind_zone_id", "team", WIND_SLOTS, I32, "scene wind zone index of each slot, -1 unused"),
    ("wind_zone_time", "team", WIND_SLOTS, F64, "phase time of each slot (starts at -10000, +freq*dt per step)"),
    ("wind_zone_main", "team", WIND_SLOTS, F64, "m/s; main speed (radial: attenuated at the team center)"),
    ("wind_zone_direction", "team", WIND_SLOTS + V3, F64, "unit world direction of each slot"),
    ("wind_zone_turbulence", "team", WIND_SLOTS, F64, "the zone's turbulence [0,1]"),
    ("moving_wind_main", "team", (), F64, "m/s; wind from the team's own movement at this step (0: none)"),
    ("moving_wind_time", "team", (), F64, "phase time of the moving wind"),
    ("wind_felt", "team", V3, F64, "m/s^2; mean wind acceleration over the Move particles at the last step"),
]
TeamState = make_soa("TeamState", TEAM_FIELDS)

COLLIDER_FIELDS = [
    ("collider_index", "slot", (), I32, "index into the scene ColliderSet"),
    ("team", "slot", (), I32, "team owning this slot"),
    ("shape", "slot", (), I32, "0 sphere, 1 capsule, 2 plane"),
    ("transform", "slot", (), I32, "hierarchy node carrying the collider"),
    ("local_center", "slot", V3, F64, "m; local offset (G.1)"),
    ("size", "slot", V3, F64, "m; (start radius, end radius, length) as G.1"),
    ("direction", "slot", (), I32, "capsule axis 0 X, 1 Y, 2 Z"),
    ("reverse_direction", "slot", (), U8, ""),
    ("aligned_on_center", "slot", (), U8, ""),
    ("first_frame", "slot", (), U8, "1 until the first frame pose is stored"),
    ("scale_suspend", "slot", (), U8, "1: scale below 1e-6 this frame: skipped (G.2)"),
    ("frame_pos", "slot", V3, F64, "m; pose read this frame (G.2)"),
    ("frame_rot", "slot", Q4, F64, ""),
    ("frame_scale", "slot", V3, F64, ""),
    ("old_frame_pos", "slot", V3, F64, "m; pose of the last frame that ran steps"),
    ("old_frame_rot", "slot", Q4, F64, ""),
    ("now_pos", "slot", V3, F64, "m; pose at this step (G.3)"),
    ("now_rot", "slot", Q4, F64, ""),
    ("old_pos", "slot", V3, F64, "m; pose at the previous step (after the local inertia shift)"),
    ("old_rot", "slot", Q4, F64, ""),
    # work data of this step (G.3)
    ("start_old", "slot", V3, F64, "m; sphere centre / capsule start, previous step"),
    ("end_old", "slot", V3, F64, "m; capsule end, previous step"),
    ("start_new", "slot", V3, F64, "m; sphere centre / capsule start / plane point, this step"),
    ("end_new", "slot", V3, F64, "m; capsule end, this step"),
    ("radius_start", "slot", (), F64, "m; scaled radius (sphere, capsule start)"),
    ("radius_end", "slot", (), F64, "m; scaled capsule end radius"),
    ("plane_normal", "slot", V3, F64, "unit; plane normal this step"),
    ("inverse_old_rot", "slot", Q4, F64, "qinv(old rotation)"),
    ("aabb_min", "slot", V3, F64, "m; swept bounds"),
    ("aabb_max", "slot", V3, F64, "m"),
]
ColliderState = make_soa("ColliderState", COLLIDER_FIELDS)


# initial values besides zero / identity (a team starts with Reset and TimeReset)
TEAM_FILL = {"reset": 1, "time_reset": 1, "scale_ratio": 1.0, "length_unit": 1.0, "gravity_ratio": 1.0,
             "gravity_dot": 1.0, "distance_weight": 1.0, "component_scale_ratio": 1.0,
             "component_scale": 1.0, "old_component_scale": 1.0,
             "frame_world_scale": 1.0, "old_frame_world_scale": 1.0, "wind_zone_id": -1}
COLLIDER_FILL = {"first_frame": 1, "frame_scale": 1.0}


def allocate_state(particle_count: int, team_count: int, slot_count: int, triangle_count: int = 0,
                   edge_count: int = 0):
    """Fresh state tables sized for the given counts (every team starts with Reset)."""
    particles = allocate(ParticleState, {"particle": particle_count, "triangle": triangle_count,
                                         "edge": edge_count})
    teams = allocate(TeamState, {"team": team_count}, fill=TEAM_FILL)
    colliders = allocate(ColliderState, {"slot": slot_count}, fill=COLLIDER_FILL)
    return particles, teams, colliders


def grow_state(particles, teams, colliders, particle_count: int, team_count: int, slot_count: int,
               triangle_count: int = 0, edge_count: int = 0):
    """The state tables enlarged to the given counts: existing rows copied bit for bit, new
    rows fresh (used when a cloth is added at runtime and a pool has no free chunk)."""
    if (particles.position.shape[0] < particle_count or particles.triangle_normal.shape[0] < triangle_count
            or particles.edge_lambda.shape[0] < edge_count):
        particles = grow(ParticleState, particles, {
            "particle": max(particle_count, particles.position.shape[0]),
            "triangle": max(triangle_count, particles.triangle_normal.shape[0]),
            "edge": max(edge_count, particles.edge_lambda.shape[0])})
    if teams.reset.shape[0] < team_count:
        teams = grow(TeamState, teams, {"team": team_count}, fill=TEAM_FILL)
    if colliders.shape.shape[0] < slot_count:
        colliders = grow(ColliderState, colliders, {"slot": slot_count}, fill=COLLIDER_FILL)
    return particles, teams, colliders


def free_particle_rows(particles, start: int, count: int) -> None:
    reset_rows(ParticleState, particles, "particle", start, start + count)


def free_team_row(teams, team: int) -> None:
    """A removed team's row: fresh values, disabled."""
    reset_rows(TeamState, teams, "team", team, team + 1, fill=TEAM_FILL)
    teams.enabled[team] = 0
    teams.active[team] = 0


def free_collider_rows(colliders, start: int, count: int) -> None:
    reset_rows(ColliderState, colliders, "slot", start, start + count, fill=COLLIDER_FILL)
