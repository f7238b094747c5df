"""The packed tables' row declarations (``solver/lanes.RowTable``): fields and shared scratch."""
import pathlib
import re

import pytest

from magica_py.solver import state as st
from magica_py.solver.lanes import LANES, QUATERNION, RowTable


def test_a_shared_field_names_rows_of_another_field_and_adds_none():
    table = RowTable("test", "item")
    first = table.add("position", 3, "m")
    scratch = table.add("scratch", 12, "scratch of a stage")
    rows = table.rows
    shared = table.share("other_scratch", 3, "scratch", "scratch of another stage", offset=9)
    assert table.rows == rows and table.width == rows * LANES
    assert first == 0 and shared == scratch + 9 * LANES
    assert "other_scratch" not in table.fields          # no fresh value, no view of its own
    with pytest.raises(ValueError, match="does not fit"):
        table.share("too_long", 4, "scratch", "", offset=9)
    with pytest.raises(ValueError, match="declared twice"):
        table.share("other_scratch", 1, "scratch", "")
    with pytest.raises(ValueError, match="declared twice"):
        table.add("position", 3, "m")
    with pytest.raises(ValueError, match="4 rows"):
        table.add("turn", 3, "", QUATERNION)


def test_every_shared_scratch_name_lies_in_the_stages_scratch_rows():
    """The stages' scratch names (``state.PARTNER_*``, ``BONE_MATRIX``, E.2's ``PARENT_*`` /
    ``CHILD_*``, E.4's ``LOCAL_OUT_*``, D.7's ``BEND_*`` ...) share the one pool of rows that
    holds values only within a stage, never state carried between stages."""
    assert {over for (_f, _n, over, _d) in st.PARTICLE.shared.values()} == {"stage_scratch"}
    assert st.STAGE_SCRATCH == st.PARTICLE.column("stage_scratch")


def test_the_scratch_names_one_module_uses_do_not_overlap():
    """A stage uses its scratch names at once (gathered rows beside sums), so within the
    source of each solver module the shared names it reads or writes must sit on distinct
    rows; names of different modules may overlap (their stages run one after another)."""
    root = pathlib.Path(st.__file__).resolve().parent
    shared = st.PARTICLE.shared
    checked = 0
    for path in sorted(root.rglob("*.py")):
        names = sorted({n for n in re.findall(r"\bst\.([A-Z_0-9]+)", path.read_text()) if n.lower() in shared})
        owner = {}
        for name in names:
            first, size, _over, _doc = shared[name.lower()]
            for row in range(first, first + size):
                assert row not in owner, f"{path.name}: {name} and {owner[row]} share row {row}"
                owner[row] = name
        checked += bool(names)
    assert checked >= 10   # the stages' modules (angle, bending, collision, distance, rotations, writeback ...)
