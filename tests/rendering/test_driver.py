"""povlens render from start to image (povlens.rendering.driver): the command line,
interrupts, the lens samples and views --method auto starts while it probes.  With the
real POV-Ray, small images."""

import json
import os
import shutil
import subprocess
import sys

import numpy as np
import pytest

from povlens.plan.convert import convert
from povlens.rendering.driver import render_outdir
from povlens.util.images import read_image

from conftest import ROOT, paper_options

SCENES = ROOT / "scenes"
pytestmark = pytest.mark.skipif(shutil.which("povray") is None, reason="POV-Ray not installed")


def povlens(*args, env=None, cwd=ROOT):
    e = dict(os.environ)
    e.update(env or {})
    return subprocess.run([sys.executable, "-m", "povlens", *args], capture_output=True,
                          text=True, cwd=cwd, env=e, timeout=600)


def test_cli_render_and_errors(tmp_path):
    r = povlens("render", str(SCENES / "chart.pov"), "--lens", "wide.22mm", "--focus", "3",
                "--width", "32", "--height", "24", "--samples", "2", "-o", str(tmp_path / "c"),
                "-q")
    assert r.returncode == 0, r.stderr
    assert (tmp_path / "c" / "image.png").exists()

    # no camera: POV-Ray's default camera, said once
    nocam = tmp_path / "nocam.pov"
    nocam.write_text('#version 3.7;\nsphere { 0, 1 pigment { rgb 1 } }\n')
    small = ("--width", "32", "--height", "24")
    r = povlens("convert", str(nocam), "--lens", "dgauss.50mm", "--focus", "3", *small, "-o",
                str(tmp_path / "n"))
    assert r.returncode == 0, r.stderr
    assert r.stderr.count("povlens: note: the scene has no camera statement") == 1

    # a camera povlens cannot evaluate (a user function): the options to give instead
    odd = tmp_path / "odd.pov"
    odd.write_text('#version 3.7;\n#declare F = function(x) { x*2 }\n'
                   'camera { location <F(1), 1, -3> look_at <0,0,0> }\n')
    r = povlens("convert", str(odd), "--lens", "dgauss.50mm", "--focus", "3", *small, "-o",
                str(tmp_path / "m"))
    assert r.returncode == 2 and "--location" in r.stderr and "Traceback" not in r.stderr
    # ... and the options make it work
    r = povlens("convert", str(odd), "--lens", "dgauss.50mm", "--focus", "3", *small, "-o",
                str(tmp_path / "m"), "--location", "0,1,-3", "--look-at", "0,0,0")
    assert r.returncode == 0, r.stderr

    broken = tmp_path / "broken.pov"
    broken.write_text('#version 3.7;\ncamera { location <0,1,-3> look_at <0,0,0> }\n'
                      'sphere { 0, 1 pigment { rgb 1 } \n')
    r = povlens("render", str(broken), "--lens", "dgauss.50mm", "--focus", "3", "--width", "16",
                "--height", "12", "--samples", "1", "-o", str(tmp_path / "b"), "-q")
    assert r.returncode == 3 and "POV-Ray failed" in r.stderr and "Traceback" not in r.stderr
    assert not (tmp_path / "b" / "image.exr").exists()

    r = povlens("render", str(SCENES / "chart.pov"), "--lens", "dgauss.50mm", "--focus", "3",
                "-o", str(tmp_path / "p"), env={"POVLENS_POVRAY": "/nonexistent/povray"})
    assert r.returncode == 3 and "POVLENS_POVRAY" in r.stderr and "Traceback" not in r.stderr


def _processes_in(folder) -> list[int]:
    """PIDs of processes whose working directory is ``folder`` (POV-Ray runs there)."""
    pids = []
    for d in os.listdir("/proc"):
        if d.isdigit():
            try:
                if os.readlink(f"/proc/{d}/cwd") == str(folder):
                    pids.append(int(d))
            except OSError:
                pass
    return pids


def test_interrupting_render_stops_povray_and_resumes(tmp_path):
    out = tmp_path / "int"
    cmd = [sys.executable, "-m", "povlens", "render", str(SCENES / "paper.pov"), "--lens",
           "dgauss.50mm", "--focus", "4", "--width", "48", "--height", "36", "--method", "mesh",
           "--samples", "48", "--batch-size", "24", "-o", str(out), "-q"]
    proc = subprocess.Popen(cmd, cwd=ROOT, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE)
    import signal
    import time
    t0 = time.monotonic()
    while not list((out / "samples").glob("sample_*.mask.npy")) if out.exists() else True:
        assert proc.poll() is None and time.monotonic() - t0 < 120, "render ended too soon"
        time.sleep(0.02)
    proc.send_signal(signal.SIGINT)
    proc.wait(timeout=60)
    assert proc.returncode != 0
    time.sleep(0.5)
    assert _processes_in(out / "samples") == [], "POV-Ray still running after the interrupt"
    assert subprocess.run(["pgrep", "-f", str(out)], capture_output=True).returncode == 1
    # no half-written files at final names; resuming finishes the render
    assert not (out / "image.exr").exists()
    done = [k for k in range(48) if (out / "samples" / f"sample_{k:04d}.exr").exists()]
    assert len(done) < 48
    render_outdir(out, quiet=True)
    full = tmp_path / "full"
    convert(paper_options(tmp_path, outdir=str(full), samples=48, batch_size=24, method="mesh"))
    render_outdir(full, quiet=True)
    np.testing.assert_array_equal(read_image(out / "image.exr"), read_image(full / "image.exr"))


@pytest.mark.parametrize("lens, focus, film_mm, tol", [("fisheye.10mm", 4.0, 35.0, 0.5),
                                                       ("dgauss.50mm", 1.5, 10.0, 0.2)])
def test_auto_renders_the_first_samples_while_probing_and_keeps_them(tmp_path, lens, focus,
                                                                     film_mm, tol):
    """The fisheye distorts far beyond the budget, and dgauss.50mm on a 10 mm film
    with a 0.2 px budget does too: the lens alone rules out the views, so povlens
    render starts lens samples 0..7 while the depth probe runs, and the samples the
    decision adds follow in the same pipeline (the rule's count for the largest blur).
    The result equals a fixed mesh render of the decided sample count."""
    from povlens.plan.decision import samples_for_blur
    from povlens.rendering.driver import convert_and_render
    auto = tmp_path / "auto"
    kw = dict(lens=lens, focus=focus, film_diagonal_mm=film_mm, batch_size=None)
    plan, _ = convert_and_render(paper_options(tmp_path, outdir=str(auto), method="auto", samples=None,
                                      tolerance_px=tol, **kw), quiet=True)
    assert plan.inputs.method == "mesh" and not plan.decision.provisional
    assert any("while the depth probe ran" in r for r in plan.decision.reasons)
    assert plan.decision.reasons[-1].startswith("-> mesh")      # the conclusion stays last
    n = plan.inputs.samples
    assert n == samples_for_blur(plan.decision.numbers["max_blur_px"])
    early = json.loads((auto / "samples" / "early.timing.json").read_text())
    assert early["samples"] == n                     # all of them, in the one pipeline
    assert not (auto / "samples" / "render.timing.json").exists()
    fixed = tmp_path / "fixed"
    convert(paper_options(tmp_path, outdir=str(fixed), method="mesh", samples=n, **kw))
    render_outdir(fixed, quiet=True)
    np.testing.assert_array_equal(read_image(auto / "image.exr"), read_image(fixed / "image.exr"))
    r = subprocess.run(["make", "-C", str(auto)], capture_output=True, text=True)
    assert r.returncode == 0 and "Nothing to be done" in r.stdout
    assert not list((auto / "samples").glob("*.inc")) and not list((auto / "samples").glob(".s*"))


def test_a_wrong_guess_stops_the_early_samples_and_renders_the_decision(tmp_path, monkeypatch):
    """The guess that the lens rules out the views is forced for telephoto.250mm,
    which auto renders with focal_blur: the early samples are stopped and dropped,
    and the folder holds the focal_blur image."""
    import povlens.plan.speculative as speculative
    from povlens.rendering.driver import convert_and_render
    monkeypatch.setattr(speculative, "lens_rules_out_views", lambda opts, plan0: True)
    out = tmp_path / "auto"
    plan, image = convert_and_render(paper_options(tmp_path, outdir=str(out), method="auto", samples=None,
                                          lens="telephoto.250mm", batch_size=None), quiet=True)
    assert plan.inputs.method == "focal-blur"
    assert any("mesh render started while the probe ran was stopped" in r
               for r in plan.decision.reasons)
    assert image.exists() and read_image(image).shape[:2] == (36, 48)
    assert _processes_in(out / "samples") == []
    assert not list((out / "samples").glob("sample_*"))


@pytest.mark.parametrize("lens, decided", [("telephoto.250mm", "focal-blur"),
                                            ("fisheye.10mm", "mesh")])
def test_an_either_guess_starts_both_and_keeps_the_decided_one(tmp_path, monkeypatch, lens,
                                                               decided):
    """When the cat's eye may or may not rule out the views (the guess "either"),
    povlens render starts the first lens samples and the focal_blur view at once;
    the decision keeps one and stops the other, and the folder is as a fixed
    render of the decided method leaves it."""
    import povlens.plan.speculative as speculative
    from povlens.rendering.driver import convert_and_render
    monkeypatch.setattr(speculative, "early_guess", lambda opts, plan0: "either")
    out = tmp_path / "auto"
    plan, image = convert_and_render(paper_options(tmp_path, outdir=str(out), method="auto", samples=None, lens=lens,
                                          batch_size=None), quiet=True)
    assert plan.inputs.method == decided
    reasons = " ".join(plan.decision.reasons)
    assert plan.decision.reasons[-1].startswith("-> " + decided)
    assert _processes_in(out / "samples") == [] and not list(out.glob(".speculative*"))
    if decided == "focal-blur":
        assert "mesh render started while the probe ran was stopped" in reasons
        assert not list((out / "samples").glob("sample_*"))
        # the view started early is the final wrapper's render (the provisional mesh
        # plan, written at the same time, must not change the wrapper it renders)
        from povlens.rendering.views import render_view
        plain = tmp_path / "plain"
        convert(paper_options(tmp_path, outdir=str(plain), method="auto", samples=None, lens=lens, batch_size=None))
        render_view(plain, "focal-blur")
        few = tmp_path / "few"
        convert(paper_options(tmp_path, outdir=str(few), method="focal-blur", lens=lens, samples=8))
        render_view(few, "focal-blur")
        a, b, c = (read_image(p)[..., :3] for p in (image, plain / "image.exr",
                                                     few / "image.exr"))
        assert a.shape[:2] == (36, 48)
        err, err_few = (float(np.sqrt(np.mean((x - b) ** 2))) for x in (a, c))
        print(f"RMSE early view / final wrapper {err:.4g}; 8 fixed samples {err_few:.4g}")
        assert err < 0.5 * err_few
    else:
        assert "focal_blur render started while the probe ran was stopped" in reasons
        assert "could rule out the views" in reasons
        assert not (out / "view-focal-blur.exr").exists()
        fixed = tmp_path / "fixed"
        convert(paper_options(tmp_path, outdir=str(fixed), method="mesh", lens=lens,
                     samples=plan.inputs.samples, batch_size=None))
        render_outdir(fixed, quiet=True)
        np.testing.assert_array_equal(read_image(image), read_image(fixed / "image.exr"))


def test_a_cancelled_early_render_leaves_no_povray_and_resumes(tmp_path):
    from povlens.rendering.driver import EarlyRender
    from povlens.rendering.folder_inputs import lens_for, pupil_table_for
    out = tmp_path / "out"
    plan = convert(paper_options(tmp_path, samples=24, batch_size=None))
    lens = lens_for(plan)
    table = pupil_table_for(out, plan, lens)
    early = EarlyRender(out, plan, lens, table, in_flight=4, quiet=True)
    import time
    t0 = time.monotonic()
    while not [f for f in (out / "samples").glob("sample_*.exr") if ".weight" not in f.name]:
        assert time.monotonic() - t0 < 60                  # a sample's image is in
        time.sleep(0.01)
    early.cancel()
    early.wait()
    assert _processes_in(out / "samples") == []
    assert not list((out / "samples").glob("*.inc")) and not list((out / "samples").glob(".s*"))
    done = [k for k in range(24) if (out / "samples" / f"sample_{k:04d}.exr").exists()]
    assert 0 < len(done) < 24
    render_outdir(out, quiet=True)
    full = tmp_path / "full"
    convert(paper_options(tmp_path, outdir=str(full), samples=24, batch_size=None))
    render_outdir(full, quiet=True)
    np.testing.assert_array_equal(read_image(out / "image.exr"), read_image(full / "image.exr"))
