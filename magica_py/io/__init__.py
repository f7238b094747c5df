"""Importers: glTF / GLB rigs and clips, VRM spring bones, BVH motion, humanoid retargeting.

Entry points (everything returned is plain data in Unity convention — Y up, left-handed,
metres, quaternions xyzw — see docs/import.md):

* ``load_gltf(path)`` → ``GltfRig`` (bones, skin joints, clips)
* ``load_vrm(path)`` → ``VrmAvatar`` (rig, humanoid, spring chains, colliders)
* ``load_bvh(path)`` → ``BvhAnimation`` (skeleton bones, clip)
* ``retarget(clip, source_bones, target_bones)`` → ``Clip``
* ``ClipDriver(clip, hierarchy).apply(hierarchy, t)`` plays a clip (numba)
* ``sections``: ``rig_section``, ``vrm_sections``, ``load_clip`` for the scene loader
"""
from magica_py.io.bvh import BvhAnimation, load_bvh
from magica_py.io.clip import Clip, ClipDriver, Track
from magica_py.io.errors import AssetError
from magica_py.io.gltf import GltfRig, load_gltf
from magica_py.io.retarget import RetargetError, retarget
from magica_py.io.vrm import VrmAvatar, load_vrm

__all__ = ["AssetError", "BvhAnimation", "Clip", "ClipDriver", "GltfRig", "RetargetError", "Track",
           "VrmAvatar", "load_bvh", "load_gltf", "load_vrm", "retarget"]
