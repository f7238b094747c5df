"""A first run's compile helper (``solver/compile_helper.py``) is forked when a ``ClothSystem``
is constructed, before its cloths are built. What makes that work: the stage switches the
specs announce cover every optional step stage the built cloths use (so the helper compiles
what the frame kernel will call), a system with no cloth has the frame kernel's argument types
of any system (so the helper's compiles are the ones the frame kernel loads from the cache),
and the forked helper compiles its share without an error."""
import os
import pathlib

import numba
import pytest

from magica_py.config import load_scene
from magica_py.solver import compile_helper
from magica_py.solver.system import ClothSystem

ROOT = pathlib.Path(__file__).resolve().parents[1]
# the step's optional stages (the helper compiles these; lines / triangles are the end of
# frame's, compiled by the system's process with the built models' switches)
STEP_STAGES = ("angle", "bending", "point_collision", "edge_collision", "motion", "quality", "wind")
QUALITY = ["cloths.hair.parameters.solver.mode=quality", "cloths.skirt.parameters.solver.mode=quality"]
SCENES = [
    ("configs/tail_orbit.yaml", []),
    ("configs/character_walk.yaml", []),
    ("configs/character_walk.yaml", QUALITY),
    ("configs/character_walk.yaml", ["cloths.skirt.collision_mode=edge", "cloths.hair.collision_mode=none"]),
    ("configs/character_walk.yaml", ["cloths.skirt.parameters.triangle_bending.stiffness=0"]),
    ("configs/crowd.yaml", []),
    ("configs/wind.yaml", []),
    ("configs/hitches_and_events.yaml", []),
    ("configs/light_chains.yaml", []),
]


def _system(path, overrides, **kwargs):
    scene = load_scene(ROOT / path, overrides=overrides)
    system = ClothSystem(scene.hierarchy, scene.cloths, scene.colliders, scene.settings,
                         wind=getattr(scene, "wind", ()), **kwargs)
    return scene, system


@pytest.fixture(autouse=True)
def _no_helper(monkeypatch):
    # the systems of these tests fork no helper of their own (the last test forks one itself)
    monkeypatch.setenv("MAGICA_COMPILE_HELPER", "0")


@pytest.mark.parametrize("path, overrides", SCENES, ids=lambda v: str(v).replace("/", "_"))
def test_specs_announce_every_step_stage_the_built_cloths_use(path, overrides, used_stages):
    _scene, system = _system(path, overrides)
    expected = system.expected_stage_switches()
    used = system.stage_switches()
    for name in STEP_STAGES:
        if getattr(used, name) is not None:
            assert getattr(expected, name) is not None, (path, overrides, name)
    # and no more than the parameters, modes and colliders ask for: a line-mode tail with no
    # collider announces neither bending nor collision
    if path.endswith("tail_orbit.yaml"):
        assert expected.bending is None and expected.point_collision is None and expected.edge_collision is None


def test_announced_switches_follow_the_parameters(used_stages):
    """Bending is announced for a mesh cloth with triangle bending and not without it; quality
    mode only where a cloth asks for it; edge collision only for an edge-mode cloth with colliders."""
    _s, plain = _system("configs/character_walk.yaml", [])
    _s, flat = _system("configs/character_walk.yaml", ["cloths.skirt.parameters.triangle_bending.stiffness=0"])
    _s, quality = _system("configs/character_walk.yaml", QUALITY)
    _s, edge = _system("configs/character_walk.yaml", ["cloths.skirt.collision_mode=edge"])
    assert plain.expected_stage_switches().bending == 1 and flat.expected_stage_switches().bending is None
    assert plain.expected_stage_switches().quality is None and quality.expected_stage_switches().quality == 1
    assert plain.expected_stage_switches().edge_collision is None and edge.expected_stage_switches().edge_collision == 1


@pytest.mark.skipif(numba.config.DISABLE_JIT, reason="numba types only exist with the JIT on")
@pytest.mark.parametrize("path", ["configs/tail_orbit.yaml", "configs/crowd.yaml", "configs/wind.yaml"])
def test_a_system_without_cloths_has_the_frame_kernel_argument_types_of_any_system(path):
    scene, system = _system(path, [])
    empty = ClothSystem(scene.hierarchy, [], scene.colliders, scene.settings, parallel=system.parallel,
                        wind=getattr(scene, "wind", ()))
    assert numba.typeof(empty._frame_arrays()) == numba.typeof(system._frame_arrays())
    assert numba.typeof(empty._frame_values) == numba.typeof(system._frame_values)
    assert numba.typeof(empty._wind_zones()) == numba.typeof(system._wind_zones())


@pytest.mark.skipif(numba.config.DISABLE_JIT or not hasattr(os, "fork"),
                    reason="the helper is a forked process compiling into numba's cache (JIT on, POSIX)")
def test_the_early_helper_compiles_its_share_without_an_error():
    """The forked helper's exit status is 0 only when it made its tables and typed (so
    compiled, or found in the cache) every stage of its share without an exception."""
    scene, system = _system("configs/character_walk.yaml", [])
    pid = compile_helper.fork_early(system, scene.settings, None, getattr(scene, "wind", ()))
    assert pid is not None
    _pid, status = os.waitpid(pid, 0)
    assert os.WIFEXITED(status) and os.WEXITSTATUS(status) == 0


class _Kernel:
    def __init__(self, signatures):
        self.signatures = signatures


@pytest.mark.skipif(numba.config.DISABLE_JIT or not os.path.exists("/proc/stat"),
                    reason="the helper is only wanted with the JIT on, on Linux")
def test_a_helper_is_wanted_where_a_cpu_is_free_now_even_if_the_load_average_still_counts_a_past_run(monkeypatch):
    monkeypatch.setenv("MAGICA_COMPILE_HELPER", "1")
    monkeypatch.setattr(compile_helper.os, "sched_getaffinity", lambda pid: {0, 1})
    fresh = _Kernel([])
    # the 1-minute load average says free: no need to look further
    monkeypatch.setattr(compile_helper.os, "getloadavg", lambda: (0.4, 0.4, 0.4))
    monkeypatch.setattr(compile_helper, "idle_cpus", lambda window=0.1: 0.0)
    assert compile_helper.wanted(fresh)
    # it says busy (a run that just ended): the CPUs' idle time now decides
    monkeypatch.setattr(compile_helper.os, "getloadavg", lambda: (1.9, 1.2, 0.8))
    assert not compile_helper.wanted(fresh)
    monkeypatch.setattr(compile_helper, "idle_cpus", lambda window=0.1: 1.9)
    assert compile_helper.wanted(fresh)
    # never once the frame kernel is compiled in this process, nor when turned off
    assert not compile_helper.wanted(_Kernel(["signature"]))
    monkeypatch.setenv("MAGICA_COMPILE_HELPER", "0")
    assert not compile_helper.wanted(fresh)


@pytest.mark.skipif(not os.path.exists("/proc/stat"), reason="/proc/stat is Linux's")
def test_idle_cpus_is_a_share_of_the_machine_s_cpus():
    idle = compile_helper.idle_cpus(0.05)
    assert 0.0 <= idle <= os.cpu_count()


@pytest.mark.skipif(numba.config.DISABLE_JIT or not os.path.exists("/proc/stat"),
                    reason="the helper is only wanted with the JIT on, on Linux")
def test_no_second_helper_while_the_early_one_compiles(monkeypatch):
    """A second system's first frame forks no helper while the first system's early helper is
    still running (a child process standing in for it here), and does once it has ended."""
    import subprocess
    import sys

    monkeypatch.setenv("MAGICA_COMPILE_HELPER", "1")
    monkeypatch.setattr(compile_helper.os, "getloadavg", lambda: (0.1, 0.1, 0.1))
    stand_in = subprocess.Popen([sys.executable, "-c", "import time; time.sleep(30)"])
    try:
        monkeypatch.setitem(compile_helper._early, "pid", stand_in.pid)
        assert compile_helper.early_helper_running()
        assert not compile_helper.wanted(_Kernel([]))
    finally:
        stand_in.kill()
        stand_in.wait()
    assert not compile_helper.early_helper_running()   # reaped (here by Popen.wait)
    assert compile_helper.wanted(_Kernel([]))


@pytest.mark.skipif(not hasattr(os, "fork"), reason="the helper is a forked process (POSIX)")
def test_a_reaped_helper_is_never_waited_for_or_killed_again(monkeypatch):
    """Once a helper's pid is reaped (by ``early_helper_running`` or a first ``finish``), the
    system may reuse it for another child; ``finish`` then leaves that pid alone. Here a live
    child stands for the process that got the pid: it is neither killed nor reaped."""
    import subprocess
    import sys

    other = subprocess.Popen([sys.executable, "-c", "import time; time.sleep(30)"])
    try:
        monkeypatch.setattr(compile_helper, "_reaped", {other.pid})
        compile_helper.finish(other.pid)
        monkeypatch.setitem(compile_helper._early, "pid", other.pid)
        assert not compile_helper.early_helper_running()
        assert other.poll() is None
    finally:
        other.kill()
        other.wait()
