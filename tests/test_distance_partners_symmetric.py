"""The distance constraint's partner lists (docs/solver.md §B.9, §D.4) are symmetric: when q is
one of p's partners, p is one of q's, with the same signed rest length. Quality mode's display
(``quality_display.display_constraints_block``, step 2) sees each link from its moving ends only and
relies on it, and D.4's Gauss-Seidel pass treats both ends of a link alike. Checked on the
build of every connection mode the configs use: line chains, a fan of strands, a looped mesh
skirt, a VRM avatar's spring bones and a wind sheet."""
import pathlib

import numpy as np
import pytest

ROOT = pathlib.Path(__file__).resolve().parents[1]


def links(models):
    """{(team, p, q): signed rest length} of every distance link of the teams' build models
    (``ClothSystem.models``, team-local particle indices), the lists the solver's blocks take."""
    pairs = {}
    for t, model in enumerate(models):
        if model is None:
            continue
        start = np.asarray(model.distance_start)
        count = np.asarray(model.distance_count)
        target = np.asarray(model.distance_target)
        rest = np.asarray(model.distance_rest)
        for p in range(start.shape[0]):
            for link in range(start[p], start[p] + count[p]):
                pairs[(t, p, int(target[link]))] = float(rest[link])
    return pairs


@pytest.mark.parametrize("config", ["tail_orbit.yaml", "character_walk.yaml", "vrm_godette_mocap.yaml",
                                    "wind.yaml", "hard/mocap_spin.yaml"])
def test_distance_partner_lists_are_symmetric_with_equal_rest_lengths(config):
    from magica_py.config import load_scene
    from magica_py.solver.system import ClothSystem

    scene = load_scene(ROOT / "configs" / config)
    system = ClothSystem(scene.hierarchy, scene.cloths, scene.colliders, scene.settings)
    pairs = links(system.models)
    assert pairs, "no distance link built"
    asymmetric = [(t, p, q) for (t, p, q) in pairs if (t, q, p) not in pairs]
    assert not asymmetric, f"{config}: links without their reverse, e.g. {asymmetric[:5]}"
    unequal = [(t, p, q) for (t, p, q), r in pairs.items() if pairs[(t, q, p)] != r]
    assert not unequal, f"{config}: reverse links with another rest length, e.g. {unequal[:5]}"
