"""Humanoid bone matching by names *and* position in the skeleton.

Names alone lie: in the Biovision / CMU-boxing family ``LeftShoulder`` is the upper arm
and ``LeftHip`` the thigh; in Rigify ``DEF-spine`` is the hips; on a hand-made rig
``leg_l`` is the thigh and ``knee_l`` the shin. So a name only *labels* a bone (its side
and the parts it could be, ``humanoid.name_label``) and the skeleton's structure decides:

* **limbs**, per side: the end bone is the topmost bone labelled hand (``hand``,
  ``wrist``) or foot (``foot``, ``ankle``); walking up from it over *core* bones (twist,
  roll and numbered split bones such as ``DEF-forearm.L.001`` are skipped) the next bone
  is the lower limb (forearm / shin), the one above it the upper limb (upper arm /
  thigh), and for an arm the one above that, if it still belongs to the side, the
  shoulder (clavicle). So a thigh is a bone with a knee child and a foot below, an upper
  arm has a forearm and a hand below, a clavicle sits between the spine and the upper
  arm. A limb without a labelled end (a rig with no feet) starts from its deepest bone
  labelled as the lower limb. Toes: the foot's first core child on the way down (a bone
  labelled toes preferred).
* **hips**: the deepest bone labelled hips / pelvis that is an ancestor of both thighs,
  else the thighs' lowest common ancestor (Rigify's ``DEF-spine``, ASF's ``root``).
* **spine**: the path from the hips up to the head (the topmost bone labelled head on a
  path of unsided bones, else the end of the longest such path); the neck is the topmost
  bone labelled neck on it, else the first bone above the bone the arms hang from; the
  bones in between are ``spine``, ``chest``, ``upperChest`` (first, middle, last).

Every place where the structure overrules a name is reported (``HumanoidMatch.notes``).
"""
from __future__ import annotations

import re
from dataclasses import dataclass, field

from magica_py.io.humanoid import HUMANOID_BONES, detect_family, name_label

ARM = ("Shoulder", "UpperArm", "LowerArm", "Hand")
LEG = ("UpperLeg", "LowerLeg", "Foot", "Toes")
_TWIST_WORDS = ("twist", "roll", "share", "helper", "corrective", "bend", "nub", "end", "tip")


@dataclass
class HumanoidMatch:
    """The humanoid map chosen for one skeleton and how it was chosen."""

    mapping: dict[str, str]                      # humanoid name -> bone name
    family: str                                  # naming family detected (humanoid.FAMILIES) or "given"
    notes: list[str] = field(default_factory=list)   # structure overruling a name, gaps
    unmapped: list[str] = field(default_factory=list)  # bones not in the map (every bone)


def _numbered_split(name: str, parent: str | None) -> bool:
    """``DEF-forearm.L.001`` under ``DEF-forearm.L``: a split (twist) bone, not a joint."""
    return parent is not None and re.sub(r"[._\-\s]+\d+$", "", name) == parent and name != parent


class _Tree:
    def __init__(self, names: list[str], parents: list[int]):
        self.names = list(names)
        self.parents = list(parents)
        self.children = [[] for _ in names]
        for i, p in enumerate(parents):
            if p >= 0:
                self.children[p].append(i)
        self.labels = [name_label(n) for n in names]
        self.depth = []
        for i in range(len(names)):
            d, p = 0, parents[i]
            while p >= 0:
                d, p = d + 1, parents[p]
            self.depth.append(d)

    def side(self, i: int) -> str | None:
        return self.labels[i][0]

    def parts(self, i: int) -> tuple[str, ...]:
        return self.labels[i][1]

    def is_core(self, i: int) -> bool:
        words = self.labels[i][2]
        if any(w in _TWIST_WORDS for w in words):
            return False
        p = self.parents[i]   # a numbered split of a limb bone (spines are numbered joints: DEF-spine.001)
        return self.side(i) is None or not _numbered_split(self.names[i], self.names[p] if p >= 0 else None)

    def ancestors(self, i: int) -> list[int]:
        out, p = [], self.parents[i]
        while p >= 0:
            out.append(p)
            p = self.parents[p]
        return out

    def subtree(self, i: int) -> list[int]:
        out, stack = [], [i]
        while stack:
            j = stack.pop()
            out.append(j)
            stack.extend(self.children[j])
        return out


def _limb(tree: _Tree, side: str, parts: tuple[str, ...], notes: list[str]) -> dict[str, int]:
    """humanoid part (``UpperArm`` ...) -> bone index for one side's arm or leg."""
    upper, lower, end = ("UpperArm", "LowerArm", "Hand") if parts is ARM else ("UpperLeg", "LowerLeg", "Foot")
    sided = [i for i in range(len(tree.names)) if tree.side(i) == side and tree.is_core(i)]
    ends = [i for i in sided if end in tree.parts(i)]
    found: dict[str, int] = {}
    if ends:
        e = min(ends, key=lambda i: tree.depth[i])
        found[end] = e
        chain = _sided_ancestors(tree, e, side)
    else:
        lowers = [i for i in sided if lower in tree.parts(i)]
        if not lowers:
            uppers = [i for i in sided if upper in tree.parts(i)]
            if uppers:
                found[upper] = min(uppers, key=lambda i: tree.depth[i])
            return found
        low = max(lowers, key=lambda i: tree.depth[i])
        chain = [low] + _sided_ancestors(tree, low, side)
    slots = [lower, upper] + (["Shoulder"] if parts is ARM else [])
    for slot, bone in zip(slots, chain):
        found[slot] = bone
    if parts is LEG and "Foot" in found:
        toes = _toes(tree, found["Foot"], side)
        if toes is not None:
            found["Toes"] = toes
    for slot, bone in found.items():
        labels = tree.parts(bone)
        if labels and slot != labels[0]:
            notes.append(f"{tree.names[bone]!r} mapped as {side}{slot} by its place in the chain "
                         f"(by its name alone it would be {side}{labels[0]})")
    return found


def _sided_ancestors(tree: _Tree, i: int, side: str) -> list[int]:
    """Core ancestors of bone i up to the first one not on ``side`` (the trunk), nearest first."""
    out = []
    for a in tree.ancestors(i):
        if tree.side(a) != side:
            break
        if tree.is_core(a):
            out.append(a)
    return out


def _toes(tree: _Tree, foot: int, side: str) -> int | None:
    below = [j for j in tree.subtree(foot) if j != foot and tree.is_core(j) and tree.side(j) in (side, None)]
    labelled = [j for j in below if "Toes" in tree.parts(j)]
    if labelled:
        return min(labelled, key=lambda i: tree.depth[i])
    kids = [j for j in tree.children[foot] if tree.is_core(j)]
    return kids[0] if len(kids) == 1 else None


def _lca(tree: _Tree, a: int, b: int) -> int | None:
    up = set([a] + tree.ancestors(a))
    for x in [b] + tree.ancestors(b):
        if x in up:
            return x
    return None


def _trunk(tree: _Tree, found: dict[str, int], notes: list[str]) -> None:
    thighs = [found.get(f"{s}UpperLeg") for s in ("left", "right")]
    hips = None
    if None not in thighs:
        common = _lca(tree, *thighs)
        if common is not None:
            shared = [common] + tree.ancestors(common)
            labelled = [i for i in shared if "hips" in tree.parts(i)]
            hips = labelled[0] if labelled else common
    if hips is None:
        labelled = [i for i in range(len(tree.names)) if "hips" in tree.parts(i) and tree.side(i) is None]
        hips = min(labelled, key=lambda i: tree.depth[i]) if labelled else None
    if hips is None:
        return
    found["hips"] = hips
    if "hips" not in tree.parts(hips) and tree.parts(hips):
        notes.append(f"{tree.names[hips]!r} mapped as hips: the legs branch from it "
                     f"(its name reads as {' or '.join(tree.parts(hips))})")
    # the unsided path from the hips to the head
    arm_roots = [a for s in ("left", "right") for a in [found.get(f"{s}Shoulder", found.get(f"{s}UpperArm"))]
                 if a is not None]
    attach = {tree.parents[a] for a in arm_roots if tree.parents[a] >= 0}
    centre = [j for j in tree.subtree(hips) if j != hips and tree.side(j) is None and tree.is_core(j)
              and all(tree.side(a) is None for a in tree.ancestors(j)[:tree.depth[j] - tree.depth[hips]])]
    heads = [j for j in centre if "head" in tree.parts(j)]
    if heads:
        head = min(heads, key=lambda i: tree.depth[i])
    else:   # the end of the unsided path through the arms' attachment, else the deepest one
        through = [j for j in centre if any(a in attach for a in [j] + tree.ancestors(j))
                   and not tree.children[j]]
        pool = through or [j for j in centre if not tree.children[j]]
        if not pool:
            return
        head = max(pool, key=lambda i: tree.depth[i])
    path = list(reversed([head] + tree.ancestors(head)))
    path = path[path.index(hips) + 1:]                     # hips excluded, head included
    path = [j for j in path if tree.is_core(j)]
    found["head"] = head
    necks = [j for j in path[:-1] if "neck" in tree.parts(j)]
    if necks:
        neck = necks[0]
    else:
        above = [k for k, j in enumerate(path[:-1]) if j in attach]
        neck = path[above[-1] + 1] if above and above[-1] + 1 < len(path) - 1 else None
        if neck is None and len(path) >= 3 and path[-2] not in attach:
            neck = path[-2]
    if neck is not None:
        found["neck"] = neck
    body = path[:path.index(neck)] if neck is not None else path[:-1]
    if body:
        found["spine"] = body[0]
    if len(body) >= 2:
        found["chest"] = body[len(body) // 2] if len(body) >= 3 else body[1]
    if len(body) >= 3:
        found["upperChest"] = body[-1]


def match_humanoid(names: list[str], parents: list[int]) -> HumanoidMatch:
    """The humanoid map of a skeleton (bone names and parent indices, -1 for roots)."""
    tree = _Tree(names, parents)
    notes: list[str] = []
    found: dict[str, int] = {}
    for side in ("left", "right"):
        for part, bone in _limb(tree, side, ARM, notes).items():
            found[f"{side}{part}"] = bone
        for part, bone in _limb(tree, side, LEG, notes).items():
            found[f"{side}{part}"] = bone
    _trunk(tree, found, notes)
    mapping = {h: tree.names[found[h]] for h in HUMANOID_BONES if h in found}
    used = set(mapping.values())
    return HumanoidMatch(mapping, detect_family(names), notes, [n for n in names if n not in used])


def resolve_humanoid(names: list[str], parents: list[int], scheme="auto", overrides=None) -> HumanoidMatch:
    """The humanoid map the retargeter uses: ``scheme`` a dict humanoid → bone (e.g. a VRM
    file's own humanoid, trusted as given), a scheme name of ``humanoid.SCHEMES`` (its
    table), or ``"auto"`` / ``"generic"`` (``match_humanoid``: names and structure); then
    ``overrides`` (a dict or YAML file, ``None`` values unmap)."""
    from magica_py.io.humanoid import SCHEMES, humanoid_map, load_overrides

    names = list(names)
    if isinstance(scheme, dict):
        match = HumanoidMatch({h: b for h, b in scheme.items() if h in HUMANOID_BONES and b in names}, "given")
    elif scheme in ("auto", "generic"):
        match = match_humanoid(names, list(parents))
    elif scheme in SCHEMES:
        match = HumanoidMatch(humanoid_map(names, scheme), scheme)
    else:
        raise ValueError(f"unknown naming scheme {scheme!r}; expected auto, {', '.join(sorted(SCHEMES))} "
                         f"or a humanoid mapping")
    for human, bone in load_overrides(overrides).items():
        if bone is None:
            match.mapping.pop(human, None)
            match.notes.append(f"{human} unmapped by an override")
        elif bone not in names:
            raise ValueError(f"humanoid override {human}: {bone!r} is not a bone of the skeleton")
        else:
            match.mapping[human] = bone
            match.notes.append(f"{human} = {bone!r} by an override")
    used = set(match.mapping.values())
    match.unmapped = [n for n in names if n not in used]
    return match
