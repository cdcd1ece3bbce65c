"""Shared fixtures of the runtime tests."""

import numpy as np
import pytest

from cslx.sim import random_pose, random_world, render_frame


@pytest.fixture(scope="session")
def render_scenes():
    """`render(sensor, kinds, seed)`: one clean rendered frame per weld kind, a random world
    and pose each from ``default_rng([seed, i])``; a list of (image, ground truth)."""

    def render(sensor, kinds, seed):
        out = []
        for i, kind in enumerate(kinds):
            rng = np.random.default_rng([seed, i])
            world = random_world(kind, rng)
            pose = random_pose(world, kind, rng, sensor)
            out.append(render_frame(sensor, world, pose, "clean", seed=i))
        return out

    return render
