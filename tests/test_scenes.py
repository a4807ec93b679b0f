"""The procedural scene families: valid typed scenes, reproducible by seed, sized to the arm, with
start and goal targets clear of the obstacles and obstacles across the way between them."""

import math

import pytest
import torch

from kinlearn.body.robot import load_robot
from kinlearn.collision.geometry import Box, Cylinder, Sphere
from kinlearn.data.scenes import SCENE_FAMILIES, build_scene, scene_scale
from kinlearn.errors import ConfigError


def _distance(layout, points: torch.Tensor) -> torch.Tensor:
    """Each point's distance to the nearest primitive of the layout (the floor left out)."""
    d = torch.full(points.shape[:1], math.inf, dtype=torch.float64)
    for p in layout.primitives:
        d = torch.minimum(d, type(p).point_distance(points, torch.tensor(p.row(), dtype=torch.float64)))
    return d


@pytest.mark.parametrize("family", SCENE_FAMILIES)
def test_family_is_reproducible_valid_and_leaves_its_targets_free(family):
    for seed in range(4):
        a = build_scene(family, torch.Generator().manual_seed(seed))
        b = build_scene(family, torch.Generator().manual_seed(seed))
        assert a.primitives == b.primitives and a.family == family
        scene = a.scene()  # validates every row (positive sizes, orthonormal rotations)
        assert scene.num_primitives == len(a.primitives) > 0
        assert float(scene.floor) == 0.0
        for sampler in (a.start, b.start), (a.goal, b.goal):
            pa = sampler[0](64, torch.Generator().manual_seed(seed))
            pb = sampler[1](64, torch.Generator().manual_seed(seed))
            assert torch.equal(pa, pb) and pa.shape == (64, 3)
            assert bool((pa[:, 2] > 0).all()), "targets above the floor"
            assert float(pa[:, :2].norm(dim=-1).quantile(0.9)) < 0.87, "targets within the iiwa14's reach"
            assert float(_distance(a, pa).min()) > 0.0, "targets outside every obstacle"
    other = build_scene(family, torch.Generator().manual_seed(99))
    assert other.primitives != a.primitives


def test_families_have_rotated_boxes_cylinders_and_obstacles_across_the_way():
    kinds, rotated, crossed = set(), 0, 0
    for family in SCENE_FAMILIES:
        for seed in range(6):
            layout = build_scene(family, torch.Generator().manual_seed(seed))
            for p in layout.primitives:
                kinds.add(type(p))
                if isinstance(p, Box) and abs(p.rotation[0] - 1.0) > 1e-6:
                    rotated += 1
            g = torch.Generator().manual_seed(seed)
            s, e = layout.start(1, g)[0], layout.goal(1, g)[0]
            line = s + torch.linspace(0, 1, 200, dtype=torch.float64)[:, None] * (e - s)
            crossed += bool(_distance(layout, line).min() < 0)
    assert kinds == {Box, Cylinder, Sphere}
    assert rotated > 50
    assert crossed >= 0.5 * 6 * len(SCENE_FAMILIES)  # most straight end-effector segments are blocked


def test_scale_follows_the_arm_and_bad_input_is_refused():
    assert scene_scale(load_robot("iiwa14")) == pytest.approx(1.0, abs=0.01)
    small = build_scene("bookcase", torch.Generator().manual_seed(3), scale=0.5, yaw=0.0)
    full = build_scene("bookcase", torch.Generator().manual_seed(3), scale=1.0, yaw=0.0)
    assert small.primitives[0].centre[0] == pytest.approx(0.5 * full.primitives[0].centre[0])
    with pytest.raises(ConfigError, match="unknown scene family"):
        build_scene("kitchen", torch.Generator())
    with pytest.raises(ConfigError, match="scale"):
        build_scene("bookcase", torch.Generator(), scale=-1.0)


def test_a_tool_raises_the_targets_inside_a_bin_and_nothing_else():
    """``tool``: a body reaching further past the end effector. The targets inside a bin are raised by it
    (the same draws, the same scene), so that the tool is low in the bin; other families are unchanged."""
    for seed in range(3):
        bare = build_scene("bin", torch.Generator().manual_seed(seed), tool=0.0)
        tool = build_scene("bin", torch.Generator().manual_seed(seed), tool=0.15)
        assert tool.primitives == bare.primitives
        lifted = tool.goal(32, torch.Generator().manual_seed(1)) - bare.goal(
            32, torch.Generator().manual_seed(1)
        )
        assert torch.allclose(lifted[:, 2], torch.full((32,), 0.15, dtype=torch.float64), atol=1e-12)
        assert torch.allclose(lifted[:, :2], torch.zeros(32, 2, dtype=torch.float64), atol=1e-12)
        for family in ("cubby", "cage"):
            a = build_scene(family, torch.Generator().manual_seed(seed), tool=0.15)
            b = build_scene(family, torch.Generator().manual_seed(seed))
            assert a.primitives == b.primitives
            g1, g2 = torch.Generator().manual_seed(2), torch.Generator().manual_seed(2)
            assert torch.equal(a.goal(8, g1), b.goal(8, g2))
    with pytest.raises(ConfigError, match="tool"):
        build_scene("bin", torch.Generator(), tool=-0.1)
