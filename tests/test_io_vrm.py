"""VRM 0.x / 1.0 spring bones → bone cloths and colliders (magica_py.io.vrm, io.sections)."""
import json
import shutil
import struct
from pathlib import Path

import numpy as np
import pytest

from magica_py.io.errors import AssetError
from magica_py.io.quat import qrotate
from magica_py.io.sections import rig_section, vrm_sections
from magica_py.io.vrm import load_vrm
from magica_py.params import resolve_parameters
from magica_py.scene.hierarchy import TransformHierarchy

DATA = Path(__file__).parents[1].parent / "shared" / "data"
GODETTE = DATA / "vrm" / "Godette_vrm_v4.vrm"
EXAMPLES = DATA / "vrm" / "three-vrm-springbone-examples"
pytestmark = pytest.mark.skipif(not DATA.is_dir(), reason=f"shared test data folder {DATA} is absent")


@pytest.fixture(scope="module")
def godette():
    with pytest.warns(UserWarning, match="radius 1 m exceeds"):
        return load_vrm(GODETTE)


def test_godette_is_vrm0_with_71_nodes_68_joints_45_humanoid_bones(godette):
    assert godette.spec_version == "0.x"
    assert len(godette.rig.bones) == 71 and len(godette.rig.joints) == 68
    assert len(godette.humanoid) == 45
    assert godette.humanoid["hips"] == "pelvis_Armature" and godette.humanoid["head"] == "head_Armature"


def test_godette_has_eight_chains_in_three_groups_with_the_file_parameters(godette):
    assert len(godette.chains) == 8
    by_group = {}
    for c in godette.chains:
        by_group.setdefault(c.group, []).append(c)
    assert [len(v) for v in by_group.values()] == [4, 1, 3]
    stiff = [v[0].vrm["stiffness"] for v in by_group.values()]
    drag = [v[0].vrm["drag_force"] for v in by_group.values()]
    assert stiff == [2.5, 2.0, 4.0] and drag == pytest.approx([0.4, 0.4, 0.1])
    assert all(c.vrm["hit_radius"] == pytest.approx(0.02) for c in godette.chains)
    # chains are a bone plus its end node; no synthetic tail was needed
    assert all(len(c.joints) == 2 and c.joints[1].lower().endswith("_end") for c in godette.chains)
    assert godette.extra_bones == []


def test_godette_colliders_are_four_spheres_on_chest_and_head(godette):
    cols = {c.name: c for c in godette.colliders}
    assert len(cols) == 4 and all(c.shape == "sphere" for c in cols.values())
    radii = sorted(round(c.radius, 3) for c in cols.values())
    assert radii == [0.1, 0.15, 0.217, 1.0]
    assert {c.transform for c in cols.values()} == {"chest_Armature", "head_Armature"}
    hair = next(c for c in godette.chains if c.name == "FrontHair_L")
    ribbon = next(c for c in godette.chains if c.name == "Ribbon")
    assert {cols[n].transform for n in hair.colliders} == {"head_Armature"}
    assert {cols[n].transform for n in ribbon.colliders} == {"chest_Armature"}
    assert [c for c in godette.chains if c.group == "HairBall"][0].colliders == []
    assert cols["vrm_col1_1"].center == pytest.approx((0.0, 1.31, 0.07), abs=1e-6)


def test_oversized_collider_can_be_clamped_or_dropped():
    with pytest.warns(UserWarning, match="clamped to 0.5 m"):
        clamped = load_vrm(GODETTE, oversized_colliders="clamp")
    assert max(c.radius for c in clamped.colliders) == 0.5
    with pytest.warns(UserWarning, match="dropped"):
        dropped = load_vrm(GODETTE, oversized_colliders="drop")
    assert len(dropped.colliders) == 3
    assert all("vrm_col1_1" not in c.colliders for c in dropped.chains)


def test_godette_cloth_entries_validate_as_cloth_parameters(godette):
    entries = godette.cloth_entries()
    assert [e["root_bones"] for e in entries] == [
        ["FrontHair_Center_L", "FrontHair_Center_R", "FrontHair_R", "FrontHair_L"], ["Ribbon"],
        ["HairBall_L", "HairBall_R", "HairBall_Center"]]
    for i, e in enumerate(entries):
        p = resolve_parameters(None, e["parameters"], f"cloths[{i}].parameters")
        assert p["radius"].value == pytest.approx(0.02)
        assert p["root_rotation"] == 1.0 and p["angle_limit.use"] is False
    assert len(godette.cloth_entries(group_by="chain")) == 8


def test_vrm_sections_keep_only_the_colliders_the_cloths_use():
    with pytest.warns(UserWarning):
        sections = vrm_sections(GODETTE, chains=["Ribbon"])
    assert [c["name"] for c in sections["cloths"]] == ["vrm_Ribbon"]
    assert [c["transform"] for c in sections["colliders"]] == ["chest_Armature", "chest_Armature"]
    assert sections["colliders"][0]["sphere"]["radius"] == pytest.approx(0.1)


def test_rig_section_of_a_vrm_lists_bones_joints_and_humanoid():
    rig = rig_section(GODETTE, name="godette")   # silent: the collider quirk is vrm_sections' to report
    assert rig["name"] == "godette" and len(rig["bones"]) == 71
    assert len(rig["joints"]) == 68 and rig["humanoid"]["leftFoot"] == "foot.l_Armature"
    assert rig["bones"][0] == {"name": "Armature_rootJoint", "parent": None, "position": [0.0, pytest.approx(0.050284), 0.0],
                               "rotation": [0.0, 0.0, 0.0, 1.0], "scale": [1.0, 1.0, 1.0]}


def test_vrm1_sphere_example_has_one_five_joint_chain_and_a_half_metre_sphere():
    avatar = load_vrm(EXAMPLES / "sphere-collider.gltf")
    assert avatar.spec_version == "1.0"
    assert [c.joints for c in avatar.chains] == [["Spring A", "Spring B", "Spring C", "Spring D", "Spring E"]]
    chain = avatar.chains[0]
    assert chain.vrm == {"stiffness": 1.0, "gravity_power": 0.0, "gravity_dir": (0.0, -1.0, 0.0),
                         "drag_force": 0.4, "hit_radius": 0.25}
    assert chain.segment_length == pytest.approx(0.5)       # -2 local units under a 0.25 scale
    (col,) = avatar.colliders
    h = TransformHierarchy(avatar.bones)
    world_radius = col.radius * h.lossy_scale[h.index(col.transform), 0]
    assert col.shape == "sphere" and world_radius == pytest.approx(0.5)
    assert np.allclose(h.world_position[h.index(col.transform)], [-0.75, 1.0, 0.0])


def test_vrm1_extended_plane_becomes_a_plane_whose_up_is_the_normal():
    avatar = load_vrm(EXAMPLES / "plane-collider.gltf")
    (col,) = avatar.colliders
    assert col.shape == "plane" and col.transform == "Collider#vrm_collider0"
    h = TransformHierarchy(avatar.bones)
    normal = h.transform_direction(h.index(col.transform), [0, 1, 0])
    # file: normal +Z in a node turned +90 deg about Y → world +X (glTF) → -X in Unity
    assert np.allclose(normal, [-1.0, 0.0, 0.0], atol=1e-9)
    assert np.allclose(h.world_position[h.index(col.transform)], [0.25, 1.0, 0.0])


def test_vrm1_inside_sphere_is_skipped_with_a_note():
    with pytest.warns(UserWarning, match=r"inside-collider\.gltf: skipped extensions\.VRMC_springBone\.colliders\[0\]"
                                         r".*inside sphere has no MagicaCloth2 counterpart"):
        avatar = load_vrm(EXAMPLES / "inside-collider.gltf")
    assert avatar.colliders == [] and len(avatar.chains) == 1
    assert any("inside sphere has no MagicaCloth2 counterpart" in s for s in avatar.skipped)
    assert avatar.cloth_entries()[0]["collision_mode"] == "none"


def test_a_vrm_without_spring_bones_says_it_adds_no_cloth(tmp_path):
    for f in ("sphere-collider.gltf", "sphere_mesh.bin"):
        shutil.copy(EXAMPLES / f, tmp_path / f)
    path = tmp_path / "sphere-collider.gltf"
    doc = json.loads(path.read_text())
    doc["extensions"]["VRMC_springBone"]["springs"] = []
    path.write_text(json.dumps(doc))
    with pytest.warns(UserWarning, match=r"sphere-collider\.gltf: the VRM has no spring bones .*: it adds no cloth"):
        assert vrm_sections(path)["cloths"] == []


def test_spring_joint_referencing_a_missing_node_names_the_json_path(tmp_path):
    for f in ("sphere-collider.gltf", "sphere_mesh.bin"):
        shutil.copy(EXAMPLES / f, tmp_path / f)
    path = tmp_path / "sphere-collider.gltf"
    doc = json.loads(path.read_text())
    doc["extensions"]["VRMC_springBone"]["springs"][0]["joints"][3]["node"] = 99
    path.write_text(json.dumps(doc))
    with pytest.raises(AssetError, match=r"sphere-collider\.gltf: extensions\.VRMC_springBone\.springs\[0\]\.joints\[3\]\.node: "
                                         r"node index 99 does not exist \(the file has 6 nodes\)"):
        load_vrm(path)


def test_vrm0_bone_group_referencing_a_missing_node_is_rejected(tmp_path):
    import pygltflib
    doc = pygltflib.GLTF2().load_binary(str(GODETTE))
    doc.extensions["VRM"]["secondaryAnimation"]["boneGroups"][1]["bones"] = [500]
    bad = tmp_path / "bad.vrm"
    doc.save_binary(str(bad))
    with pytest.raises(AssetError, match=r"boneGroups\[1\]\.bones\[0\]: node index 500 does not exist"):
        load_vrm(bad)


def test_a_childless_root_gets_a_7cm_virtual_tail(tmp_path):
    for f in ("sphere-collider.gltf", "sphere_mesh.bin"):
        shutil.copy(EXAMPLES / f, tmp_path / f)
    path = tmp_path / "sphere-collider.gltf"
    doc = json.loads(path.read_text())
    # turn the file into VRM 0.x: one bone group whose root is the leaf "Spring E"
    del doc["extensions"]["VRMC_springBone"]
    doc["extensions"]["VRM"] = {"secondaryAnimation": {"boneGroups": [{"bones": [4], "stiffiness": 1.0, "dragForce": 0.4,
                                                                         "hitRadius": 0.02, "gravityPower": 0}],
                                                        "colliderGroups": []}}
    path.write_text(json.dumps(doc))
    avatar = load_vrm(path)
    (tail,) = avatar.extra_bones
    assert tail.name == "Spring E_vrm_tail" and avatar.chains[0].joints == ["Spring E", "Spring E_vrm_tail"]
    h = TransformHierarchy(avatar.bones)
    step = h.world_position[h.index(tail.name)] - h.world_position[h.index("Spring E")]
    assert np.allclose(step, [0.0, -0.07 * 0.25, 0.0], atol=1e-12)   # 7 cm x the joint's 0.25 world scale


def test_file_without_vrm_data_is_rejected():
    with pytest.raises(AssetError, match=r"Fox\.glb: extensions: no VRM data"):
        load_vrm(DATA / "gltf" / "Fox.glb")


def test_vrm1_capsules_along_an_axis_or_oblique_and_the_vrm1_humanoid(tmp_path):
    doc = {
        "asset": {"version": "2.0"}, "scene": 0, "scenes": [{"nodes": [0]}],
        "nodes": [{"name": "hips", "translation": [0, 1, 0], "children": [1, 3]},
                  {"name": "hair", "translation": [0.1, 0.5, 0], "children": [2]},
                  {"name": "hair_end", "translation": [0, -0.2, 0]},
                  {"name": "leg", "translation": [0.1, -0.1, 0]}],
        "extensionsUsed": ["VRMC_vrm", "VRMC_springBone"],
        "extensions": {
            "VRMC_vrm": {"specVersion": "1.0", "humanoid": {"humanBones": {"hips": {"node": 0}, "leftUpperLeg": {"node": 3}}}},
            "VRMC_springBone": {"specVersion": "1.0",
                "colliders": [{"node": 3, "shape": {"capsule": {"offset": [0, 0, 0], "tail": [0, -0.3, 0], "radius": 0.05}}},
                              {"node": 0, "shape": {"capsule": {"offset": [0, 0, 0], "tail": [0.1, 0.1, 0], "radius": 0.02}}}],
                "colliderGroups": [{"colliders": [0, 1]}],
                "springs": [{"name": "hair", "colliderGroups": [0],
                             "joints": [{"node": 1, "hitRadius": 0.01, "stiffness": 1.0, "dragForce": 0.1, "gravityPower": 0.1,
                                         "gravityDir": [1, 0, 0]}, {"node": 2}]}]}},
    }
    path = tmp_path / "capsules.gltf"
    path.write_text(json.dumps(doc))
    avatar = load_vrm(path)
    assert avatar.humanoid == {"hips": "hips", "leftUpperLeg": "leg"}
    assert avatar.chains[0].vrm["gravity_dir"] == (-1.0, 0.0, 0.0)      # glTF +X is Unity -X
    leg, oblique = avatar.colliders
    assert (leg.transform, leg.direction) == ("leg", "y")
    assert leg.center == pytest.approx((0.0, -0.15, 0.0)) and leg.length == pytest.approx(0.4)
    assert leg.to_entry()["capsule"] == {"radius": 0.05, "end_radius": 0.05, "length": pytest.approx(0.4), "direction": "y",
                                         "reverse": False, "aligned_on_center": True}
    assert oblique.transform == "hips#vrm_collider1" and oblique.direction == "y"
    h = TransformHierarchy(avatar.bones)
    axis = h.transform_direction(h.index(oblique.transform), [0, 1, 0])
    assert np.allclose(axis, np.array([-1.0, 1.0, 0.0]) / np.sqrt(2))
    assert np.allclose(h.world_position[h.index(oblique.transform)], [-0.05, 1.05, 0.0])
    assert oblique.length == pytest.approx(np.sqrt(0.02) + 0.04)
    entry = avatar.cloth_entries()[0]
    assert entry["root_bones"] == ["hair"] and entry["colliders"] == [leg.name, oblique.name]


def test_springs_with_the_same_name_stay_separate_cloths(tmp_path):
    for f in ("sphere-collider.gltf", "sphere_mesh.bin"):
        shutil.copy(EXAMPLES / f, tmp_path / f)
    path = tmp_path / "sphere-collider.gltf"
    doc = json.loads(path.read_text())
    springs = doc["extensions"]["VRMC_springBone"]["springs"]
    first = dict(springs[0], name="Hair", joints=springs[0]["joints"][:3])
    second = dict(springs[0], name="Hair", joints=[dict(j, stiffness=0.5) for j in springs[0]["joints"][2:]])
    doc["extensions"]["VRMC_springBone"]["springs"] = [first, second]
    path.write_text(json.dumps(doc))
    entries = load_vrm(path).cloth_entries()
    assert [e["name"] for e in entries] == ["vrm_Hair", "vrm_Hair_1"]
    assert [e["root_bones"] for e in entries] == [["Spring A"], ["Spring C"]]
    assert entries[0]["parameters"] != entries[1]["parameters"]


def _glb_chunks(data: bytes) -> list:
    length = struct.unpack_from("<I", data, 8)[0]
    off, chunks = 12, []
    while off < length:
        size, kind = struct.unpack_from("<II", data, off)
        chunks.append([kind, data[off + 8:off + 8 + size]])
        off += 8 + size
    return chunks


def _as_vrm1(path: Path, out: Path) -> Path:
    """Godette (VRM 0.x) written as a VRM 1.0 file, by the rules of the two specifications: the
    same nodes under a root turned 180 degrees about Y (0.x models face -Z, 1.0 ones +Z); the
    humanoid bones; one spring per chain of a bone group, every joint with the group's
    parameters; the sphere colliders with their offsets turned from the Unity axes 0.x stores
    them in into glTF axes (UniVRM 0.x's glTF is Unity's with Z reversed: z negated)."""
    chunks = _glb_chunks(path.read_bytes())
    doc = json.loads(chunks[0][1])
    vrm = doc["extensions"].pop("VRM")
    doc["nodes"].append({"name": "vrm1_root", "children": doc["scenes"][0]["nodes"], "rotation": [0, 1, 0, 0]})
    doc["scenes"][0]["nodes"] = [len(doc["nodes"]) - 1]
    colliders, groups, springs = [], [], []
    for g in vrm["secondaryAnimation"]["colliderGroups"]:
        groups.append({"colliders": list(range(len(colliders), len(colliders) + len(g["colliders"])))})
        colliders += [{"node": g["node"], "shape": {"sphere": {"offset": [c["offset"]["x"], c["offset"]["y"],
                                                                          -c["offset"]["z"]],
                                                               "radius": c["radius"]}}} for c in g["colliders"]]
    for g in vrm["secondaryAnimation"]["boneGroups"]:
        for bone in g["bones"]:
            chain = [bone]
            while doc["nodes"][chain[-1]].get("children"):
                chain.append(doc["nodes"][chain[-1]]["children"][0])
            joint = {"stiffness": g["stiffiness"], "gravityPower": g["gravityPower"], "dragForce": g["dragForce"],
                     "hitRadius": g["hitRadius"], "gravityDir": [0, -1, 0]}
            springs.append({"joints": [dict(joint, node=n) for n in chain], "colliderGroups": g.get("colliderGroups", [])})
    doc["extensions"]["VRMC_vrm"] = {"specVersion": "1.0", "meta": {"name": "godette as 1.0"}, "humanoid": {
        "humanBones": {h["bone"]: {"node": h["node"]} for h in vrm["humanoid"]["humanBones"]}}}
    doc["extensions"]["VRMC_springBone"] = {"specVersion": "1.0", "colliders": colliders, "colliderGroups": groups,
                                            "springs": springs}
    doc["extensionsUsed"] = ["VRMC_vrm", "VRMC_springBone"]
    text = json.dumps(doc).encode()
    chunks[0][1] = text + b" " * (-len(text) % 4)
    body = b"".join(struct.pack("<II", len(d), kind) + d for kind, d in chunks)
    out.write_bytes(struct.pack("<III", 0x46546C67, 2, 12 + len(body)) + body)
    return out


def _world(avatar):
    h = TransformHierarchy(avatar.bones)
    return h, {n: h.world_position[h.index(n)] for n in h.names}


def test_a_vrm0_avatar_and_its_vrm1_form_give_the_same_bones_springs_and_colliders(godette, tmp_path):
    """Two conventions, one avatar: the 0.x file read with Z mirrored and its 1.0 form read with
    X mirrored under a root turned about Y place every bone, spring joint and collider at the
    same world position, with the same spring parameters and cloth entries."""
    with pytest.warns(UserWarning, match="radius 1 m exceeds"):
        v1 = load_vrm(_as_vrm1(GODETTE, tmp_path / "godette1.vrm"))
    assert v1.spec_version == "1.0" and v1.humanoid == godette.humanoid
    h0, world0 = _world(godette)
    h1, world1 = _world(v1)
    for name, p in world0.items():
        np.testing.assert_allclose(world1[name], p, atol=1e-9, err_msg=name)
    assert [(c.root, c.joints, c.vrm) for c in v1.chains] == [(c.root, c.joints, c.vrm) for c in godette.chains]

    def centres(avatar, h):
        out = []
        for c in avatar.colliders:
            i = h.index(c.transform)
            out.append(h.world_position[i] + qrotate(h.world_rotation[i], np.asarray(c.center) * h.lossy_scale[i]))
        return np.array(sorted(map(tuple, out)))
    np.testing.assert_allclose(centres(v1, h1), centres(godette, h0), atol=1e-9)
    assert [c.radius for c in sorted(v1.colliders, key=lambda c: c.radius)] == \
        [c.radius for c in sorted(godette.colliders, key=lambda c: c.radius)]
    params = lambda avatar: [e["parameters"] for e in avatar.cloth_entries(group_by="chain")]   # noqa: E731
    assert params(v1) == params(godette)
