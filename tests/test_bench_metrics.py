"""bench.metrics / reference / report against hand-computed cases and synthetic trajectories
(no solver: these run in milliseconds)."""
from __future__ import annotations

import math
from types import SimpleNamespace

import numpy as np
import pytest

from magica_py.bench import metrics as M
from magica_py.bench.numpy_baseline import NumpyChain
from magica_py.bench.reference import fit_order, resolved_error
from magica_py.bench.report import markdown_table, pareto_front, pareto_plot, write_csv


def chain_model(parents, attribute=None, teams=None):
    n = len(parents)
    parents = np.asarray(parents)
    edges = np.array([(p, i) for i, p in enumerate(parents) if p >= 0]).reshape(-1, 2)
    root = np.array([0 if p >= 0 else -1 for p in parents])
    attribute = np.asarray(attribute if attribute is not None else [1] + [2] * (n - 1), dtype=np.uint8)
    team = np.zeros(n, dtype=np.int64) if teams is None else np.asarray(teams)
    return SimpleNamespace(edges=edges, parent=parents, root_index=root, attribute=attribute,
                           particle_team=team, team_particle_count=np.bincount(team),
                           depth=np.linspace(0, 1, n), child_count=np.r_[np.ones(n - 1), 0])


STRAIGHT = np.array([[0, 0, 0], [0, -0.1, 0], [0, -0.2, 0], [0, -0.3, 0]], dtype=float)


def test_chain_geometry_arc_length_and_rest_lengths():
    g = M.chain_geometry(chain_model([-1, 0, 1, 2]), STRAIGHT)
    assert g.edge_rest == pytest.approx([0.1, 0.1, 0.1])
    assert g.arc_length == pytest.approx([0, 0.1, 0.2, 0.3])
    assert g.root_rest == pytest.approx([0, 0.1, 0.2, 0.3])
    assert g.chain_length == pytest.approx(0.3)
    assert g.moving.tolist() == [False, True, True, True]


def test_edge_stretch_of_a_uniformly_scaled_chain_is_the_scale_minus_one():
    g = M.chain_geometry(chain_model([-1, 0, 1, 2]), STRAIGHT)
    stretched = STRAIGHT * 1.05
    assert M.edge_stretch(stretched, g) == pytest.approx([0.05] * 3)
    assert M.root_distance_stretch(stretched, g)[1:] == pytest.approx([0.05] * 3)
    # one edge compressed by 2 cm: -20 %
    bent = STRAIGHT.copy()
    bent[3] = [0, -0.28, 0]
    assert M.edge_stretch(bent, g)[2] == pytest.approx(-0.2)


def test_zero_length_edges_report_no_ratio_but_their_drift():
    rest = np.array([[0, 0, 0], [0, -0.1, 0], [0, -0.1, 0]], dtype=float)
    g = M.chain_geometry(chain_model([-1, 0, 1]), rest)
    moved = rest.copy()
    moved[2] = [0.003, -0.1, 0.004]
    assert M.edge_stretch(moved, g)[1] == 0.0
    assert M.zero_length_drift(moved, g) == pytest.approx(0.005)


def shapes(kind, position, radius=0.0, end_radius=0.0, start=None, end=None, normal=(0, 0, 0), suspended=False):
    p = np.asarray([position], dtype=float)
    return SimpleNamespace(shape=np.array([kind]), position=p, radius=np.array([radius]),
                           end_radius=np.array([end_radius]),
                           start=np.asarray([start if start is not None else position], dtype=float),
                           end=np.asarray([end if end is not None else position], dtype=float),
                           normal=np.asarray([normal], dtype=float), suspended=np.array([suspended]))


def test_penetration_depth_sphere_capsule_plane_by_hand():
    pts = np.array([[0.0, 0.05, 0.0], [0.0, 0.5, 0.0]])
    radius = np.array([0.02, 0.02])
    pairs = (np.array([0, 1]), np.array([0, 0]))
    # sphere r=0.1 at the origin: 0.1 + 0.02 - 0.05 = 0.07 inside; the far point is outside
    d = M.penetration_depth(pts, radius, pairs, shapes(0, [0, 0, 0], radius=0.1))
    assert d == pytest.approx([0.07, 0.0])
    # capsule from (-1,0,0) r=0.1 to (1,0,0) r=0.3: at x=0 the radius is 0.2
    cap = shapes(1, [0, 0, 0], radius=0.1, end_radius=0.3, start=[-1, 0, 0], end=[1, 0, 0])
    assert M.penetration_depth(pts, radius, pairs, cap) == pytest.approx([0.2 + 0.02 - 0.05, 0.0])
    # plane y=0.1 facing +Y: the point at y=0.05 is 0.05 + 0.02 under the shell
    plane = shapes(2, [0, 0.1, 0], normal=(0, 1, 0))
    assert M.penetration_depth(pts, radius, pairs, plane) == pytest.approx([0.07, 0.0])
    # a suspended collider is skipped
    assert M.penetration_depth(pts, radius, pairs, shapes(0, [0, 0, 0], radius=0.1, suspended=True)).max() == 0


def test_particle_collider_pairs_follow_the_teams():
    pi, ci = M.particle_collider_pairs(np.array([0, 0, 1]), [[2], [0, 1]])
    assert sorted(zip(pi.tolist(), ci.tolist())) == [(0, 2), (1, 2), (2, 0), (2, 1)]


def test_particle_radius_interpolates_the_depth_table():
    model = SimpleNamespace(particle_team=np.array([0, 0, 0]), depth=np.array([0.0, 0.5, 1.0]))
    params = SimpleNamespace(radius_curve=np.linspace(0.01, 0.04, 16)[None, :])
    assert M.particle_radius(model, params) == pytest.approx([0.01, 0.025, 0.04])
    assert M.particle_radius(model, params, np.array([2.0])) == pytest.approx([0.02, 0.05, 0.08])


def test_frame_speeds_and_energy_of_a_free_fall():
    g = 9.81
    t = np.linspace(0.0, 1.0, 101)
    pos = np.zeros((101, 1, 3))
    pos[:, 0, 1] = -0.5 * g * t * t
    v = M.frame_speeds(pos, t)
    # the mean speed over [t-dt, t] is g (t - dt/2)
    assert v[50, 0] == pytest.approx(g * (0.5 - 0.005), rel=1e-9)
    e = M.energy_envelope(pos, t, np.array([True]), g)
    # kinetic (from the midpoint speeds) + potential stays within O(g^2 dt^2) of its start value
    assert np.ptp(e[1:]) < 0.01 * e[1]


def test_frame_speeds_are_zero_over_a_pause():
    t = np.array([0.0, 0.1, 0.1, 0.2])
    pos = np.array([[[0, 0, 0]], [[0.1, 0, 0]], [[0.1, 0, 0]], [[0.3, 0, 0]]], dtype=float)
    assert M.frame_speeds(pos, t)[:, 0] == pytest.approx([0, 1, 0, 2])


def test_settling_time_is_measured_from_the_disturbance_end():
    t = np.arange(0, 5.0, 0.5)
    speed = np.array([5, 5, 3, 2, 1, 0.5, 0.01, 0.01, 0.01, 0.01])
    assert M.settling_time(speed, t, 0.1, after=1.0) == pytest.approx(2.0)     # below from t=3.0
    assert M.settling_time(speed, t, 10.0) == 0.0
    assert math.isinf(M.settling_time(np.r_[speed[:-1], 1.0], t, 0.1))          # moves again at the end


def test_sample_at_interpolates_linearly_and_clamps():
    t = np.array([0.0, 1.0, 2.0])
    v = np.array([[0.0], [10.0], [30.0]])
    assert M.sample_at(t, v, np.array([0.5, 1.5, 3.0, -1.0]))[:, 0] == pytest.approx([5, 20, 30, 0])


def test_frame_rate_spread_of_the_same_motion_sampled_at_two_rates_is_tiny():
    def record(fps):
        t = np.arange(1, int(2 * fps) + 1) / fps
        tip = np.stack([np.cos(t), np.sin(t), 0 * t], axis=1)[:, None, :]
        return t, tip
    same = M.frame_rate_spread([record(30), record(240)], length=1.0)
    assert same < 2e-3          # linear interpolation of a unit circle at 30 fps: (1/30)^2/8
    t, tip = record(60)
    shifted = (t, tip + np.array([0.0, 0.05, 0.0]))
    assert M.frame_rate_spread([record(60), shifted], length=0.5) == pytest.approx(0.1)


def test_frame_errors_normalise_by_chain_length_over_the_masked_particles():
    ref = np.zeros((2, 3, 3))
    pos = ref.copy()
    pos[1, 1, 0] = 0.03
    pos[1, 2, 0] = 0.04
    pos[1, 0, 0] = 9.0             # masked out (a fixed particle)
    rms, mx = M.frame_errors(pos, ref, np.full(3, 0.1), np.array([False, True, True]))
    assert rms == pytest.approx([0.0, math.sqrt((0.09 + 0.16) / 2)])
    assert mx == pytest.approx([0.0, 0.4])


def test_resolved_error_keeps_only_frames_the_reference_resolves():
    err = np.full(10, 0.05)
    residual = np.r_[np.full(6, 0.001), np.full(4, 0.02)]   # reference diverges after frame 6
    r = resolved_error(err, err * 2, residual)
    assert r.mask.tolist() == [True] * 6 + [False] * 4
    assert r.rms == pytest.approx(0.05) and r.max == pytest.approx(0.1)
    assert r.coverage == pytest.approx(0.6) and r.residual_rms == pytest.approx(0.001)
    # an error smaller than ten residuals is not resolved anywhere
    r = resolved_error(np.full(10, 0.005), np.full(10, 0.005), np.full(10, 0.001))
    assert not r.resolved and math.isnan(r.rms)


def test_fit_order_recovers_the_exponent_of_a_power_law():
    f = np.array([30, 60, 120, 240, 480])
    order, r2 = fit_order(f, 3.0 * (1.0 / f) ** 2)
    assert order == pytest.approx(2.0) and r2 == pytest.approx(1.0)
    order, _ = fit_order(f, np.r_[0.1 / f[:4], np.nan])          # nan points are ignored
    assert order == pytest.approx(1.0)
    assert math.isnan(fit_order([30], [0.1])[0])


def test_pareto_front_drops_dominated_points():
    pts = [(1.0, 10.0), (2.0, 5.0), (3.0, 6.0), (0.5, 20.0), (4.0, 1.0), (5.0, math.nan)]
    assert pareto_front(pts) == [3, 0, 1, 4]


def test_report_writers_produce_table_csv_and_png(tmp_path):
    rows = [{"scene": "s", "family": "magica", "frequency": f, "ms_per_frame": 0.1 * f / 30,
             "rms_error": 10.0 / f, "max_edge_stretch": 5.0 / f} for f in (30, 90, 360)]
    rows.append({"scene": "s", "family": "frequency_consistent", "frequency": 90, "ms_per_frame": 0.2,
                 "rms_error": None, "max_edge_stretch": math.inf})
    cols = (("scene", "scene", "{}"), ("frequency", "Hz", "{}"), ("rms_error", "err", "{:.3g}"),
            ("max_edge_stretch", "stretch", "{:.2f}"))
    text = markdown_table(rows, cols)
    assert text.splitlines()[0] == "| scene | Hz | err | stretch |"
    assert "| s | 90 | 0.111 | 0.06 |" in text and "| s | 90 | - | inf |" in text
    write_csv(tmp_path / "t.csv", rows, cols)
    assert (tmp_path / "t.csv").read_text().splitlines()[1] == "s,30,0.3333333333333333,0.16666666666666666"
    from magica_py.bench.sweep import SceneResult

    sweep = [dict(r, short_error=r["rms_error"] or 1.0, ms_q1=0.9 * r["ms_per_frame"], ms_q3=1.1 * r["ms_per_frame"],
                  resolved="yes" if r["frequency"] < 360 else "NO") for r in rows]
    result = SceneResult(rows=sweep, references=[{"reference": "frequency_consistent", "short_residual": 0.005}],
                         families=[{"family": "magica", "spread": 0.3}])
    pareto_plot(tmp_path / "p.png", [result])
    assert (tmp_path / "p.png").read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"


def test_numpy_baseline_chain_hangs_straight_and_keeps_its_lengths():
    rest = np.array([[0, 0, 0], [0.1, 0, 0], [0.2, 0, 0], [0.3, 0, 0]], dtype=float)   # horizontal
    chain = NumpyChain.from_rest(rest, np.array([-1, 0, 1, 2]), rest[0], (0, 0, 0, 1),
                                 gravity=9.81, restoration=0.0, damping=0.05)
    for _ in range(600):
        chain.frame(1 / 60, rest[0], (0, 0, 0, 1), rest[0], (0, 0, 0, 1))
    p = chain.position
    assert np.abs(p[:, 0]).max() < 0.01                          # hangs straight down
    lengths = np.linalg.norm(np.diff(p, axis=0), axis=1)
    assert np.abs(lengths / 0.1 - 1).max() < 0.03                 # tether + two Jacobi passes
    assert np.isfinite(p).all()


# ----------------------------------------------------------------------------- end to end (small)
def test_bench_cli_writes_table_csv_and_plot_with_an_extra_family(tmp_path, capsys):
    import csv

    from magica_py.bench.cli import main_bench
    from magica_py.bench.report import BENCH_CSV_COLUMNS

    code = main_bench(["--scenes", "tail_orbit", "--frequencies", "45,90", "--families", "frequency_consistent",
                       "--family", "tight:solver.rate_mode=frequency_consistent,tether.distance_compression=0.05",
                       "--repeats", "2", "--duration", "0.5", "--skip", "fps,numpy,features,crowd",
                       "--out", str(tmp_path), "--quiet"])
    assert code in (0, 1)                                       # 1: the reference check failed (stated in bench.md)
    with (tmp_path / "bench.csv").open() as fh:
        rows = list(csv.DictReader(fh))
    assert len(rows) == 4                                       # 2 families x 2 frequencies
    assert {r["family"] for r in rows} == {"frequency_consistent", "tight"}
    assert list(rows[0]) == [c[0] for c in BENCH_CSV_COLUMNS]
    for r in rows:
        for key in ("ms_per_frame", "ms_q1", "ms_q3", "particle_steps_per_s", "short_error", "short_max",
                    "max_edge_stretch", "max_root_stretch", "max_penetration_mm", "ms_per_frame_min"):
            assert math.isfinite(float(r[key])), (key, r[key])
        assert float(r["ms_q1"]) <= float(r["ms_per_frame"]) <= float(r["ms_q3"])
        assert float(r["short_error"]) > 0 and r["resolved"] in ("yes", "NO")
    text = (tmp_path / "bench.md").read_text()
    assert "| tail_orbit | frequency_consistent | 90 |" in text and "short-horizon residual" in text
    assert text.index("## Reference check") < text.index("## Sweep")
    assert "load average" in text
    assert (tmp_path / "pareto.png").read_bytes()[:4] == b"\x89PNG"


def test_stability_cli_reports_a_case_and_exits_zero_within_bounds(tmp_path):
    from magica_py.bench.cli import main_stability

    assert main_stability(["--case", "scale_0_01", "--out", str(tmp_path), "--quiet"]) == 0
    table = (tmp_path / "stability.md").read_text()
    assert "| scale_0_01 | yes |" in table and "| ok |" in table
    assert main_stability(["--case", "no_such_case", "--quiet"]) == 2


def test_kinetic_envelope_of_two_particles_at_known_speeds():
    t = np.array([0.0, 0.5, 1.0])
    pos = np.zeros((3, 3, 3))
    pos[:, 1, 0] = [0.0, 1.0, 2.0]        # 2 m/s
    pos[:, 2, 2] = [0.0, 0.0, 1.5]        # 0 then 3 m/s
    pos[:, 0, 1] = [0.0, 5.0, 9.0]        # not moving (fixed): ignored
    e = M.kinetic_envelope(pos, t, np.array([False, True, True]))
    assert e == pytest.approx([0.0, 2.0, 2.0 + 4.5])
    # the team's mean velocity removed: frame 1 mean (1, 0, 0) -> 0.5 * (1 + 1); frame 2
    # mean (1, 0, 1.5) -> 0.5 * (1 + 2.25) * 2
    e = M.kinetic_envelope(pos, t, np.array([False, True, True]), team=np.zeros(3, dtype=int))
    assert e == pytest.approx([0.0, 1.0, 3.25])
    assert M.kinetic_envelope(pos, t, np.array([False, True, True]), window=2) == pytest.approx([0.0, 2.0, 6.5])
    assert M.kinetic_envelope(pos[::-1], t, np.array([False, True, True]), window=3)[-1] == pytest.approx(6.5)


def test_log_axis_ticks_are_few_plain_values_inside_the_range():
    from magica_py.bench.report import log_tick_values

    assert log_tick_values(0.062, 0.27) == pytest.approx([0.07, 0.08, 0.1, 0.15, 0.2, 0.25])
    assert log_tick_values(0.2, 4.0) == pytest.approx([0.2, 0.3, 0.5, 0.7, 1.0, 2.0, 3.0])
    assert log_tick_values(0.01, 100.0) == pytest.approx([0.01, 0.1, 1.0, 10.0, 100.0])
    for lo, hi in ((0.062, 0.27), (0.3, 0.45), (1e-3, 30.0), (0.2, 4.0)):
        values = log_tick_values(lo, hi)
        assert 1 <= len(values) <= 7 and all(lo <= v <= hi for v in values)
