"""Sensor geometry, triangulation (correction 3) and the calibration JSON contract."""

import json

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from cslx.sensor import (
    TABLE4_DIST,
    TABLE4_K,
    CalibrationError,
    cross_projector_planes,
    default_sensor,
    load_sensor,
    plane_angle_deg,
    save_sensor,
    sensor_from_arrays,
    sensor_to_dict,
    triangulate,
)
from cslx.sensor.camera import project


def test_default_rig_is_orthogonal_and_proper():
    s = default_sensor()
    assert plane_angle_deg(s.planes[0], s.planes[1]) == pytest.approx(90.0, abs=1e-9)
    R = np.asarray(s.R_cr)
    np.testing.assert_allclose(R.T @ R, np.eye(3), atol=1e-12)
    assert np.linalg.det(R) == pytest.approx(1.0)


@pytest.mark.parametrize("plane", [0, 1])
def test_triangulate_inverts_projection(plane):
    s = default_sensor()
    n = np.asarray(s.planes[plane])
    rng = np.random.default_rng(0)
    # Random points on the plane, in front of the camera.
    z = rng.uniform(180, 300, 200)
    x = rng.uniform(-60, 60, 200)
    if abs(n[1]) > abs(n[0]):
        y = -(n[0] * x + n[2] * z + 1) / n[1]
        X = np.stack([x, y, z], -1)
    else:
        y = x
        x = -(n[1] * y + n[2] * z + 1) / n[0]
        X = np.stack([x, y, z], -1)
    uv = project(jnp.asarray(X), s.camera)
    got = triangulate(s, uv, plane)
    np.testing.assert_allclose(np.asarray(got), X, atol=1e-7)
    X_r = triangulate(s, uv, plane, robot_frame=True)
    np.testing.assert_allclose(
        np.asarray(X_r), X @ np.asarray(s.R_cr).T + np.asarray(s.T_cr), atol=1e-7
    )


def test_triangulate_jit_vmap_grad():
    s = default_sensor()
    uv = jnp.array([[100.0, 200.0], [320.0, 250.0], [500.0, 260.0]])
    plain = triangulate(s, uv, 0)
    jitted = jax.jit(triangulate, static_argnums=2)(s, uv, 0)
    vm = jax.vmap(lambda p: triangulate(s, p, 0))(uv)
    np.testing.assert_allclose(np.asarray(jitted), np.asarray(plain), atol=1e-10)
    np.testing.assert_allclose(np.asarray(vm), np.asarray(plain), atol=1e-10)
    g = jax.grad(lambda p: triangulate(s, p, 0)[..., 2].sum())(uv)
    assert np.all(np.isfinite(np.asarray(g)))
    nan = triangulate(s, jnp.array([[jnp.nan, 3.0]]), 0)
    assert np.all(np.isnan(np.asarray(nan)))


def test_cross_projector_through_centre_rejected():
    with pytest.raises(CalibrationError, match="camera centre"):
        cross_projector_planes(origin=(0.0, 0.0, 0.0), target=(0.0, 0.0, 200.0))


def test_json_round_trip(tmp_path):
    s = default_sensor()
    path = tmp_path / "sensor.json"
    save_sensor(s, path, rms_px=0.12, note="test")
    data = json.loads(path.read_text())
    for key in ("image_size", "K", "dist", "rms_px", "planes", "R_cr", "T_cr"):
        assert key in data
    assert data["note"] == "test"
    s2 = load_sensor(path)
    np.testing.assert_allclose(np.asarray(s2.planes), np.asarray(s.planes), rtol=1e-15)
    np.testing.assert_allclose(np.asarray(s2.camera.K), np.asarray(s.camera.K))
    assert s2.camera.image_size == (640, 480)
    # Deterministic bytes without the date stamp.
    save_sensor(s, tmp_path / "again.json", rms_px=0.12, note="test")
    assert (tmp_path / "again.json").read_bytes() == path.read_bytes()


def _corrupt(tmp_path, mutate):
    data = sensor_to_dict(default_sensor(), 0.1)
    mutate(data)
    path = tmp_path / "bad.json"
    path.write_text(json.dumps(data))
    return path


@pytest.mark.parametrize(
    "mutate, message",
    [
        (lambda d: d.pop("K"), "missing key 'K'"),
        (lambda d: d.__setitem__("dist", [0.1, 0.2]), "'dist' must have shape"),
        # OpenCV's calibrateCamera writes five coefficients, k3 last
        (lambda d: d.__setitem__("dist", [[-0.29, 0.1, 0.001, 0.0, 0.02]]), "no k3.*FIX_K3"),
        (lambda d: d.__setitem__("dist", [-0.29, 0.1, 0.001, 0.0, 0.0]), "no k3"),
        (lambda d: d.__setitem__("T_cr", [0.0, float("nan"), 1.0]), "non-finite"),
        (lambda d: d.__setitem__("planes", [[0, 0, 0], [0.01, 0, 0.004]]), "zero normal"),
        (lambda d: d.__setitem__("planes", [[5.0, 0, 0], [0.01, 0, 0.004]]), "camera centre"),
        (lambda d: d.__setitem__("R_cr", np.diag([1.0, 1.0, -1.0]).tolist()), "not a proper"),
        (lambda d: d.__setitem__("R_cr", (2 * np.eye(3)).tolist()), "not a proper"),
        (lambda d: d.__setitem__("image_size", [640, -480]), "image_size"),
    ],
)
def test_bad_calibration_files_named(tmp_path, mutate, message):
    with pytest.raises(CalibrationError, match=message):
        load_sensor(_corrupt(tmp_path, mutate))


def test_unreadable_calibration_files(tmp_path):
    with pytest.raises(CalibrationError, match="no such calibration file"):
        load_sensor(tmp_path / "nope.json")
    p = tmp_path / "garbage.json"
    p.write_text("{not json")
    with pytest.raises(CalibrationError, match="not valid JSON"):
        load_sensor(p)


def test_one_plane_sensor_round_trip_and_triangulation(tmp_path):
    """A line laser's calibration: one plane, named by `stripes`; the other stripe refused."""
    from cslx.sensor import sensor_from_arrays

    cross = default_sensor()
    cam = cross.camera
    one = sensor_from_arrays(
        cam.K, cam.dist, cross.planes[1:], cross.R_cr, cross.T_cr, cam.image_size, stripes=["v"]
    )
    assert one.n_planes == 1 and one.plane_stripes == ("v",)
    assert one.has_plane("v") and not one.has_plane(0)
    uv = jnp.array([[400.0, 100.0], [410.0, 300.0]])
    np.testing.assert_allclose(
        np.asarray(triangulate(one, uv, "v")), np.asarray(triangulate(cross, uv, 1)), rtol=1e-12
    )
    jitted = jax.jit(triangulate, static_argnums=2)(one, uv, 1)
    np.testing.assert_allclose(np.asarray(jitted), np.asarray(triangulate(cross, uv, 1)))
    with pytest.raises(CalibrationError, match="no laser plane for the horizontal stripe"):
        triangulate(one, uv, 0)
    with pytest.raises(CalibrationError, match="tracking needs 2 laser planes"):
        one.require_planes(2, "tracking")
    cross.require_planes(2, "tracking")
    path = tmp_path / "line.json"
    save_sensor(one, path, rms_px=0.1)
    data = json.loads(path.read_text())
    assert data["stripes"] == ["v"] and len(data["planes"]) == 1
    assert "plane_angle_deg" not in data
    back = load_sensor(path)
    assert back.plane_stripes == ("v",)
    np.testing.assert_allclose(np.asarray(back.planes), np.asarray(one.planes))
    # Without "stripes", one plane is the horizontal stripe's (horizontal first).
    data.pop("stripes")
    path.write_text(json.dumps(data))
    assert load_sensor(path).plane_stripes == ("h",)


@pytest.mark.parametrize(
    "mutate, message",
    [
        (lambda d: d.__setitem__("planes", []), "one plane .* or two"),
        (lambda d: d.__setitem__("planes", d["planes"] * 2), "got 4"),
        (lambda d: d.__setitem__("stripes", ["v", "v"]), "'stripes' must name"),
        (lambda d: d.__setitem__("stripes", ["h"]), "'stripes' must name"),
        (lambda d: (d.pop("planes"), d.__setitem__("camera_only", True)), "camera-only"),
        (lambda d: d.pop("planes"), "no laser calibration"),
    ],
)
def test_bad_plane_sets_named(tmp_path, mutate, message):
    with pytest.raises(CalibrationError, match=message):
        load_sensor(_corrupt(tmp_path, mutate))


def test_directory_as_calibration_file(tmp_path):
    with pytest.raises(CalibrationError, match="is a directory"):
        load_sensor(tmp_path)


def test_sensor_from_concrete_values_compiles_nothing(caplog):
    """Building a sensor from plain values runs no XLA program (the tracker's start-up, issue 13),
    and a traced build (under jit) gives the same leaves."""
    jax.config.update("jax_log_compiles", True)
    try:
        with caplog.at_level("WARNING"):
            sensor = default_sensor()
    finally:
        jax.config.update("jax_log_compiles", False)
    assert not [r for r in caplog.records if "Compiling" in r.getMessage()]
    K = jnp.asarray(TABLE4_K)

    def build(K):
        s = sensor_from_arrays(K, TABLE4_DIST, sensor.planes, sensor.R_cr, sensor.T_cr, (640, 480))
        return s.camera.fx, s.camera.v0, s.camera.dist, s.planes

    for got, want in zip(jax.jit(build)(K), build(np.asarray(TABLE4_K)), strict=True):
        assert got.dtype == want.dtype
        np.testing.assert_array_equal(np.asarray(got), np.asarray(want))
    v0 = np.asarray(sensor.camera.v0)
    np.testing.assert_array_equal(v0, np.asarray(TABLE4_K, v0.dtype)[1, 2])
