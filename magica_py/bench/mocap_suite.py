"""The motion-capture stress suite (issue 16 item 7; ``magica-py stability --suite mocap``).

Each case is a scene ``configs/hard/mocap_*.yaml`` (violent procedural motion written by
``benchmarks/mocap_scenes.py``, and CMU capture 01_01) on the character rig (hair fan + skirt)
or on Godette (her VRM spring-bone cloths). Every case runs in both modes (faithful,
quality) at 30, 60, 144 and 240 fps (90 Hz simulation), for the scene's motion and then
``REST`` s standing still, and reports per run and per cloth kind (``skirt`` for cloths named
so, ``hair`` for every other cloth: hair, ribbons, hair balls):

* displayed edge stretch: every proxy edge of the bones after the write-back (what a user
  sees), ``|p1 - p0| / rest - 1``, max over the frames;
* simulated edge stretch: the same of the solver state at the end of a step, after a frame
  that ran steps: its last step's state (``particles.old_pos``) and the one before it
  (``old_pos - real_velocity dt``, D.10), the two states the quality display interpolates; at
  60, 144 and 240 fps that is every step, at 30 fps two steps in three;
* root-distance stretch, displayed and simulated (a particle's distance to its root);
* deepest penetration at the end of a step, against the colliders at that step's pose (the
  solver's collider slots): the deepest particle centre inside a collider (m; > 0 means a
  centre inside) and the deepest particle sphere, as % of its radius;
* fastest ejection: for particles touching a body part at the end of a step (sphere within
  one radius of a collider carried by a bone; the static ground is not a body part), their
  world velocity against the body part's velocity at the particle (rigid motion of the
  collider's bone over the frame, rotation included): ``|v| - |v_body|`` (the issue's bound:
  at most 2 m/s), ``|v - v_body|`` and the ejection proper ``v.n - max(v_body.n, 0)``. The
  solver's velocity is in its inertia-shifted frame (C.3/C.4 carry part of the body's motion
  rigidly, so a head that stops in the world still moves there): ``v`` is the body's world
  velocity plus the particle's velocity relative to the collider slot's motion over the last
  step in the solver's frame (``solver_body_velocity``) (the
  speed leaving the surface beyond the body's own push, ``metrics.ejection_speeds``: a strand
  swinging along the body or left behind by it counts 0);
* the same two readings in contact only (``contact_pairs``): of those pairs, the ones whose
  sphere touches the collider (gap at most ``TOUCH_TOLERANCE`` of its radius) or whose
  particle D.8 pushed in that step (``pushed_by_collision``). "Within one radius" also counts
  a strand in free flight past a body part: a 2 cm particle flying straight at 4 m/s past a
  still 10 cm sphere reads v.n = |v| s / (R + r + gap) (s its distance from the tangent point),
  2.06 m/s at a gap of one radius, with no contact force at all; and a strand the body carried
  and then stopped under reads the body's old speed against its new one;
  penetration and ejection are seen at the end of each frame's last step only (the solver
  runs a frame's steps in one call), every step at 144 and 240 fps, two in three at 60 fps,
  one in three at 30 fps;
* settling time: from the end of the motion, when every bone of the kind moves below
  ``REST_SPEED`` on the display and stays so (``metrics.settling_time``); "> REST s" when not.

The metrics themselves are ``bench.metrics`` (one implementation each); this module only
gathers the arrays of a run.
"""
from __future__ import annotations

import math
import pathlib
import time
from dataclasses import dataclass

import numpy as np

from magica_py.bench import metrics as M
from magica_py.bench.stability import find_case
from magica_py.bench.variants import Variant, prepare, rest_geometry
from magica_py.scene.colliders import static_transform_name

HARD_DIR = pathlib.Path(__file__).resolve().parents[2] / "configs" / "hard"
FRAME_RATES = (30.0, 60.0, 144.0, 240.0)
MODES = ("quality", "faithful")
REST = 4.0              # s of standing still run after the motion (settling window)
REST_SPEED = 0.02       # m/s: a bone slower than this is at rest (as the hard-case suite)
CONTACT_RANGE = 1.0     # particle radii: a sphere closer than this to a collider is near it (the first readings)
TOUCH_TOLERANCE = 0.05  # particle radii: a sphere this close to a collider at the end of a step touches it
KINDS = ("hair", "skirt")


@dataclass(frozen=True)
class MocapCase:
    name: str
    scene: str                 # file name in configs/hard
    motion_end: float          # s: the motion is over (standing still afterwards)
    rig: str                   # "character" or "godette"
    motion: str                # what the motion is, for the report

    @property
    def path(self) -> str:
        return str(HARD_DIR / self.scene)

    @property
    def duration(self) -> float:
        return self.motion_end + REST


def _cases() -> tuple[MocapCase, ...]:
    motions = (("backflip", 1.5, "full backward turn in 0.5 s of a jump"),
               ("spin", 1.7, "3 rev/s about the vertical for 1.5 s, running on the spot"),
               ("roll", 1.8, "crouch and forward roll (360 deg in 0.8 s)"),
               ("sprint", 1.9, "sprint start and stop at 10 m/s^2 (0-6-0 m/s)"),
               ("jitter", 1.8, "root +-5 mm and head +-3 deg noise re-drawn every 1/120 s, 1.5 s"),
               ("cmu", 2.0, "CMU 01_01 seconds 2-4 (a forward jump), retargeted"))
    out = []
    for rig in ("character", "godette"):
        for motion, end, text in motions:
            scene = "mocap_spin.yaml" if (motion, rig) == ("spin", "character") else f"mocap_{motion}_{rig}.yaml"
            out.append(MocapCase(f"{motion}_{rig}", scene, end, rig, text))
    return tuple(out)


CASES: tuple[MocapCase, ...] = _cases()


def case(name: str) -> MocapCase:
    return find_case(CASES, name, "mocap")


@dataclass
class KindResult:
    """Maxima over one run for one cloth kind (relative stretch, m, m/s, s)."""

    shown_edge: float = 0.0
    state_edge: float = 0.0
    shown_root: float = 0.0
    state_root: float = 0.0
    centre_depth: float = -math.inf       # m, deepest centre (> 0: inside a collider)
    sphere_depth_ratio: float = 0.0        # deepest sphere penetration / its radius (>= 0)
    ejection_excess: float = -math.inf     # m/s, max |v| - |v_body| of touching particles
    ejection_relative: float = 0.0         # m/s, max |v - v_body|
    ejection_outward: float = -math.inf    # m/s, max v.n - max(v_body.n, 0) (n: outward normal)
    ejection_at: tuple = ()                # (time s, particle speed, body speed) of the max excess
    contact_excess: float = -math.inf      # m/s, the same two of the particles in contact only (contact_pairs)
    contact_outward: float = -math.inf
    contact_at: tuple = ()                 # (time s, particle speed, body speed) of the max excess in contact
    settle: float = math.inf               # s after the motion's end (inf: not by the end; nan: run too short)
    particles: int = 0


@dataclass
class MocapRun:
    case: MocapCase
    mode: str
    fps: float
    frames: int
    kinds: dict                 # kind -> KindResult (only kinds the scene has)
    finite: bool
    guard_resets: int
    wall: float                 # s, the whole run
    times: np.ndarray = None    # (F,) s, unscaled time at the end of each frame
    speeds: dict = None         # kind -> (F,) m/s, fastest displayed moving bone of the kind


# ----------------------------------------------------------------------------- solver arrays
@dataclass(frozen=True)
class StepColliders:
    """The colliders at the pose of the last simulated step, one row per solver slot (a
    collider per cloth, docs/solver.md §G.3), with the fields ``metrics.pair_depths`` reads."""

    shape: np.ndarray           # (S,) 0 sphere, 1 capsule, 2 plane
    position: np.ndarray        # (S,3) m: sphere centre / plane point
    start: np.ndarray           # (S,3) m: capsule start
    end: np.ndarray             # (S,3) m: capsule end
    radius: np.ndarray          # (S,) m
    end_radius: np.ndarray      # (S,) m
    normal: np.ndarray          # (S,3) unit, planes
    suspended: np.ndarray       # (S,) bool: skipped this step (scale ~ 0)


def step_collider_shapes(system, slots: int) -> StepColliders:
    """The first ``slots`` collider slots of ``system`` (``ClothSystem.collider_state``, team
    order) at the pose of its last step; each field gathered once."""
    cs = system.collider_state
    _team, _index, shape = system.collider_slots()
    start = cs.start_new[:slots]
    return StepColliders(shape[:slots], start, start, cs.end_new[:slots], cs.radius_start[:slots],
                         cs.radius_end[:slots], cs.plane_normal[:slots], cs.scale_suspend[:slots] != 0)


def slot_pairs(system, pairs) -> np.ndarray:
    """The solver slot of each (particle, scene collider) pair of ``variants.colliding_pairs``
    (an index of ``collider_state``: ``ClothSystem.collider_slots``)."""
    slot_team, slot_collider, _shape = system.collider_slots()
    team = np.asarray(system.model.particle_team, dtype=np.int64)
    slot_of = {(int(t), int(c)): k for k, (t, c) in enumerate(zip(slot_team, slot_collider))}
    return np.array([slot_of[(int(team[p]), int(c))] for p, c in zip(*pairs)], dtype=np.int64)


def friction_keep(system) -> np.ndarray:
    """D.10's per-step friction retention of each team (x0.6 per step; ``keep^(90/f)`` in
    frequency-consistent mode away from 90 Hz, ``parameters.step_keep``)."""
    from magica_py.solver.step import FRICTION_DAMPING_RATE

    ratio = 90.0 / float(system.time_settings.frequency)
    rate_mode = np.asarray(system.parameters.rate_mode)
    return np.where((rate_mode == 0) | (ratio == 1.0), FRICTION_DAMPING_RATE, FRICTION_DAMPING_RATE ** ratio)


def pushed_by_collision(friction: np.ndarray, keep: np.ndarray) -> np.ndarray:
    """Did D.8 push each particle out of a collider in the last step? Read from the particle's
    friction after the step: D.8 sets it to ``1 - saturate(d / r)`` of the nearest collider
    within range, which is 1 exactly when the sphere was inside one (d <= 0: the push; edge
    mode records ``trunc`` of it, 1 likewise), and D.10 then multiplies it by the step's keep.
    A particle not pushed ends below keep: its value is at most max(keep, 1 - d/r) x keep with
    d > 0. (Quality mode's collision last ends a pushed particle on the surface, which the
    ``TOUCH_TOLERANCE`` of ``contact_pairs`` sees.)"""
    return np.asarray(friction) >= np.asarray(keep) * (1.0 - 1e-9)


def contact_pairs(sphere_depth: np.ndarray, radius: np.ndarray, pushed: np.ndarray
                  ) -> tuple[np.ndarray, np.ndarray]:
    """(near, touching) of (particle, collider) pairs at the end of a step, from the pair's
    sphere depth (m, < 0 the gap), the particle's radius (m) and whether collision pushed it
    this step: near, within ``CONTACT_RANGE`` radii (the first readings); touching, near and
    either within ``TOUCH_TOLERANCE`` radii or pushed. The push is per particle, not per
    collider: a particle pushed by one collider counts as touching every collider it is near
    (an over-count, never an under-count)."""
    near = sphere_depth > -CONTACT_RANGE * radius
    return near, near & ((sphere_depth >= -TOUCH_TOLERANCE * radius) | pushed)


def cloth_kind(name: str) -> str:
    return "skirt" if "skirt" in name.lower() else "hair"


# ----------------------------------------------------------------------------- the run
def run_case(c: MocapCase, mode: str, fps: float, duration: float | None = None, progress=None,
             parameters: dict | None = None) -> MocapRun:
    """Run one case in ``mode`` at ``fps`` for its motion and rest (or ``duration`` s), and
    gather the maxima per cloth kind. ``progress(done, total)`` after every frame;
    ``parameters``: further cloth parameters applied to every cloth (validated)."""
    if mode not in MODES:
        raise ValueError(f"mode {mode!r}: expected one of {', '.join(MODES)}")
    if not fps > 0:
        raise ValueError(f"fps {fps!r}: expected a positive frame rate")
    started = time.perf_counter()
    variant = Variant(f"{c.name}/{mode}@{fps:g}", c.path, parameters={**(parameters or {}), "solver.mode": mode},
                      fps=fps, duration=c.duration if duration is None else duration, family="mocap")
    p = prepare(variant)
    scene, player, system = p.scene, p.player, p.system
    model = system.model
    h = scene.hierarchy
    nodes, geometry, pairs = rest_geometry(p)
    team = geometry.team
    kind_of_team = np.array([cloth_kind(getattr(spec, "name", "")) for spec in system.specs])
    kind = kind_of_team[team]                                    # (N,) per particle
    edge_kind = kind[geometry.edges[:, 0]] if geometry.edges.size else np.zeros(0, dtype=kind.dtype)
    kinds = [k for k in KINDS if (kind == k).any()]
    moving = geometry.moving

    slot = slot_pairs(system, pairs)
    slot_count = int(slot.max(initial=-1)) + 1
    step_pairs = (pairs[0], slot)
    collider_index = pairs[1]
    # colliders without a transform (the ground) sit on their own static node: no body part
    static = np.array([h.names[int(t)] == static_transform_name(name)
                       for t, name in zip(scene.colliders.transform, scene.colliders.names)], dtype=bool)
    body_pair = ~static[collider_index] if collider_index.size else np.zeros(0, dtype=bool)
    radius_base = M.particle_radius(model, system.parameters)
    keep = friction_keep(system)[team]                           # (N,) D.10's friction keep per particle

    out = {k: KindResult(particles=int(((kind == k) & moving).sum())) for k in kinds}
    times = np.zeros(p.frames)
    speed = {k: np.zeros(p.frames) for k in kinds}               # m/s, fastest displayed bone of the kind
    finite, resets = True, 0
    ps = system.particles
    step_dt = 1.0 / p.frequency
    previous = h.world_position[nodes].copy()
    previous_time = 0.0
    shapes_before = scene.colliders.world_shapes(h)
    for i in range(p.frames):
        ctx = player.step()
        times[i] = ctx.time.unscaled_time
        dt = times[i] - previous_time
        now = h.world_position[nodes].copy()
        shapes_now = scene.colliders.world_shapes(h)
        old_pos = ps.old_pos          # the view gathers a copy of the packed state: once per frame
        velocity = ps.velocity
        finite &= bool(np.isfinite(now).all() and np.isfinite(old_pos).all() and np.isfinite(velocity).all())
        resets += sum(1 for kind_, _ in ctx.events if kind_ == "cloth_reset")
        shown_edge = M.edge_stretch(now, geometry)
        shown_root = M.root_distance_stretch(now, geometry)
        if i > 0 and dt > 1e-12:
            v = np.linalg.norm(now - previous, axis=1) / dt
            for k in kinds:
                speed[k][i] = v[(kind == k) & moving].max(initial=0.0)
        stepped = ctx.metrics.get("cloth.simulation_steps", 0.0) > 0
        if stepped:
            # the last step's state and the one before it (D.10: old - real_velocity dt), the
            # two the quality display interpolates
            state = old_pos
            before = state - ps.real_velocity * step_dt
            state_edge = np.maximum(M.edge_stretch(state, geometry), M.edge_stretch(before, geometry))
            state_root = np.maximum(M.root_distance_stretch(state, geometry), M.root_distance_stretch(before, geometry))
        for k in kinds:
            r = out[k]
            sel_e, sel_p = edge_kind == k, kind == k
            r.shown_edge = max(r.shown_edge, float(shown_edge[sel_e].max(initial=0.0)))
            r.shown_root = max(r.shown_root, float(shown_root[sel_p].max(initial=0.0)))
            if stepped:
                r.state_edge = max(r.state_edge, float(state_edge[sel_e].max(initial=0.0)))
                r.state_root = max(r.state_root, float(state_root[sel_p].max(initial=0.0)))
        if stepped and slot_count:
            # frame 0 has no body velocity: the previous pose is the build pose, which a capture's
            # first frame jumps away from
            _contacts(system, state, velocity, radius_base, keep, step_pairs, slot_count, collider_index,
                      body_pair if i > 0 else np.zeros_like(body_pair), kind, shapes_before, shapes_now, dt,
                      times[i], out, step_dt)
        previous, previous_time, shapes_before = now, times[i], shapes_now
        if progress is not None:
            progress(i + 1, p.frames)
    ended = times.size and times[-1] >= c.motion_end
    for k in kinds:      # nan: the run ends before the motion does (a short run)
        out[k].settle = M.settling_time(speed[k], times, REST_SPEED, after=c.motion_end) if ended else math.nan
    return MocapRun(c, mode, float(fps), p.frames, out, finite, resets, time.perf_counter() - started,
                    times, speed)


def solver_body_velocity(system, slots: np.ndarray, points: np.ndarray, step_dt: float) -> np.ndarray:
    """Velocity (m/s, (P,3)) over the last step of the body point of collider slot ``slots[i]``
    at ``points[i]``, in the solver's frame (the slot's previous-step pose after the local
    inertia shift to its pose of the step, G.3): the frame of ``particles.velocity``. Read
    after the step: ``start_old`` and ``inverse_old_rot`` keep the previous pose (the start
    point, a point fixed to the body), ``start_new`` and ``now_rot`` the step's."""
    from magica_py.io.quat import qconj

    cs = system.collider_state
    q_old = qconj(cs.inverse_old_rot[slots])   # unit quaternions: the inverse of the inverse
    return M.rigid_point_velocity(points, (cs.start_old[slots], q_old), (cs.start_new[slots], cs.now_rot[slots]),
                                  step_dt)


def _contacts(system, state, velocity, radius_base, keep, step_pairs, slot_count, collider_index, body_pair, kind,
              shapes_before, shapes_now, dt, t, out, step_dt) -> None:
    """Penetration and ejection at the end of this frame's last step, into ``out``."""
    ts = system.teams
    team = np.asarray(system.model.particle_team, dtype=np.int64)
    radius = radius_base * (ts.scale_ratio * ts.length_unit)[team]
    shapes = step_collider_shapes(system, slot_count)
    pi = step_pairs[0]
    sphere, normal = M.pair_contacts(state, radius, step_pairs, shapes)       # (P,) m, (P,3)
    centre = sphere - radius[pi]
    pushed = pushed_by_collision(system.particles.friction[pi], keep[pi])
    near, in_contact = contact_pairs(sphere, radius[pi], pushed)
    touching = near & body_pair                   # the first readings: within one radius of a body part
    if touching.any():
        tp, tc = pi[touching], collider_index[touching]
        points = state[tp]
        vb = M.rigid_point_velocity(points, (shapes_before.position[tc], shapes_before.rotation[tc]),
                                    (shapes_now.position[tc], shapes_now.rotation[tc]), dt)
        # the solver's velocity is in its inertia-shifted frame (C.3/C.4 carry part of the
        # body's motion rigidly): its velocity relative to the body part, taken against the
        # slot's motion over the last step in that same frame, plus the body's world velocity
        v = vb + velocity[tp] - solver_body_velocity(system, step_pairs[1][touching], points, step_dt)
        relative, excess, outward = M.ejection_speeds(v, vb, normal[touching])
        strict = in_contact[touching]             # of those, the ones in contact (touching or pushed)
    for k, r in out.items():
        sel = kind[pi] == k
        if not sel.any():
            continue
        r.centre_depth = max(r.centre_depth, float(centre[sel].max()))
        r.sphere_depth_ratio = max(r.sphere_depth_ratio, float((np.maximum(sphere[sel], 0.0) / radius[pi][sel]).max()))
        if touching.any():
            mine = kind[tp] == k
            if mine.any():
                j = int(np.argmax(np.where(mine, excess, -np.inf)))
                if excess[j] > r.ejection_excess:
                    r.ejection_excess = float(excess[j])
                    r.ejection_at = (float(t), float(np.linalg.norm(v[j])), float(np.linalg.norm(vb[j])))
                r.ejection_relative = max(r.ejection_relative, float(relative[mine].max()))
                r.ejection_outward = max(r.ejection_outward, float(outward[mine].max()))
                mine = mine & strict
                if mine.any():
                    j = int(np.argmax(np.where(mine, excess, -np.inf)))
                    if excess[j] > r.contact_excess:
                        r.contact_excess = float(excess[j])
                        r.contact_at = (float(t), float(np.linalg.norm(v[j])), float(np.linalg.norm(vb[j])))
                    r.contact_outward = max(r.contact_outward, float(outward[mine].max()))


# ----------------------------------------------------------------------------- report
HAIR_BOUND, SKIRT_BOUND = 0.02, 0.03      # issue 16: edge stretch, displayed and simulated
SPHERE_BOUND = 0.10                       # penetration of the particle sphere / its radius
EJECTION_BOUND = 2.0                      # m/s above the body part's speed

CSV_COLUMNS = (
    ("case", "case", "{}"), ("rig", "rig", "{}"), ("mode", "mode", "{}"), ("fps", "fps", "{:g}"),
    ("kind", "kind", "{}"), ("particles", "moving particles", "{}"), ("frames", "frames", "{}"),
    ("shown_edge_pct", "displayed edge stretch (%)", "{:.2f}"), ("state_edge_pct", "simulated edge stretch (%)", "{:.2f}"),
    ("shown_root_pct", "displayed root stretch (%)", "{:.2f}"), ("state_root_pct", "simulated root stretch (%)", "{:.2f}"),
    ("centre_depth_mm", "deepest centre (mm, > 0 inside)", "{:.2f}"),
    ("sphere_pct", "sphere penetration (% of radius)", "{:.1f}"),
    ("ejection_excess", "ejection |v| - |v_body| (m/s)", "{:.2f}"),
    ("ejection_relative", "ejection |v - v_body| (m/s)", "{:.2f}"),
    ("ejection_outward", "ejection v.n - max(v_body.n, 0) (m/s)", "{:.2f}"),
    ("ejection_time", "at (s)", "{:.3f}"), ("ejection_speed", "particle speed (m/s)", "{:.2f}"),
    ("body_speed", "body speed (m/s)", "{:.2f}"),
    ("contact_excess", "in contact: |v| - |v_body| (m/s)", "{:.2f}"),
    ("contact_outward", "in contact: v.n - max(v_body.n, 0) (m/s)", "{:.2f}"),
    ("contact_time", "in contact: at (s)", "{:.3f}"), ("contact_speed", "in contact: particle speed (m/s)", "{:.2f}"),
    ("contact_body_speed", "in contact: body speed (m/s)", "{:.2f}"),
    ("settle", "settling (s after the motion)", "{:.2f}"), ("finite", "finite", "{}"),
    ("guard_resets", "guard resets", "{}"), ("wall_s", "wall (s)", "{:.1f}"),
)


def run_rows(run: MocapRun) -> list[dict]:
    """One CSV row per cloth kind of a run (percentages, mm, m/s, s)."""
    rows = []
    for k, r in run.kinds.items():
        t, vp, vb = r.ejection_at if r.ejection_at else (None, None, None)
        ct, cvp, cvb = r.contact_at if r.contact_at else (None, None, None)
        rows.append({"case": run.case.name, "rig": run.case.rig, "mode": run.mode, "fps": run.fps, "kind": k,
                     "particles": r.particles, "frames": run.frames,
                     "shown_edge_pct": 100 * r.shown_edge, "state_edge_pct": 100 * r.state_edge,
                     "shown_root_pct": 100 * r.shown_root, "state_root_pct": 100 * r.state_root,
                     "centre_depth_mm": 1000 * r.centre_depth if math.isfinite(r.centre_depth) else None,
                     "sphere_pct": 100 * r.sphere_depth_ratio,
                     "ejection_excess": r.ejection_excess if math.isfinite(r.ejection_excess) else None,
                     "ejection_relative": r.ejection_relative if r.ejection_at else None,
                     "ejection_outward": r.ejection_outward if math.isfinite(r.ejection_outward) else None,
                     "ejection_time": t, "ejection_speed": vp, "body_speed": vb,
                     "contact_excess": r.contact_excess if math.isfinite(r.contact_excess) else None,
                     "contact_outward": r.contact_outward if math.isfinite(r.contact_outward) else None,
                     "contact_time": ct, "contact_speed": cvp, "contact_body_speed": cvb,
                     "settle": r.settle, "finite": "yes" if run.finite else "NO",
                     "guard_resets": run.guard_resets, "wall_s": run.wall})
    return rows


def _pair(q_row, f_row, key, fmt):
    """``quality / faithful`` of one column ("-" for a value a run has not got, e.g. no
    contact); one value when only one mode ran."""
    def one(v):
        if v is None:
            return "-"
        if isinstance(v, float) and math.isnan(v):
            return "n/a"
        if isinstance(v, float) and not math.isfinite(v):
            return f"> {REST:g}" if v > 0 else "-"
        return fmt.format(v)
    values = [one(row.get(key)) for row in (q_row, f_row) if row is not None]
    return " / ".join(values)


SIDE_BY_SIDE = (("shown_edge_pct", "displayed edge %", "{:.2f}"), ("state_edge_pct", "simulated edge %", "{:.2f}"),
                ("shown_root_pct", "displayed root %", "{:.2f}"), ("state_root_pct", "simulated root %", "{:.2f}"),
                ("centre_depth_mm", "deepest centre mm (> 0 inside)", "{:.1f}"),
                ("sphere_pct", "sphere pen. % of r", "{:.1f}"),
                ("ejection_excess", "\\|v\\|-\\|v_body\\| m/s", "{:.2f}"),
                ("ejection_outward", "ejection m/s", "{:.2f}"),
                ("contact_excess", "in contact: \\|v\\|-\\|v_body\\| m/s", "{:.2f}"),
                ("contact_outward", "in contact: ejection m/s", "{:.2f}"),
                ("settle", "settling s", "{:.2f}"))


def side_by_side_table(rows: list[dict]) -> str:
    """Markdown: one line per case, fps and kind, each cell ``quality / faithful``."""
    keyed = {(r["case"], r["fps"], r["kind"], r["mode"]): r for r in rows}
    keys = []
    for r in rows:
        key = (r["case"], r["fps"], r["kind"])
        if key not in keys:
            keys.append(key)
    head = "| case | fps | kind | " + " | ".join(c[1] for c in SIDE_BY_SIDE) + " |"
    lines = [head, "|" + "---|" * (3 + len(SIDE_BY_SIDE))]
    for key in keys:
        q, f = keyed.get(key + ("quality",)), keyed.get(key + ("faithful",))
        cells = [_pair(q, f, c[0], c[2]) for c in SIDE_BY_SIDE]
        lines.append(f"| {key[0]} | {key[1]:g} | {key[2]} | " + " | ".join(cells) + " |")
    return "\n".join(lines)


def bound_summary(rows: list[dict]) -> str:
    """The issue's bounds, per mode: runs meeting each, and the worst run."""
    checks = (
        ("displayed and simulated edge stretch <= 2 % (hair) / 3 % (skirt)",
         lambda r: max(r["shown_edge_pct"], r["state_edge_pct"]),
         lambda r: 100 * (HAIR_BOUND if r["kind"] == "hair" else SKIRT_BOUND), "{:.2f} %"),
        ("no particle centre inside a collider at the end of a step",
         lambda r: r["centre_depth_mm"] if r["centre_depth_mm"] is not None else -math.inf, lambda r: 0.0, "{:.2f} mm"),
        ("particle sphere penetration <= 10 % of its radius", lambda r: r["sphere_pct"],
         lambda r: 100 * SPHERE_BOUND, "{:.1f} %"),
        ("no particle faster than the body part it touches + 2 m/s",
         lambda r: r["ejection_excess"] if r["ejection_excess"] is not None else -math.inf,
         lambda r: EJECTION_BOUND, "{:.2f} m/s"),
        ("(the same bound read as an ejection: leaving the surface <= 2 m/s beyond the body's push)",
         lambda r: r["ejection_outward"] if r["ejection_outward"] is not None else -math.inf,
         lambda r: EJECTION_BOUND, "{:.2f} m/s"),
        ("in contact (sphere within 5 % of its radius, or pushed by D.8 this step): "
         "no particle faster than the body part + 2 m/s",
         lambda r: r["contact_excess"] if r["contact_excess"] is not None else -math.inf,
         lambda r: EJECTION_BOUND, "{:.2f} m/s"),
        ("in contact: leaving the surface <= 2 m/s beyond the body's push",
         lambda r: r["contact_outward"] if r["contact_outward"] is not None else -math.inf,
         lambda r: EJECTION_BOUND, "{:.2f} m/s"),
    )
    lines = ["| bound | mode | runs within | worst (case, fps, kind) |", "|---|---|---|---|"]
    for text, value, bound, fmt in checks:
        for mode in MODES:
            mine = [r for r in rows if r["mode"] == mode]
            if not mine:
                continue
            ok = sum(1 for r in mine if value(r) <= bound(r) + 1e-12)
            worst = max(mine, key=lambda r: value(r) - bound(r))
            lines.append(f"| {text} | {mode} | {ok}/{len(mine)} | {fmt.format(value(worst))} "
                         f"({worst['case']}, {worst['fps']:g}, {worst['kind']}) |")
    return "\n".join(lines)
