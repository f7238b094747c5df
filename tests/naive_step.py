"""A slow, plain-numpy reference of one simulation step (docs/solver.md §C.3, §G.3, §D.1-§D.10) for a
small line-mode scene with point collision, written independently of the numba kernels
(its own quaternion maths, Python loops over particles) to check them to float tolerance.

``naive_step(model, state, params, team_state, colliders, team, frame_interpolation, dt)``
works on dicts of numpy arrays copied from the solver's team-ordered views and the team's
build model (``tests/test_solver_naive.py``: ``naive_inputs``) and updates them in place.
Scope: MagicaCloth2 rate mode, no bending/volume, no edge collision, no external force.
"""
from __future__ import annotations

import math

import numpy as np

MOVE = 0x02
INVALID_MOTION = 0x08
NO_COLLISION = 0x10


# ----------------------------------------------------------------------------- maths (§0.2)
def qmul(a, b):
    ax, ay, az, aw = a
    bx, by, bz, bw = b
    return np.array([aw * bx + ax * bw + ay * bz - az * by,
                     aw * by - ax * bz + ay * bw + az * bx,
                     aw * bz + ax * by - ay * bx + az * bw,
                     aw * bw - ax * bx - ay * by - az * bz])


def qinv(q):
    return np.array([-q[0], -q[1], -q[2], q[3]]) / float(q @ q)


def qrot(q, v):
    p = qmul(qmul(q, np.array([v[0], v[1], v[2], 0.0])), qinv(q))
    return p[:3]


def qnorm(q):
    n = np.linalg.norm(q)
    return np.array([0.0, 0.0, 0.0, 1.0]) if n < 1e-12 else q / n


def slerp(a, b, t):
    d = float(a @ b)
    if d < 0.0:
        b = -b
        d = -d
    if d < 0.9995:
        th = math.acos(d)
        return qnorm((math.sin((1 - t) * th) * a + math.sin(t * th) * b) / math.sin(th))
    return qnorm(a + (b - a) * t)


def axis_angle(axis, angle):
    return np.array([*(np.asarray(axis) * math.sin(angle / 2)), math.cos(angle / 2)])


def fromto_unit(a, b, t=1.0):
    c = float(np.clip(a @ b, -1.0, 1.0))
    if abs(1.0 + c) < 1e-6:
        axis = np.cross(a, [0.0, 1.0, 0.0]) if (a[0] > a[1] and a[0] > a[2]) else np.cross(a, [1.0, 0.0, 0.0])
        return axis_angle(axis / np.linalg.norm(axis), math.pi * t)
    if abs(1.0 - c) < 1e-6:
        return np.array([0.0, 0.0, 0.0, 1.0])
    axis = np.cross(a, b)
    return axis_angle(axis / np.linalg.norm(axis), math.acos(c) * t)


def angle_q(a, b):
    d = float(a @ b)
    if abs(d) < 0.9999:
        ang = 2.0 * math.acos(np.clip(d, -1.0, 1.0))
        return 2.0 * math.pi - ang if ang > math.pi else ang
    return 0.0


def clamp_len(v, n):
    ln = np.linalg.norm(v)
    return v * (n / ln) if ln > 1e-9 and ln > n else v


def curve(table, d, clamp=False):
    sd = min(max(d, 0.0), 1.0)
    i = int(sd * 15.0)
    u = (d - i / 15.0) * 15.0
    j = min(i + 1, 15)
    v = table[i] + (table[j] - table[i]) * u
    return min(max(v, 0.0), 1.0) if clamp else v


def sat(x):
    return min(max(x, 0.0), 1.0)


def plane_push(c, n, p):
    v = p - c
    d = float(v @ n)
    if d < 0.0:
        return -abs(d) * np.linalg.norm(n), p - d * n
    return abs(d) * np.linalg.norm(n), p


# ----------------------------------------------------------------------------- the step
def naive_step(M, S, P, T, C, team, frac, dt):
    """One step of team ``team``; M model, S particle state, P parameters, T team state,
    C collider state: dicts of arrays (modified in place)."""
    t = team
    s0 = M["team_particle_start"][t]
    parts = range(s0, s0 + M["team_particle_count"][t])
    att = M["attribute"]
    depth = M["depth"]
    # --- C.3 team step update
    old_wp, old_wr = T["now_world_pos"][t].copy(), T["now_world_rot"][t].copy()
    T["old_world_pos"][t], T["old_world_rot"][t] = old_wp, old_wr
    now_wp = T["old_frame_world_pos"][t] + (T["frame_world_pos"][t] - T["old_frame_world_pos"][t]) * frac
    now_wr = slerp(T["old_frame_world_rot"][t], T["frame_world_rot"][t], frac)
    wscl = T["old_frame_world_scale"][t] + (T["frame_world_scale"][t] - T["old_frame_world_scale"][t]) * frac
    T["now_world_pos"][t], T["now_world_rot"][t] = now_wp, now_wr
    step_vec = now_wp - old_wp
    step_rot = qmul(now_wr, qinv(old_wr))
    step_ang = angle_q(old_wr, now_wr)
    li = P["local_inertia"][t]
    mv = rv = 1.0 - li
    felt = np.linalg.norm(step_vec) * (1 - mv) / dt
    lim = P["local_movement_speed_limit"][t]
    if lim >= 0 and felt > lim:
        mv = 1.0 + (mv - 1.0) * lim / felt
    felt = math.degrees(step_ang * (1 - rv) / dt)
    lim = P["local_rotation_speed_limit"][t]
    if lim >= 0 and felt > lim:
        rv = 1.0 + (rv - 1.0) * lim / felt
    inertia_vec = step_vec * mv
    inertia_rot = slerp(np.array([0.0, 0, 0, 1]), step_rot, rv)
    ang_vel = step_ang / dt
    axis = np.zeros(3)
    if ang_vel > 1e-8:
        a = math.acos(step_rot[3]) if abs(step_rot[3]) < 0.9999 else 0.0
        if abs(math.sin(a)) >= 1e-6:
            axis = step_rot[:3] / math.sin(a)
    scale_ratio = max(np.linalg.norm(wscl) / np.linalg.norm(M["team_init_scale"][t]), 1e-6)
    g = P["gravity_direction"][t]
    gdot = 1.0
    if g @ g > 1e-8:
        gdot = sat(float(qrot(now_wr, M["team_init_local_gravity"][t]) @ g) * 0.5 + 0.5)
    gratio = 1.0
    if P["gravity"][t] > 1e-6 and P["gravity_falloff"][t] > 1e-6:
        gratio = sat(1 - P["gravity_falloff"][t]) + (1 - sat(1 - P["gravity_falloff"][t])) * sat(1 - gdot)
    if T["velocity_weight"][t] < 1.0:
        stab = P["stabilization_time"][t]
        T["velocity_weight"][t] = sat(T["velocity_weight"][t] + (dt / stab if stab > 1e-6 else 1.0))
    vw = T["velocity_weight"][t]
    T["blend_weight"][t] = sat(vw * P["blend_weight"][t] * T["distance_weight"][t])
    T["gravity_dot"][t], T["scale_ratio"][t] = gdot, scale_ratio
    # --- G.3 collider step
    c0 = T["collider_start"][t]
    for k in range(c0, c0 + T["collider_count"][t]):
        npos = C["old_frame_pos"][k] + (C["frame_pos"][k] - C["old_frame_pos"][k]) * frac
        nrot = slerp(C["old_frame_rot"][k], C["frame_rot"][k], frac)
        opos = C["old_pos"][k] + (npos - C["old_pos"][k]) * mv
        orot = slerp(C["old_rot"][k], nrot, rv)
        C["now_pos"][k], C["now_rot"][k], C["old_pos"][k], C["old_rot"][k] = npos, nrot, opos, orot
        assert C["shape"][k] in (0, 2), "naive_step models spheres and planes"
        if C["shape"][k] == 0:
            C["radius_start"][k] = C["size"][k][0] * abs(C["frame_scale"][k][0])
        else:
            C["plane_normal"][k] = qrot(nrot, [0.0, np.sign(C["frame_scale"][k][1]) or 1.0, 0.0])
    # --- D.1 predict
    damp_table = P["damping_curve"][t]
    grav = g * P["gravity"][t] * gratio
    for p in parts:
        bp = S["old_position"][p] + (S["position"][p] - S["old_position"][p]) * frac
        br = slerp(S["old_rotation"][p], S["rotation"][p], frac)
        S["base_pos"][p], S["base_rot"][p] = bp, br
        S["step_basic_pos"][p], S["step_basic_rot"][p] = bp.copy(), br.copy()
        if not att[p] & MOVE:
            S["next_pos"][p] = bp.copy()
            S["velocity_pos"][p] = bp.copy()
            continue
        k = P["depth_inertia"][t] * (1 - depth[p] ** 2)
        iv = inertia_vec + (step_vec - inertia_vec) * k
        iq = slerp(inertia_rot, step_rot, k)
        w = old_wp + qrot(iq, S["old_pos"][p] - old_wp) + iv
        vel = qrot(iq, S["velocity"][p]) * vw
        vel = vel * sat(1 - curve(damp_table, depth[p], True))
        vel = vel + grav * scale_ratio * dt
        S["velocity"][p] = vel
        S["velocity_pos"][p] = w
        S["next_pos"][p] = w + vel * dt
    # --- D.2 step basic pose
    a = P["animation_pose_ratio"][t]
    if a <= 0.99:
        sc = M["team_init_scale"][t] * scale_ratio
        for b in range(M["team_baseline_start"][t], M["team_baseline_start"][t] + M["team_baseline_count"][t]):
            e0 = M["baseline_start"][b]
            for e in range(e0 + 1, e0 + M["baseline_count"][b]):
                v = M["baseline_data"][e]
                pr = M["parent"][v]
                S["step_basic_pos"][v] = qrot(S["step_basic_rot"][pr], M["baseline_local_position"][v] * sc) + S["step_basic_pos"][pr]
                S["step_basic_rot"][v] = qmul(S["step_basic_rot"][pr], M["baseline_local_rotation"][v])
    # --- D.3 tether
    comp = 1 - P["tether_compression"][t]
    for p in parts:
        r = M["root_index"][p]
        if not att[p] & MOVE or r < 0:
            continue
        v = S["next_pos"][r] - S["next_pos"][p]
        ln = np.linalg.norm(v)
        l0 = np.linalg.norm(S["step_basic_pos"][p] - S["step_basic_pos"][r])
        if ln < 1e-8 or l0 == 0:
            continue
        ratio = ln / l0
        if ratio < comp:
            d, kk = ln - comp * l0, sat((comp - ratio) / 0.3)
        elif ratio > 1.03:
            d, kk = ln - 1.03 * l0, sat((ratio - 1.03) / 0.3)
        else:
            continue
        delta = v / ln * d * kk
        S["next_pos"][p] = S["next_pos"][p] + delta
        S["velocity_pos"][p] = S["velocity_pos"][p] + 0.7 * delta

    def distance():
        sc = M["team_init_scale"][t][0] * scale_ratio
        for p in parts:
            if not att[p] & MOVE:
                continue
            wp = 1 / (1 + 3 * S["friction"][p] + 5 * (1 - depth[p]) ** 2)
            k = curve(P["distance_stiffness_curve"][t], depth[p], True)
            acc = np.zeros(3)
            n = 0
            for link in range(M["distance_start"][p], M["distance_start"][p] + M["distance_count"][p]):
                q = M["distance_target"][link]
                rest = M["distance_rest"][link]
                v = S["next_pos"][q] - S["next_pos"][p]
                if rest == 0:
                    acc = 0.5 * v
                    n += 1
                    continue
                kk = sat(k if rest > 0 else k * 0.5)
                wq = 1 / 50 if not att[q] & MOVE else 1 / (1 + 3 * S["friction"][q] + 5 * (1 - depth[q]) ** 2)
                l0 = abs(rest) * sc + (np.linalg.norm(S["base_pos"][p] - S["base_pos"][q]) - abs(rest) * sc) * a
                ln = np.linalg.norm(v)
                if ln < 1e-8:
                    continue
                acc = acc + (ln - l0) * kk * v / ln * wp / (wp + wq)
                n += 1
            if n:
                S["next_pos"][p] = S["next_pos"][p] + acc / n
                S["velocity_pos"][p] = S["velocity_pos"][p] + 0.3 * acc / n

    distance()
    # --- D.5/D.6 angle (restoration; the limit only when enabled)
    use_limit, use_rest = P["use_angle_limit"][t], P["use_restoration"][t]
    if use_limit or use_rest:
        gfac = (1 - P["restoration_gravity_falloff"][t]) + P["restoration_gravity_falloff"][t] * gdot
        for b in range(M["team_baseline_start"][t], M["team_baseline_start"][t] + M["team_baseline_count"][t]):
            e0 = M["baseline_start"][b]
            ents = [M["baseline_data"][e] for e in range(e0, e0 + M["baseline_count"][b])]
            length, lpos, lrot, rvec = {}, {}, {}, {}
            for c in ents[1:]:
                pr = M["parent"][c]
                ln = np.linalg.norm(S["next_pos"][c] - S["next_pos"][pr])
                bv = S["step_basic_pos"][c] - S["step_basic_pos"][pr]
                if ln < 1e-8 or np.linalg.norm(bv) < 1e-8:
                    length[c], lpos[c], lrot[c] = 0.0, np.zeros(3), np.array([0.0, 0, 0, 1])
                else:
                    iq = qinv(S["step_basic_rot"][pr])
                    length[c], lpos[c] = ln, qrot(iq, bv / np.linalg.norm(bv))
                    lrot[c] = qmul(iq, S["step_basic_rot"][c])
                rvec[c] = bv
            for it in range(3):
                rp = 0.1 + 0.4 * it / 2
                for c in ents[1:]:
                    if not att[c] & MOVE:
                        continue
                    pr = M["parent"][c]
                    cp, pp = S["next_pos"][c].copy(), S["next_pos"][pr].copy()
                    wc, wpp = 1 / (1 + 3 * S["friction"][c]), 1 / (1 + 3 * S["friction"][pr])
                    if use_limit:
                        raise NotImplementedError("naive_step: angle limit not modelled")
                    if use_rest:
                        tv = rvec[c]
                        if np.linalg.norm(tv) < 1e-8:
                            S["velocity_pos"][c] += pp - cp
                            S["next_pos"][c] = pp
                            continue
                        v = cp - pp
                        if np.linalg.norm(v) < 1e-8:
                            continue
                        kr = sat(curve(P["restoration_stiffness_curve"][t], depth[c], True)) * gfac
                        q = fromto_unit(v / np.linalg.norm(v), tv / np.linalg.norm(tv), kr)
                        r = qrot(q, v)
                        pivot = pp + v * rp
                        dpp = (pivot - r * rp - pp) * wpp
                        dc = (pivot + r * (1 - rp) - cp) * wc
                        attn = P["restoration_attenuation"][t]
                        S["next_pos"][c] = S["next_pos"][c] + dc
                        S["velocity_pos"][c] = S["velocity_pos"][c] + attn * dc
                        if att[pr] & MOVE:
                            S["next_pos"][pr] = S["next_pos"][pr] + dpp
                            S["velocity_pos"][pr] = S["velocity_pos"][pr] + attn * dpp
    # --- D.8 point collision (spheres and planes)
    if P["collision_mode"][t] == 1:
        for p in parts:
            if not att[p] & MOVE or att[p] & NO_COLLISION:
                continue
            r = max(curve(P["radius_curve"][t], depth[p]), 1e-4) * scale_ratio
            x = S["next_pos"][p].copy()
            push, sn, nacc, cnt, mind, touched = np.zeros(3), np.zeros(3), np.zeros(3), 0, np.inf, False
            for k in range(c0, c0 + T["collider_count"][t]):
                if C["shape"][k] == 2:
                    n = C["plane_normal"][k]
                    d, x2 = plane_push(C["now_pos"][k] + n * r, n, x)
                else:
                    R = C["radius_start"][k]
                    lo = np.minimum(C["old_pos"][k], C["now_pos"][k]) - R
                    hi = np.maximum(C["old_pos"][k], C["now_pos"][k]) + R
                    if np.any(x + 2 * r < lo) or np.any(x - 2 * r > hi):
                        continue
                    n = x - C["old_pos"][k]
                    n = n / np.linalg.norm(n)
                    d, x2 = plane_push(C["now_pos"][k] + n * (R + r), n, x)
                if d <= 0:
                    push, sn, cnt = push + (x2 - x), sn + n, cnt + 1
                if d <= r:
                    touched, nacc, mind = True, nacc + n, min(mind, d)
            if cnt:
                m = np.linalg.norm(sn / cnt)
                if m >= 1e-8:
                    S["next_pos"][p] = x + push / cnt * min(m, 1.0)
            if touched and nacc @ nacc > 1e-6:
                S["friction"][p] = max(S["friction"][p], 1 - sat(mind / r))
                nacc = nacc / np.linalg.norm(nacc)
            S["collision_normal"][p] = nacc
    distance()
    # --- D.9 motion (max distance only)
    if P["use_max_distance"][t] or P["use_backstop"][t]:
        assert not P["use_backstop"][t], "naive_step: backstop not modelled"
        for p in parts:
            if not att[p] & MOVE or att[p] & INVALID_MOTION:
                continue
            o = S["next_pos"][p].copy()
            x = S["base_pos"][p] + clamp_len(o - S["base_pos"][p], curve(P["max_distance_curve"][t], depth[p] ** 2))
            x = o + (x - o) * P["motion_stiffness"][t]
            S["next_pos"][p] = x
            S["velocity_pos"][p] = S["velocity_pos"][p] + 0.95 * (x - o)
    # --- D.10 end of step
    fr = P["friction"][t]
    for p in parts:
        nxt, old = S["next_pos"][p].copy(), S["old_pos"][p].copy()
        if att[p] & MOVE:
            cn, f, sf = S["collision_normal"][p], S["friction"][p], S["static_friction"][p]
            contact = cn @ cn > 1e-8 and f > 1e-8
            vp = S["velocity_pos"][p].copy()
            if contact and fr * scale_ratio > 0:
                d = nxt - old
                tv = d - (d @ cn) * cn
                spd = np.linalg.norm(tv) / dt
                th = fr * scale_ratio
                sf = sat(sf + 0.04) if spd < th else sat(sf - max((spd - th) / 0.2, 0.05))
                nxt, vp = nxt - tv * sf, vp - tv * sf
                S["next_pos"][p] = nxt
            else:
                sf = sat(sf - 0.05)
            S["static_friction"][p] = sf
            vel = (nxt - vp) / dt
            if contact and fr > 0 and vel @ vel >= 1e-8:
                dd = 0.5 + 0.5 * float(cn @ (vel / np.linalg.norm(vel)))
                vel = vel - vel * (1 - dd * dd) * sat(f * fr)
            S["friction"][p] = f * 0.6
            if P["particle_speed_limit"][t] >= 0:
                vel = clamp_len(vel, P["particle_speed_limit"][t] * scale_ratio)
            assert P["centrifugal_acceleration"][t] == 0.0, "naive_step: centrifugal term not modelled"
            S["velocity"][p] = vel * vw
        S["real_velocity"][p] = (nxt - old) / dt
        S["old_pos"][p] = nxt
    # --- G.3 end of step
    for k in range(c0, c0 + T["collider_count"][t]):
        C["old_pos"][k], C["old_rot"][k] = C["now_pos"][k].copy(), C["now_rot"][k].copy()
    del axis
