"""Simulation state: the packed lane tables of every block (docs/solver.md §D.0, §C, §G).

Every table is a ``lanes.RowTable`` (float64, ``(items, rows * LANES)``; ``solver/lanes.py``);
world space, metres and seconds. The field constants below are the first columns of the
fields, used by the kernels with ``lanes.get3`` / ``put3``.

* ``PARTICLE`` (``PS``): one item per particle slot ``g = block particle base + j`` (j the
  particle's index in its team), lane = the team's lane in its block;
* ``TRIANGLE_STATE`` / ``EDGE_STATE``: per-triangle and per-edge scratch of E.3 and of quality
  mode's edge projection (one item per triangle / edge slot of the block);
* ``TEAM`` (``TS``): one item per block, a lane per team: center, inertia, flags, weights;
* ``COLLIDER`` (``CS``): one item per collider slot of the block (colliders are per team,
  §G.3: a collider shared by two cloths is simulated as two slots).

A step never allocates: every buffer a kernel needs is a field here.
"""
from __future__ import annotations

from magica_py.solver.lanes import INTEGER, LANES, QUATERNION, RowTable

PARTICLE = RowTable("particle state", "particle slot")
_p = PARTICLE.add
# animated pose (C.1 writes position/rotation each frame; E.1 overwrites position with the display)
POSITION = _p("position", 3, "m; base pose skinned this frame (C.1), then display position (E.1)")
ROTATION = _p("rotation", 4, "xyzw; base rotation (C.1), then simulated rotation (E.2/E.3)", QUATERNION)
BASE_POS_BUFFER = _p("base_pos_buffer", 3, "m; animated pose of this frame kept for E.2 (E.1)")
BASE_ROT_BUFFER = _p("base_rot_buffer", 4, "xyzw; animated rotation of this frame kept for E.2 (E.1)", QUATERNION)
# simulation state (D.0)
NEXT_POS = _p("next_pos", 3, "m; prediction being corrected within a step")
OLD_POS = _p("old_pos", 3, "m; final position of the previous step (D.10)")
VELOCITY_POS = _p("velocity_pos", 3, "m; reference position for the end-of-step velocity")
VELOCITY = _p("velocity", 3, "m/s; velocity carried to the next step (D.10)")
REAL_VELOCITY = _p("real_velocity", 3, "m/s; (next - old)/dt of the last step (D.10)")
BASE_POS = _p("base_pos", 3, "m; animated pose interpolated at this step (D.1)")
BASE_ROT = _p("base_rot", 4, "xyzw; animated rotation interpolated at this step (D.1)", QUATERNION)
OLD_POSITION = _p("old_position", 3, "m; animated pose of the last frame that ran steps (E.1)")
OLD_ROTATION = _p("old_rotation", 4, "xyzw; same, rotation (E.1)", QUATERNION)
DISP_POS = _p("disp_pos", 3, "m; display position (E.1)")
FRICTION = _p("friction", 1, "[0,1]; collision friction, decays x0.6 per step (D.8, D.10)")
STATIC_FRICTION = _p("static_friction", 1, "[0,1]; static friction ramp (D.10)")
COLLISION_NORMAL = _p("collision_normal", 3, "unit or 0; contact normal of the last step (D.8)")
STEP_BASIC_POS = _p("step_basic_pos", 3, "m; rest reference of this step (D.2)")
STEP_BASIC_ROT = _p("step_basic_rot", 4, "xyzw; rest reference rotation of this step (D.2)", QUATERNION)
INVERSE_MASS = _p("inverse_mass", 1, "D.4's inverse mass of this pass: 1/(1 + 3 friction + 5 (1 - depth)^2), 1/50 "
                  "when fixed (each distance pass writes it first)")
K_VERTICAL = _p("k_vertical", 1, "D.4's stiffness of vertical links at the particle's depth, this pass")
K_HORIZONTAL = _p("k_horizontal", 1, "D.4's stiffness of horizontal and shear links, this pass")
# transform data (E.4)
TRANSFORM_POSITION = _p("transform_position", 3, "m; world position written to the bone (E.4)")
TRANSFORM_ROTATION = _p("transform_rotation", 4, "xyzw; world rotation written to the bone (E.4)", QUATERNION)
# the end of the rows every scene's stages carry from one stage to the next (the read-ahead,
# frame.warm_block, fetches them for every block; the scratch and the optional stages' rows
# below only where the frame compiles a stage that reads them)
CARRIED_ROWS = PARTICLE.rows
# the stages' scratch: values that live within one stage call (a partner's values gathered next
# to the particle being solved, so that the solving loop touches one item per table, lanes.py;
# sums over a particle's links). One pool of rows that every stage reuses under its own names
# (``PARTICLE.share``): stages run one after another, so only the names one stage uses at
# once must not overlap (tests/test_row_tables.py checks it per module): 32 rows where separate
# fields would take 74 (docs/BENCHMARKS.md, session 23).
STAGE_SCRATCH = _p("stage_scratch", 32, "scratch rows of the stages (the names shared over them below)")


def _s(name: str, size: int, offset: int, doc: str) -> int:
    """A scratch name over rows ``offset .. offset + size`` of the pool (its first column)."""
    return PARTICLE.share(name, size, "stage_scratch", doc, offset=offset)


# the steps' stages (D.3-D.9, quality mode) and E.1's display
PARTNER_POS = _s("partner_pos", 3, 0, "m; a partner's position (gathered within a stage)")
PARTNER_BASE = _s("partner_base", 3, 3, "m; a partner's rest reference (gathered within a stage)")
PARTNER_W = _s("partner_w", 1, 6, "a partner's inverse mass (gathered within a stage)")
PARTNER_VELOCITY_POS = _s("partner_velocity_pos", 3, 7, "m; a partner's velocity_pos (D.5)")
PARTNER_ROTATION = _s("partner_rotation", 4, 10, "xyzw; a partner's rotation (D.5)")
ACCUM3 = _s("accum3", 3, 14, "m; a correction summed over a particle's links within a stage")
ACCUM_N = _s("accum_n", 1, 17, "the number of links summed in accum3")
CONTACT_NORMAL_SUM = _s("contact_normal_sum", 3, 18, "D.8 point mode: normals of the colliders penetrated")
CONTACT_NEAR_SUM = _s("contact_near_sum", 3, 21, "D.8 point mode: normals of the colliders within range")
CONTACT_MIN_DIST = _s("contact_min_dist", 1, 24, "m; D.8 point mode and the contact speed limit: closest distance "
                      "within range")
CONTACT_BODY_VELOCITY = _s("contact_body_velocity", 3, 25, "m/s; the contact speed limit: velocity of the nearest "
                           "collider's body point at the particle")
# C.1 (D.7 shares these rows: bend_partner_*)
BONE_MATRIX = _s("bone_matrix", 12, 0, "C.1: the first three rows of the bone's local-to-world matrix, row major "
                 "(gathered from the hierarchy)")
# E.2 (from row 6 on: E.4 uses parent_rotation beside partner_pos / partner_base; D.7 shares child_rest_sum)
PARENT_ROTATION = _s("parent_rotation", 4, 6, "xyzw; E.2 and E.4: the parent bone's rotation (gathered)")
PARENT_BASE_ROT = _s("parent_base_rot", 4, 10, "xyzw; E.2: the parent bone's animated rotation")
PARENT_BASE_POS = _s("parent_base_pos", 3, 14, "m; E.2: the parent bone's animated position")
PARENT_POSITION = _s("parent_position", 3, 17, "m; E.2: the parent bone's display position")
CHILD_REST_EDGE = _s("child_rest_edge", 3, 20, "m; E.2: this child's rest edge from its parent (tv)")
CHILD_EDGE = _s("child_edge", 3, 23, "m; E.2: this child's simulated edge (its rest edge when fixed)")
CHILD_REST_SUM = _s("child_rest_sum", 3, 26, "m; E.2: the children's rest edges summed (ctv); D.7: bend_rest / "
                    "sign / ok")
CHILD_EDGE_SUM = _s("child_edge_sum", 3, 29, "m; E.2: the children's simulated edges summed (cv)")
# E.4 (beside partner_pos, partner_base, parent_rotation)
LOCAL_OUT_POSITION = _s("local_out_position", 3, 10, "m; E.4: the local position the bone is written with")
LOCAL_OUT_ROTATION = _s("local_out_rotation", 4, 13, "xyzw; E.4: the local rotation the bone is written with")
PARENT_HAS_NODE = _s("parent_has_node", 1, 17, "E.4: 1 when a fixed bone has a parent node")
# D.7's per-pair scratch (constraints/bending.py): a pair's vertices 1-3 and rest values
# gathered into its vertex 0's slot, solved there, the corrections scattered back
BEND_PARTNER_POS = _s("bend_partner_pos", 9, 0, "m; D.7: next_pos of the pair's vertices 1, 2, 3 (gathered), then "
                      "their corrections (solved)")
BEND_PARTNER_W = _s("bend_partner_w", 3, 9, "D.7: inverse masses of the pair's vertices 1, 2, 3 (gathered)")
BEND_REST = _s("bend_rest", 1, 26, "rad or 1000 m^3; D.7: the pair's rest angle or rest volume x scale ratio "
               "(gathered)")
BEND_SIGN = _s("bend_sign", 1, 27, "D.7: the dihedral pair's sign (gathered)")
BEND_OK = _s("bend_ok", 1, 28, "D.7: 1 where the pair's correction applies (solved)")
# the optional stages' rows, a span each (``*_ROWS``: first row, end), so that a scene's
# read-ahead can leave out the spans of the stages it does not compile
# fixed-point accumulators of bending and edge collision (§0.2; 1 unit = 1e-6 m)
ACCUM_VECTOR = _p("accum_vector", 3, "1e-6 m integer units summed as float64 (exact below 2^53)")
ACCUM_COUNT = _p("accum_count", 1, "number of contributions", INTEGER)
BEND_INVERSE_MASS = _p("bend_inverse_mass", 1, "inverse mass of this bending pass (D.7, per step)")
ACCUM_FRICTION = _p("accum_friction", 1, "edge collision recorded friction (fixed-point max)")
ACCUM_NORMAL = _p("accum_normal", 3, "edge collision normal sum")
BENDING_EDGE_ROWS = (ACCUM_VECTOR // LANES, PARTICLE.rows)   # bending or edge collision
# angle constraint buffers (D.5/D.6), written in its buffering pass (the limit's only with the limit)
ANGLE_LENGTH = _p("angle_length", 1, "m; segment length when the angle routine starts")
ANGLE_LOCAL_POS = _p("angle_local_pos", 3, "unit; rest edge direction in the parent's frame")
ANGLE_LOCAL_ROT = _p("angle_local_rot", 4, "xyzw; rest rotation relative to the parent", QUATERNION)
ANGLE_INVERSE_MASS = _p("angle_inverse_mass", 1, "1/(1 + 3 friction) of this angle pass (per step)")
ANGLE_REST_LENGTH = _p("angle_rest_length", 1, "m; length of the rest edge (restoration, per step)")
ANGLE_REST_DIRECTION = _p("angle_rest_direction", 3, "unit; the rest edge's direction (restoration, per step)")
ANGLE_ROTATION = _p("angle_rotation", 4, "xyzw; working rotation of the limit pass", QUATERNION)
ANGLE_LIMIT = _p("angle_limit", 1, "rad; limit angle at the particle's depth (per step)")
ANGLE_LIMIT_COS = _p("angle_limit_cos", 1, "cos of angle_limit: the no-violation test without acos")
ANGLE_RESTORATION_K = _p("angle_restoration_k", 1, "restoration stiffness of this step (curve, rate, gravity factor)")
ANGLE_RARE = _p("angle_rare", 1, "scratch of D.5/D.6: 1 where this iteration's lean pass met a limit violation, "
                "an opposite swing or an opposite restoration turn (the lane is solved again on the full path)")
ANGLE_ROWS = (ANGLE_LENGTH // LANES, PARTICLE.rows)
# display of quality mode (display.py): the last two step states in their display frame
# (the particle's fixed root, or the team center), written at the end of each step (D.10)
DISPLAY_LOCAL = _p("display_local", 3, "m; state of the last step in its display frame (D.10)")
DISPLAY_PREV_LOCAL = _p("display_prev_local", 3, "m; state of the step before it, same frame (D.10)")
DISPLAY_HISTORY = _p("display_history", 1, "0-2: step states recorded since the last reset (C.5 sets 0)", INTEGER)
# quality mode's edge projection (edge_projection.edge_projection_lane, per step)
PROJECTION_INVERSE_MASS = _p("projection_inverse_mass", 1, "inverse mass of the edge projection (0: fixed)")
PROJECTION_GATHER = _p("projection_gather", 3, "W J^T p of the projection's conjugate gradients")
PROJECTION_CONTACT = _p("projection_contact", 3, "unit or 0; direction collision last pushed it this step")
QUALITY_DRIFT = _p("quality_drift", 3, "m; the angle pass's share of this step's correction kept out of the "
                   "velocity (restoration drift)")
DISPLAY_FRACTION = _p("display_fraction", 1, "[0,1]; scratch of the quality display: the particle's move "
                      "fraction in a move pass (quality_display.py, the frame)")
QUALITY_ROWS = (DISPLAY_LOCAL // LANES, PARTICLE.rows)
del _p, _s

TRIANGLE_STATE = RowTable("triangle state", "triangle slot")
TRIANGLE_NORMAL = TRIANGLE_STATE.add("triangle_normal", 3, "unit or 0; display normal of each triangle (E.3, per frame)")
TRIANGLE_TANGENT = TRIANGLE_STATE.add("triangle_tangent", 3, "unit; display uv tangent of each triangle (E.3, per frame)")

EDGE_STATE = RowTable("edge state", "edge slot")
_e = EDGE_STATE.add
EDGE_NORMAL = _e("edge_normal", 3, "unit direction a -> b of a stretched edge, 0 otherwise")
EDGE_LAMBDA = _e("edge_lambda", 1, "m; the edge projection's multiplier")
EDGE_RESIDUAL = _e("edge_residual", 1, "m; conjugate-gradient residual")
EDGE_DIRECTION = _e("edge_direction", 1, "m; conjugate-gradient search direction")
EDGE_PRODUCT = _e("edge_product", 1, "m; (J W J^T + compliance) times the search direction")
EDGE_DIAGONAL = _e("edge_diagonal", 1, "the edge's diagonal entry of J W J^T + compliance")
EDGE_COMPLIANCE = _e("edge_compliance", 1, "the edge's compliance times (w_a + w_b)")
EDGE_ACTIVE = _e("edge_active", 1, "the stretched edges of a team, listed from its first edge slot", INTEGER)
EDGE_DISPLAY_BOUND = _e("edge_display_bound", 1, "m; the longest the quality display may show the edge "
                        "(quality_display.display_edge_bound, the frame)")
del _e

WIND_SLOTS = 4   # one area (or global) zone and up to three additive zones (§C, TeamWindData)

TEAM = RowTable("team state", "block")
_t = TEAM.add
# flags (A.7 clears reset, keep_teleport, inertia_shift, running at the end of a frame)
RESET = _t("reset", 1, "1: snap particles to the base pose this frame (C.5)", INTEGER, fill=1)
TIME_RESET = _t("time_reset", 1, "1: time counters were reset (build, ResetCloth)", INTEGER, fill=1)
KEEP_TELEPORT = _t("keep_teleport", 1, "1: carry the shape rigidly with the component this frame", INTEGER)
INERTIA_SHIFT = _t("inertia_shift", 1, "1: a frame shift is applied this frame (C.4/C.5)", INTEGER)
RUNNING = _t("running", 1, "1: the team runs at least one step this frame", INTEGER)
ACTIVE = _t("active", 1, "1: simulated this frame (enabled, not culled, not scale-suspended)", INTEGER)
ENABLED = _t("enabled", 1, "1: component enabled (lane in use)", INTEGER)
CULLED = _t("culled", 1, "1: distance culled", INTEGER)
SCALE_SUSPENDED = _t("scale_suspended", 1, "1: component scale below 1e-6 (A.4)", INTEGER)
GUARD_CODE = _t("guard_code", 1, "0 ok, 1 non-finite, 2 speed bound exceeded (guards.py)", INTEGER)
GUARD_NON_FINITE_SEEN = _t("guard_non_finite_seen", 1, "1: a particle of the team is non-finite (E.5 check, this frame)",
                           INTEGER)
GUARD_TOO_FAST_SEEN = _t("guard_too_fast_seen", 1, "1: a particle of the team is above the speed bound (E.5 check)",
                         INTEGER)
TRANSFORM_OK = _t("transform_ok", 1, "1: every value of the team's transform data is finite (E.4, this frame)", INTEGER)
STEP_RUNS = _t("step_runs", 1, "1: the team runs the block's current step (A.6, begin of each step)", INTEGER)
FRAME_INTERPOLATION = _t("frame_interpolation", 1, "[0,1]: the team's frame interpolation at this step (A.6)")
DISPLAY_T = _t("display_t", 1, "[0,1]: E.1's frame interpolation of the display (the frame, before the end stages)")
DISPLAY_ALPHA = _t("display_alpha", 1, "[0,1): quality display's time since the last step / dt (the frame)")
DISPLAY_LANE = _t("display_lane", 1, "quality display's progress of the lane (quality_display.py, the frame): "
                  "0 done, 1 shown, 2 moving, 3 in the move passes", INTEGER)
PROJECTION_NEEDED = _t("projection_needed", 1, "1: an edge of the lane is stretched beyond the edge projection's "
                       "threshold (edge_projection.stretched_lanes, the inextensibility pass)", INTEGER)
DISPLAY_COMMON = _t("display_common", 1, "[0,1]; quality display: the team's common move fraction (the frame)")
RAMP_FROM_BUILD = _t("ramp_from_build", 1, "1 while the team's last reset was the build reset (quality)", INTEGER)
# component pose (C.2)
COMPONENT_POS = _t("component_pos", 3, "m; component world position read this frame")
COMPONENT_ROT = _t("component_rot", 4, "xyzw", QUATERNION)
COMPONENT_SCALE = _t("component_scale", 3, "lossy scale", fill=1.0)
OLD_COMPONENT_POS = _t("old_component_pos", 3, "m; last frame's component position (shift pivot)")
OLD_COMPONENT_ROT = _t("old_component_rot", 4, "xyzw", QUATERNION)
OLD_COMPONENT_SCALE = _t("old_component_scale", 3, "", fill=1.0)
COMPONENT_SCALE_RATIO = _t("component_scale_ratio", 1, "|scale|/|init scale|", fill=1.0)
# center (C.2, C.3)
FRAME_WORLD_POS = _t("frame_world_pos", 3, "m; center of this frame")
FRAME_WORLD_ROT = _t("frame_world_rot", 4, "xyzw", QUATERNION)
FRAME_WORLD_SCALE = _t("frame_world_scale", 3, "", fill=1.0)
OLD_FRAME_WORLD_POS = _t("old_frame_world_pos", 3, "m; center of the last frame that ran steps")
OLD_FRAME_WORLD_ROT = _t("old_frame_world_rot", 4, "", QUATERNION)
OLD_FRAME_WORLD_SCALE = _t("old_frame_world_scale", 3, "", fill=1.0)
NOW_WORLD_POS = _t("now_world_pos", 3, "m; center interpolated at this step")
NOW_WORLD_ROT = _t("now_world_rot", 4, "", QUATERNION)
OLD_WORLD_POS = _t("old_world_pos", 3, "m; center at the previous step")
OLD_WORLD_ROT = _t("old_world_rot", 4, "", QUATERNION)
STEP_VECTOR = _t("step_vector", 3, "m; center motion of this step")
STEP_ROTATION = _t("step_rotation", 4, "center rotation of this step", QUATERNION)
INERTIA_VECTOR = _t("inertia_vector", 3, "m; part of step_vector removed rigidly (C.3)")
INERTIA_ROTATION = _t("inertia_rotation", 4, "", QUATERNION)
INERTIA_SLERP_TO = _t("inertia_slerp_to", 4, "xyzw; step_rotation on inertia_rotation's side (math3d.q_slerp_path), "
                      "D.1's depth-inertia slerp from inertia_rotation towards step_rotation (C.3, per step)",
                      QUATERNION)
INERTIA_SLERP_ANGLE = _t("inertia_slerp_angle", 1, "rad; the angle of that slerp (q_slerp_path)")
INERTIA_SLERP_INV_SIN = _t("inertia_slerp_inv_sin", 1, "1 / sin(inertia_slerp_angle) (q_slerp_path)")
INERTIA_SLERP_FAR = _t("inertia_slerp_far", 1, "1 where that slerp takes its sine path, 0 its lerp (q_slerp_path)")
STEP_MOVE_INERTIA_RATIO = _t("step_move_inertia_ratio", 1, "C.3 m")
STEP_ROTATION_INERTIA_RATIO = _t("step_rotation_inertia_ratio", 1, "C.3 r")
ANGULAR_VELOCITY = _t("angular_velocity", 1, "rad/s of the center this step")
ROTATION_AXIS = _t("rotation_axis", 3, "unit axis of the center rotation this step, or 0")
SCALE_RATIO = _t("scale_ratio", 1, "max(|scale|/|init scale|, 1e-6) at this step", fill=1.0)
LENGTH_UNIT = _t("length_unit", 1, "m; the cloth's length unit (parameters.length_unit; C.2 writes it; 1 faithful)",
                 fill=1.0)
GRAVITY_DOT = _t("gravity_dot", 1, "C.3", fill=1.0)
GRAVITY_RATIO = _t("gravity_ratio", 1, "C.3", fill=1.0)
VELOCITY_WEIGHT = _t("velocity_weight", 1, "stabilisation ramp after a reset [0,1]")
BLEND_WEIGHT = _t("blend_weight", 1, "[0,1] display blend (C.3, H.3)")
DISTANCE_WEIGHT = _t("distance_weight", 1, "[0,1] distance-culling fade (H.1)", fill=1.0)
SMOOTHING_VELOCITY = _t("smoothing_velocity", 3, "m/s; smoothed component velocity (C.4)")
FRAME_SHIFT_VECTOR = _t("frame_shift_vector", 3, "m; rigid shift of this frame (C.4)")
FRAME_SHIFT_ROTATION = _t("frame_shift_rotation", 4, "", QUATERNION)
FRAME_MOVING_SPEED = _t("frame_moving_speed", 1, "m/s (C.4 wind bookkeeping)")
FRAME_MOVING_DIRECTION = _t("frame_moving_direction", 3, "unit or 0; direction of frame_moving_speed (C.4)")
# anchor (C.4.1)
ANCHOR_POS = _t("anchor_pos", 3, "m; anchor pose of this frame")
ANCHOR_ROT = _t("anchor_rot", 4, "", QUATERNION)
OLD_ANCHOR_ROT = _t("old_anchor_rot", 4, "", QUATERNION)
ANCHOR_COMPONENT_LOCAL_POS = _t("anchor_component_local_pos", 3, "component position in anchor space")
ANCHOR_VALID = _t("anchor_valid", 1, "1: anchor pose stored", INTEGER)
# external force (D.1), applied on every step of the next frame that runs
EXTERNAL_FORCE = _t("external_force", 3, "m/s^2 impact force direction * speed")
EXTERNAL_FORCE_MODE = _t("external_force_mode", 1, "0 none, 1 add, 2 add w/o depth, 3 change, 4 change w/o depth",
                         INTEGER)
# wind (§C team selection, §D.1; magica_py/wind): the zones a team feels this frame, written
# once per frame by wind.selection, phases advanced per step by the wind stage
WIND_ZONE_COUNT = _t("wind_zone_count", 1, "zones felt this frame (<= WIND_SLOTS: one area zone + 3 additive)",
                     INTEGER)
WIND_ZONE_ID = _t("wind_zone_id", WIND_SLOTS, "scene wind zone index of each slot, -1 unused", INTEGER, fill=-1)
WIND_ZONE_TIME = _t("wind_zone_time", WIND_SLOTS, "phase time of each slot (starts at -10000, +freq*dt per step)")
WIND_ZONE_MAIN = _t("wind_zone_main", WIND_SLOTS, "m/s; main speed (radial: attenuated at the team center)")
WIND_ZONE_DIRECTION = _t("wind_zone_direction", 3 * WIND_SLOTS, "unit world direction of each slot (x, y, z "
                         "rows of slot 0, then slot 1, ...)")
WIND_ZONE_TURBULENCE = _t("wind_zone_turbulence", WIND_SLOTS, "the zone's turbulence [0,1]")
MOVING_WIND_MAIN = _t("moving_wind_main", 1, "m/s; wind from the team's own movement at this step (0: none)")
MOVING_WIND_TIME = _t("moving_wind_time", 1, "phase time of the moving wind")
WIND_FELT = _t("wind_felt", 3, "m/s^2; mean wind acceleration over the Move particles at the last step")
# wind (wind.force.wind_block): the lane's part of a step, kept for its particle loop
WIND_RUNS = _t("wind_runs", 1, "1: the lane's particles take wind at this step (wind_lane)", INTEGER)
WIND_ZONE_FRAME = _t("wind_zone_frame", 4 * WIND_SLOTS, "direction_angles (cos x, sin x, cos y, sin y) of each "
                     "slot's direction at this step (4 rows per slot)")
MOVING_WIND_FRAME = _t("moving_wind_frame", 4, "direction_angles of the moving wind's direction at this step")
WIND_LINE = _t("wind_line", 3, "m/s; wind at the root line of the particle being pushed (scratch)")
del _t

COLLIDER = RowTable("collider state", "collider slot")
_c = COLLIDER.add
LOCAL_CENTER = _c("local_center", 3, "m; local offset (G.1)")
SIZE = _c("size", 3, "m; (start radius, end radius, length) as G.1")
FIRST_FRAME = _c("first_frame", 1, "1 until the first frame pose is stored", INTEGER, fill=1)
SCALE_SUSPEND = _c("scale_suspend", 1, "1: scale below 1e-6 this frame: skipped (G.2)", INTEGER)
FRAME_POS = _c("frame_pos", 3, "m; pose read this frame (G.2)")
FRAME_ROT = _c("frame_rot", 4, "", QUATERNION)
FRAME_SCALE = _c("frame_scale", 3, "", fill=1.0)
OLD_FRAME_POS = _c("old_frame_pos", 3, "m; pose of the last frame that ran steps")
OLD_FRAME_ROT = _c("old_frame_rot", 4, "", QUATERNION)
NOW_POS = _c("now_pos", 3, "m; pose at this step (G.3)")
NOW_ROT = _c("now_rot", 4, "", QUATERNION)
C_OLD_POS = _c("old_pos", 3, "m; pose at the previous step (after the local inertia shift)")
C_OLD_ROT = _c("old_rot", 4, "", QUATERNION)
# work data of this step (G.3)
START_OLD = _c("start_old", 3, "m; sphere centre / capsule start, previous step")
END_OLD = _c("end_old", 3, "m; capsule end, previous step")
START_NEW = _c("start_new", 3, "m; sphere centre / capsule start / plane point, this step")
END_NEW = _c("end_new", 3, "m; capsule end, this step")
RADIUS_START = _c("radius_start", 1, "m; scaled radius (sphere, capsule start)")
RADIUS_END = _c("radius_end", 1, "m; scaled capsule end radius")
PLANE_NORMAL = _c("plane_normal", 3, "unit; plane normal this step")
INVERSE_OLD_ROT = _c("inverse_old_rot", 4, "qinv(old rotation)", QUATERNION)
AABB_MIN = _c("aabb_min", 3, "m; swept bounds")
AABB_MAX = _c("aabb_max", 3, "m")
# the quality display's colliders at this frame's pose (quality_display.display_colliders_block)
DISPLAY_START = _c("display_start", 3, "m; sphere centre / capsule start / plane point, this frame's pose")
DISPLAY_END = _c("display_end", 3, "m; capsule end (a sphere's: its centre), this frame's pose")
DISPLAY_RADIUS_START = _c("display_radius_start", 1, "m; sphere / capsule start radius, this frame's scale")
DISPLAY_RADIUS_END = _c("display_radius_end", 1, "m; capsule end radius (a sphere's: its radius)")
DISPLAY_NORMAL = _c("display_normal", 3, "unit; plane normal, this frame's pose")
del _c
