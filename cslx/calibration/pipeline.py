"""The whole sensor calibration in one call: corners → camera → laser planes → robot frame.

`calibrate_sensor` is the one orchestration of the calibration steps (paper section 2.3)
used by `cslx calibrate`, the demo and Table 5:

1. chessboard corners (`corners.detect_corners`); images that cannot be read, have another
   size than the first, or show no board are skipped and listed with the reason;
2. the camera: Zhang's closed form refined by Levenberg–Marquardt (`camera.calibrate_camera`);
3. the laser planes from laser-on images of the same poses (`planes.calibrate_planes`): one
   plane for a line laser, two for the cross, found from the images (or forced by `lines`);
   a plane that fits poorly is refused with the reason, never returned. The laser images
   may be the plain images themselves (the stripe centres are taken inside the board);
4. optionally the camera-to-robot transform by a rigid fit (`robot_frame.fit_rigid`) of
   points known in both frames, or of a board pose whose corners are known in the robot
   frame (the paper's Figure 20); without either, R_cr = I and T_cr = 0 and the report says so.

The result carries the `Sensor` (None for a camera-only calibration), every step's result
and the report that the calibration file keeps as extras (docs/contracts.md).
"""

from __future__ import annotations

import dataclasses
import os
import time
from collections.abc import Callable, Sequence

import numpy as np

from ..images import read_rgb
from ..sensor.rig import CalibrationError, Sensor, sensor_from_arrays
from .camera import CameraCalibration, calibrate_camera
from .corners import board_points, detect_corners
from .planes import PlaneCalibration, PlaneGates, calibrate_planes
from .robot_frame import fit_rigid

__all__ = ["SensorCalibration", "calibrate_sensor", "read_image"]


def read_image(image) -> np.ndarray:
    """A path or an array → (H, W, 3) uint8 RGB (or (H, W) gray kept as is).

    Raises:
        OSError: the path is a directory, missing, truncated or not an image OpenCV can read
            (`cslx.images.read_rgb`; the message starts with the path).
    """
    if isinstance(image, str | os.PathLike):
        path = os.fspath(image)
        try:
            return read_rgb(path)
        except OSError as e:  # FileNotFoundError, IsADirectoryError, OSError: with the path
            raise type(e)(f"{path}: {e}") from None
    img = np.asarray(image)
    if img.dtype != np.uint8 or img.ndim not in (2, 3):
        raise OSError(f"an image must be uint8 (H, W) or (H, W, 3), got {img.dtype} {img.shape}")
    return img


@dataclasses.dataclass(frozen=True)
class SensorCalibration:
    """Result of `calibrate_sensor`.

    Attributes:
        sensor: the calibrated `Sensor` (camera + 1 or 2 planes + R_cr, T_cr), or None for a
            camera-only calibration.
        camera: the camera step (`CameraCalibration`: intrinsics, poses, RMS, std, …); its
            view j is image `used[j]`.
        planes: the plane step (`PlaneCalibration`: planes, fits, rejected lines), or None.
        R_cr, T_cr: camera → robot transform (identity and zero without robot data).
        robot_residuals_mm: residuals of the rigid fit, or None.
        robot_frame: how R_cr, T_cr were obtained, in words.
        image_size: (w, h).
        names: label of every input image.
        used: indices (into the inputs) of the images the calibration used.
        skipped: (name, reason) of every image left out.
        time_s: wall time of the calibration (corners to robot frame).
        pattern, square: the board.
    """

    sensor: Sensor | None
    camera: CameraCalibration
    planes: PlaneCalibration | None
    R_cr: np.ndarray
    T_cr: np.ndarray
    robot_residuals_mm: np.ndarray | None
    robot_frame: str
    image_size: tuple[int, int]
    names: list[str]
    used: list[int]
    skipped: list[tuple[str, str]]
    time_s: float
    pattern: tuple[int, int]
    square: float

    @property
    def rms_px(self) -> float:
        return self.camera.rms

    def report(self) -> dict:
        """The calibration's report: what the calibration file keeps beside the contract keys."""
        cal = self.camera
        used_names = [os.path.basename(self.names[i]) for i in self.used]
        out = dict(
            pattern=list(self.pattern),
            square_mm=self.square,
            images=used_names,
            skipped_images={os.path.basename(n): why for n, why in self.skipped},
            per_image_rms_px=dict(zip(used_names, map(float, cal.per_image_rms), strict=True)),
            std={k: float(v) for k, v in cal.std.items() if k not in ("rvecs", "tvecs")},
            lm_steps=cal.n_iter,
            lm_converged=cal.converged,
            robot_frame=self.robot_frame,
            calibration_time_s=self.time_s,
        )
        if self.planes is not None:
            out.update(self.planes.summary())
            out["stripe_points_per_image"] = {
                n: c.tolist() for n, c in zip(used_names, self.planes.counts, strict=True)
            }
        if self.robot_residuals_mm is not None:
            out["robot_residuals_mm"] = np.asarray(self.robot_residuals_mm).tolist()
        return out

    def to_dict(self, *, stamp: bool = False, **extra) -> dict:
        """The calibration JSON object (docs/contracts.md); camera-only without `planes`."""
        from ..sensor.calibration_file import sensor_to_dict

        rep = {**self.report(), **extra}
        if self.sensor is not None:
            return sensor_to_dict(self.sensor, self.camera.rms, stamp=stamp, **rep)
        cam = self.camera.camera
        out = dict(
            image_size=list(self.image_size),
            K=np.asarray(cam.K, float).tolist(),
            dist=np.asarray(cam.dist, float).tolist(),
            rms_px=self.camera.rms,
            camera_only=True,
        )
        if stamp:
            import datetime as _dt

            out["date"] = _dt.datetime.now(_dt.UTC).isoformat(timespec="seconds")
        out.update(rep)
        return out

    def save(self, path: str | os.PathLike, *, stamp: bool = True, **extra) -> None:
        """Write the calibration JSON atomically (the previous file stays intact on failure)."""
        from ..sensor.calibration_file import write_json_atomic

        write_json_atomic(path, self.to_dict(stamp=stamp, **extra))


def calibrate_sensor(
    images: Sequence,
    pattern: tuple[int, int],
    square: float,
    *,
    laser_images: Sequence | None = None,
    lines: int | None = None,
    method: str = "auto",
    gates: PlaneGates | None = None,
    robot_points: tuple[np.ndarray, np.ndarray] | None = None,
    robot_board: tuple[int, np.ndarray] | None = None,
    names: Sequence[str] | None = None,
    min_views: int = 3,
    dtype=None,
    seed: int = 0,
    log: Callable[[str], None] | None = None,
) -> SensorCalibration:
    """Calibrate camera, laser planes and robot frame from chessboard images (section 2.3).

    Args:
        images: plain chessboard images (paths or uint8 arrays), one per board pose.
        pattern: inner corners (cols, rows); square: the squares' side, mm.
        laser_images: laser-on images of the same poses, paired by index; may be `images`
            itself (one image per pose with the laser on: the corners are found around the
            line and the line's centres are taken inside the board). None: camera only.
        lines: number of laser lines (None: detect from the images; 1: a line laser; 2: the
            cross, both required).
        method: stripe-centre extractor of the plane step ("auto" = Steger, "simple", …).
        gates: when a plane is refused (`PlaneGates()`).
        robot_points: (P_c, P_r), (N, 3) points known in the camera and the robot frame.
        robot_board: (i, P_r): the board in input image i has its corners (`board_points`
            order) at P_r (N, 3) in the robot frame; its calibrated pose gives P_c.
        names: labels of the images for messages (default: the paths or "image i").
        min_views: fewest usable board views.
        dtype: float dtype of the returned `Sensor` (default: JAX's default float).
        seed: seed of the robust plane fits.
        log: called with one line per step and per skipped image (e.g. a progress printer).

    Raises:
        CalibrationError: too few usable views, no laser line (or fewer than `lines`), a plane
            that fits poorly, degenerate robot points; the message says what and why.
    """
    say = log or (lambda msg: None)
    t0 = time.perf_counter()
    n = len(images)
    if names is None:
        names = [
            os.fspath(im) if isinstance(im, str | os.PathLike) else f"image {i}"
            for i, im in enumerate(images)
        ]
    names = list(names)
    same = laser_images is not None and (
        laser_images is images
        or (
            len(laser_images) == n
            and all(
                isinstance(a, str | os.PathLike)
                and isinstance(b, str | os.PathLike)
                and os.path.abspath(a) == os.path.abspath(b)
                for a, b in zip(images, laser_images, strict=True)
            )
        )
    )
    if laser_images is not None and len(laser_images) != n:
        raise CalibrationError(
            f"{len(laser_images)} laser images for {n} plain images: they are paired by "
            "index (sorted file names) and must be equally many"
        )
    skipped: list[tuple[str, str]] = []
    corners, used, size = [], [], None
    for i, image in enumerate(images):
        try:
            img = read_image(image)
        except OSError as e:
            skipped.append((names[i], f"unreadable ({e})"))
            say(f"{names[i]}: unreadable ({e}); skipped")
            continue
        h, w = img.shape[:2]
        if size is None:
            size = (w, h)
        elif (w, h) != size:
            why = f"{w}×{h}, not {size[0]}×{size[1]} like the first image"
            skipped.append((names[i], why))
            say(f"{names[i]}: {why}; skipped")
            continue
        if laser_images is not None and not same:
            try:
                lz = read_image(laser_images[i])
                if lz.shape[:2] != (h, w):
                    raise OSError(f"{lz.shape[1]}×{lz.shape[0]}, not {w}×{h}")
            except OSError as e:
                skipped.append((names[i], f"its laser image is unusable ({e})"))
                say(f"{names[i]}: its laser image is unusable ({e}); skipped")
                continue
        (c,), _ = detect_corners([img], pattern)
        if c is None:
            why = f"no {pattern[0]}x{pattern[1]} board found"
            skipped.append((names[i], why))
            say(f"{names[i]}: {why}; skipped")
            continue
        corners.append(c)
        used.append(i)
    if len(used) < min_views:
        hint = ""
        if not used and any(b.startswith("no ") and "board found" in b for _, b in skipped):
            # no board in any readable image: most often the pattern, not the photos
            hint = (
                f"; is the pattern {pattern[0]}x{pattern[1]} right? It counts the board's "
                "inner corners, columns x rows (a board of 10 × 7 squares has 9x6)"
            )
        raise CalibrationError(
            f"the board was found in {len(used)} of {n} images; at least {min_views} are "
            f"needed ({len(skipped)} skipped: "
            + "; ".join(f"{os.path.basename(a)}: {b}" for a, b in skipped[:5])
            + (" …" if len(skipped) > 5 else "")
            + ")"
            + hint
        )
    obj = board_points(pattern, square)
    say(f"camera: {len(used)} views ({len(skipped)} skipped) ...")
    cal = calibrate_camera(corners, obj, size)
    say(f"camera: RMS {cal.rms:.4f} px, {cal.n_iter} LM steps")
    pc = None
    if laser_images is not None:
        say(f"laser planes from {len(used)} laser images ...")
        pc = calibrate_planes(
            cal, [laser_images[i] for i in used], pattern, square, method=method, lines=lines,
            gates=gates, seed=seed,
        )  # fmt: skip
        for s, f in zip(pc.stripes, pc.fits, strict=True):
            say(
                f"plane {s}: RMS {f.rms:.4f} mm, {int(f.inliers.sum())} of {len(f.inliers)} "
                "points inliers"
            )
        for s, why in pc.rejected.items():
            say(f"no plane for the {s} stripe: {why}")
    R_cr, T_cr, res, how = np.eye(3), np.zeros(3), None, "identity (no robot points given)"
    if robot_points is not None and robot_board is not None:
        raise ValueError("give robot_points or robot_board, not both")
    if robot_points is not None:
        P_c, P_r = (np.asarray(a, np.float64) for a in robot_points)
        R_cr, T_cr, res = fit_rigid(P_c, P_r)
        how = f"rigid fit of {len(P_c)} points known in both frames"
    elif robot_board is not None:
        i, P_r = robot_board
        if i not in used:
            raise CalibrationError(
                f"the robot-frame board is image {i} ({names[i]}), which was skipped"
            )
        j = used.index(i)
        P_c = obj @ cal.rotations[j].T + cal.tvecs[j]
        R_cr, T_cr, res = fit_rigid(P_c, np.asarray(P_r, np.float64))
        how = f"rigid fit of the {len(obj)} corners of the board in {os.path.basename(names[i])}"
    if res is not None:
        say(f"robot frame: RMS residual {float(np.sqrt(np.mean(res**2))):.4f} mm")
    sensor = None
    if pc is not None:
        sensor = sensor_from_arrays(
            np.asarray(cal.camera.K), np.asarray(cal.camera.dist), pc.planes, R_cr, T_cr, size,
            dtype=dtype, stripes=pc.stripes,
        )  # fmt: skip
    return SensorCalibration(
        sensor=sensor,
        camera=cal,
        planes=pc,
        R_cr=np.asarray(R_cr),
        T_cr=np.asarray(T_cr),
        robot_residuals_mm=None if res is None else np.asarray(res),
        robot_frame=how,
        image_size=size,
        names=names,
        used=used,
        skipped=skipped,
        time_s=time.perf_counter() - t0,
        pattern=(int(pattern[0]), int(pattern[1])),
        square=float(square),
    )
