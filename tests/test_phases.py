"""Phases as data (magica_py/runtime/phases.py)."""
from __future__ import annotations

import numpy as np
import pytest

from magica_py.runtime.phases import Phase, RestoreRegistry, Schedule, System


def noop(ctx):
    pass


def test_phases_are_the_six_unity_hooks_in_order():
    assert [p.name for p in Phase] == ["RESTORE", "FIXED_UPDATE", "UPDATE", "LATE_UPDATE",
                                       "RENDER_WRITE", "AFTER_RENDERING"]
    assert list(Phase) == sorted(Phase)


def test_every_phase_documents_what_belongs_in_it():
    import inspect

    source = inspect.getsource(Phase)
    for phase in Phase:
        assert f"{phase.name} = {phase.value}\n    \"\"\"" in source, phase.name


def test_add_appends_and_inserts_before_or_after():
    s = Schedule()
    s.add(Phase.LATE_UPDATE, System("cloth", noop))
    s.add(Phase.LATE_UPDATE, System("camera", noop))
    s.add(Phase.LATE_UPDATE, System("read", noop), before="cloth")
    s.add(Phase.LATE_UPDATE, System("after_cloth", noop), after="cloth")
    s.add(Phase.RENDER_WRITE, System("rerun", noop))
    assert s.describe() == [
        ("RESTORE", []), ("FIXED_UPDATE", []), ("UPDATE", []),
        ("LATE_UPDATE", ["read", "cloth", "after_cloth", "camera"]),
        ("RENDER_WRITE", ["rerun"]), ("AFTER_RENDERING", []),
    ]
    assert s.find("rerun") is Phase.RENDER_WRITE and s.find("nope") is None


def test_remove_returns_the_system_and_unknown_names_raise():
    s = Schedule()
    sys_a = s.add(Phase.UPDATE, System("a", noop))
    s.add(Phase.UPDATE, System("b", noop))
    assert s.remove("a") is sys_a
    assert s.describe()[Phase.UPDATE][1] == ["b"]
    with pytest.raises(KeyError, match="'a'"):
        s.remove("a")


def test_schedule_errors_name_the_problem():
    s = Schedule()
    s.add(Phase.UPDATE, System("anim", noop))
    with pytest.raises(ValueError, match="already scheduled in UPDATE"):
        s.add(Phase.LATE_UPDATE, System("anim", noop))
    with pytest.raises(ValueError, match="no system 'cloth' in phase LATE_UPDATE"):
        s.add(Phase.LATE_UPDATE, System("x", noop), before="cloth")
    with pytest.raises(ValueError, match="not both"):
        s.add(Phase.UPDATE, System("y", noop), before="anim", after="anim")
    with pytest.raises(TypeError):
        s.add(Phase.UPDATE, noop)
    with pytest.raises(ValueError):
        System("", noop)
    with pytest.raises(TypeError):
        System("z", 42)


def test_restore_registry_merges_owners_sorted_unique_int32():
    r = RestoreRegistry()
    r.register([5, 2, 2], owner="tail")
    r.register(np.array([3, 5]), owner="hair")
    assert r.indices.dtype == np.int32
    assert r.indices.tolist() == [2, 3, 5]
    r.register([9], owner="tail")
    r.unregister("hair")
    assert r.indices.tolist() == [2, 5, 9]
    r.unregister("tail")
    assert r.indices.tolist() == []
    with pytest.raises(ValueError, match="negative"):
        r.register([-1])
