"""The packed tables' row declarations (``solver/lanes.RowTable``): fields and shared scratch."""
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


def test_bending_scratch_lies_in_the_frame_stages_scratch_rows_only():
    """D.7's gathered pair (``state.BEND_*``) may only use rows that hold values within one
    stage of the frame (C.1's bone matrix, E.2's sums), never state carried between stages."""
    shared = st.PARTICLE.shared
    assert {name: over for name, (_f, _n, over, _d) in shared.items() if name.startswith("bend_")} == {
        "bend_partner_pos": "bone_matrix", "bend_partner_w": "bone_matrix", "bend_rest": "child_rest_sum",
        "bend_sign": "child_rest_sum", "bend_ok": "child_rest_sum"}
    # and the five do not overlap one another
    cells = [c for name, (first, n, _o, _d) in shared.items() if name.startswith("bend_")
             for c in range(first, first + n)]
    assert len(cells) == len(set(cells)) == 9 + 3 + 3
