"""`process_batch`: the warm batch (MED started from the previous frame) agrees with cold frames."""

import jax.numpy as jnp
import numpy as np
import pytest

from cslx.runtime.batch import process_batch
from cslx.runtime.pipeline import PipelineConfig
from cslx.sensor import default_sensor


@pytest.fixture(scope="module")
def batches(render_scenes):
    sensor = default_sensor(jnp.float32)
    images = [img for img, _ in render_scenes(sensor, ("cross", "straight"), 37)]
    # The first frame twice (a warm start on the same image), then an unrelated scene.
    frames = np.stack([images[0], images[0], images[1]])
    config = PipelineConfig(L_v=240)  # as tests/runtime/test_pipeline.py: cheaper in tests
    warm, _ = process_batch(sensor, config, frames, warm=True, vmap_size=1)
    cold, _ = process_batch(sensor, config, frames, warm=False, vmap_size=1)
    return warm, cold


def test_warm_batch_carries_the_filters(batches):
    warm, cold = batches
    steps_w, steps_c = np.asarray(warm.med_steps), np.asarray(cold.med_steps)
    np.testing.assert_array_equal(steps_w[0], steps_c[0])  # the first frame starts cold
    assert np.all(steps_w[1] < steps_c[1])  # the same image again: already converged


def test_warm_batch_agrees_with_cold_frames(batches):
    warm, cold = batches
    for name in ("centres_h", "centres_v"):
        cw, cc = getattr(warm, name), getattr(cold, name)
        vw, vc = np.asarray(cw.valid), np.asarray(cc.valid)
        assert np.mean(vw == vc) >= 0.99
        d = np.abs(np.asarray(cw.pos) - np.asarray(cc.pos))[vw & vc]
        assert np.median(d) < 0.01
        assert np.mean(d < 0.1) >= 0.99
    for name in ("feature_h", "feature_v"):
        fw, fc = getattr(warm, name), getattr(cold, name)
        np.testing.assert_array_equal(np.asarray(fw.found), np.asarray(fc.found))
        found = np.asarray(fc.found)
        np.testing.assert_allclose(
            np.asarray(fw.position)[found], np.asarray(fc.position)[found], atol=0.5
        )
    np.testing.assert_array_equal(np.asarray(warm.junction), np.asarray(cold.junction))
