"""Distance (D.4), tether (D.3) and motion (D.9) in block form give exactly the bits of their
per-team stages (``solver/batched``), from a mid-motion crowd state and from states built so
that, within one block, some lanes take a per-lane path (degenerate link, tether band side,
max-distance clamp, backstop push) and others do not."""
import numba
import numpy as np
import pytest

from batched_harness import block_rows, block_tables, compare_stage, crowd_system, restore, snapshot
from magica_py.solver.batch_tables import borrow
from magica_py.solver.constraints.distance import distance_block, distance_team
from magica_py.solver.constraints.motion import motion_block, motion_team, normal_axis_vector
from magica_py.solver.constraints.tether import STRETCH_LIMIT, tether_block, tether_team
from magica_py.solver.parameters import curve_at

RATIO, POWER_Y = 1.0, 1.0
DISTANCE_ATTENUATION, TETHER_ATTENUATION, MOTION_ATTENUATION = 0.3, 0.7, 0.95
MOTION_OVERRIDES = {f"cloths.{c}.parameters.motion.{k}": v for c in ("hair", "skirt")
                    for k, v in (("use_max_distance", "true"), ("max_distance", 0.04), ("use_backstop", "true"),
                                 ("backstop_radius", 0.3), ("backstop_distance", 0.01))}


@pytest.fixture(scope="module")
def crowd():
    return crowd_system(instances=6, frames=25)


@pytest.fixture(scope="module")
def motion_crowd():
    return crowd_system(instances=6, frames=25, overrides=MOTION_OVERRIDES)


# ------------------------------------------------------------------ stage wrappers (harness API)
@numba.njit
def _distance_teams(m, ps, prm, ts, cs, tt, teams):
    m, ps, prm, ts = borrow(m), borrow(ps), borrow(prm), borrow(ts)
    for t in teams:
        distance_team(m, ps, prm, ts, t, RATIO, POWER_Y, DISTANCE_ATTENUATION)


@numba.njit
def _distance_blocks(m, ps, prm, ts, cs, tt, blk, bs, blocks):
    m, prm, blk, bs = borrow(m), borrow(prm), borrow(blk), borrow(bs)
    for b in blocks:
        distance_block(m, bs, prm, blk, b, RATIO, POWER_Y, DISTANCE_ATTENUATION)


@numba.njit
def _tether_teams(m, ps, prm, ts, cs, tt, teams):
    m, ps, prm = borrow(m), borrow(ps), borrow(prm)
    for t in teams:
        tether_team(m, ps, prm, t, TETHER_ATTENUATION)


@numba.njit
def _tether_blocks(m, ps, prm, ts, cs, tt, blk, bs, blocks):
    m, prm, blk, bs = borrow(m), borrow(prm), borrow(blk), borrow(bs)
    for b in blocks:
        tether_block(m, bs, prm, blk, b, TETHER_ATTENUATION)


@numba.njit
def _motion_teams(m, ps, prm, ts, cs, tt, teams):
    m, ps, prm = borrow(m), borrow(ps), borrow(prm)
    for t in teams:
        motion_team(m, ps, prm, t, MOTION_ATTENUATION)


@numba.njit
def _motion_blocks(m, ps, prm, ts, cs, tt, blk, bs, blocks):
    m, prm, blk, bs = borrow(m), borrow(prm), borrow(blk), borrow(bs)
    for b in blocks:
        motion_block(m, bs, prm, blk, b, MOTION_ATTENUATION)


# ------------------------------------------------------------------ helpers
def _team_rows(system, t):
    start = int(system.model.team_particle_start[t])
    return np.arange(start, start + int(system.model.team_particle_count[t]))


def _lanes(blk, b):
    base = int(blk.block_lane_base[b])
    return [int(t) for t in blk.lane_team[base:base + int(blk.block_width[b])]]


def _links(system, t):
    """(p, q, rest) global rows of team t's distance links from moving particles."""
    m = system.model
    out = []
    for p in _team_rows(system, t):
        if m.attribute[p] & 0x02:
            s = int(m.distance_start[p])
            for link in range(s, s + int(m.distance_count[p])):
                out.append((p, int(m.distance_target[link]), float(m.distance_rest[link])))
    return out


def _assert_scratch_cleared(system, blk, bs):
    for name in ("accum_vector", "accum_count"):
        got = block_rows(system, blk, bs, name)
        rows = np.concatenate([_team_rows(system, t) for t in blk.lane_team])
        assert np.array_equal(got[rows], getattr(system.particles, name)[rows]), name
        assert not getattr(system.particles, name)[rows].any(), f"{name} not zero between stages"


class _Modified:
    """Temporarily edited solver state (the fixtures are shared by the module's tests)."""

    def __init__(self, system):
        self.system = system

    def __enter__(self):
        self.before = snapshot(self.system)
        return self.system.particles

    def __exit__(self, *exc):
        restore(self.system, self.before)


# ------------------------------------------------------------------ distance
def test_distance_block_is_bit_identical_to_distance_team(crowd):
    compare_stage(crowd, _distance_teams, _distance_blocks, ["next_pos", "velocity_pos", "friction"])


def test_distance_block_leaves_its_accumulators_cleared(crowd):
    blk, bs = block_tables(crowd)
    from batched_harness import run_block_stage
    with _Modified(crowd):
        run_block_stage(crowd, _distance_blocks, blk, bs)
        _assert_scratch_cleared(crowd, blk, bs)


def test_distance_block_matches_with_collapsed_lanes_and_degenerate_links(crowd):
    """Per block: lane 0 collapsed to one point (every link degenerate: no correction at all),
    lane 1 with each moving particle on one of its partners (one degenerate link among
    normal ones), the other lanes as they are."""
    blk, _bs = block_tables(crowd)
    with _Modified(crowd) as ps:
        collapsed, partial_degenerate, normal = [], 0, 0
        for b in range(len(blk.block_width)):
            lanes = _lanes(blk, b)
            rows = _team_rows(crowd, lanes[0])
            ps.next_pos[rows] = ps.next_pos[rows[0]]
            collapsed.append(lanes[0])
            for p, q, _r in _links(crowd, lanes[1])[::5]:
                ps.next_pos[p] = ps.next_pos[q]
            for t in lanes[1:]:
                for p, q, _r in _links(crowd, t):
                    if np.linalg.norm(ps.next_pos[q] - ps.next_pos[p]) < 1e-8:
                        partial_degenerate += 1
                    else:
                        normal += 1
        assert partial_degenerate >= 10 and normal >= 1000, (partial_degenerate, normal)
        before = ps.next_pos.copy()
        compare_stage(crowd, _distance_teams, _distance_blocks, ["next_pos", "velocity_pos"])
        # the per-team run: collapsed lanes did not move (n == 0 everywhere), the others did
        from batched_harness import run_team_stage
        run_team_stage(crowd, _distance_teams, blk)
        for t in blk.lane_team:
            rows = _team_rows(crowd, t)
            moved = int((ps.next_pos[rows] != before[rows]).any(axis=1).sum())
            assert (moved == 0) if t in collapsed else (moved > 10), (t, moved)


def test_distance_block_matches_with_zero_rest_links(crowd):
    """Zero-rest links (ZeroDistance pairs, docs/solver.md Appendix 2.1: they overwrite the sum) on every
    third link of every team (the same links in every lane, so the blocks stay valid)."""
    rest = crowd.model.distance_rest
    saved = rest.copy()
    zero = np.zeros(len(rest), dtype=bool)
    m = crowd.model
    for t in range(len(m.team_particle_start)):
        rows = _team_rows(crowd, t)
        first = int(m.distance_start[rows[0]])
        last = int(m.distance_start[rows[-1]] + m.distance_count[rows[-1]])
        zero[first + 1:last:3] = True
    rest.flags.writeable = True
    try:
        rest[zero] = 0.0
        assert (rest == 0.0).sum() > 100
        compare_stage(crowd, _distance_teams, _distance_blocks, ["next_pos", "velocity_pos"])
    finally:
        rest[:] = saved
        rest.flags.writeable = False


# ------------------------------------------------------------------ tether
def _tether_paths(system, teams):
    """How many moving particles of ``teams`` start compressed, stretched, inside the band or
    on their root (the tether reads only the particle and its fixed root: the pre-state
    decides the path exactly)."""
    m, ps, prm = system.model, system.particles, system.parameters
    counts = dict(compressed=0, stretched=0, inside=0, degenerate=0)
    for t in teams:
        limit = 1.0 - prm.tether_compression[t]
        for p in _team_rows(system, t):
            r = m.root_index[p]
            if not (m.attribute[p] & 0x02) or r < 0:
                continue
            rest = np.linalg.norm(ps.step_basic_pos[p] - ps.step_basic_pos[r])
            length = np.linalg.norm(ps.next_pos[r] - ps.next_pos[p])
            if length < 1e-8 or rest == 0.0:
                counts["degenerate"] += 1
            elif length / rest < limit:
                counts["compressed"] += 1
            elif length / rest > 1.0 + STRETCH_LIMIT:
                counts["stretched"] += 1
            else:
                counts["inside"] += 1
    return counts


def test_tether_block_is_bit_identical_to_tether_team(crowd):
    compare_stage(crowd, _tether_teams, _tether_blocks, ["next_pos", "velocity_pos"])


def test_tether_block_matches_when_lanes_take_different_band_sides(crowd):
    """Per block: lane 0 squeezed towards its roots, lane 1 stretched, lane 2 on its roots,
    the others as they are: all four paths of the tether occur within each block."""
    blk, _bs = block_tables(crowd)
    m = crowd.model
    with _Modified(crowd) as ps:
        for b in range(len(blk.block_width)):
            lanes = _lanes(blk, b)
            for lane, factor in ((0, 0.1), (1, 1.6), (2, 0.0)):
                for p in _team_rows(crowd, lanes[lane]):
                    r = m.root_index[p]
                    if (m.attribute[p] & 0x02) and r >= 0:
                        ps.next_pos[p] = ps.next_pos[r] + factor * (ps.next_pos[p] - ps.next_pos[r])
            counts = _tether_paths(crowd, lanes)
            assert min(counts.values()) >= 5, (b, counts)
        compare_stage(crowd, _tether_teams, _tether_blocks, ["next_pos", "velocity_pos"])


# ------------------------------------------------------------------ motion
def _motion_paths(system, teams):
    """(clamped, not clamped, pushed out of the backstop, not pushed) over the moving
    particles of ``teams`` (a numpy twin of D.9's tests; particles are independent)."""
    m, ps, prm = system.model, system.particles, system.parameters
    clamped = free = pushed = outside = 0
    for t in teams:
        axis = np.array(normal_axis_vector(int(prm.normal_axis[t])))
        radius = prm.backstop_radius[t]
        for p in _team_rows(system, t):
            if not (m.attribute[p] & 0x02) or (m.attribute[p] & 0x08):
                continue
            depth = m.depth[p]
            d2 = depth * depth
            x, base = ps.next_pos[p].copy(), ps.base_pos[p]
            max_distance = curve_at(prm.max_distance_curve, t, d2)
            if np.linalg.norm(x - base) > max_distance:
                clamped += 1
                x = base + (x - base) * (max_distance / np.linalg.norm(x - base))
            else:
                free += 1
            qx, qy, qz, qw = ps.base_rot[p]
            u = np.array([qx, qy, qz])
            direction = axis + 2.0 * np.cross(u, np.cross(u, axis) + qw * axis)
            c = base - direction * (curve_at(prm.backstop_distance_curve, t, d2) + radius)
            r = max(curve_at(prm.radius_curve, t, depth), 1e-4)
            length = np.linalg.norm(x - c)
            if 1e-8 < length < min(radius, radius + r):
                pushed += 1
            else:
                outside += 1
    return clamped, free, pushed, outside


def test_motion_block_is_bit_identical_to_motion_team(motion_crowd):
    compare_stage(motion_crowd, _motion_teams, _motion_blocks, ["next_pos", "velocity_pos"])


def test_motion_block_matches_when_some_lanes_are_clamped_or_pushed(motion_crowd):
    """Per block: lane 0 thrown far out (clamped), lane 1 on its animated pose (free), lane 2
    pushed behind its backstop (inside the sphere), the others as they are."""
    system = motion_crowd
    blk, _bs = block_tables(system)
    m, prm = system.model, system.parameters
    with _Modified(system) as ps:
        for b in range(len(blk.block_width)):
            lanes = _lanes(blk, b)
            rows = _team_rows(system, lanes[0])
            ps.next_pos[rows] += np.array([0.5, -0.3, 0.2])
            rows = _team_rows(system, lanes[1])
            ps.next_pos[rows] = ps.base_pos[rows]
            t = lanes[2]
            axis = np.array(normal_axis_vector(int(prm.normal_axis[t])))
            for p in _team_rows(system, t):
                qx, qy, qz, qw = ps.base_rot[p]
                u = np.array([qx, qy, qz])
                direction = axis + 2.0 * np.cross(u, np.cross(u, axis) + qw * axis)
                ps.next_pos[p] = ps.base_pos[p] - 0.03 * direction
            clamped, free, pushed, outside = _motion_paths(system, lanes)
            assert min(clamped, free, pushed, outside) >= 5, (b, clamped, free, pushed, outside)
        compare_stage(system, _motion_teams, _motion_blocks, ["next_pos", "velocity_pos"])


def test_motion_block_does_nothing_when_the_team_uses_neither_limit(crowd):
    assert not crowd.parameters.use_max_distance.any() and not crowd.parameters.use_backstop.any()
    blk, bs = block_tables(crowd)
    from batched_harness import run_block_stage
    with _Modified(crowd) as ps:
        before = ps.next_pos.copy(), ps.velocity_pos.copy()
        run_block_stage(crowd, _motion_blocks, blk, bs)
        assert np.array_equal(ps.next_pos, before[0]) and np.array_equal(ps.velocity_pos, before[1])


# ------------------------------------------------------------------ lane-stream fallbacks
class _Writable:
    """Model arrays edited for one test (they are read-only after build), restored after."""

    def __init__(self, *arrays):
        self.arrays = arrays

    def __enter__(self):
        self.saved = [a.copy() for a in self.arrays]
        for a in self.arrays:
            a.flags.writeable = True
        return self.arrays

    def __exit__(self, *exc):
        for a, s in zip(self.arrays, self.saved):
            a[...] = s
            a.flags.writeable = False


def test_distance_block_matches_with_self_links_and_particles_without_links(crowd):
    """The block's fallbacks, never reached by a built model: a particle whose last link
    targets itself (its links run without applying, then a separate apply loop; with 1, 2, 5
    and 8 links: after a pair and after a single link) and a moving particle without links
    (left as it is). The same team-local particles are edited in every team, so that the
    blocks stay valid."""
    m = crowd.model
    with _Writable(m.distance_target, m.distance_count) as (target, count):
        edited = {"self": {}, "none": 0}
        for t in range(len(m.team_particle_start)):
            rows = _team_rows(crowd, t)
            for local, p in enumerate(rows):
                n = int(count[p])
                if not (m.attribute[p] & 0x02) or n == 0:
                    continue
                if local % 3 == 0:
                    target[m.distance_start[p] + n - 1] = p
                    edited["self"][n] = edited["self"].get(n, 0) + 1
                elif local % 7 == 1:
                    count[p] = 0
                    edited["none"] += 1
        assert edited["none"] >= 6 and all(edited["self"].get(n, 0) >= 6 for n in (1, 2, 5, 8)), edited
        blk, _bs = block_tables(crowd)
        with _Modified(crowd) as ps:
            before = ps.next_pos.copy()
            compare_stage(crowd, _distance_teams, _distance_blocks, ["next_pos", "velocity_pos"])
            from batched_harness import run_team_stage
            run_team_stage(crowd, _distance_teams, blk)
            linkless = [p for t in blk.lane_team for p in _team_rows(crowd, t)
                        if (m.attribute[p] & 0x02) and count[p] == 0]
            moved = [p for t in blk.lane_team for p in _team_rows(crowd, t) if (before[p] != ps.next_pos[p]).any()]
            assert linkless and not set(linkless) & set(moved) and len(moved) > 100, (len(linkless), len(moved))


def test_tether_block_matches_when_a_particle_is_its_own_root(crowd):
    """A particle that is its own root (never in a built model) takes the block's second lane
    loop, which reads the particle's row for both roles; the others the streamed loop."""
    m = crowd.model
    with _Writable(m.root_index) as (root_index,):
        own = 0
        for t in range(len(m.team_particle_start)):
            for local, p in enumerate(_team_rows(crowd, t)):
                if (m.attribute[p] & 0x02) and root_index[p] >= 0 and local % 2 == 0:
                    root_index[p] = p
                    own += 1
        assert own >= 50, own
        with _Modified(crowd) as ps:
            blk, _bs = block_tables(crowd)
            for b in range(len(blk.block_width)):  # lane 0 squeezed: the others keep their roots' paths
                for p in _team_rows(crowd, _lanes(blk, b)[0]):
                    r = root_index[p]
                    if (m.attribute[p] & 0x02) and r >= 0 and r != p:
                        ps.next_pos[p] = ps.next_pos[r] + 0.1 * (ps.next_pos[p] - ps.next_pos[r])
            compare_stage(crowd, _tether_teams, _tether_blocks, ["next_pos", "velocity_pos"])
