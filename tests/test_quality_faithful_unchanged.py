"""Faithful mode is unchanged by the quality-mode work (issue 8): after 200 frames of each
showcase config, the sha256 of the particle positions and bone transforms equal the golden
hashes recorded before quality mode existed (``benchmarks/golden_hashes.json``, kept by the
solver-speed work, ``benchmarks/golden_hashes.py``).

The scenes are run from the configs as they were when the golden file was last written
(``git show <that commit>:configs/<scene>.yaml``, the check's ``--config-dir``), so that an
edit of a showcase YAML is not mistaken for a change of the solver's arithmetic.
"""
import importlib.util
import pathlib
import subprocess

import pytest

ROOT = pathlib.Path(__file__).resolve().parents[1]


def golden_module():
    spec = importlib.util.spec_from_file_location("golden_hashes", ROOT / "benchmarks" / "golden_hashes.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def golden_configs(folder: pathlib.Path, scene: str) -> pathlib.Path:
    """The scene's YAML at the commit that last wrote the golden file, in ``folder``."""
    def git(*args):
        return subprocess.run(["git", *args], cwd=ROOT, check=True, capture_output=True).stdout

    commit = git("log", "-1", "--format=%H", "--", "benchmarks/golden_hashes.json").decode().strip()
    (folder / f"{scene}.yaml").write_bytes(git("show", f"{commit}:configs/{scene}.yaml"))
    return folder


@pytest.mark.parametrize("stages", ["used", "all"])
@pytest.mark.parametrize("scene", ["tail_orbit", "character_walk", "hitches_and_events", "crowd"])
def test_faithful_positions_are_bit_identical_to_the_golden_hashes(scene, stages, capsys, tmp_path, monkeypatch):
    """With the stages each scene uses (what ``magica-py`` runs) and with every stage
    compiled (``MAGICA_STAGES=all``, the rest of the suite: tests/conftest.py)."""
    monkeypatch.setenv("MAGICA_STAGES", stages)
    golden = golden_module()
    folder = golden_configs(tmp_path, scene)
    assert golden.main(["--check", "--scenes", scene, "--config-dir", str(folder)]) == 0, capsys.readouterr().out


def test_quality_mode_changes_the_positions():
    """The same check sees quality mode (so a silent no-op would be caught)."""
    import json

    from magica_py.config import load_scene
    from magica_py.runtime.player import Player
    from magica_py.solver.system import ClothSystem

    golden = golden_module()
    scene = load_scene(ROOT / "configs" / "tail_orbit.yaml")
    for spec in scene.cloths:
        object.__setattr__(spec, "parameters", spec.parameters.with_changes({"solver.mode": "quality"}, where="test"))
    player = Player.for_scene(scene)
    system = ClothSystem(scene.hierarchy, scene.cloths, scene.colliders, scene.settings).attach(player)
    player.run(200)
    stored = json.loads(golden.GOLDEN.read_text())["frames=200"]["tail_orbit"]
    assert golden._sha(system.particles.position) != stored["particles"]
