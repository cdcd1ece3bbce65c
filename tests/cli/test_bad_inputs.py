"""Every bad-input class of the command line, with real files: one line naming the input
and what to do, exit 2 for usage errors (1 when images fail), no traceback, and no partial
or header-only file at the output path (a previous file stays intact).

The usage errors are found before JAX compiles anything, so these tests are fast; the ones
that run a segmentation use the centre-of-mass baseline (no compile).
"""

import csv
import json
import os
import subprocess
import sys

import cv2
import numpy as np
import pytest

from cslx.cli import main

ROOT = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))


def cross_png(path, shape=(120, 160), row=50, col=70):
    """A real PNG of a dark plate with a red laser cross (Gaussian profiles, 2 px)."""
    h, w = shape
    yy, xx = np.mgrid[0:h, 0:w]
    red = 230 * np.maximum(
        np.exp(-0.5 * ((yy - row) / 2.0) ** 2), np.exp(-0.5 * ((xx - col) / 2.0) ** 2)
    )
    rgb = np.zeros((h, w, 3), np.uint8)
    rgb[..., 0] = np.clip(20 + red, 0, 255).astype(np.uint8)
    rgb[..., 1] = 20
    rgb[..., 2] = 20
    assert cv2.imwrite(str(path), rgb[..., ::-1])
    return str(path)


def one_error_line(capsys, *needles):
    """The command wrote exactly one line to stderr, naming every needle; nothing else."""
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1, err
    assert "Traceback" not in err[0]
    for n in needles:
        assert n in err[0], (n, err[0])
    return err[0]


@pytest.fixture
def img(tmp_path):
    return cross_png(tmp_path / "cross.png")


# ----------------------------------------------------------------------------- extract
@pytest.mark.parametrize("sigma", ["-1", "0", "nan", "inf"])
def test_extract_refuses_bad_sigma_up_front(tmp_path, img, capsys, sigma):
    out = tmp_path / "c.csv"
    assert main(["extract", img, "--sigma", sigma, "--out", str(out)]) == 2
    one_error_line(capsys, "--sigma", "positive")
    assert not out.exists()


def test_extract_directory_as_image_says_is_a_directory(tmp_path, img, capsys):
    out = tmp_path / "c.csv"
    assert main(["extract", img, str(tmp_path), "--out", str(out)]) == 2
    one_error_line(capsys, str(tmp_path), "is a directory", "*.png")
    assert not out.exists()


def test_extract_missing_image(tmp_path, img, capsys):
    out = tmp_path / "c.csv"
    missing = str(tmp_path / "nope.png")
    assert main(["extract", img, missing, "--out", str(out)]) == 2
    one_error_line(capsys, missing, "no such file")
    assert not out.exists()


@pytest.mark.parametrize("where", ["missing_folder", "directory", "read_only_folder"])
def test_extract_unwritable_out(tmp_path, img, capsys, where, monkeypatch):
    if where == "missing_folder":
        out, needle = tmp_path / "no" / "c.csv", "does not exist"
    elif where == "directory":
        out, needle = tmp_path, "is a directory"
    else:
        ro = tmp_path / "ro"
        ro.mkdir()
        ro.chmod(0o500)
        if os.geteuid() == 0:
            # root ignores permission bits, so os.access reports the folder writable; give
            # the access check the answer an ordinary user gets for a 0o500 folder
            real_access = os.access

            def access(path, mode, *a, **k):
                if os.path.realpath(path) == os.path.realpath(ro) and mode & os.W_OK:
                    return False
                return real_access(path, mode, *a, **k)

            monkeypatch.setattr("cslx.files.os.access", access)
        out, needle = ro / "c.csv", "not writable"
    assert main(["extract", img, "--out", str(out)]) == 2
    one_error_line(capsys, "--out", needle)


def test_extract_bad_space_and_bad_calibration(tmp_path, img, capsys):
    out = tmp_path / "c.csv"
    assert main(["extract", img, "--space", "purple", "--out", str(out)]) == 2
    one_error_line(capsys, "purple")
    calib = tmp_path / "calib.json"
    calib.write_text("{not json")
    assert main(["extract", img, "--calib", str(calib), "--out", str(out)]) == 2
    one_error_line(capsys, str(calib))
    assert not out.exists()


def test_extract_every_image_failing_writes_no_file_and_keeps_the_old_one(tmp_path, capsys):
    bad = [tmp_path / "a.png", tmp_path / "b.png"]
    for p in bad:
        p.write_bytes(b"not a png at all")
    out = tmp_path / "c.csv"
    out.write_text("previous,result\n")
    assert main(["extract", *map(str, bad), "--method", "cm", "--out", str(out)]) == 1
    err = capsys.readouterr().err
    assert "not a readable image" in err and "not written" in err and "Traceback" not in err
    assert out.read_text() == "previous,result\n"
    assert [p.name for p in tmp_path.iterdir() if p.name.startswith(".")] == []  # no temp left


def test_extract_some_images_failing_keeps_the_others_and_exits_1(tmp_path, img, capsys):
    bad = tmp_path / "bad.png"
    bad.write_bytes(b"\x89PNG truncated")
    out = tmp_path / "c.csv"
    assert main(["extract", img, str(bad), "--method", "cm", "--out", str(out)]) == 1
    err = capsys.readouterr().err
    assert f"{bad}: not a readable image; skipped" in err
    assert "1 of 2 images failed" in err
    rows = list(csv.DictReader(out.open()))
    assert {r["image"] for r in rows} == {img}
    assert {r["stripe"] for r in rows} == {"h", "v"}
    h = [r for r in rows if r["stripe"] == "h"]
    assert abs(np.median([float(r["v"]) for r in h]) - 50) < 0.5  # the stripe's true row


def test_extract_prints_a_summary_with_the_weights(tmp_path, img, capsys):
    out = tmp_path / "c.csv"
    assert main(["extract", img, "--method", "cm", "--stripe", "h", "--out", str(out)]) == 0
    line = one_error_line(capsys, "1 of 1 images", str(out), "centres per image", "r-g")
    with out.open() as f:
        assert f.readline().strip() == "image,stripe,u,v"
    rows = list(csv.DictReader(out.open()))
    assert 150 <= len(rows) <= 160  # at most one centre per column of the 160-column image
    assert f"(median) h {len(rows)};" in line


def test_extract_rows_match_the_csv_module_byte_for_byte():
    """The vectorised row formatting equals csv.writer with f"{x:.4f}" fields."""
    import io

    from cslx.cli.extract import format_rows

    rng = np.random.default_rng(0)
    uv = rng.uniform(-5, 700, (50, 2))
    uv[3] = [-0.00001, 1e-9]  # rounds to -0.0000 / 0.0000
    xyz = rng.normal(0, 300, (50, 3))
    for path in ["frames/a.png", 'odd, "name".png', "100%.png"]:
        for extra in (None, xyz):
            buf = io.StringIO()
            w = csv.writer(buf)
            for i in range(len(uv)):
                vals = list(uv[i]) + ([] if extra is None else list(extra[i]))
                w.writerow([path, "v", *(f"{x:.4f}" for x in vals)])
            assert format_rows(path, "v", uv, extra) == buf.getvalue()
    assert format_rows("a.png", "h", np.zeros((0, 2))) == ""


# ----------------------------------------------------------------------------- render, demo
@pytest.mark.parametrize(
    ("argv", "needles"),
    [
        (["--frames", "0"], ["--frames 0", "at least 1"]),
        (["--power", "-3"], ["--power", "positive"]),
        (["--power", "nan"], ["--power", "positive"]),
    ],
)
def test_render_refuses_bad_numbers(tmp_path, capsys, argv, needles):
    out = tmp_path / "data"
    assert main(["render", "--out", str(out), *argv]) == 2
    one_error_line(capsys, *needles)
    assert not out.exists()


def test_render_refuses_a_file_as_out_and_a_missing_calibration(tmp_path, capsys):
    f = tmp_path / "file.txt"
    f.write_text("x")
    assert main(["render", "--out", str(f)]) == 2
    one_error_line(capsys, str(f), "not a directory")
    missing = tmp_path / "sensor.json"
    assert main(["render", "--out", str(tmp_path / "d"), "--calib", str(missing)]) == 2
    one_error_line(capsys, str(missing))


@pytest.mark.parametrize(
    ("argv", "needles"),
    [
        (["--poses", "2"], ["--poses 2", "at least 3"]),
        (["--frames", "0"], ["--frames 0"]),
        (["--loop-frames", "-1"], ["--loop-frames -1"]),
    ],
)
def test_demo_refuses_bad_numbers(tmp_path, capsys, argv, needles):
    assert main(["demo", "--out", str(tmp_path / "demo"), *argv]) == 2
    one_error_line(capsys, *needles)
    assert not (tmp_path / "demo").exists()


def test_demo_refuses_a_file_as_out(tmp_path, capsys):
    f = tmp_path / "report.md"
    f.write_text("old report")
    assert main(["demo", "--out", str(f)]) == 2
    one_error_line(capsys, str(f), "not a directory")
    assert f.read_text() == "old report"


def test_usage_errors_exit_2(capsys):
    with pytest.raises(SystemExit) as e:
        main(["extract", "--method", "nope", "x.png", "--out", "c.csv"])
    assert e.value.code == 2
    assert "Traceback" not in capsys.readouterr().err


# ----------------------------------------------------------------------------- a real process
def test_real_command_is_quiet_on_cpu(tmp_path):
    """`python -m cslx extract` in a fresh process: no backend-probe warning (no TPU line),
    no traceback, only the one summary line on stderr."""
    img = cross_png(tmp_path / "cross.png")
    out = tmp_path / "c.csv"
    env = {k: v for k, v in os.environ.items() if k not in ("JAX_PLATFORMS", "JAX_PLATFORM_NAME")}
    proc = subprocess.run(
        [sys.executable, "-m", "cslx", "extract", img, "--method", "cm", "--out", str(out)],
        cwd=ROOT,
        env=env,
        capture_output=True,
        text=True,
        timeout=300,
    )
    assert proc.returncode == 0, proc.stderr
    lines = proc.stderr.strip().splitlines()
    assert not any("tpu" in ln.lower() or "backend" in ln.lower() for ln in lines), lines
    assert len(lines) == 1 and lines[0].startswith("cslx extract: 1 of 1 images"), lines
    assert out.exists()


def test_calibration_json_written_atomically_keeps_the_old_file(tmp_path):
    """save_sensor (calibration JSON) either writes the whole file or leaves the old one."""
    from cslx.sensor import default_sensor, load_sensor, save_sensor

    path = tmp_path / "sensor.json"
    save_sensor(default_sensor(), path)
    before = path.read_bytes()
    with pytest.raises(TypeError):
        save_sensor(default_sensor(), path, note=object())  # not JSON-serialisable, mid-dump
    assert path.read_bytes() == before
    assert json.loads(before)["image_size"] == list(load_sensor(path).camera.image_size)
    assert sorted(p.name for p in tmp_path.iterdir()) == ["sensor.json"]


def test_python_dash_m_cslx_runs_the_command():
    """`python -m cslx` is the installed `cslx` script (same parser, same exit codes)."""
    import subprocess
    import sys

    ok = subprocess.run([sys.executable, "-m", "cslx", "--help"], capture_output=True, text=True)
    assert ok.returncode == 0 and "usage: cslx" in ok.stdout
    bad = subprocess.run(
        [sys.executable, "-m", "cslx", "demo", "--poses", "1"], capture_output=True, text=True
    )
    assert bad.returncode == 2 and "--poses 1" in bad.stderr
