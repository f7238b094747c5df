"""Importers: glTF / GLB rigs and clips, VRM spring bones, BVH motion, humanoid retargeting.

Entry points (everything returned is plain data in Unity convention — Y up, left-handed,
metres, quaternions xyzw — see docs/import.md):

* ``load_gltf(path)`` → ``GltfRig`` (bones, skin joints, clips)
* ``load_vrm(path)`` → ``VrmAvatar`` (rig, humanoid, spring chains, colliders)
* ``load_bvh(path)`` → ``BvhAnimation`` (skeleton bones, clip)
* ``retarget(clip, source_bones, target_bones)`` → ``Clip``; ``retarget_with_report`` →
  (``Clip``, ``RetargetReport``: bone maps, facings, hips heights, rest alignment, lost bones)
* ``match_humanoid(names, parents)`` → ``HumanoidMatch`` (humanoid map by names and structure)
* ``ClipDriver(clip, hierarchy).apply(hierarchy, t)`` plays a clip (numba)
* ``sections``: ``rig_section``, ``vrm_sections``, ``load_clip`` for the scene loader
"""
from magica_py.io.bvh import BvhAnimation, load_bvh
from magica_py.io.clip import Clip, ClipDriver, Track
from magica_py.io.errors import AssetError
from magica_py.io.gltf import GltfRig, load_gltf
from magica_py.io.retarget import RetargetError, RetargetReport, retarget, retarget_with_report
from magica_py.io.skeleton_match import HumanoidMatch, match_humanoid
from magica_py.io.vrm import VrmAvatar, load_vrm

__all__ = ["AssetError", "BvhAnimation", "Clip", "ClipDriver", "GltfRig", "HumanoidMatch", "RetargetError",
           "RetargetReport", "Track", "VrmAvatar", "load_bvh", "load_gltf", "load_vrm", "match_humanoid", "retarget",
           "retarget_with_report"]
