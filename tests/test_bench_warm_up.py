"""The bench's feature-cost and crowd timings start after an untimed warm-up of the very
variants they time (issue 22: "a warm-up that leaves compile out"): each feature case and the
crowd is its own set of stages, so the sweep's warm-up does not compile their frame kernels,
and a cold numba cache once put a 17 s compile into the crowd's ms/frame."""
from magica_py.bench import cli
from magica_py.bench import variants as V


def test_the_crowd_is_run_untimed_before_it_is_timed(monkeypatch):
    calls = []
    monkeypatch.setattr(V, "run_variant", lambda v, record_positions=True: calls.append(("run", v.label, v.duration)))
    monkeypatch.setattr(V, "time_variant", lambda v, repeats=3, frames=None: calls.append(("time", v.label, repeats))
                        or (0.01, 1e6))
    result = cli.crowd_speed(lambda text: None)
    assert calls == [("run", "crowd", 0.1), ("time", "crowd", 3)]
    assert result["ms_per_frame"] == 10.0


def test_every_feature_case_is_run_untimed_before_the_timings(monkeypatch):
    calls = []
    monkeypatch.setattr(V, "run_variant", lambda v, record_positions=True: calls.append(("run", v.duration)))

    def timed(variants, repeats=9, frames=None, progress=None):
        calls.append(("time", len(variants)))
        return [(0.001, 1e6, 0.001)] * len(variants)

    monkeypatch.setattr(V, "time_interleaved", timed)
    rows = cli.feature_costs(1, lambda text: None)
    assert calls[-1] == ("time", len(rows))
    assert calls[:-1] == [("run", 0.1)] * len(rows)
