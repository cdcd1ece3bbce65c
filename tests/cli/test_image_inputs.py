"""Image files as a user's camera writes them, through the real commands.

Grayscale (a monochrome camera, 8 or 16 bit), RGBA, 16-bit RGB and EXIF-rotated JPEG files
give the same centres as the plain RGB PNG; a truncated PNG or JPEG is skipped with one line
that says so (OpenCV would decode half a JPEG and only warn); a folder of JPEG frames is a
`cslx track` source; a board pattern that matches no image says to check the pattern. The
extractions use the centre-of-mass baseline (no compile), so these tests are fast.
"""

import csv
import pathlib
import shutil

import cv2
import numpy as np
import pytest
from PIL import Image

from cslx.cli import main
from cslx.images import read_rgb

ROW, COL = 50, 70
DATA = pathlib.Path(__file__).resolve().parents[1] / "data" / "opencv-samples"


def cross_rgb(shape=(120, 160)):
    """A dark plate with a red laser cross (Gaussian profiles, 2 px), uint8 RGB."""
    h, w = shape
    yy, xx = np.mgrid[0:h, 0:w]
    red = 230 * np.maximum(
        np.exp(-0.5 * ((yy - ROW) / 2.0) ** 2), np.exp(-0.5 * ((xx - COL) / 2.0) ** 2)
    )
    rgb = np.full((h, w, 3), 20, np.uint8)
    rgb[..., 0] = np.clip(20 + red, 0, 255).astype(np.uint8)
    return rgb


def centres(path, stripe):
    """{column (h) or row (v): centre} of one stripe in a centre CSV."""
    rows = [r for r in csv.DictReader(open(path)) if r["stripe"] == stripe]
    key, val = ("u", "v") if stripe == "h" else ("v", "u")
    return {round(float(r[key])): float(r[val]) for r in rows}


def extract(paths, out, *extra):
    return main(["extract", *map(str, paths), "--method", "cm", "--out", str(out), *extra])


def test_read_rgb_gray_alpha_16_bit_and_exif(tmp_path):
    rgb = cross_rgb()
    red = rgb[..., 0]
    Image.fromarray(red).save(tmp_path / "gray.png")
    assert cv2.imwrite(str(tmp_path / "gray16.png"), red.astype(np.uint16) * 257)
    assert cv2.imwrite(str(tmp_path / "rgb16.png"), rgb[..., ::-1].astype(np.uint16) * 257)
    rgba = np.dstack([rgb, np.full(red.shape, 0, np.uint8)])  # fully transparent
    Image.fromarray(rgba, "RGBA").save(tmp_path / "rgba.png")
    for name in ("gray.png", "gray16.png"):
        img = read_rgb(tmp_path / name)
        assert img.shape == (*red.shape, 3) and img.dtype == np.uint8
        assert np.array_equal(img, np.repeat(red[..., None], 3, axis=2)), name
    for name in ("rgb16.png", "rgba.png"):
        assert np.array_equal(read_rgb(tmp_path / name), rgb), name
    # stored turned a quarter left, with EXIF orientation 6 ("turn right to view")
    exif = Image.Exif()
    exif[0x0112] = 6
    Image.fromarray(np.rot90(rgb)).save(tmp_path / "exif.jpg", quality=95, exif=exif)
    viewed = read_rgb(tmp_path / "exif.jpg")
    assert viewed.shape == rgb.shape
    assert np.abs(viewed.astype(int) - rgb).mean() < 3


@pytest.mark.parametrize("kind", ["png", "jpg"])
def test_truncated_file_is_skipped_with_one_line(tmp_path, capfd, kind):
    rgb = cross_rgb()
    good = tmp_path / "good.png"
    Image.fromarray(rgb).save(good)
    whole = tmp_path / f"whole.{kind}"
    Image.fromarray(rgb).save(whole, quality=90) if kind == "jpg" else Image.fromarray(rgb).save(
        whole
    )
    cut = tmp_path / f"cut.{kind}"
    data = whole.read_bytes()
    cut.write_bytes(data[: len(data) * 2 // 3])
    with pytest.raises(OSError, match="truncated"):
        read_rgb(cut)
    out = tmp_path / "c.csv"
    assert extract([good, cut], out) == 1
    err = capfd.readouterr().err
    assert f"{cut}: truncated {kind.replace('jpg', 'jpeg').upper()} file" in err
    # one line for the file, nothing from the decoder ("Premature end of JPEG file", libpng)
    assert err.count(str(cut)) == 1 and "Premature" not in err and "libpng" not in err
    assert {r["image"] for r in csv.DictReader(open(out))} == {str(good)}
    # the whole file is fine
    assert extract([whole], tmp_path / "w.csv") == 0


@pytest.mark.parametrize("depth", [8, 16])
def test_grayscale_image_with_fixed_colour_weights(tmp_path, capsys, depth):
    """A monochrome camera's frame: R − G (the paper's methods' default) would be zero."""
    red = cross_rgb()[..., 0]
    path = tmp_path / "mono.png"
    if depth == 8:
        Image.fromarray(red).save(path)
    else:
        assert cv2.imwrite(str(path), red.astype(np.uint16) * 257)
    out = tmp_path / "c.csv"
    assert extract([path], out) == 0
    err = capsys.readouterr().err
    assert "1 of 1 images are grayscale" in err and "Traceback" not in err
    h, v = centres(out, "h"), centres(out, "v")
    assert len(h) >= 150 and len(v) >= 110
    assert abs(np.median(list(h.values())) - ROW) < 0.2
    assert abs(np.median(list(v.values())) - COL) < 0.2
    # an explicit colour space too
    assert extract([path], out, "--space", "2r-g-b", "--stripe", "h") == 0
    assert abs(np.median(list(centres(out, "h").values())) - ROW) < 0.2


def test_rgba_16_bit_and_exif_jpeg_give_the_plain_centres(tmp_path):
    rgb = cross_rgb()
    plain = tmp_path / "plain.png"
    Image.fromarray(rgb).save(plain)
    rgba = tmp_path / "rgba.png"
    Image.fromarray(np.dstack([rgb, np.full(rgb.shape[:2], 255, np.uint8)]), "RGBA").save(rgba)
    rgb16 = tmp_path / "rgb16.png"
    assert cv2.imwrite(str(rgb16), rgb[..., ::-1].astype(np.uint16) * 257)
    exif = Image.Exif()
    exif[0x0112] = 6
    jpg = tmp_path / "exif.jpg"
    Image.fromarray(np.rot90(rgb)).save(jpg, quality=95, exif=exif)
    ref = tmp_path / "ref.csv"
    assert extract([plain], ref) == 0
    for path, tol in ((rgba, 1e-4), (rgb16, 1e-4), (jpg, 0.1)):
        out = tmp_path / f"{path.stem}.csv"
        assert extract([path], out) == 0, path
        for s in "hv":
            a, b = centres(ref, s), centres(out, s)
            common = sorted(set(a) & set(b))
            assert len(common) >= 0.95 * len(a), (path, s)
            assert np.median([abs(a[k] - b[k]) for k in common]) <= tol, (path, s)


def test_track_takes_a_folder_of_jpeg_frames(tmp_path):
    from cslx.cli.track import _Source

    for i in range(3):
        Image.fromarray(cross_rgb()).save(tmp_path / f"f{i}.jpg", quality=90)
    (tmp_path / "notes.txt").write_text("not a frame")
    frames = list(_Source(str(tmp_path), fps=10.0))
    assert [name for name, _, _ in frames] == ["f0.jpg", "f1.jpg", "f2.jpg"]
    assert all(rgb.shape == (120, 160, 3) for _, rgb, _ in frames)


def test_calibrate_says_to_check_the_pattern_when_no_image_shows_it(tmp_path, capsys):
    for name in ("left01.jpg", "left02.jpg", "left03.jpg"):
        shutil.copy(DATA / name, tmp_path / name)
    cut = (DATA / "left04.jpg").read_bytes()
    (tmp_path / "left04.jpg").write_bytes(cut[: len(cut) // 2])
    out = tmp_path / "cam.json"
    argv = ["calibrate", "--images", str(tmp_path), "--camera-only", "--out", str(out)]
    assert main(argv) == 2  # the photos show a 9x6 board, not the default 10x7
    err = capsys.readouterr().err
    assert "left04.jpg: unreadable" in err and "truncated JPEG" in err
    last = err.strip().splitlines()[-1]
    assert "found in 0 of 4 images" in last and "is the pattern 10x7 right?" in last
    assert not out.exists()


def test_extract_folders_and_patterns_say_what_to_give(tmp_path, capsys):
    empty = tmp_path / "empty"
    empty.mkdir()
    photos = tmp_path / "photos"
    photos.mkdir()
    for name in ("a.jpg", "b.JPG"):
        Image.fromarray(cross_rgb()).save(photos / name, format="JPEG")
    (photos / "notes.txt").write_text("x")
    out = tmp_path / "c.csv"
    cases = [
        ([empty], f"{empty}: is a directory with no images in it"),
        ([photos], f"{photos}: is a directory; give the image files in it (e.g. {photos}/*.JPG"),
        ([f"{empty}/*"], f"{empty}/*: no file matches this pattern"),  # the shell left it
        ([f"{photos}/*.jpg"], "a pattern matching 1 file: write it without quotes"),
    ]
    for paths, needle in cases:
        assert extract(paths, out) == 2, paths
        err = capsys.readouterr().err.strip().splitlines()
        assert len(err) == 1 and needle in err[0], (paths, err)
    assert not out.exists()
