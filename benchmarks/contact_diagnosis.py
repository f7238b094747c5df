"""Is a particle the mocap suite counts as touching a body part really in contact?
(issue 16: "no particle faster than the body part it touches plus 2 m/s"; docs/STABILITY.md)

The suite (``magica_py.bench.mocap_suite``) reads, at the end of a step, the particles whose
sphere lies within one radius of a collider carried by a bone. This script reruns a case in
pure Python (``NUMBA_DISABLE_JIT=1``: no compile, ~10 s per Godette run) with hooks around
D.8 (``point_collision_block`` / ``edge_collision_block``), quality mode's collision last
(``collision_last_lane``) and its follow-the-leader with the colliders (``ftl_collision_lane``):
it records, per step and particle, how far each of them moved it, with the state, velocity and
friction after the step and the collider slots' pose. The solver steps a block of teams at a
time (``frame.run_step``, the lane form): after a block's step, each team of the block that ran
it gets the step's record, read through the system's team-ordered views. For every reading of the suite it then knows the gap to the
collider at that step's end and the step before (mm and share of the radius), whether
collision moved the particle in that step or the step before, and its normal velocity at the
start and end of the step. The solver's results are those of the JIT build (same code, same
order; the backflip and roll figures of docs/STABILITY.md come out to the hundredth).

    python benchmarks/contact_diagnosis.py                        # the suite's 14 quality misses, both modes
    python benchmarks/contact_diagnosis.py roll_godette:quality:240 backflip_godette:faithful:60
    python benchmarks/contact_diagnosis.py --trace roll_godette:quality:240:5:2:1.30:1.47
    python benchmarks/contact_diagnosis.py --coulomb backflip_godette:quality:144

Per run: the first readings (max ``|v| - |v_body|`` and ejection), how many readings beyond 2
m/s were in contact (gap <= 5 % of the radius, or moved by collision in that step), the
same maxima over the readings in contact as instrumented here and as the suite reads them
(gap, or D.8's friction mark ``mocap_suite.pushed_by_collision``), and the worst reading of
each kind. ``--trace case:mode:fps:particle:collider:t0:t1`` prints one particle's steps
against one scene collider; ``--coulomb`` what an ideal inelastic Coulomb contact would
leave of the in-contact readings beyond 2 m/s (friction the cloth's, and 1).
"""
from __future__ import annotations

import os

os.environ["NUMBA_DISABLE_JIT"] = "1"   # before magica_py: plain Python kernels, which the hooks replace

import pathlib  # noqa: E402
import sys  # noqa: E402
import warnings  # noqa: E402

import numpy as np  # noqa: E402

sys.path.insert(0, str(pathlib.Path(__file__).resolve().parent.parent))
warnings.simplefilter("ignore")         # the branch-free kernels divide by zero where the JIT gives inf

from magica_py.bench import metrics as M  # noqa: E402
from magica_py.bench import mocap_suite as S  # noqa: E402
from magica_py.bench.variants import Variant, prepare, rest_geometry  # noqa: E402
from magica_py.scene.colliders import static_transform_name  # noqa: E402
import magica_py.solver.constraints.angle as A  # noqa: E402
import magica_py.solver.frame as F  # noqa: E402
import magica_py.solver.quality as Q  # noqa: E402

import magica_py.solver.blocks as B  # noqa: E402
import magica_py.solver.state as ST  # noqa: E402
from magica_py.solver.lanes import get1  # noqa: E402

MISSES = ("backflip_godette", "roll_godette", "spin_godette")
PASSES = ("d8", "cl", "ftl")
COLLIDER_FIELDS = ("start_new", "end_new", "radius_start", "radius_end", "plane_normal", "scale_suspend")
_moves = {}
STEPS: dict = {}                          # team -> list of per-step records
SYSTEM = []                               # the ClothSystem being diagnosed (its views read the packed state)


def _mover(fn, key):
    """``fn`` (a stage driver) with the moves it makes to every particle's next_pos (team order)
    added to ``_moves[key]``."""
    def wrapped(*args):
        before = SYSTEM[0].particles.next_pos
        out = fn(*args)
        move = SYSTEM[0].particles.next_pos - before
        _moves[key] = move if key not in _moves else _moves[key] + move
        return out
    return wrapped


F.point_collision_block = _mover(F.point_collision_block, "d8")
F.edge_collision_block = _mover(F.edge_collision_block, "d8")
Q.collision_last_lane = _mover(Q.collision_last_lane, "cl")
Q.ftl_collision_lane = _mover(Q.ftl_collision_lane, "ftl")
_run_step = F.run_step
_restoration_offset = A.restoration_offset


def _offset(*args):
    # the branch-free kernel divides by |w| = 0 when parallel and then selects ZERO3 (the JIT's
    # inf is never used); plain Python raises instead
    try:
        return _restoration_offset(*args)
    except ZeroDivisionError:
        return A.ZERO3, False


A.restoration_offset = _offset


def _step(T, b, *rest):
    """``run_step`` of block b (``T``: the frame's arrays), recorded for each of its teams that
    runs this step (the others' lanes are put back by the caller afterwards)."""
    system = SYSTEM[0]
    _moves.clear()
    v_before = system.particles.velocity
    _run_step(T, b, *rest)
    zero = np.zeros_like(v_before)
    record = {key: _moves.get(key, zero) for key in PASSES}
    ps = system.particles
    record.update(pos=ps.old_pos, vel=ps.velocity, v_before=v_before, friction=ps.friction,
                  colliders={f: getattr(system.collider_state, f) for f in COLLIDER_FIELDS})
    record["colliders"]["shape"] = system.collider_slots()[2]
    for lane in range(B.lane_width(T.BI, b)):
        t = int(T.TI[b, B.TI_TEAM + lane])
        if t >= 0 and get1(T.TS, b, ST.ACTIVE, lane) != 0.0 and T.tt_step_running[t]:
            STEPS.setdefault(t, []).append(record)


F.run_step = _step


def _shapes(colliders, slots):
    """A step's collider slots (copied after the step) as ``mocap_suite.step_collider_shapes``."""
    c = {k: v[:slots] for k, v in colliders.items()}
    return S.StepColliders(c["shape"], c["start_new"], c["start_new"], c["end_new"], c["radius_start"],
                           c["radius_end"], c["plane_normal"], c["scale_suspend"] != 0)


def _prepare(name, mode, fps):
    c = S.case(name)
    return prepare(Variant(f"{name}/{mode}@{fps:g}", c.path, parameters={"solver.mode": mode}, fps=fps,
                           duration=c.duration, family="mocap"))


def diagnose(name: str, mode: str, fps: float) -> list[dict]:
    """Every reading of the suite's first criterion (a particle within one radius of a body
    part at the end of a step) in one run, with what the hooks saw."""
    p = _prepare(name, mode, fps)
    scene, player, system = p.scene, p.player, p.system
    SYSTEM[:] = [system]
    h = scene.hierarchy
    nodes, _geometry, pairs = rest_geometry(p)
    n = nodes.shape[0]
    slot = S.slot_pairs(system, pairs)
    slots = int(slot.max(initial=-1)) + 1
    pi, ci = pairs
    static = np.array([h.names[int(t)] == static_transform_name(nm)
                       for t, nm in zip(scene.colliders.transform, scene.colliders.names)], dtype=bool)
    body = ~static[ci]
    team = np.asarray(system.model.particle_team, dtype=np.int64)[:n]
    keep = S.friction_keep(system)[team]
    mu = np.asarray(system.parameters.friction)[team]
    base = M.particle_radius(system.model, system.parameters)[:n]
    STEPS.clear()
    count = lambda: sum(len(v) for v in STEPS.values())   # noqa: E731
    previous_time, shapes_before = 0.0, scene.colliders.world_shapes(h)
    rows = []
    for i in range(p.frames):
        before = count()
        t = player.step().time.unscaled_time
        dt = t - previous_time
        shapes_now = scene.colliders.world_shapes(h)
        if count() > before and i > 0:
            ts = system.teams
            radius = base * (ts.scale_ratio * ts.length_unit)[team]
            last = {f: np.zeros((n, 3)) for f in ("pos", "prev", "vel", "v_before") + PASSES + tuple("p" + k for k in PASSES)}
            friction = np.zeros(n)
            sphere, sphere_prev = np.full(pi.shape[0], -np.inf), np.full(pi.shape[0], np.nan)
            normal = np.zeros((pi.shape[0], 3))
            # each team's last step (and the one before) against its own collider slots as they
            # were after that step: the blocks run one after the other within a frame
            for tm, steps in STEPS.items():
                sel = team == tm
                mine = sel[pi]
                a = steps[-1]
                b = steps[-2] if len(steps) >= 2 else None
                for f in ("pos", "vel", "v_before") + PASSES:
                    last[f][sel] = a[f][:n][sel]
                friction[sel] = a["friction"][:n][sel]
                sphere[mine], normal[mine] = M.pair_contacts(a["pos"][:n], radius, (pi[mine], slot[mine]),
                                                             _shapes(a["colliders"], slots))
                if b is not None:
                    last["prev"][sel] = b["pos"][:n][sel]
                    for k in PASSES:
                        last["p" + k][sel] = b[k][:n][sel]
                    sphere_prev[mine] = M.pair_contacts(b["pos"][:n], radius, (pi[mine], slot[mine]),
                                                        _shapes(b["colliders"], slots))[0]
            near = (sphere > -S.CONTACT_RANGE * radius[pi]) & body
            if near.any():
                tp, tc = pi[near], ci[near]
                vb = M.rigid_point_velocity(last["pos"][tp], (shapes_before.position[tc], shapes_before.rotation[tc]),
                                            (shapes_now.position[tc], shapes_now.rotation[tc]), dt)
                v = last["vel"][tp]
                nrm = normal[near]
                _rel, excess, outward = M.ejection_speeds(v, vb, nrm)
                for j, q in enumerate(tp):
                    rows.append(dict(
                        t=t, p=int(q), c=int(tc[j]), r=float(radius[q]), mu=float(mu[q]),
                        gap=-float(sphere[near][j]), gap_prev=-float(sphere_prev[near][j]),
                        v=v[j].copy(), vb=vb[j].copy(), n=nrm[j].copy(), v_before=last["v_before"][q].copy(),
                        excess=float(excess[j]), outward=float(outward[j]),
                        moved={k: float(np.linalg.norm(last[k][q])) for k in PASSES},
                        moved_prev={k: float(np.linalg.norm(last["p" + k][q])) for k in PASSES},
                        mark=bool(S.pushed_by_collision(friction[q], keep[q]))))
        previous_time, shapes_before = t, shapes_now
    return rows


def moved(r, key="moved"):
    return any(v > 0.0 for v in r[key].values())


def in_contact(r):
    """Instrumented: touching (gap <= TOUCH_TOLERANCE r) or moved by any collision pass this step."""
    return r["gap"] <= S.TOUCH_TOLERANCE * r["r"] or moved(r)


def as_the_suite_reads(r):
    """The suite's reading: touching, or D.8's friction mark."""
    return r["gap"] <= S.TOUCH_TOLERANCE * r["r"] or r["mark"]


def describe(r):
    mm = lambda d: "/".join(f"{1000 * d[k]:.2f}" for k in PASSES)   # noqa: E731
    return (f"t={r['t']:.3f} p{r['p']} c{r['c']} gap {1000 * r['gap']:.1f} mm = {100 * r['gap'] / r['r']:.0f} % r "
            f"(step before {1000 * r['gap_prev']:.1f} mm = {100 * r['gap_prev'] / r['r']:.0f} % r), moved by "
            f"D.8/collision last/FTL {mm(r['moved'])} mm (step before {mm(r['moved_prev'])}), |v| "
            f"{np.linalg.norm(r['v']):.2f} |v_body| {np.linalg.norm(r['vb']):.2f} m/s, v.n {r['v'] @ r['n']:.2f} "
            f"(start of step {r['v_before'] @ r['n']:.2f}), v_body.n {r['vb'] @ r['n']:.2f}")


def summary(label, rows):
    if not rows:
        print(f"{label}: no particle near a body part")
        return
    beyond = [r for r in rows if r["excess"] > S.EJECTION_BOUND or r["outward"] > S.EJECTION_BOUND]
    contact = [r for r in rows if in_contact(r)]
    suite = [r for r in rows if as_the_suite_reads(r)]
    top = lambda rs, k: max((r[k] for r in rs), default=float("nan"))   # noqa: E731
    d8_disagree = sum(r["mark"] != (r["moved"]["d8"] > 0.0) for r in rows)
    print(f"{label}: near: excess {top(rows, 'excess'):.2f}, ejection {top(rows, 'outward'):.2f} m/s | "
          f"{len(beyond)} readings beyond 2 m/s: {sum(in_contact(r) for r in beyond)} in contact, "
          f"{sum(moved(r) for r in beyond)} moved this step, {sum(moved(r, 'moved_prev') for r in beyond)} the step "
          f"before | in contact: excess {top(contact, 'excess'):.2f}, ejection {top(contact, 'outward'):.2f} "
          f"({len(contact)}/{len(rows)} readings); as the suite reads it: {top(suite, 'excess'):.2f}, "
          f"{top(suite, 'outward'):.2f} | D.8 mark against D.8's moves: {d8_disagree} disagree")
    print("    near, max excess:     " + describe(max(rows, key=lambda r: r["excess"])))
    print("    near, max ejection:   " + describe(max(rows, key=lambda r: r["outward"])))
    if contact:
        print("    contact, max excess:  " + describe(max(contact, key=lambda r: r["excess"])))
        print("    contact, max ejection:" + describe(max(contact, key=lambda r: r["outward"])))
    sys.stdout.flush()


def coulomb(r, mu):
    """``|v'| - |v_body|`` after an ideal inelastic Coulomb contact: the relative normal
    velocity raised to 0 if inward (an impulse J per unit mass), the relative tangential speed
    cut by mu J."""
    rel = r["v"] - r["vb"]
    rn = float(rel @ r["n"])
    rt = rel - rn * r["n"]
    j = max(0.0, -rn)
    t = float(np.linalg.norm(rt))
    kept = rt * (max(0.0, t - mu * j) / t if t > 0.0 else 0.0)
    v2 = r["vb"] + max(rn, 0.0) * r["n"] + kept
    return float(np.linalg.norm(v2) - np.linalg.norm(r["vb"])), j, rn, t


def coulomb_summary(label, rows):
    beyond = [r for r in rows if in_contact(r) and r["excess"] > S.EJECTION_BOUND]
    if not beyond:
        print(f"{label}: no reading in contact beyond 2 m/s")
        return
    w = max(beyond, key=lambda r: r["excess"])
    after_mu, j, rn, rt = coulomb(w, w["mu"])
    after_1 = coulomb(w, 1.0)[0]
    print(f"{label}: {len(beyond)} readings in contact beyond 2 m/s; the worst ({w['excess']:.2f} m/s at t={w['t']:.3f}): "
          f"relative normal {rn:+.2f} m/s, relative tangential {rt:.2f} m/s, inelastic impulse {j:.2f} m/s; after an "
          f"ideal Coulomb contact {after_mu:.2f} (friction {w['mu']:.2f}) / {after_1:.2f} (friction 1); over those "
          f"readings at most {max(coulomb(r, r['mu'])[0] for r in beyond):.2f} / {max(coulomb(r, 1.0)[0] for r in beyond):.2f}")
    sys.stdout.flush()


def trace(name, mode, fps, particle, collider, t0, t1):
    """One particle against one scene collider, every step between t0 and t1 s."""
    rows = [r for r in diagnose(name, mode, fps) if r["p"] == particle and r["c"] == collider and t0 <= r["t"] <= t1]
    print(f"{name} {mode} {fps:g} fps: particle {particle} against collider {collider} (steps where it is near)")
    for r in rows:
        print("  " + describe(r))


def main(argv) -> int:
    if argv[:1] == ["--trace"]:
        name, mode, fps, particle, collider, t0, t1 = argv[1].split(":")
        trace(name, mode, float(fps), int(particle), int(collider), float(t0), float(t1))
        return 0
    report = summary
    if argv[:1] == ["--coulomb"]:
        report, argv = coulomb_summary, argv[1:]
    specs = argv or [f"{c}:{m}:{f}" for m in S.MODES for c in MISSES for f in (30, 60, 144, 240)]
    for spec in specs:
        name, mode, fps = spec.split(":")
        report(spec, diagnose(name, mode, float(fps)))
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
