"""Bake: write the simulated motion of a scene's bones out as animation (issue 21).

``magica-py bake SCENE.yaml --out FILE.glb|FILE.gltf|FILE.vrm|FILE.bvh`` runs the scene the
way ``magica-py run`` does, captures the local pose of every bone of its rigs (or the bones
matching ``--bones``) once per rendered frame (``capture.py``) and writes them:

* glTF / GLB / VRM (``gltf_writer.py``): for a rig loaded from a glTF, GLB or VRM file, an
  animation in a copy of that file (mesh, skin, materials and VRM data kept); otherwise a
  new file with the rig's nodes;
* BVH (``bvh_writer.py``, our own writer): for BVH rigs and generated rigs.

Both write in the file format's own handedness and units, the inverse of the import
conversion (``magica_py.io.coords``, the rig's ``unit_scale``), so loading the baked file
as a clip on the same rig reproduces the simulated local poses (``tests/test_bake*.py``).
"""
from __future__ import annotations

from magica_py.bake.bake import BakeResult, bake_scene, bake_capture
from magica_py.bake.capture import CapturedMotion, PoseCapture, select_bones, simulate_and_capture

__all__ = ["BakeResult", "bake_scene", "bake_capture", "CapturedMotion", "PoseCapture", "select_bones",
           "simulate_and_capture"]
