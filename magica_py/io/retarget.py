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

import warnings
from dataclasses import dataclass, field

from magica_py.io.body_frame import BodyFrame, detect_frame, floor_level, frame_rotation, norm
from magica_py.io.clip import Clip, Track, sample_track_many
from magica_py.io.humanoid import REQUIRED_BONES
from magica_py.io.quat import qconj, qfrom_to, qmul, qnormalize, qrotate
from magica_py.io.skeleton_match import HumanoidMatch, resolve_humanoid
from magica_py.scene.hierarchy import BoneSpec, TransformHierarchy
from magica_py.kernels import portable

ALIGNMENT_WARNING_DEG = 20.0      # validate / run warn above this rest alignment error
LOST_BONE_FRACTION = 0.1          # a source bone this long (x leg length) without a target is reported


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
        lengths.append(sum(float(norm(world_pos[idx[k + 1]] - world_pos[idx[k]])) for k in range(2)))
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


@dataclass
class RetargetReport:
    """What one retargeting did (``magica-py retarget-check`` prints it)."""

    clip: str
    source: HumanoidMatch
    target: HumanoidMatch
    source_frame: BodyFrame
    target_frame: BodyFrame
    turn_deg: float                         # angle of the facing turn applied to the source
    rest: str                               # "bind pose" or "frame k"
    hips: dict = field(default_factory=dict)   # heights (m) and ratio used for root motion
    limb_errors: dict = field(default_factory=dict)   # humanoid bone -> rest alignment error (deg)
    lost: list = field(default_factory=list)  # (source bone, length m, bones below) without a target
    same_named: int = 0
    warnings: list = field(default_factory=list)

    def lines(self) -> list[str]:
        out = [f"clip {self.clip}: rest = {self.rest}",
               f"  source skeleton: {self.source.family} names, {len(self.source.mapping)} humanoid bones mapped",
               f"  target skeleton: {self.target.family} names, {len(self.target.mapping)} humanoid bones mapped",
               "  bone map (humanoid: source -> target):"]
        for human in sorted(set(self.source.mapping) | set(self.target.mapping), key=_humanoid_order):
            out.append(f"    {human:14s} {self.source.mapping.get(human, '-')!s:28s} -> {self.target.mapping.get(human, '-')}")
        for label, match in (("source", self.source), ("target", self.target)):
            for note in match.notes:
                out.append(f"  {label} map: {note}")
            shown = ", ".join(match.unmapped[:12]) + (f" ... ({len(match.unmapped)})" if len(match.unmapped) > 12 else "")
            out.append(f"  unmapped {label} bones: {shown or 'none'}")
        out.append(f"  source facing: {self.source_frame.describe()}")
        out.append(f"  target facing: {self.target_frame.describe()}")
        out.append(f"  facing turn applied to the source: {self.turn_deg:.1f} deg")
        if self.hips:
            h = self.hips
            out.append(f"  hips: source {h['source_height']:.3f} m above its feet, target {h['target_height']:.3f} m; "
                       f"root motion x {h['ratio']:.3f} ({h['ratio_from']})")
        out.append("  rest alignment error after retargeting (deg):")
        for human, err in self.limb_errors.items():
            out.append(f"    {human:14s} {err:6.2f}" + ("  <-- worse than 20" if err > ALIGNMENT_WARNING_DEG else ""))
        if self.lost:
            for bone, length, below in self.lost:
                out.append(f"  source bone without a target: {bone} ({length:.2f} m, {below} bones below)")
        for w in self.warnings:
            out.append(f"  warning: {w}")
        return out


def _humanoid_order(human: str) -> int:
    from magica_py.io.humanoid import HUMANOID_BONES
    return HUMANOID_BONES.index(human) if human in HUMANOID_BONES else len(HUMANOID_BONES)


def _angle_deg(a, b) -> float:
    """Angle between two directions (diagnostics only: not fed to the simulation)."""
    na, nb = float(norm(a)), float(norm(b))
    if na < 1e-9 or nb < 1e-9:
        return 0.0
    c = float(np.sum(np.asarray(a) * np.asarray(b))) / (na * nb)
    return float(np.degrees(portable.acos(c)))


def _fk_positions(h: TransformHierarchy, world_rot: np.ndarray, hips: int | None, hips_world) -> np.ndarray:
    """World positions (J, 3) for world rotations (J, 4); the hips placed at ``hips_world``."""
    pos = np.zeros((h.count, 3))
    for j in range(h.count):
        p = h.parent[j]
        if j == hips and hips_world is not None:
            pos[j] = hips_world
        elif p < 0:
            pos[j] = h.rest_local_position[j]
        else:
            pos[j] = pos[p] + qrotate(world_rot[p], h.rest_local_position[j] * h.lossy_scale[p])
    return pos


def _segments(names: dict[str, str]):
    """(humanoid bone, next humanoid bone) for every bone with a mapped next one."""
    for human, candidates in _NEXT.items():
        if human in names:
            nxt = next((c for c in candidates if c in names), None)
            if nxt is not None:
                yield human, nxt


def _lost_bones(src_h: TransformHierarchy, transferred: set[int], rest_pos: np.ndarray, threshold: float):
    """(name, length m, bones below) of the topmost source bones at least ``threshold`` long
    (to their farthest child) with no transferred bone in their subtree: motion that is lost."""
    covered = np.zeros(src_h.count, dtype=bool)
    children = [[] for _ in range(src_h.count)]
    for j in range(src_h.count):
        if src_h.parent[j] >= 0:
            children[src_h.parent[j]].append(j)
    for j in reversed(range(src_h.count)):          # parents come before their children
        covered[j] = j in transferred or any(covered[c] for c in children[j])
    out, chosen = [], set()
    for j in range(src_h.count):
        if covered[j] or not children[j] or any(a in chosen for a in _ancestors(src_h, j)):
            continue
        length = max(float(norm(rest_pos[c] - rest_pos[j])) for c in children[j])
        if length >= threshold:
            chosen.add(j)
            out.append((src_h.names[j], length, len(src_h.descendants(j)) - 1))
    return out


def _ancestors(h: TransformHierarchy, j: int) -> list[int]:
    out, p = [], h.parent[j]
    while p >= 0:
        out.append(p)
        p = h.parent[p]
    return out


def _hips_root_motion(src_names, tgt_names, src_h, tgt_h, src_pos, rest_pos, tgt_rest_pos, up):
    """Target hips world positions (F, 3) and the figures behind them.

    Heights are measured along the (common, after the facing turn) ``up`` from the floor:
    the target's floor is its lowest rest foot / toes joint; the source's floor in the clip is
    the lowest its feet go over the clip, and its standing hips height is the rest pose's
    hips above the rest pose's feet. So a source whose rest pose puts the hips at the floor
    (BVH OFFSETs) or anywhere else still stands the target's hips at their own height:
    ``height_t(t) = H_t + (height_s(t) - H_s) · ratio``; horizontal motion is the source
    hips' displacement from their rest position times ``ratio``, the leg-length ratio
    (upper + lower leg, both sides), else the ratio of standing hips heights."""
    s_hips, t_hips = src_h.index(src_names["hips"]), tgt_h.index(tgt_names["hips"])
    src_leg = leg_length(src_names, src_h, rest_pos)
    tgt_leg = leg_length(tgt_names, tgt_h, tgt_rest_pos)
    src_floor_rest = floor_level(src_names, src_h.index_of, rest_pos, up)
    tgt_floor = floor_level(tgt_names, tgt_h.index_of, tgt_rest_pos, up)
    tgt_floor_from = "its feet"
    if tgt_floor is None:        # a rig without feet: the root it stands on (e.g. a path bone at the floor)
        chain = _ancestors(tgt_h, t_hips)
        tgt_floor = float(np.sum(tgt_rest_pos[chain[-1]] * up)) if chain else None
        tgt_floor_from = f"its root {tgt_h.names[chain[-1]]!r}" if chain else "unknown"
    src_floor_clip = floor_level(src_names, src_h.index_of, src_pos, up)
    rest_hips_height = float(np.sum(rest_pos[s_hips] * up))
    tgt_hips_height = float(np.sum(tgt_rest_pos[t_hips] * up))
    source_height = rest_hips_height - src_floor_rest if src_floor_rest is not None else None
    target_height = tgt_hips_height - tgt_floor if tgt_floor is not None else None
    if src_leg > 1e-9 and tgt_leg > 1e-9:
        ratio, ratio_from = tgt_leg / src_leg, "leg lengths"
    elif source_height and target_height and source_height > 1e-6 and target_height > 1e-6:
        ratio, ratio_from = target_height / source_height, "standing hips heights"
    else:
        ratio, ratio_from = 1.0, "no legs to compare: 1"
    moved = src_pos[:, s_hips] - rest_pos[s_hips]
    vertical = np.sum(moved * up, axis=-1)
    horizontal = moved - vertical[:, None] * up
    if source_height is not None and src_floor_clip is not None:
        # height above the clip's floor minus the standing height (0 when standing)
        vertical = (np.sum(src_pos[:, s_hips] * up, axis=-1) - src_floor_clip) - source_height
    hips_world = tgt_rest_pos[t_hips] + (horizontal + vertical[:, None] * up) * ratio
    if (target_height is not None and tgt_floor < -0.5 * target_height and src_floor_clip is not None
            and source_height is not None):
        # the target's rest pose stands below the world floor (a BVH-style bind pose with the
        # hips at the origin): it lives in the source's world, on the source's floor (scaled)
        standing = src_floor_clip * ratio + target_height
        hips_world = hips_world + up * (standing - tgt_hips_height)
        tgt_floor_from = "the source clip's floor (its rest pose stands below the origin)"
    figures = {"source_height": source_height if source_height is not None else float("nan"),
               "target_height": target_height if target_height is not None else float("nan"),
               "ratio": ratio, "ratio_from": ratio_from, "target_floor": tgt_floor_from,
               "source_floor_in_clip": src_floor_clip}
    return hips_world, figures


def retarget(clip: Clip, source_bones: list[BoneSpec], target_bones: list[BoneSpec], **options) -> Clip:
    """A clip for ``target_bones`` that moves them like ``clip`` moves ``source_bones``
    (``retarget_with_report`` without the report; its warnings are issued)."""
    return retarget_with_report(clip, source_bones, target_bones, **options)[0]


def retarget_with_report(clip: Clip, source_bones: list[BoneSpec], target_bones: list[BoneSpec], *,
                         source_map="auto", target_map="auto", source_overrides=None, target_overrides=None,
                         source_rest="bind", source_forward=None, source_up=None,
                         root_translation: bool = True, same_names: bool = True,
                         align_rest: bool = True, rate: float | None = None,
                         name: str | None = None, warn: bool = True) -> tuple[Clip, RetargetReport]:
    """The retargeted clip and a ``RetargetReport``.

    ``source_map`` / ``target_map``: ``"auto"`` (names and structure, ``io.skeleton_match``),
    a scheme name (``cmu``, ``mixamo``, ``vrm``) or a dict humanoid → bone (e.g.
    ``VrmAvatar.humanoid``); ``*_overrides``: a dict or YAML file path. ``source_rest``:
    ``"bind"`` or a frame index. ``source_forward`` / ``source_up``: the source's facing in
    project axes (Unity: +Z forward, +Y up) when the detection should not be used; both
    skeletons' facings are otherwise read from their rest poses and the source is turned
    onto the target's. ``same_names``: also transfer bones named alike on both sides that
    the humanoid map leaves out. ``align_rest``: turn each mapped target bone's rest
    direction onto the source's first (A-pose / T-pose). ``rate``: sampling rate in Hz
    (default: the clip's frame rate, else 60 Hz). ``warn``: issue ``UserWarning``s for a
    limb worse than 20° at rest, an undetermined facing, a large source bone without target.
    """
    src_h = TransformHierarchy(source_bones)
    tgt_h = TransformHierarchy(target_bones)
    src_match = resolve_humanoid(src_h.names, src_h.parent, source_map, source_overrides)
    tgt_match = resolve_humanoid(tgt_h.names, tgt_h.parent, target_map, target_overrides)
    src_names, tgt_names = src_match.mapping, tgt_match.mapping
    for bone in REQUIRED_BONES:
        if bone not in src_names:
            raise RetargetError(f"source skeleton: no bone mapped to humanoid {bone!r} (bones: {src_h.names[:8]}...); "
                                f"name it with source_overrides: {{{bone}: BONE}} or give source_map: cmu, mixamo "
                                "or vrm (docs/import.md)")
        if bone not in tgt_names:
            raise RetargetError(f"target skeleton: no bone mapped to humanoid {bone!r} (bones: {tgt_h.names[:8]}...); "
                                f"name it with target_overrides: {{{bone}: BONE}} or give target_map: cmu, mixamo "
                                "or vrm (docs/import.md)")
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
        rest_label = "bind pose"
    elif isinstance(source_rest, (int, np.integer)) and not isinstance(source_rest, bool) and 0 <= source_rest < frames:
        rest_rot, rest_pos = src_rot[source_rest:source_rest + 1], src_pos[source_rest:source_rest + 1]
        rest_label = f"frame {int(source_rest)}"
    else:
        raise RetargetError(f"source_rest must be 'bind' or a frame index in 0..{frames - 1}, got {source_rest!r}")
    tgt_rest_rot, tgt_rest_pos = pose_world(None, tgt_h, None)

    # facing: both frames from the rest poses; the source is turned onto the target's
    src_frame = detect_frame(src_names, src_h.index_of, rest_pos[0], source_forward, source_up)
    tgt_frame = detect_frame(tgt_names, tgt_h.index_of, tgt_rest_pos[0])
    notes = []
    report_warnings = []
    if src_frame.determined and tgt_frame.determined:
        turn = frame_rotation(src_frame, tgt_frame)
    else:
        turn = np.array([0.0, 0.0, 0.0, 1.0])
        which = "source" if not src_frame.determined else "target"
        problem = (src_frame if not src_frame.determined else tgt_frame).problem
        report_warnings.append(f"the {which} skeleton's facing could not be determined ({problem}): the clip is not "
                               f"turned; give retarget: source_forward / source_up")
    for frame, label in ((src_frame, "source"), (tgt_frame, "target")):
        if frame.determined and frame.feet == "disagree":
            report_warnings.append(f"the {label} skeleton's feet point against its detected forward "
                                   f"{frame.describe()}: are its left and right bones swapped?")
    up = tgt_frame.up if tgt_frame.determined else np.array([0.0, 1.0, 0.0])
    src_rot, src_pos = qnormalize(qmul(turn, src_rot)), qrotate(turn, src_pos)
    rest_rot, rest_pos = qnormalize(qmul(turn, rest_rot)), qrotate(turn, rest_pos)

    # the rest pose is transferred as one extra frame (the report's alignment check)
    all_rot = np.concatenate([src_rot, rest_rot], axis=0)
    target_world = {}
    align = _rest_alignment(src_names, tgt_names, src_h, tgt_h, rest_pos[0], tgt_rest_pos[0]) if align_rest else {}
    for source_bone, target_bone in pairs:
        s = src_h.index(source_bone)
        t = tgt_h.index(target_bone)
        delta = qmul(all_rot[:, s], qconj(rest_rot[0, s]))
        rest = qmul(align[t], tgt_rest_rot[0, t]) if t in align else tgt_rest_rot[0, t]
        target_world[t] = qnormalize(qmul(delta, rest))
    world = np.repeat(tgt_rest_rot, frames + 1, axis=0)
    tracks = []
    for j in range(tgt_h.count):
        p = tgt_h.parent[j]
        parent_world = world[:, p] if p >= 0 else np.array([0.0, 0.0, 0.0, 1.0])
        if j in target_world:
            world[:, j] = target_world[j]
            local = qnormalize(qmul(qconj(parent_world), world[:, j]))
            local = np.where(np.sum(local * tgt_h.rest_local_rotation[j], axis=-1, keepdims=True) < 0, -local, local)
            tracks.append(Track(tgt_h.names[j], "rotation", times, local[:frames]))
        else:
            world[:, j] = qnormalize(qmul(parent_world, tgt_h.rest_local_rotation[j])) if p >= 0 else tgt_h.rest_local_rotation[j]

    s_hips, t_hips = src_h.index(src_names["hips"]), tgt_h.index(tgt_names["hips"])
    hips_world, hips_figures = _hips_root_motion(src_names, tgt_names, src_h, tgt_h, src_pos,
                                                 rest_pos[0], tgt_rest_pos[0], up)
    if root_translation:
        p = tgt_h.parent[t_hips]
        if p >= 0:  # into the parent's rest space (ancestors of the hips are not animated)
            local = qrotate(qconj(tgt_rest_rot[0, p]), hips_world - tgt_rest_pos[0, p]) / tgt_h.lossy_scale[p]
        else:
            local = hips_world
        tracks.append(Track(tgt_h.names[t_hips], "translation", times, local))

    # report: rest alignment of every mapped segment, bones lost, warnings
    rest_positions = _fk_positions(tgt_h, world[frames], t_hips, tgt_rest_pos[0, t_hips])
    errors = {}
    for human, nxt in _segments(tgt_names):
        if human not in src_names or nxt not in src_names:
            continue
        s0, s1 = src_h.index(src_names[human]), src_h.index(src_names[nxt])
        t0, t1 = tgt_h.index(tgt_names[human]), tgt_h.index(tgt_names[nxt])
        errors[human] = _angle_deg(rest_positions[t1] - rest_positions[t0], rest_pos[0, s1] - rest_pos[0, s0])
    for human, err in errors.items():
        if err > ALIGNMENT_WARNING_DEG:
            report_warnings.append(f"{human} ({tgt_names[human]}) is {err:.1f} deg off the source's "
                                   f"{src_names[human]} in the rest pose after retargeting")
    transferred = {src_h.index(a) for a, _ in pairs}
    src_leg = leg_length(src_names, src_h, rest_pos[0]) or float(np.sum(rest_pos[0, s_hips] * up))
    lost = _lost_bones(src_h, transferred, rest_pos[0], LOST_BONE_FRACTION * max(src_leg, 1e-6))
    if lost:
        names = ", ".join(f"{b} ({length:.2f} m)" for b, length, _ in lost[:6])
        report_warnings.append(f"source bones without a target (their motion is lost): {names}"
                               + (f" and {len(lost) - 6} more" if len(lost) > 6 else ""))
    turn_deg = float(np.degrees(2.0 * portable.acos(abs(float(turn[3])))))
    report = RetargetReport(clip=name or clip.name, source=src_match, target=tgt_match, source_frame=src_frame,
                            target_frame=tgt_frame, turn_deg=turn_deg, rest=rest_label, hips=hips_figures,
                            limb_errors=errors, lost=lost, same_named=len(pairs) - len(shared),
                            warnings=report_warnings)
    if warn:
        for w in report_warnings:
            warnings.warn(f"retargeting {clip.name}: {w}", UserWarning, stacklevel=2)
    notes.append(f"retargeted {len(shared)} humanoid bones ({', '.join(shared)}) and {len(pairs) - len(shared)} "
                 f"same-named bones; source {src_frame.describe()}, turned {turn_deg:.1f} deg")
    out = Clip(name=name or f"{clip.name}@retarget", tracks=tracks, source=clip.source,
               frame_time=period, notes=clip.notes + notes)
    return out, report
