"""`process_batch`: the warm batch (MED started from the previous frame) agrees with cold frames."""

import jax.numpy as jnp
import numpy as np
import pytest

from cslx.runtime.batch import process_batch
from cslx.runtime.pipeline import PipelineConfig, init_state, process_frame
from cslx.sensor import default_sensor


@pytest.fixture(scope="module")
def batches(render_scenes):
    """The warm batch and, per frame, the cold reference.

    The warm batch sees the first frame twice (a warm start on the same image), then an
    unrelated scene. Its first frame starts cold by construction; the cold references are
    `process_frame` on the full frame from the start state (the program
    tests/runtime/test_pipeline.py compiles too, so the persistent compile cache shares it),
    rather than a second batch program (`warm=False`, compiled in test_pipeline.py).
    """
    sensor = default_sensor(jnp.float32)
    images = [img for img, _ in render_scenes(sensor, ("cross", "straight"), 37)]
    frames = np.stack([images[0], images[0], images[1]])
    config = PipelineConfig(L_v=240)  # as tests/runtime/test_pipeline.py: cheaper in tests
    warm, _ = process_batch(sensor, config, frames, warm=True, vmap_size=1)
    state0 = init_state(config, sensor.camera.image_size)
    cold = [process_frame(sensor, config, img, state0, roi=False)[0] for img in frames]
    return warm, cold


def test_warm_batch_carries_the_filters(batches):
    warm, cold = batches
    steps_w = np.asarray(warm.med_steps)
    steps_c = np.stack([np.asarray(c.med_steps) for c in cold])
    np.testing.assert_array_equal(steps_w[0], steps_c[0])  # the first frame starts cold
    assert np.all(steps_w[1] < steps_c[1])  # the same image again: already converged


def test_warm_batch_agrees_with_cold_frames(batches):
    warm, cold = batches
    for k, c in enumerate(cold):
        for name in ("centres_h", "centres_v"):
            cw, cc = getattr(warm, name), getattr(c, name)
            vw, vc = np.asarray(cw.valid[k]), np.asarray(cc.valid)
            assert np.mean(vw == vc) >= 0.99
            d = np.abs(np.asarray(cw.pos[k]) - np.asarray(cc.pos))[vw & vc]
            assert np.median(d) < 0.01
            assert np.mean(d < 0.1) >= 0.99
        for name in ("feature_h", "feature_v"):
            fw, fc = getattr(warm, name), getattr(c, name)
            found = bool(fc.found)
            assert bool(fw.found[k]) == found
            if found:
                assert abs(float(fw.position[k]) - float(fc.position)) < 0.5
        assert bool(warm.junction[k]) == bool(c.junction)
