"""convert / render / composite on the bundled scenes with the real POV-Ray, small images."""

import json
import os
import shutil
import subprocess
import sys

import numpy as np
import pytest

from povlens.plan.convert import ConvertOptions, convert
from povlens.plan.schema import read_plan
from povlens.util.images import read_image
from povlens.rendering.driver import render_outdir
from povlens.rendering.folder_composite import composite_outdir
from povlens.rendering.mesh_samples import render_batch
from povlens.rendering.views import render_view

from conftest import ROOT

SCENES = ROOT / "scenes"
pytestmark = pytest.mark.skipif(shutil.which("povray") is None, reason="POV-Ray not installed")


def povlens(*args, env=None, cwd=ROOT):
    e = dict(os.environ)
    e.update(env or {})
    return subprocess.run([sys.executable, "-m", "povlens", *args], capture_output=True,
                          text=True, cwd=cwd, env=e, timeout=600)


def opts(tmp_path, **kw):
    base = dict(scene=str(SCENES / "paper.pov"), lens="dgauss.50mm", focus=4.0,
                outdir=str(tmp_path / "out"), width=48, height=36, samples=4, batch_size=2)
    base.update(kw)
    return ConvertOptions(**base)


def test_convert_writes_plan_wrappers_and_makefile(tmp_path):
    before = (SCENES / "paper.pov").read_bytes()
    plan = convert(opts(tmp_path))
    out = tmp_path / "out"
    for name in ("plan.json", "pinhole.pov", "focal_blur.pov", "Makefile",
                 "samples/batch_000.pov", "samples/batch_001.pov"):
        assert (out / name).exists(), name
    saved = json.loads((out / "plan.json").read_text())
    assert saved["batches"] == [[0, 2], [1, 3]]        # dealt round-robin
    cam = saved["povray_camera"]
    # focal_blur aperture is twice the entrance-pupil diameter, in scene units (m)
    assert cam["aperture"] == pytest.approx(2 * 24.8051e-3, rel=1e-4)
    assert saved["model_error"]["max_distortion_px"] >= 0
    assert "#include" in (out / "focal_blur.pov").read_text()
    # the scene itself is untouched
    assert (SCENES / "paper.pov").read_bytes() == before
    assert plan.focus.film_distance_mm > plan.lens.efl_mm * 0.7


def test_make_renders_and_a_second_make_does_nothing(tmp_path):
    convert(opts(tmp_path))
    out = tmp_path / "out"
    r = subprocess.run(["make", "-C", str(out), "-j2"], capture_output=True, text=True)
    assert r.returncode == 0, r.stderr
    img = read_image(out / "image.exr")
    assert img.shape == (36, 48, 3) and np.isfinite(img).all() and img.mean() > 0.05
    assert (out / "image.png").exists()
    again = subprocess.run(["make", "-C", str(out)], capture_output=True, text=True)
    assert again.returncode == 0 and "Nothing to be done" in again.stdout


def test_interrupted_render_resumes_to_the_same_image(tmp_path):
    full = tmp_path / "full"
    convert(opts(tmp_path, outdir=str(full)))
    render_outdir(full, jobs=1, quiet=True)
    reference = read_image(full / "image.exr")

    part = tmp_path / "part"
    convert(opts(tmp_path, outdir=str(part)))
    render_batch(part, 0)                              # the run stops after one batch ...
    (part / "samples" / "sample_0002.exr").unlink()    # ... and one sample of it is lost
    render_outdir(part, jobs=2, quiet=True)            # re-run
    np.testing.assert_array_equal(read_image(part / "image.exr"), reference)


def test_tiny_stop_mesh_render_matches_the_pinhole_render(tmp_path):
    o = opts(tmp_path, width=640, height=480, samples=8, batch_size=8, stop_diameter_mm=2.0,
             jitter=False)
    convert(o)
    out = tmp_path / "out"
    render_outdir(out, jobs=2, quiet=True)
    # without vignetting (cos^4 falloff is physical, and a pinhole has none)
    mesh = composite_outdir(out, vignetting=False, write=False)
    pin = read_image(render_view(out, "pinhole"))[..., :3]
    diff = np.abs(mesh - pin).mean(axis=2)
    # Same view pixel for pixel, up to the real lens's residual geometry against the
    # fitted perspective (its distortion, up to 2 px at the frame's corners at this
    # size, under 0.05 px in the central quarter used here, and rays spread over a
    # 2 mm stop), which flips pixels only where a hard checker edge crosses the pixel
    # centre, and the aliased checker floor near the horizon.
    c = diff[180:300, 240:400]
    assert np.median(c) < 0.01
    assert (c > 0.2).mean() < 0.05
    # the field meshes were certified to 0.05 px
    assert read_plan(out).field_mesh.max_ray_error_px <= 0.05
    # a view shifted by one pixel is clearly worse, so the test can fail (vertically:
    # the floor's checker rows near the horizon show it; per-pixel meshes give the same
    # numbers, 3.1 % against 22-25 % of the pixels)
    for shifted in (mesh[1:] - pin[:-1], mesh[:-1] - pin[1:]):
        assert (np.abs(shifted).mean(axis=2)[180:300, 240:400] > 0.2).mean() > 4.0 * (c > 0.2).mean()


def test_focal_blur_method_renders_one_image(tmp_path):
    convert(opts(tmp_path, method="focal-blur", samples=7))
    out = tmp_path / "out"
    render_outdir(out, quiet=True)
    img = read_image(out / "image.exr")
    assert img.shape[:2] == (36, 48) and np.isfinite(img).all()
    assert "blur_samples 7, 7" in (out / "focal_blur.pov").read_text()


def test_cli_render_and_errors(tmp_path):
    r = povlens("render", str(SCENES / "chart.pov"), "--lens", "wide.22mm", "--focus", "3",
                "--width", "32", "--height", "24", "--samples", "2", "-o", str(tmp_path / "c"),
                "-q")
    assert r.returncode == 0, r.stderr
    assert (tmp_path / "c" / "image.png").exists()

    # no camera: POV-Ray's default camera, said once
    nocam = tmp_path / "nocam.pov"
    nocam.write_text('#version 3.7;\nsphere { 0, 1 pigment { rgb 1 } }\n')
    r = povlens("convert", str(nocam), "--lens", "dgauss.50mm", "--focus", "3", "-o",
                str(tmp_path / "n"))
    assert r.returncode == 0, r.stderr
    assert r.stderr.count("povlens: note: the scene has no camera statement") == 1

    # a camera povlens cannot evaluate (a user function): the options to give instead
    odd = tmp_path / "odd.pov"
    odd.write_text('#version 3.7;\n#declare F = function(x) { x*2 }\n'
                   'camera { location <F(1), 1, -3> look_at <0,0,0> }\n')
    r = povlens("convert", str(odd), "--lens", "dgauss.50mm", "--focus", "3", "-o",
                str(tmp_path / "m"))
    assert r.returncode == 2 and "--location" in r.stderr and "Traceback" not in r.stderr
    # ... and the options make it work
    r = povlens("convert", str(odd), "--lens", "dgauss.50mm", "--focus", "3", "-o",
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


def test_changed_inputs_drop_stale_samples_and_exposure(tmp_path):
    convert(opts(tmp_path, samples=2, batch_size=2))
    out = tmp_path / "out"
    render_outdir(out, jobs=1, quiet=True)
    assert (out / "exposure.txt").exists() and (out / "pupil.npz").exists()
    e_f2 = float((out / "exposure.txt").read_text())
    convert(opts(tmp_path, samples=2, batch_size=2, f_number=4.0))   # the stop changed
    assert not (out / "exposure.txt").exists()
    assert not list((out / "samples").glob("sample_*.exr"))
    render_outdir(out, jobs=1, quiet=True)
    # exposure = 1 / (E/L) at the centre, and E/L goes as 1/N^2: f/2.03 -> f/4 is ~3.9x
    assert float((out / "exposure.txt").read_text()) == pytest.approx(e_f2 * (4.0 / 2.03) ** 2,
                                                                      rel=0.15)


def test_samples_in_flight_render_the_same_image_as_one_at_a_time(tmp_path):
    one = tmp_path / "one"
    convert(opts(tmp_path, outdir=str(one), samples=6, batch_size=6))
    render_batch(one, 0, in_flight=1)
    many = tmp_path / "many"
    convert(opts(tmp_path, outdir=str(many), samples=6, batch_size=6))
    render_batch(many, 0, in_flight=6)
    rendered = 0
    for k in range(6):
        name = f"samples/sample_{k:04d}.exr"
        assert (many / name).exists() == (one / name).exists()   # or both all blocked
        if (one / name).exists():
            np.testing.assert_array_equal(read_image(many / name), read_image(one / name))
            rendered += 1
    assert rendered >= 4
    # the meshes and the per-sample temporary folders are gone
    assert not list((many / "samples").glob("*.inc"))
    assert not list((many / "samples").glob(".sample_*"))


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
    convert(opts(tmp_path, outdir=str(full), samples=48, batch_size=24, method="mesh"))
    render_outdir(full, quiet=True)
    np.testing.assert_array_equal(read_image(out / "image.exr"), read_image(full / "image.exr"))


def test_more_samples_reuse_the_rendered_ones(tmp_path):
    """Raising N keeps samples 0..N-1 (Sobol point k does not depend on N): only the
    new samples are traced and rendered, and the image equals a fresh render."""
    out = tmp_path / "out"
    convert(opts(tmp_path, samples=3, batch_size=3))
    render_outdir(out, jobs=1, quiet=True)
    s = out / "samples"
    before = {k: (s / f"sample_{k:04d}.exr").stat().st_mtime_ns for k in range(3)}
    convert(opts(tmp_path, samples=5, batch_size=5))
    assert not (out / "image.exr").exists()
    assert (out / "exposure.txt").exists()
    rendered = render_batch(out, 0)
    assert rendered == [3, 4]
    assert {k: (s / f"sample_{k:04d}.exr").stat().st_mtime_ns for k in range(3)} == before
    composite_outdir(out)
    fresh = tmp_path / "fresh"
    convert(opts(tmp_path, outdir=str(fresh), samples=5, batch_size=5))
    render_outdir(fresh, jobs=1, quiet=True)
    np.testing.assert_array_equal(read_image(out / "image.exr"), read_image(fresh / "image.exr"))
    # a change that alters every sample (the seed) drops them all
    convert(opts(tmp_path, samples=5, batch_size=5, seed=3))
    assert not list(s.glob("sample_*.exr")) and not (out / "exposure.txt").exists()


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
    plan, _ = convert_and_render(opts(tmp_path, outdir=str(auto), method="auto",
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
    convert(opts(tmp_path, outdir=str(fixed), method="mesh", samples=n, **kw))
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
    plan, image = convert_and_render(opts(tmp_path, outdir=str(out), method="auto",
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
    plan, image = convert_and_render(opts(tmp_path, outdir=str(out), method="auto", lens=lens,
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
        convert(opts(tmp_path, outdir=str(plain), method="auto", lens=lens, batch_size=None))
        render_view(plain, "focal-blur")
        few = tmp_path / "few"
        convert(opts(tmp_path, outdir=str(few), method="focal-blur", lens=lens, samples=8))
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
        convert(opts(tmp_path, outdir=str(fixed), method="mesh", lens=lens,
                     samples=plan.inputs.samples, batch_size=None))
        render_outdir(fixed, quiet=True)
        np.testing.assert_array_equal(read_image(image), read_image(fixed / "image.exr"))


def test_a_cancelled_early_render_leaves_no_povray_and_resumes(tmp_path):
    from povlens.rendering.driver import EarlyRender
    from povlens.rendering.folder_inputs import lens_for, pupil_table_for
    out = tmp_path / "out"
    plan = convert(opts(tmp_path, samples=24, batch_size=None))
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
    convert(opts(tmp_path, outdir=str(full), samples=24, batch_size=None))
    render_outdir(full, quiet=True)
    np.testing.assert_array_equal(read_image(out / "image.exr"), read_image(full / "image.exr"))


def test_a_damaged_pass_mask_is_a_clear_error_naming_the_file(tmp_path):
    """Field-mesh samples keep their pass mask (the weights follow from it); a
    damaged one stops the composite with the file's name, not a traceback or a
    silently wrong image."""
    from povlens.errors import PovlensError
    convert(opts(tmp_path, samples=2, batch_size=2))
    out = tmp_path / "out"
    render_outdir(out, jobs=2, quiet=True)
    masks = sorted((out / "samples").glob("sample_*.mask.npy"))
    assert len(masks) == 2 and not list((out / "samples").glob("*.weight.exr"))
    good = composite_outdir(out, write=False)
    assert np.isfinite(good).all() and good.max() > 0
    masks[0].write_bytes(b"not a mask")
    with pytest.raises(PovlensError, match=masks[0].name):
        composite_outdir(out, write=False)
    np.save(masks[0], np.zeros((3, 1), np.uint8))       # the wrong size
    with pytest.raises(PovlensError, match="mask"):
        composite_outdir(out, write=False)
