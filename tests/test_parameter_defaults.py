"""Parameter defaults have one source, the table (``params/table.py``): the solver's job data
and the build's switches fall back to it for keys a parameter mapping does not carry."""
from __future__ import annotations

import numpy as np

from magica_py.build.constraints import CURVE_PARAMETERS, curve_samples, parameter
from magica_py.params import PARAMETER_DEFS, default_parameters, resolve_parameters
from magica_py.solver.parameters import allocate_parameters, write_row


def _rows_equal(a, b):
    return [f for f in a._fields if not np.array_equal(getattr(a, f), getattr(b, f))]


def test_an_empty_mapping_gives_the_job_data_of_the_table_defaults():
    empty, full = allocate_parameters(1), allocate_parameters(1)
    write_row(empty, 0, {})
    write_row(full, 0, resolve_parameters())
    assert _rows_equal(empty, full) == []


def test_the_linear_curve_defaults_reach_the_job_data():
    # restoration stiffness (0.2, 1 -> 0.2, on) x 0.2 and limit angle (60 deg, 0 -> 1, on)
    table = allocate_parameters(1)
    write_row(table, 0, {"gravity": 2.0})
    depth = np.arange(16) / 15.0
    assert np.allclose(table.restoration_stiffness_curve[0], 0.2 * 0.2 * (1.0 - 0.8 * depth), rtol=0, atol=1e-15)
    assert np.allclose(table.limit_angle_curve[0], 60.0 * depth, rtol=0, atol=1e-12)
    assert table.gravity[0] == 2.0 and table.local_movement_speed_limit[0] == -1.0
    assert table.culling_length[0] == -1.0 and table.movement_speed_limit[0] == 5.0


def test_the_build_falls_back_to_the_table_defaults():
    defaults = default_parameters()
    for key in CURVE_PARAMETERS:
        assert np.array_equal(curve_samples(parameter({}, key)), curve_samples(defaults[key])), key
    assert parameter(None, "triangle_bending.stiffness") == 1.0
    assert parameter({"triangle_bending.stiffness": 0.5}, "triangle_bending.stiffness") == 0.5


def test_default_parameters_hold_every_key_of_the_table():
    assert set(default_parameters()) == {d.key for d in PARAMETER_DEFS}
