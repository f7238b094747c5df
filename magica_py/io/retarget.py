"""Retargeting a clip from one skeleton onto another by humanoid bone names.

Method (world-space rotation deltas, the classic "rest-pose relative" transfer):

* both skeletons are posed in their rest pose (the target's file pose; the source's bind
  pose or a chosen frame, e.g. the T-pose frame 0 of CMU files);
* for every humanoid bone mapped on both sides, the source's world rotation change
  ``Δ(t) = W_src(t) · W_src_rest⁻¹`` is applied to the target's rest world rotation:
  ``W_tgt(t) = Δ(t) · W_tgt_rest``; target bones in between keep their rest local rotation;
  local rotations follow as ``parent_world⁻¹ · W_tgt(t)``, parents first;
* the hips translate by the source hips' world displacement from its rest position scaled
  by the ratio of leg lengths (upper + lower leg, mean of both sides):
  ``P_tgt(t) = P_tgt_rest + (P_src(t) - P_src_rest) · L_tgt / L_src``.

Rest postures: with ``align_rest`` (default) each mapped target bone is first turned so its
rest direction towards the next mapped humanoid bone matches the source's (``W_tgt_rest``
becomes ``C · W_tgt_rest`` with ``C`` the shortest rotation between the two directions), so
an A-pose target follows a T-pose source; twist about the bone is not aligned. Both
skeletons must face the same way (+Z after import). Retargeting a clip onto its own
skeleton reproduces it (every ``C`` is the identity).
"""
from __future__ import annotations

import numpy as np

from magica_py.io.clip import Clip, Track, sample_track_many
from magica_py.io.humanoid import REQUIRED_BONES, humanoid_map
from magica_py.io.quat import qconj, qmul, qnormalize, qrotate
from magica_py.scene.hierarchy import BoneSpec, TransformHierarchy
from magica_py.kernels import portable


class RetargetError(ValueError):
    """Skeletons that cannot be matched (missing hips, mapped bone not in the skeleton)."""


def _order(bones: list[BoneSpec]):
    h = TransformHierarchy(bones)
    return h, list(h.names), h.parent.copy()


def pose_world(clip: Clip | None, hierarchy: TransformHierarchy, times: np.ndarray | None):
    """World rotations (F, J, 4) and positions (F, J, 3) of every joint, with the clip's
    tracks (if any) applied over the rest pose at each time. Scale is taken from the rest."""
    n = hierarchy.count
    frames = 1 if times is None else len(times)
    local_rot = np.repeat(hierarchy.rest_local_rotation[None], frames, axis=0)
    local_pos = np.repeat(hierarchy.rest_local_position[None], frames, axis=0)
    if clip is not None:
        for tr in clip.tracks:
            if tr.node not in hierarchy.index_of or tr.path == "scale":
                continue
            j = hierarchy.index_of[tr.node]
            values = sample_track_many(tr, times)
            if tr.path == "rotation":
                local_rot[:, j] = values
            else:
                local_pos[:, j] = values
    world_rot = np.zeros((frames, n, 4))
    world_pos = np.zeros((frames, n, 3))
    scale = hierarchy.lossy_scale
    for j in range(n):
        p = hierarchy.parent[j]
        if p < 0:
            world_rot[:, j] = local_rot[:, j]
            world_pos[:, j] = local_pos[:, j]
        else:
            world_rot[:, j] = qnormalize(qmul(world_rot[:, p], local_rot[:, j]))
            world_pos[:, j] = world_pos[:, p] + qrotate(world_rot[:, p], local_pos[:, j] * scale[p])
    return world_rot, world_pos


def leg_length(names: dict[str, str], hierarchy: TransformHierarchy, world_pos: np.ndarray) -> float:
    """Mean over both sides of |upper→lower leg| + |lower leg→foot| in the rest pose."""
    lengths = []
    for side in ("left", "right"):
        chain = [names.get(f"{side}UpperLeg"), names.get(f"{side}LowerLeg"), names.get(f"{side}Foot")]
        if None in chain:
            continue
        idx = [hierarchy.index(b) for b in chain]
        lengths.append(sum(portable.norm(world_pos[idx[k + 1]] - world_pos[idx[k]]) for k in range(2)))
    return float(np.mean(lengths)) if lengths else 0.0


# The next humanoid bone along each limb (first one mapped on both sides is used) that
# defines a bone's direction for rest-posture alignment. The hips are not aligned.
_NEXT = {
    "spine": ("chest", "upperChest", "neck"), "chest": ("upperChest", "neck"), "upperChest": ("neck",),
    "neck": ("head",),
    **{f"{side}{a}": nxt for side in ("left", "right") for a, nxt in (
        ("Shoulder", (f"{side}UpperArm",)), ("UpperArm", (f"{side}LowerArm",)), ("LowerArm", (f"{side}Hand",)),
        ("UpperLeg", (f"{side}LowerLeg",)), ("LowerLeg", (f"{side}Foot",)), ("Foot", (f"{side}Toes",)))},
}


def _rest_alignment(src_names, tgt_names, src_h, tgt_h, src_rest_pos, tgt_rest_pos) -> dict[int, np.ndarray]:
    """Target bone index → world rotation taking its rest bone direction onto the source's."""
    from magica_py.io.quat import qfrom_to
    out = {}
    for human, candidates in _NEXT.items():
        if human not in src_names or human not in tgt_names:
            continue
        nxt = next((c for c in candidates if c in src_names and c in tgt_names), None)
        if nxt is None:
            continue
        s, sc = src_h.index(src_names[human]), src_h.index(src_names[nxt])
        t, tc = tgt_h.index(tgt_names[human]), tgt_h.index(tgt_names[nxt])
        out[t] = qfrom_to(tgt_rest_pos[tc] - tgt_rest_pos[t], src_rest_pos[sc] - src_rest_pos[s])
    return out


def retarget(clip: Clip, source_bones: list[BoneSpec], target_bones: list[BoneSpec], *,
             source_map="auto", target_map="auto", source_overrides=None, target_overrides=None,
             source_rest="bind", root_translation: bool = True, same_names: bool = True,
             align_rest: bool = True, rate: float | None = None,
             name: str | None = None) -> Clip:
    """A clip for ``target_bones`` that moves them like ``clip`` moves ``source_bones``.

    ``source_map`` / ``target_map``: ``"auto"``, a scheme name (``cmu``, ``mixamo``,
    ``vrm``) or a dict humanoid → bone (e.g. ``VrmAvatar.humanoid``); ``*_overrides``: a
    dict or YAML file path. ``same_names``: also transfer bones named alike on both sides
    that the humanoid map leaves out (so a clip retargeted onto its own skeleton is
    reproduced exactly, intermediate joints included). ``align_rest``: first turn each
    mapped target bone so that its rest direction towards its next mapped humanoid bone is
    the source's (an A-pose target follows a T-pose source; identity when the rest postures
    already agree). ``source_rest``: ``"bind"`` or a frame index. ``rate``: sampling
    rate in Hz (default: the clip's frame rate, else 60 Hz).
    """
    src_h = TransformHierarchy(source_bones)
    tgt_h = TransformHierarchy(target_bones)
    src_names = humanoid_map(src_h.names, source_map, source_overrides)
    tgt_names = humanoid_map(tgt_h.names, target_map, target_overrides)
    for bone in REQUIRED_BONES:
        if bone not in src_names:
            raise RetargetError(f"source skeleton: no bone mapped to humanoid {bone!r} (bones: {src_h.names[:8]}...)")
        if bone not in tgt_names:
            raise RetargetError(f"target skeleton: no bone mapped to humanoid {bone!r} (bones: {tgt_h.names[:8]}...)")
    shared = [b for b in src_names if b in tgt_names]
    pairs = [(src_names[b], tgt_names[b]) for b in shared]
    if same_names:  # bones outside the humanoid set named alike on both sides (fingers, a twist bone, ...)
        used_s, used_t = {a for a, _ in pairs}, {b for _, b in pairs}
        pairs += [(n, n) for n in src_h.names if n in tgt_h.index_of and n not in used_s and n not in used_t]
    period = clip.frame_time if rate is None and clip.frame_time else 1.0 / (rate or 60.0)
    frames = int(round(clip.duration / period)) + 1
    times = np.arange(frames) * period

    src_rot, src_pos = pose_world(clip, src_h, times)
    if source_rest == "bind":
        rest_rot, rest_pos = pose_world(None, src_h, None)
    elif isinstance(source_rest, int) and 0 <= source_rest < frames:
        rest_rot, rest_pos = src_rot[source_rest:source_rest + 1], src_pos[source_rest:source_rest + 1]
    else:
        raise RetargetError(f"source_rest must be 'bind' or a frame index in 0..{frames - 1}, got {source_rest!r}")
    tgt_rest_rot, tgt_rest_pos = pose_world(None, tgt_h, None)

    # target world rotations of mapped bones, then locals parents-first
    target_world = {}
    align = _rest_alignment(src_names, tgt_names, src_h, tgt_h, rest_pos[0], tgt_rest_pos[0]) if align_rest else {}
    for source_bone, target_bone in pairs:
        s = src_h.index(source_bone)
        t = tgt_h.index(target_bone)
        delta = qmul(src_rot[:, s], qconj(rest_rot[0, s]))
        rest = qmul(align[t], tgt_rest_rot[0, t]) if t in align else tgt_rest_rot[0, t]
        target_world[t] = qnormalize(qmul(delta, rest))
    world = np.repeat(tgt_rest_rot, frames, axis=0)
    tracks = []
    for j in range(tgt_h.count):
        p = tgt_h.parent[j]
        parent_world = world[:, p] if p >= 0 else np.array([0.0, 0.0, 0.0, 1.0])
        if j in target_world:
            world[:, j] = target_world[j]
            local = qnormalize(qmul(qconj(parent_world), world[:, j]))
            local = np.where(np.sum(local * tgt_h.rest_local_rotation[j], axis=-1, keepdims=True) < 0, -local, local)
            tracks.append(Track(tgt_h.names[j], "rotation", times, local))
        else:
            world[:, j] = qnormalize(qmul(parent_world, tgt_h.rest_local_rotation[j])) if p >= 0 else tgt_h.rest_local_rotation[j]

    if root_translation:
        s_hips, t_hips = src_h.index(src_names["hips"]), tgt_h.index(tgt_names["hips"])
        src_leg = leg_length(src_names, src_h, rest_pos[0])
        tgt_leg = leg_length(tgt_names, tgt_h, tgt_rest_pos[0])
        ratio = tgt_leg / src_leg if src_leg > 1e-9 and tgt_leg > 1e-9 else 1.0
        hips_world = tgt_rest_pos[0, t_hips] + (src_pos[:, s_hips] - rest_pos[0, s_hips]) * ratio
        p = tgt_h.parent[t_hips]
        if p >= 0:  # into the parent's space (its rest pose: ancestors of the hips are not animated)
            m = tgt_h.local_to_world[p]
            local = portable.rotate_vectors(portable.inverse3(m[:3, :3]), hips_world - m[:3, 3])
        else:
            local = hips_world
        tracks.append(Track(tgt_h.names[t_hips], "translation", times, local))
    notes = [f"retargeted {len(shared)} humanoid bones ({', '.join(shared)}) and {len(pairs) - len(shared)} same-named bones"]
    return Clip(name=name or f"{clip.name}@retarget", tracks=tracks, source=clip.source,
                frame_time=period, notes=clip.notes + notes)
