"""Skirts that keep their shape in quality mode (issue 16 item 3, docs/quality-mode.md *Long
chains and skirts*).

* Oracles of the edge projection (``edge_projection.edge_projection_lane``) on a hand-made ring: a
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

import numpy as np
import pytest

ROOT = pathlib.Path(__file__).resolve().parents[1]
SPIN = str(ROOT / "configs" / "hard" / "mocap_spin.yaml")

N = 12          # strands of the ring
RADIUS = 0.2    # m


class Ring:
    """A horizontal ring of N moving particles (depth 1: equal masses) at rest radius RADIUS,
    edges (i, i + 1) around it, in lane 0 of a hand-made block (``hand_blocks.HandBlock``);
    ``next_pos`` / ``projection_contact`` are set per particle, the drivers run on the block."""

    def __init__(self, stretch: float, attribute=None):
        from hand_blocks import HandBlock

        angles = 2.0 * np.pi * np.arange(N) / N
        self.rest = np.stack([RADIUS * np.cos(angles), np.zeros(N), RADIUS * np.sin(angles)], axis=1)
        self.edges = np.array([[i, (i + 1) % N] for i in range(N)], np.int32)
        self.hb = HandBlock(attribute=np.full(N, 0x02, np.uint8) if attribute is None else attribute,
                            edges=self.edges)
        self.hb.write("step_basic_pos", self.rest)
        self.hb.write("next_pos", self.rest * (1.0 + stretch))
        self.hb.write("friction", np.zeros(N))

    @property
    def next_pos(self):
        return self.hb.read("next_pos")

    def set(self, field, values):
        self.hb.write(field, values)

    def project(self, iterations, contacts):
        """One edge projection (``edge_projection.edge_projection_lane``)."""
        from magica_py.solver.edge_projection import edge_projection_lane

        hb = self.hb
        return edge_projection_lane(hb.PS, hb.PM, hb.EDS, hb.BI, hb.topology, hb.b, hb.lane, iterations, contacts)

    def edge_pass(self):
        """One Gauss-Seidel edge pass (``edge_projection.edge_pass_lanes``)."""
        from magica_py.solver.edge_projection import edge_pass_lanes

        hb = self.hb
        edge_pass_lanes(hb.PS, hb.PM, hb.BI, hb.topology, hb.b, hb.lane, hb.lane + 1)


def edge_stretch(ring):
    e = ring.edges
    x = ring.next_pos
    length = np.linalg.norm(x[e[:, 1]] - x[e[:, 0]], axis=1)
    rest = np.linalg.norm(ring.rest[e[:, 1]] - ring.rest[e[:, 0]], axis=1)
    return length / rest - 1.0


def test_a_uniformly_stretched_ring_comes_back_in_one_projection():
    """5 % uniform expansion: one projection (4 conjugate-gradient iterations) leaves < 0.05 %
    (the right-hand side is an eigenvector of the ring's circulant J W J^T, so the solve is
    exact after one iteration up to the 0.1 % compliance; a uniform scaling is exact under
    the linearisation); two Gauss-Seidel edge passes leave > 3 % (each removes ~13 % of this
    mode on a 12-particle ring: 2 sin^2(pi/12))."""
    from magica_py.solver.edge_projection import PROJECTION_ITERATIONS

    ring = Ring(0.05)
    assert ring.project(PROJECTION_ITERATIONS, False)
    s = edge_stretch(ring)
    assert np.abs(s).max() < 5e-4
    assert np.allclose(ring.next_pos[:, 1], 0.0)        # moved radially in its plane
    radius = np.linalg.norm(ring.next_pos, axis=1)
    assert radius == pytest.approx(np.full(N, radius.mean()), rel=1e-9)   # still a circle

    ring = Ring(0.05)
    for _ in range(2):
        ring.edge_pass()
    assert edge_stretch(ring).max() > 0.03
    assert 2 * math.sin(math.pi / N) ** 2 == pytest.approx(0.134, abs=1e-3)


def test_the_projection_leaves_short_edges_and_fixed_particles_alone():
    """Unilateral: a compressed ring does not move; a fixed particle never moves (the 5 %
    ring with one fixed particle is left at 0.9 % by 4 iterations: the ring now has to
    shift towards the fixed particle, a mode the truncated solve leaves partly to the
    Gauss-Seidel passes that follow it)."""
    ring = Ring(-0.05)
    before = ring.next_pos
    ring.project(4, False)
    assert np.array_equal(ring.next_pos, before)
    attribute = np.full(N, 0x02, np.uint8)
    attribute[0] = 0x01   # fixed
    ring = Ring(0.05, attribute)
    x0 = ring.next_pos[0]
    ring.project(4, False)
    assert np.array_equal(ring.next_pos[0], x0)
    assert np.abs(edge_stretch(ring)).max() < 0.01


def test_a_pushed_particle_slides_along_its_push_plane_and_its_neighbours_give_way():
    """One particle pushed 2 cm outwards (its contact direction radial: its two edges 6.6 %
    long): the filtered projection moves it only in the plane normal to the push, and its
    neighbours move in towards it. Edges at their rest length join the solve (kept from
    stretching), so the give spreads around the ring, one edge further per iteration: 4
    iterations leave < 2 %, 8 leave < 0.2 %."""
    for iterations, bound in ((4, 0.02), (8, 0.002)):
        ring = Ring(0.0)
        x = ring.next_pos
        out = x[0] / np.linalg.norm(x[0])
        x[0] += 0.02 * out
        ring.set("next_pos", x)
        contact = np.zeros((N, 3))
        contact[0] = out
        ring.set("projection_contact", contact)
        before = ring.next_pos
        assert edge_stretch(ring).max() > 0.066
        ring.project(iterations, True)
        after = ring.next_pos
        assert abs(float((after[0] - before[0]) @ out)) < 1e-12
        assert edge_stretch(ring).max() < bound
        assert np.linalg.norm(after[1] - before[1]) > 5e-3


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
    m, ps, view = system.model, system.particles, system.collider_state
    team = [getattr(s, "name", "") for s in system.specs].index("skirt")
    start, count = int(m.team_particle_start[team]), int(m.team_particle_count[team])
    idx = np.arange(start, start + count)
    idx = idx[(np.asarray(m.attribute)[idx] & 0x02) != 0]
    radius = M.particle_radius(m, system.parameters)[idx]
    slot_team, _index, shape = system.collider_slots()
    slots = [k for k in range(slot_team.shape[0]) if slot_team[k] == team]
    assert sorted(int(shape[k]) for k in slots) == [1, 1, 2]   # two thigh capsules and the floor
    deepest = 0.0
    for _ in range(p.frames):
        p.player.step()
        x = ps.old_pos[idx]
        cs = {name: getattr(view, name) for name in ("start_new", "end_new", "plane_normal", "radius_start",
                                                     "radius_end")}   # the slots after the step
        for k in slots:
            if shape[k] == 2:
                depth = radius - (x - cs["start_new"][k]) @ cs["plane_normal"][k]
            else:
                a, b = cs["start_new"][k], cs["end_new"][k]
                ab = b - a
                t = np.clip(((x - a) @ ab) / float(ab @ ab), 0.0, 1.0)
                reach = cs["radius_start"][k] + (cs["radius_end"][k] - cs["radius_start"][k]) * t + radius
                depth = reach - np.linalg.norm(x - (a + t[:, None] * ab), axis=1)
            deepest = max(deepest, float(depth.max()))
    assert deepest <= 1e-5
