"""The per-step conversions of ``solver.rate_mode: frequency_consistent`` (issue 22,
docs/parameters.md *solver.rate_mode*): each pinned against a hand-computed value at 180 Hz
(90/f = 0.5), bit for bit MagicaCloth2's value at 90 Hz, and left alone in MagicaCloth2 mode.
"""
import math

import pytest

from magica_py.params import resolve_parameters
from magica_py.solver.attenuations import step_attenuations
from magica_py.solver.constraints.tether import solve_tether
from magica_py.solver.constraints.distance import distance_stiffness
from magica_py.solver.parameters import (
    PRM_RATE_MODE, PRM_RESTORATION_ATTENUATION, allocate_parameters, constraint_stiffness, packed_row, step_keep,
    step_rate, step_share, write_row,
)
from magica_py.solver.step import dynamic_friction_brake, dynamic_friction_keep, static_friction_step


def row(**overrides):
    """The kernels' parameter table (one block row) of a tail with ``overrides``."""
    table = allocate_parameters(1)
    write_row(table, 0, resolve_parameters("tail", overrides, where="test"))
    return packed_row(table, 0)[None, :]


FC = {"solver.rate_mode": "frequency_consistent"}


def test_frequency_consistent_attenuations_at_180_hz():
    """Hard limits (tether 0.7, angle limit 0.9, motion 0.95) as retentions a^(90/f);
    restoration's velocity share 1 - a linear in the step; distance's 0.3 as a rate."""
    t = row(**FC, **{"angle_restoration.velocity_attenuation": 0.5})
    tether, distance, limit, restoration, motion = step_attenuations(t, 0, 0.5)
    assert tether == pytest.approx(math.sqrt(0.7), rel=1e-14)
    assert limit == pytest.approx(math.sqrt(0.9), rel=1e-14)
    assert motion == pytest.approx(math.sqrt(0.95), rel=1e-14)
    assert restoration == pytest.approx(1.0 - 0.5 * 0.5, rel=1e-14)      # 1 - (1 - 0.5) 90/180
    assert distance == pytest.approx(1.0 - math.sqrt(0.7), rel=1e-14)   # 1 - (1 - 0.3)^(90/180)


def test_attenuations_are_magica_bits_at_90_hz_and_in_magica_mode():
    for table, ratio in ((row(**FC), 1.0), (row(), 1.0), (row(), 0.5), (row(), 0.25)):
        assert step_attenuations(table, 0, ratio) == (0.7, 0.3, 0.9, table[0, PRM_RESTORATION_ATTENUATION], 0.95)


def test_step_conversions():
    assert step_share(0.1, 0.25, 1) == 0.025          # a per-step amount: x 90/f
    assert step_share(0.1, 0.25, 0) == 0.1
    assert step_share(0.8, 2.0, 1) == 1.0             # clamped (f = 45 Hz)
    assert step_keep(0.6, 0.5, 1) == pytest.approx(math.sqrt(0.6), rel=1e-14)
    assert step_rate(0.5, 0.5, 1.0, 1) == pytest.approx(1.0 - math.sqrt(0.5), rel=1e-14)


def test_tether_share_is_converted_as_a_rate():
    """A particle 1.18 x its rest distance from the root: excess 0.15 over the 1.03 band,
    k = 0.15 / 0.3 = 0.5 of the distance beyond the band removed at 90 Hz, 1 - 0.5^(90/f) at f."""
    root = (0.0, 0.0, 0.0)
    x = (1.18, 0.0, 0.0)
    beyond = 1.18 - 1.03
    assert solve_tether(x, root, 1.0, 0.5)[0] == pytest.approx(-beyond * 0.5, rel=1e-12)
    assert solve_tether(x, root, 1.0, 0.5, 1.0)[0] == solve_tether(x, root, 1.0, 0.5)[0]
    assert solve_tether(x, root, 1.0, 0.5, 0.5)[0] == pytest.approx(-beyond * (1.0 - math.sqrt(0.5)), rel=1e-12)


def test_dynamic_friction_keeps_its_share_per_second():
    """Sliding along the surface (direction normal to the contact normal, dd = 0.75): the brake
    keeps 1 - 0.75 f mu of the velocity per 90 Hz step; at 180 Hz (1 - 0.75 f mu)^0.5 per step,
    so two steps keep what one 90 Hz step keeps."""
    vel, direction, normal = (2.0, 0.0, 0.0), (1.0, 0.0, 0.0), (0.0, 1.0, 0.0)
    keep90 = dynamic_friction_brake(vel, direction, normal, 0.8, 0.5)[0] / 2.0
    assert keep90 == pytest.approx(1.0 - 0.75 * 0.8 * 0.5, rel=1e-14)
    once = dynamic_friction_keep(vel, direction, normal, 0.8, 0.5, 0.5)
    twice = dynamic_friction_keep(once, direction, normal, 0.8, 0.5, 0.5)
    assert twice[0] / 2.0 == pytest.approx(keep90, rel=1e-12)


def test_static_friction_loss_scales_with_the_step():
    """Slipping at 0.15 m/s over a 0.05 m/s threshold: the factor drops by (0.15 - 0.05) / 0.2
    = 0.5 per 90 Hz step, by half that per 180 Hz step (loss_scale 0.5)."""
    dt = 1.0 / 180.0
    normal = (0.0, 1.0, 0.0)
    old = (0.0, 0.0, 0.0)
    nxt = (0.15 * dt, 0.0, 0.0)
    sf90 = static_friction_step(nxt, old, old, normal, 0.9, dt, 0.05, 0.04, 1.0)[2]
    sf180 = static_friction_step(nxt, old, old, normal, 0.9, dt, 0.05, 0.04, 0.5)[2]
    assert sf90 == pytest.approx(0.9 - 0.5, abs=1e-12)
    assert sf180 == pytest.approx(0.9 - 0.25, abs=1e-12)


def test_projection_stiffness_is_a_per_step_strength():
    """Distance and triangle-bending stiffness are not converted in frequency-consistent mode
    (a rate-converted soft link whose correction becomes velocity stiffens with f); quality
    mode converts them as rates, MagicaCloth2 mode scales them by SimulationPower."""
    assert constraint_stiffness(0.5, 0.25, 1.0, 1, 0) == 0.5
    assert constraint_stiffness(0.5, 0.25, 1.0, 1, 1) == pytest.approx(1.0 - 0.5 ** 0.25, rel=1e-14)
    assert constraint_stiffness(0.5, 0.25, 0.5, 0, 0) == 0.25
    fc = row(**FC)
    assert fc[0, PRM_RATE_MODE] == 1.0
    assert distance_stiffness(0.8, 0.5, 0.125, int(fc[0, PRM_RATE_MODE]), 0) == (0.8, 0.4)
    faithful = row()
    assert distance_stiffness(0.8, 0.5, 0.125, int(faithful[0, PRM_RATE_MODE]), 0) == (0.1, 0.05)
    assert distance_stiffness(0.8, 1.0, 0.5, int(faithful[0, PRM_RATE_MODE]), 0) == (0.4, 0.2)
