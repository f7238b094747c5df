"""Skirts that keep their shape in quality mode (issue 16 item 3, docs/quality-mode.md *Long
chains and skirts*).

* Oracles of the edge projection (``quality.edge_projection_team``) on a hand-made ring: a
  ring stretched uniformly (the slowest mode of its edges for Gauss-Seidel passes) comes
  back to its rest lengths in one projection, where two Gauss-Seidel passes leave most of the
  stretch; with a contact direction, the pushed particle does not move along it.
* The character's skirt on the 3 rev/s spin (``configs/hard/mocap_spin.yaml``): simulated and
  displayed edges within 3 % at 30 and 144 fps (main before this change: rings 6.0-6.8 %,
  parent links 2.0-2.4 %), hair within 2 %, and no skirt particle sphere inside a thigh or
  the floor at the end of any step.
"""
import importlib.util
import math
import pathlib
from collections import namedtuple

import numpy as np
import pytest

ROOT = pathlib.Path(__file__).resolve().parents[1]
SPIN = str(ROOT / "configs" / "hard" / "mocap_spin.yaml")

N = 12          # strands of the ring
RADIUS = 0.2    # m

M = namedtuple("M", "team_edge_start team_edge_count edges attribute depth team_particle_start "
                    "team_particle_count")
P = namedtuple("P", "step_basic_pos next_pos friction projection_inverse_mass projection_gather "
                    "projection_contact edge_normal edge_lambda edge_residual edge_direction edge_product "
                    "edge_diagonal edge_compliance edge_active")


def ring(stretch: float):
    """A horizontal ring of N moving particles (depth 1: equal masses) at rest radius RADIUS,
    its positions scaled by 1 + stretch; edges (i, i + 1) around it."""
    angles = 2.0 * np.pi * np.arange(N) / N
    rest = np.stack([RADIUS * np.cos(angles), np.zeros(N), RADIUS * np.sin(angles)], axis=1)
    edges = np.array([[i, (i + 1) % N] for i in range(N)], np.int32)
    m = M(np.array([0], np.int32), np.array([N], np.int32), edges, np.full(N, 0x02, np.uint8), np.ones(N),
          np.array([0], np.int32), np.array([N], np.int32))
    ps = P(rest, rest * (1.0 + stretch), np.zeros(N), np.zeros(N), np.zeros((N, 3)), np.zeros((N, 3)),
           np.zeros((N, 3)), np.zeros(N), np.zeros(N), np.zeros(N), np.zeros(N), np.zeros(N), np.zeros(N), np.zeros(N, np.int32))
    return m, ps


def edge_stretch(m, ps):
    e = m.edges
    length = np.linalg.norm(ps.next_pos[e[:, 1]] - ps.next_pos[e[:, 0]], axis=1)
    rest = np.linalg.norm(ps.step_basic_pos[e[:, 1]] - ps.step_basic_pos[e[:, 0]], axis=1)
    return length / rest - 1.0


def test_a_uniformly_stretched_ring_comes_back_in_one_projection():
    """5 % uniform expansion: one projection (4 conjugate-gradient iterations) leaves < 0.05 %
    (the right-hand side is an eigenvector of the ring's circulant J W J^T, so the solve is
    exact after one iteration up to the 0.1 % compliance; a uniform scaling is exact under
    the linearisation); two Gauss-Seidel edge passes leave > 3 % (each removes ~13 % of this
    mode on a 12-particle ring: 2 sin^2(pi/12))."""
    from magica_py.solver.quality import PROJECTION_ITERATIONS, edge_pass_team, edge_projection_team

    m, ps = ring(0.05)
    edge_projection_team(m, ps, 0, PROJECTION_ITERATIONS, False)
    s = edge_stretch(m, ps)
    assert np.abs(s).max() < 5e-4
    assert np.allclose(ps.next_pos[:, 1], 0.0)        # moved radially in its plane
    radius = np.linalg.norm(ps.next_pos, axis=1)
    assert radius == pytest.approx(np.full(N, radius.mean()), rel=1e-9)   # still a circle

    m, ps = ring(0.05)
    for _ in range(2):
        edge_pass_team(m, ps, 0)
    assert edge_stretch(m, ps).max() > 0.03
    assert 2 * math.sin(math.pi / N) ** 2 == pytest.approx(0.134, abs=1e-3)


def test_the_projection_leaves_short_edges_and_fixed_particles_alone():
    """Unilateral: a compressed ring does not move; a fixed particle never moves (the 5 %
    ring with one fixed particle is left at 0.9 % by 4 iterations: the ring now has to
    shift towards the fixed particle, a mode the truncated solve leaves partly to the
    Gauss-Seidel passes that follow it)."""
    from magica_py.solver.quality import edge_projection_team

    m, ps = ring(-0.05)
    before = ps.next_pos.copy()
    edge_projection_team(m, ps, 0, 4, False)
    assert np.array_equal(ps.next_pos, before)
    m, ps = ring(0.05)
    m.attribute[0] = 0x01   # fixed
    x0 = ps.next_pos[0].copy()
    edge_projection_team(m, ps, 0, 4, False)
    assert np.array_equal(ps.next_pos[0], x0)
    assert np.abs(edge_stretch(m, ps)).max() < 0.01


def test_a_pushed_particle_slides_along_its_push_plane_and_its_neighbours_give_way():
    """One particle pushed 2 cm outwards (its contact direction radial: its two edges 6.6 %
    long): the filtered projection moves it only in the plane normal to the push, and its
    neighbours move in towards it. Edges at their rest length join the solve (kept from
    stretching), so the give spreads around the ring, one edge further per iteration: 4
    iterations leave < 2 %, 8 leave < 0.2 %."""
    from magica_py.solver.quality import edge_projection_team

    for iterations, bound in ((4, 0.02), (8, 0.002)):
        m, ps = ring(0.0)
        out = ps.next_pos[0] / np.linalg.norm(ps.next_pos[0])
        ps.next_pos[0] += 0.02 * out
        ps.projection_contact[0] = out
        before = ps.next_pos.copy()
        assert edge_stretch(m, ps).max() > 0.066
        edge_projection_team(m, ps, 0, iterations, True)
        assert abs(float((ps.next_pos[0] - before[0]) @ out)) < 1e-12
        assert edge_stretch(m, ps).max() < bound
        assert np.linalg.norm(ps.next_pos[1] - before[1]) > 5e-3


@pytest.fixture(scope="module")
def display_stretch():
    spec = importlib.util.spec_from_file_location("display_stretch", ROOT / "benchmarks" / "display_stretch.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


@pytest.mark.parametrize("fps", [30.0, 144.0])
def test_the_skirt_keeps_its_shape_on_the_spin(display_stretch, fps):
    r = display_stretch.measure(SPIN, fps, "quality", None, {})
    j = r["teams"].index("skirt")
    h = r["teams"].index("hair")
    for key in ("shown", "state", "shown_other", "state_other"):
        assert r[key][:, j].max() <= 0.03, key        # main before: rings 6.0-6.8 %
        assert r[key][:, h].max() <= 0.02, key


def test_no_skirt_particle_ends_a_step_inside_a_thigh_or_the_floor():
    """90 fps at 90 Hz: one step per frame, so after each frame the state and the colliders'
    work data are those of the last step."""
    from magica_py.bench import metrics as M
    from magica_py.bench.variants import Variant, prepare

    p = prepare(Variant("spin", SPIN, parameters={"solver.mode": "quality"}, fps=90.0, duration=1.8))
    system = p.system
    m, ps, cs = system.model, system.particles, system.collider_state
    team = [getattr(s, "name", "") for s in system.specs].index("skirt")
    start, count = int(m.team_particle_start[team]), int(m.team_particle_count[team])
    idx = np.arange(start, start + count)
    idx = idx[(np.asarray(m.attribute)[idx] & 0x02) != 0]
    radius = M.particle_radius(m, system.parameters)[idx]
    slots = [k for k in range(cs.team.shape[0]) if cs.team[k] == team]
    assert sorted(int(cs.shape[k]) for k in slots) == [1, 1, 2]   # two thigh capsules and the floor
    deepest = 0.0
    for _ in range(p.frames):
        p.player.step()
        x = ps.old_pos[idx]
        for k in slots:
            if cs.shape[k] == 2:
                depth = radius - (x - cs.start_new[k]) @ cs.plane_normal[k]
            else:
                a, b = cs.start_new[k], cs.end_new[k]
                ab = b - a
                t = np.clip(((x - a) @ ab) / float(ab @ ab), 0.0, 1.0)
                reach = cs.radius_start[k] + (cs.radius_end[k] - cs.radius_start[k]) * t + radius
                depth = reach - np.linalg.norm(x - (a + t[:, None] * ab), axis=1)
            deepest = max(deepest, float(depth.max()))
    assert deepest <= 1e-5
