"""``scene.threads``: which frame kernel a scene runs on (``system.choose_threads``) and how
the setting is checked. That the parallel kernel gives the serial bits is pinned in
``test_solver_frame.py``."""
from __future__ import annotations

import numba
import pytest

from magica_py.config import load_scene_text
from magica_py.config.errors import ConfigError
from magica_py.solver.system import AUTO_PARALLEL_PARTICLES, AUTO_PARALLEL_TEAMS, choose_threads

SCENE = """
version: 1
scene: {{fps: 60, frames: 10{threads}}}
rigs:
  - name: r
    bones: [{{name: root}}]
    parts:
      - chain: {{name: tail, parent: root, bones: 4, length: 0.3, direction: [0, -1, 0]}}
cloths:
  - {{name: tail, root_bones: [tail_0]}}
"""


def test_auto_uses_numbas_threads_only_for_many_teams_and_particles():
    available = numba.get_num_threads()
    many = (AUTO_PARALLEL_TEAMS, AUTO_PARALLEL_PARTICLES)
    assert choose_threads(None, "auto", *many) == available
    assert choose_threads(None, "auto", AUTO_PARALLEL_TEAMS - 1, 10 * AUTO_PARALLEL_PARTICLES) == 1
    assert choose_threads(None, "auto", 10 * AUTO_PARALLEL_TEAMS, AUTO_PARALLEL_PARTICLES - 1) == 1
    assert choose_threads(None, "auto", 1, 8) == 1


def test_a_count_is_kept_within_numbas_threads_and_parallel_overrides_the_setting():
    available = numba.get_num_threads()
    assert choose_threads(None, 1, 1000, 10 ** 6) == 1
    assert choose_threads(None, 1024, 1, 8) == available
    assert choose_threads(None, 2, 1, 8) == min(2, available)
    assert choose_threads(False, 1024, 1000, 10 ** 6) == 1
    assert choose_threads(True, 1, 1, 8) == available


@pytest.mark.parametrize("text,expected", [("", "auto"), (", threads: auto", "auto"), (", threads: 3", 3)])
def test_threads_setting_is_read_from_the_scene(text, expected):
    scene = load_scene_text(SCENE.format(threads=text), source="t.yaml")
    assert scene.settings.threads == expected


@pytest.mark.parametrize("bad", ["0", "-2", "1.5", "many", "true", "2000"])
def test_a_bad_threads_setting_names_the_path_and_what_was_expected(bad):
    with pytest.raises(ConfigError) as info:
        load_scene_text(SCENE.format(threads=f", threads: {bad}"), source="t.yaml")
    text = str(info.value)
    assert "scene.threads" in text and "expected 'auto' or an integer in [1, 1024]" in text
