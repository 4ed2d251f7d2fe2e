"""Lens samples on a Dask cluster (povlens.cluster): a ``dask scheduler`` and two
``dask worker`` processes started here on 127.0.0.1 (no nanny, one thread each), every
wait bounded, every process killed at the end.  The renders are tiny (80x60)."""

from __future__ import annotations

import json
import os
import shutil
import signal
import socket
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest

pytest.importorskip("distributed")
pytestmark = pytest.mark.skipif(shutil.which("povray") is None, reason="POV-Ray not installed")

import povlens                                                    # noqa: E402
from povlens.cli import main                                      # noqa: E402
from povlens.cluster import bundle as bundle_module               # noqa: E402
from povlens.cluster.bundle import make_bundle                    # noqa: E402
from povlens.cluster.render import render_outdir_on_cluster       # noqa: E402
from povlens.errors import ParameterError, PovlensError, PovrayError  # noqa: E402
from povlens.plan.schema import read_plan                         # noqa: E402
from povlens.util.images import read_image, write_png_srgb        # noqa: E402

from conftest import ROOT                                         # noqa: E402

SCENE = ROOT / "scenes" / "paper.pov"
RENDER = dict(lens="dgauss.50mm", focus=4, method="mesh", samples=6, width=80, height=60)
START_TIMEOUT_S = 60


def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


class Cluster:
    """A scheduler and its workers in separate processes on the loopback address."""

    def __init__(self, tmp: Path):
        self.tmp = tmp
        self.address = f"tcp://127.0.0.1:{_free_port()}"
        self.procs: list[subprocess.Popen] = []
        self.env = dict(os.environ, TMPDIR=str(tmp / "workers"))   # replicas land here
        (tmp / "workers").mkdir()
        self.scheduler = self._start("dask_scheduler", "--host", "127.0.0.1", "--port",
                                     self.address.rsplit(":", 1)[1], "--no-dashboard")

    def _start(self, module: str, *args: str) -> subprocess.Popen:
        log = open(self.tmp / f"{module}-{len(self.procs)}.log", "w")
        p = subprocess.Popen([sys.executable, "-m", f"distributed.cli.{module}", *args],
                             stdout=log, stderr=subprocess.STDOUT, env=self.env,
                             start_new_session=True)
        self.procs.append(p)
        return p

    def add_worker(self) -> subprocess.Popen:
        return self._start("dask_worker", self.address, "--nthreads", "1", "--no-nanny",
                           "--no-dashboard", "--host", "127.0.0.1",
                           "--local-directory", str(self.tmp / "workers"))

    def wait_for_workers(self, n: int) -> None:
        from distributed import Client
        with Client(self.address, timeout=f"{START_TIMEOUT_S}s", set_as_default=False) as c:
            c.wait_for_workers(n, timeout=START_TIMEOUT_S)

    def stop(self) -> None:
        for p in self.procs:
            if p.poll() is None:
                p.kill()
        for p in self.procs:
            p.wait(timeout=30)


@pytest.fixture(scope="module")
def cluster(tmp_path_factory):
    c = Cluster(tmp_path_factory.mktemp("cluster"))
    try:
        c.add_worker()
        c.add_worker()
        c.wait_for_workers(2)
        yield c
    finally:
        c.stop()


@pytest.fixture(scope="module")
def local_image(tmp_path_factory) -> np.ndarray:
    """The reference: the same render on this machine, without Dask."""
    out = tmp_path_factory.mktemp("local") / "o"
    povlens.render(SCENE, outdir=out, **RENDER)
    return read_image(out / "image.exr")


def _timing(outdir: Path) -> dict:
    return json.loads((outdir / "samples" / "cluster.timing.json").read_text())


def test_a_render_through_two_workers_equals_the_local_render(cluster, local_image, tmp_path):
    out = tmp_path / "o"
    result = povlens.render(SCENE, outdir=out, scheduler=cluster.address, **RENDER)
    image = read_image(result.image_exr)
    assert image.shape == local_image.shape and image.max() > 0
    assert np.array_equal(image, local_image)        # bit for bit
    tasks = _timing(out)["tasks"]
    assert sorted(t["k"] for t in tasks) == list(range(RENDER["samples"]))
    assert len({t["pid"] for t in tasks}) == 2          # both workers rendered samples
    # POV-Ray ran for each sample with an image (one whose rays are all blocked has none)
    assert all(t["povray_s"] > 0 for t in tasks if (out / "samples" /
                                                     f"sample_{t['k']:04d}.exr").exists())


def test_the_cli_renders_on_the_cluster_from_the_environment(cluster, local_image, tmp_path,
                                                              monkeypatch):
    monkeypatch.setenv("POVLENS_SCHEDULER", cluster.address)
    out = tmp_path / "o"
    args = ["render", str(SCENE), "--lens", "dgauss.50mm", "--focus", "4", "--method", "mesh",
            "--samples", "6", "--width", "80", "--height", "60", "-q", "-o", str(out)]
    assert main(args) == 0
    assert (out / "samples" / "cluster.timing.json").exists()
    assert np.array_equal(read_image(out / "image.exr"), local_image)


def test_a_worker_killed_mid_render_loses_nothing(cluster, local_image, tmp_path):
    from distributed import Client
    victim = cluster.add_worker()
    cluster.wait_for_workers(3)
    out = tmp_path / "o"
    povlens.convert(SCENE, outdir=out, **RENDER)
    in_flight = []

    with Client(cluster.address, timeout="30s", set_as_default=False) as monitor:
        [addr] = [a for a, pid in monitor.run(os.getpid).items() if pid == victim.pid]

        def on_sample(task):
            # at the first sample back, the victim is rendering one: kill it then
            if not in_flight:
                in_flight.extend(monitor.processing([addr])[addr])
                assert victim.poll() is None
                os.killpg(victim.pid, signal.SIGKILL)
                victim.wait(timeout=30)

        _, stats = render_outdir_on_cluster(out, cluster.address, on_sample=on_sample)
    assert in_flight, "the victim had no sample in flight when it was killed"
    tasks = stats["tasks"]
    lost = {int(key.split("-")[2]) for key in in_flight}
    # the victim's samples in flight were rendered again, by the others
    assert all(t["pid"] != victim.pid for t in tasks if t["k"] in lost)
    assert sorted(t["k"] for t in tasks) == list(range(RENDER["samples"]))
    assert np.array_equal(read_image(out / "image.exr"), local_image)


def _scene_with_include_and_map(folder: Path) -> Path:
    (folder / "parts").mkdir(parents=True)
    (folder / "maps").mkdir()
    y, x = np.mgrid[0:16, 0:16]
    checker = ((x // 4 + y // 4) % 2).astype(np.float64)
    write_png_srgb(folder / "maps" / "checker.png",
                   np.stack([checker, 0.3 + 0 * checker, 1 - checker], axis=-1))
    (folder / "parts" / "look.inc").write_text(
        "#declare Look = texture { pigment { image_map { png \"maps/checker.png\" } "
        "translate <-0.5, -0.5, 0> scale 4 } finish { ambient 1 diffuse 0 } }\n")
    scene = folder / "main.pov"
    scene.write_text(
        "#version 3.7;\n#include \"parts/look.inc\"\n"
        "camera { location <0, 0, -6> look_at <0, 0, 0> }\n"
        "plane { z, 0 texture { Look } }\n")
    return scene


def test_a_scene_with_an_include_file_and_an_image_map_renders_on_the_workers(cluster,
                                                                            tmp_path):
    scene = _scene_with_include_and_map(tmp_path / "scene")
    opts = dict(lens="dgauss.50mm", focus=6, method="mesh", samples=3, width=80, height=60)
    local = povlens.render(scene, outdir=tmp_path / "scene" / "local", **opts)
    dist = povlens.render(scene, outdir=tmp_path / "dist", scheduler=cluster.address, **opts)
    a, b = read_image(local.image_exr), read_image(dist.image_exr)
    assert b[..., 0].max() > 0.5 and b[..., 2].max() > 0.5     # the map's two colours
    assert np.array_equal(a, b)
    # the workers rendered from their own copy, which holds the include and the map
    # (and not the local render folder inside the scene's folder)
    replicas = list((cluster.tmp / "workers" / "povlens-cluster").glob("*/" + str(
        tmp_path / "scene").lstrip("/")))
    assert replicas
    assert any((r / "parts" / "look.inc").is_file() and (r / "maps" / "checker.png").is_file()
               and not (r / "local").exists() for r in replicas)


def test_an_interrupted_cluster_render_resumes_here(cluster, local_image, tmp_path):
    out = tmp_path / "o"
    povlens.convert(SCENE, outdir=out, **RENDER)
    done = []

    def interrupt(task):
        done.append(task["k"])
        if len(done) == 3:
            raise KeyboardInterrupt

    with pytest.raises(KeyboardInterrupt):
        render_outdir_on_cluster(out, cluster.address, on_sample=interrupt)
    assert len(list((out / "samples").glob("sample_*.exr"))) == 3
    result = povlens.render(SCENE, outdir=out, **RENDER)         # locally, resumed
    assert json.loads((out / "samples" / "render.timing.json").read_text())["samples"] == 3
    assert np.array_equal(read_image(result.image_exr), local_image)


def test_shared_dir_writes_the_samples_in_place_through_a_client(cluster, local_image,
                                                                 tmp_path):
    from distributed import Client
    out = tmp_path / "o"
    with Client(cluster.address, timeout="30s", set_as_default=False) as client:
        povlens.render(SCENE, outdir=out, scheduler=client, shared_dir=True, **RENDER)
        assert client.status == "running"                # the caller's client: left open
    assert _timing(out)["bundle_bytes"] == 0
    assert np.array_equal(read_image(out / "image.exr"), local_image)


def test_a_scheduler_without_workers_is_a_clear_error(tmp_path):
    from distributed import Client
    empty = Cluster(tmp_path)
    try:
        with Client(empty.address, timeout=f"{START_TIMEOUT_S}s", set_as_default=False):
            pass                                          # it answers
        out = tmp_path / "o"
        povlens.convert(SCENE, outdir=out, lens="dgauss.50mm", focus=4, method="mesh",
                        samples=2, width=32, height=24)
        with pytest.raises(PovlensError, match="no Dask worker joined the scheduler"):
            render_outdir_on_cluster(out, empty.address, worker_wait_s=1)
    finally:
        empty.stop()


def test_a_scene_failing_on_the_workers_is_a_povray_error(cluster, tmp_path):
    scene = tmp_path / "scene" / "bad.pov"
    scene.parent.mkdir()
    scene.write_text("camera { location <0, 0, -5> look_at 0 }\nsphere { 0, 1 pigment { rgb 1 } }\n"
                     "light_source { <0, 5, -5> rgb 1 }\n")
    out = tmp_path / "o"
    povlens.convert(scene, outdir=out, lens="dgauss.50mm", focus=5, method="mesh", samples=2,
                    width=32, height=24)
    scene.write_text(scene.read_text() + "sphere { 0 1 undeclared_thing }\n")
    with pytest.raises(PovrayError, match="lens sample [01] on worker"):
        render_outdir_on_cluster(out, cluster.address)


def test_a_scheduler_that_does_not_answer_is_a_clear_error(tmp_path, capsys):
    address = f"tcp://127.0.0.1:{_free_port()}"           # nothing listens there
    out = tmp_path / "o"
    povlens.convert(SCENE, outdir=out, lens="dgauss.50mm", focus=4, method="mesh", samples=2,
                    width=32, height=24)
    t0 = time.perf_counter()
    with pytest.raises(ParameterError, match="no Dask scheduler answered") as e:
        render_outdir_on_cluster(out, address, connect_timeout_s=1)
    assert e.value.parameter == "scheduler" and time.perf_counter() - t0 < 10
    args = ["render", str(SCENE), "--lens", "dgauss.50mm", "--focus", "4", "--method", "mesh",
            "--samples", "2", "--width", "32", "--height", "24", "-o", str(tmp_path / "c"),
            "--scheduler", address, "--scheduler-timeout", "1"]
    t0 = time.perf_counter()
    assert main(args) == 2
    err = capsys.readouterr().err
    assert f"--scheduler {address}: no Dask scheduler answered within 1 s" in err
    assert "Traceback" not in err and time.perf_counter() - t0 < 10
    assert not (tmp_path / "c" / "plan.json").exists()      # asked before converting


@pytest.mark.parametrize("extra, message", [
    (["--scheduler", "nonsense"], "--scheduler nonsense: not a scheduler address"),
    (["--shared-dir"], "--shared-dir needs --scheduler"),
])
def test_bad_cluster_options_through_the_cli(tmp_path, capsys, monkeypatch, extra, message):
    monkeypatch.delenv("POVLENS_SCHEDULER", raising=False)
    args = ["render", str(SCENE), "--lens", "dgauss.50mm", "--focus", "4", "--method", "mesh",
            "--samples", "2", "--width", "32", "--height", "24", "-o", str(tmp_path / "c"),
            *extra]
    assert main(args) == 2
    err = capsys.readouterr().err
    assert message in err and "Traceback" not in err


def test_shared_dir_without_a_scheduler_through_the_api(tmp_path, monkeypatch):
    monkeypatch.delenv("POVLENS_SCHEDULER", raising=False)
    with pytest.raises(ParameterError, match="shared_dir=True needs 'scheduler'"):
        povlens.render(SCENE, outdir=tmp_path / "o", shared_dir=True, **RENDER)


def test_a_scene_folder_past_the_limit_asks_for_shared_dir(tmp_path, monkeypatch):
    out = tmp_path / "o"
    povlens.convert(SCENE, outdir=out, lens="dgauss.50mm", focus=4, method="mesh", samples=2,
                    width=32, height=24)
    plan = read_plan(out)
    key, data = make_bundle(out, plan)
    assert len(key) == 64 and len(data) > 0
    monkeypatch.setattr(bundle_module, "BUNDLE_LIMIT_BYTES", 1000)
    with pytest.raises(ParameterError, match="more than the 0 MB") as e:
        make_bundle(out, plan)
    assert e.value.parameter == "shared_dir"


def test_parsing_render_imports_no_dask():
    probe = ("import sys\nimport povlens.cli as c\nc.build_parser('render')\n"
             "print(sorted(m for m in sys.modules if m.split('.')[0] in "
             "('dask', 'distributed')))")
    r = subprocess.run([sys.executable, "-c", probe], capture_output=True, text=True, cwd=ROOT,
                       timeout=120)
    assert r.returncode == 0, r.stderr
    assert r.stdout.strip().splitlines()[-1] == "[]"


def test_a_dispersion_render_on_the_cluster_equals_the_local_one(cluster, tmp_path):
    # the composite's sums come from rendering/samples.sample_sums: spectral weights too
    opts = dict(lens="dgauss.50mm", focus=4, method="mesh", samples=4, width=48, height=36,
                dispersion=True)
    local = povlens.render(SCENE, outdir=tmp_path / "local", **opts)
    dist = povlens.render(SCENE, outdir=tmp_path / "dist", scheduler=cluster.address, **opts)
    assert np.array_equal(read_image(local.image_exr), read_image(dist.image_exr))
