"""Focus pulls (``--focus A:B --frames N``): the distances, the errors, the frames
folder, and the sharp plane moving on a depth-graded scene (scenes/cards.pov)."""

import json
import math
import os
import subprocess

import numpy as np
import pytest

from conftest import ROOT

import povlens
from povlens.cli import main
from povlens.errors import ParameterError
from povlens.plan.focus_series import FocusPull, focus_series, parse_focus
from povlens.plan.schema import read_plan
from povlens.util.images import read_image

CARDS = str(ROOT / "scenes" / "cards.pov")
#: scenes/cards.pov: card k at Z[k] m, its centre at (k - 2) * 0.36 of the half width of
#: a 31 degree view, half the card 0.13 of it.
Z = (0.8, 1.3, 2.1, 3.4, 5.5)
SMALL = ["--width", "160", "--height", "120"]


# ----- distances --------------------------------------------------------------------------

def test_a_pull_is_even_in_dioptres_with_exact_ends():
    d = focus_series(FocusPull(start=0.8, end=5.5), 5)
    assert d[0] == 0.8 and d[-1] == 5.5
    steps = np.diff(1.0 / np.array(d))
    assert np.allclose(steps, steps[0]) and steps[0] < 0
    assert focus_series((5.5, 0.8), 3)[1] == pytest.approx(1 / ((1 / 5.5 + 1 / 0.8) / 2))


def test_parse_focus_forms():
    assert parse_focus("4") == 4.0
    assert parse_focus("1:3") == FocusPull(start=1.0, end=3.0)
    assert parse_focus("2,3,5") == FocusPull(values=(2.0, 3.0, 5.0))
    assert focus_series(parse_focus("2,3,5"), None) == [2.0, 3.0, 5.0]
    assert focus_series(4.0, None) is None
    with pytest.raises(ParameterError) as e:
        focus_series([1.0, 2.0], 3)
    assert e.value.parameter == "frames"


# ----- errors through the command line -------------------------------------------------------

@pytest.mark.parametrize("args, words", [
    (["--focus", "1:3", "--frames", "0"], ["--frames 0", ">= 1"]),
    (["--focus", "0:3", "--frames", "3"], ["--focus 0:3", "positive"]),
    (["--focus", "1:-2", "--frames", "3"], ["'-2'", "positive"]),
    (["--focus", "1:inf", "--frames", "3"], ["positive and finite", "1e6", "a still takes inf"]),
    (["--focus", "2,x,5"], ["'x' is not a number"]),
    (["--focus", "1:2:3", "--frames", "3"], ["A:B"]),
    (["--focus", "1:3,4", "--frames", "3"], ["not both"]),
    (["--focus", "4", "--frames", "3"], ["--frames 3 needs a focus pull"]),
    (["--focus", "1:3"], ["--frames N", ">= 2"]),
    (["--focus", "1:3", "--frames", "1"], ["--frames N", ">= 2"]),
    (["--focus", "2,3,5", "--frames", "2"], ["--frames 2", "3 distances"]),
    (["--focus-at", "3,3", "--frames", "3"], ["--focus-at focuses one frame"]),
])
@pytest.mark.parametrize("command", ["render", "convert"])
def test_bad_pulls_are_one_clear_error(command, args, words, tmp_path, capsys):
    out = tmp_path / "out"
    code = main([command, CARDS, "--lens", "dgauss.50mm", *args, "-o", str(out)])
    err = capsys.readouterr().err
    assert code == 2, err
    first = err.strip().splitlines()[0]
    assert first.startswith(f"povlens {command}: error: ")
    for w in words:
        assert w in err, (w, err)
    assert "Traceback" not in err
    assert not (out / "frames.json").exists()


def test_plan_takes_one_focus(capsys):
    code = main(["plan", CARDS, "--lens", "dgauss.50mm", "--focus", "1:3"])
    err = capsys.readouterr().err
    assert code == 2 and "takes one distance" in err


def test_api_refuses_a_single_focus(tmp_path):
    with pytest.raises(ParameterError) as e:
        povlens.render_frames(CARDS, lens="dgauss.50mm", outdir=tmp_path, focus=2.0)
    assert e.value.parameter == "focus"


def test_the_depth_probe_runs_once_for_all_frames(monkeypatch):
    from povlens.plan import probe_reuse

    class Probe:
        view, image = "view", None

        def result(self):
            return np.array([[1.0, np.inf]])

        def cancel(self):
            pass

    started = []
    monkeypatch.setattr(probe_reuse, "start_depth_probe",
                        lambda *a: started.append(a) or Probe())
    reuse = probe_reuse.ProbeReuse()
    first = reuse("opts", "film", "plan")
    assert reuse("opts", "film", "plan") is not first   # not finished: would run again...
    assert len(started) == 2                            # (frames run one after the other)
    first.result()
    later = reuse("opts2", "film2", "plan2")
    assert len(started) == 2 and later.view == "view"
    assert np.array_equal(later.result(), [[1.0, np.inf]])


# ----- a focus pull on a depth-graded scene -----------------------------------------------

def _card_sharpness(image: np.ndarray, hfov_deg: float) -> np.ndarray:
    """Gradient energy (mean squared gradient of the luminance) inside each card of
    scenes/cards.pov, (5,), from the card positions and the frame's field of view."""
    lum = image[..., :3].mean(axis=-1)
    h, w = lum.shape
    gy, gx = np.gradient(lum)
    energy = gx ** 2 + gy ** 2
    t = math.tan(math.radians(15.5)) / math.tan(math.radians(hfov_deg / 2))
    half = 0.13 * t * w / 2 * 0.8                      # inside the card, with margin
    out = []
    for k in range(5):
        cx = w / 2 * (1 + (k - 2) * 0.36 * t)
        x0, x1 = int(round(cx - half)), int(round(cx + half)) + 1
        y0, y1 = int(round(h / 2 - half)), int(round(h / 2 + half)) + 1
        out.append(energy[y0:y1, x0:x1].mean())
    return np.array(out)


@pytest.fixture(scope="module")
def pulls(tmp_path_factory):
    """A 3-frame pull 0.8 m -> 5.5 m through focal_blur (CLI) and its pinhole twin (API):
    the pinhole frames give each card's sharpness without blur."""
    base = tmp_path_factory.mktemp("pull")
    blur, pin = base / "blur", base / "pin"
    code = main(["render", CARDS, "--lens", "dgauss.50mm", "--focus", "0.8:5.5", "--frames",
                 "3", "--method", "focal-blur", "--samples", "32", *SMALL, "-o", str(blur),
                 "-q"])
    assert code == 0
    result = povlens.render_frames(CARDS, lens="dgauss.50mm", outdir=pin, focus=(0.8, 5.5),
                                   frames=3, method="pinhole", width=160, height=120)
    return blur, pin, result


def test_the_sharp_plane_moves_with_the_focus(pulls):
    blur, pin, _ = pulls
    index = json.loads((blur / "frames.json").read_text())
    assert index["focus_pull"] == pytest.approx([0.8, 1 / ((1 / 0.8 + 1 / 5.5) / 2), 5.5])
    sharpest = []
    for f in index["frames"]:
        hfov = read_plan(blur / f["folder"]).povray_camera.hfov_deg
        relative = (_card_sharpness(read_image(blur / f["image_exr"]), hfov)
                    / _card_sharpness(read_image(pin / f["image_exr"]), hfov))
        sharpest.append(int(np.argmax(relative)))
        # the card nearest the focus (in dioptres) is the sharpest one
        nearest = int(np.argmin(np.abs(1 / np.array(Z) - 1 / f["focus"])))
        assert sharpest[-1] == nearest, (f["focus"], relative)
    assert sharpest[0] < sharpest[1] < sharpest[2]


def test_the_lens_breathes(pulls):
    blur, _, result = pulls
    frames = json.loads((blur / "frames.json").read_text())["frames"]
    fd = [f["film_distance_mm"] for f in frames]
    hfov = [f["hfov_deg"] for f in frames]
    assert fd[0] > fd[1] > fd[2]                 # focusing near moves the lens out
    assert hfov[0] < hfov[1] < hfov[2]           # ... and narrows the view
    assert hfov[2] / hfov[0] - 1 > 0.02
    assert [r.film_distance_mm for r in result.frames] == pytest.approx(fd)


def test_frames_folder_layout_and_make_targets(pulls):
    blur, pin, result = pulls
    for d in (blur, pin):
        for i in (1, 2, 3):
            assert (d / f"frame-{i:04d}" / "plan.json").is_file()
            assert read_image(d / f"image.{i:04d}.png").shape[:2] == (120, 160)
    assert result.images_exr == [pin / f"image.{i:04d}.exr" for i in (1, 2, 3)]
    assert read_plan(pin / "frame-0003").inputs.focus == 5.5
    make = (blur / "Makefile").read_text()
    assert "frame-0002:" in make and "all: $(FRAMES)" in make
    (blur / "image.0002.png").unlink()
    subprocess.run(["make", "-s", "-C", str(blur), "frame-0002"], check=True,
                   capture_output=True, timeout=60)
    assert (blur / "image.0002.png").read_bytes() == \
        (blur / "frame-0002" / "image.png").read_bytes()


def test_a_rerun_skips_finished_frames(pulls, capsys):
    blur, _, _ = pulls
    before = {p.name: p.stat().st_mtime_ns for p in blur.glob("frame-*/image.exr")}
    code = main(["render", CARDS, "--lens", "dgauss.50mm", "--focus", "0.8:5.5", "--frames",
                 "3", "--method", "focal-blur", "--samples", "32", *SMALL, "-o", str(blur)])
    err = capsys.readouterr().err
    assert code == 0 and err.count("already rendered") == 3
    assert {p.name: p.stat().st_mtime_ns for p in blur.glob("frame-*/image.exr")} == before


def test_report_shows_the_strip(pulls, tmp_path):
    from povlens.report.html import make_report
    blur, _, _ = pulls
    page = make_report([blur], tmp_path / "r.html", render_missing=False).read_text()
    assert "focus pull, 3 frames" in page
    assert page.count('<img class="render"') == 3
    frames = json.loads((blur / "frames.json").read_text())["frames"]
    assert f"{frames[2]['film_distance_mm']:.4f} mm" in page
    breath = 100 * (frames[2]["hfov_deg"] / frames[0]["hfov_deg"] - 1)
    assert f"{breath:+.2f} %" in page


def test_convert_writes_frame_folders_without_rendering(tmp_path, capsys):
    out = tmp_path / "conv"
    code = main(["convert", CARDS, "--lens", "dgauss.50mm", "--focus", "1,3", "--method",
                 "pinhole", *SMALL, "-o", str(out)])
    assert code == 0, capsys.readouterr().err
    assert (out / "frame-0002" / "Makefile").is_file()
    assert not list(out.glob("image.*"))
    frames = json.loads((out / "frames.json").read_text())["frames"]
    assert [f["focus"] for f in frames] == [1.0, 3.0] and not any(f["done"] for f in frames)
    assert os.path.exists(out / "Makefile")
