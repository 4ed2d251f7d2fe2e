"""Lens samples on a Dask cluster (povlens.cluster): a ``dask scheduler`` and two
``dask worker`` processes started here on 127.0.0.1 (no nanny, one thread each), every
wait bounded, every process killed at the end.  The renders are tiny (80x60)."""

from __future__ import annotations

import contextlib
import json
import os
import shutil
import signal
import socket
import subprocess
import sys
import threading
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
from povlens.cluster.client import render_outdir_on_cluster, task_samples  # noqa: E402
from povlens.errors import ParameterError, PovlensError, PovrayError  # noqa: E402
from povlens.plan.schema import read_plan                         # noqa: E402
from povlens.rendering.groups import write_group                  # noqa: E402
from povlens.rendering.mesh_samples import render_batch  # noqa: E402
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


@contextlib.contextmanager
def two_workers(folder: Path):
    """A scheduler and two workers (:class:`Cluster`) for the block, killed after it."""
    c = Cluster(folder)
    try:
        c.add_worker()
        c.add_worker()
        c.wait_for_workers(2)
        yield c
    finally:
        c.stop()


def render_here_and_there(scene: Path, cluster: Cluster, here: Path, there: Path,
                          group_size: int = 1, **opts) -> tuple[np.ndarray, np.ndarray]:
    """The images of ``scene`` rendered on this machine (into ``here``) and on
    ``cluster`` (into ``there``), with the same options."""
    local = povlens.render(scene, outdir=here, **opts)
    remote = povlens.render(scene, outdir=there, scheduler=cluster.address,
                            group_size=group_size, **opts)
    return read_image(local.image_exr), read_image(remote.image_exr)


@pytest.fixture(scope="module")
def cluster(tmp_path_factory):
    with two_workers(tmp_path_factory.mktemp("cluster")) as c:
        yield c


@pytest.fixture(scope="module")
def local_image(tmp_path_factory) -> np.ndarray:
    """The reference: the same render on this machine, without Dask."""
    out = tmp_path_factory.mktemp("local") / "o"
    povlens.render(SCENE, outdir=out, **RENDER)
    return read_image(out / "image.exr")


def _timing(outdir: Path) -> dict:
    return json.loads((outdir / "samples" / "cluster.timing.json").read_text())


def _close(image: np.ndarray, reference: np.ndarray) -> bool:
    """Equal within the float32 rounding of the groups' partial sums."""
    return (image.shape == reference.shape and reference.max() > 0
            and np.abs(image - reference).max() <= 1e-5 * reference.max())


def test_groups_through_two_workers_equal_the_local_render(cluster, local_image, tmp_path):
    out = tmp_path / "o"
    result = povlens.render(SCENE, outdir=out, scheduler=cluster.address, group_size=2,
                            **RENDER)
    image = read_image(result.image_exr)
    assert _close(image, local_image)
    stats = _timing(out)
    assert stats["group_size"] == 2
    assert sorted(t["ks"] for t in stats["tasks"]) == [[0, 1], [2, 3], [4, 5]]
    assert all(t["in_flight"] >= 2 for t in stats["tasks"])   # several POV-Ray at once
    files = sorted(p.name for p in (out / "samples").glob("group_*.npz"))
    assert files == ["group_0000_0002.npz", "group_0002_0004.npz", "group_0004_0006.npz"]
    assert not list((out / "samples").glob("sample_*.exr"))    # no per-sample images back
    # povlens composite (here, no cluster) reads the group files: the same image
    assert np.array_equal(povlens.composite(out).astype(np.float32), image)


def test_a_render_through_two_workers_equals_the_local_render(cluster, local_image, tmp_path):
    out = tmp_path / "o"
    result = povlens.render(SCENE, outdir=out, scheduler=cluster.address, group_size=1,
                            **RENDER)
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
    assert _timing(out)["group_size"] == 2                 # 6 samples, 2 workers: 3 groups
    assert _close(read_image(out / "image.exr"), local_image)


def test_a_worker_killed_mid_render_loses_nothing(cluster, local_image, tmp_path):
    from distributed import Client
    victim = cluster.add_worker()
    cluster.wait_for_workers(3)
    in_flight = []

    with Client(cluster.address, timeout="30s", set_as_default=False) as monitor:
        [addr] = [a for a, pid in monitor.run(os.getpid).items() if pid == victim.pid]

        def kill_when_busy():
            # as soon as the victim is rendering a group, kill it
            deadline = time.monotonic() + 60
            while time.monotonic() < deadline and not in_flight and not done.is_set():
                busy = monitor.processing([addr]).get(addr, [])
                if busy:
                    in_flight.extend(busy)
                    os.killpg(victim.pid, signal.SIGKILL)
                    victim.wait(timeout=30)
                time.sleep(0.01)

        # the scheduler may leave the victim idle through a render (the other workers
        # took its groups first, as under the load of a parallel test run): render again
        # into a fresh folder until it was killed mid-render
        for attempt in range(4):
            out = tmp_path / f"o{attempt}"
            povlens.convert(SCENE, outdir=out, **RENDER)
            done = threading.Event()
            killer = threading.Thread(target=kill_when_busy, daemon=True)
            killer.start()
            _, stats = render_outdir_on_cluster(out, cluster.address, group_size=2)
            done.set()
            killer.join(timeout=60)
            if in_flight:
                break
    assert in_flight, "the victim had no group in flight when it was killed"
    tasks = stats["tasks"]
    lost = {tuple(task_samples(key)) for key in in_flight}
    # the victim's groups in flight were rendered again, by the others
    assert lost and all(t["pid"] != victim.pid for t in tasks if tuple(t["ks"]) in lost)
    assert sorted(t["ks"] for t in tasks) == [[0, 1], [2, 3], [4, 5]]
    assert _close(read_image(out / "image.exr"), local_image)


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
    povlens.convert(scene, outdir=tmp_path / "dist", **opts)
    base = cluster.tmp / "workers" / "povlens-cluster"
    replicas = []

    def look(task):        # while the render runs: the workers' copies
        replicas.extend((r, (r / "parts" / "look.inc").is_file()
                         and (r / "maps" / "checker.png").is_file() and not (r / "local").exists())
                        for r in base.glob("*/" + str(tmp_path / "scene").lstrip("/")))

    exr, stats = render_outdir_on_cluster(tmp_path / "dist", cluster.address, on_sample=look)
    a, b = read_image(local.image_exr), read_image(exr)
    assert b[..., 0].max() > 0.5 and b[..., 2].max() > 0.5     # the map's two colours
    assert _close(b, a)
    # the workers rendered from their own copy, which holds the include and the map
    # (and not the local render folder inside the scene's folder)
    assert replicas and all(complete for _, complete in replicas)
    # and deleted it when the render ended
    key = make_bundle(tmp_path / "dist", read_plan(tmp_path / "dist"))[0]
    assert not (base / key).exists() and not any(r.exists() for r, _ in replicas)


def test_an_interrupted_cluster_render_resumes_here(cluster, local_image, tmp_path):
    out = tmp_path / "o"
    povlens.convert(SCENE, outdir=out, **RENDER)
    done = []

    def interrupt(task):
        done.append(task["ks"])
        raise KeyboardInterrupt

    with pytest.raises(KeyboardInterrupt):
        render_outdir_on_cluster(out, cluster.address, on_sample=interrupt, group_size=2)
    [ks] = done
    assert [p.name for p in (out / "samples").glob("group_*.npz")] == [
        f"group_{ks[0]:04d}_{ks[-1] + 1:04d}.npz"]
    result = povlens.render(SCENE, outdir=out, **RENDER)         # locally, resumed
    # the group's samples were not rendered again
    assert json.loads((out / "samples" / "render.timing.json").read_text())["samples"] == 4
    assert not any((out / "samples" / f"sample_{k:04d}.exr").exists() for k in ks)
    assert _close(read_image(result.image_exr), local_image)


def test_a_cluster_render_resumes_from_samples_and_groups(cluster, local_image, tmp_path):
    out = tmp_path / "o"
    povlens.convert(SCENE, outdir=out, batch_size=2, **RENDER)
    assert render_batch(out, 1) == [1, 4]                  # samples 1 and 4 rendered here
    _, stats = render_outdir_on_cluster(out, cluster.address, group_size=4)
    # only what was missing, in runs of consecutive samples
    assert sorted(t["ks"] for t in stats["tasks"]) == [[0], [2, 3], [5]]
    assert _close(read_image(out / "image.exr"), local_image)
    _, stats = render_outdir_on_cluster(out, cluster.address)      # all done: no task
    assert stats["samples"] == 0
    write_group(out, [2, 3], b"not a group file")          # damaged: an error naming it
    with pytest.raises(PovlensError, match="group_0002_0004.npz: cannot read"):
        povlens.composite(out)


def test_shared_dir_writes_the_samples_in_place_through_a_client(cluster, local_image,
                                                                 tmp_path):
    from distributed import Client
    out = tmp_path / "o"
    with Client(cluster.address, timeout="30s", set_as_default=False) as client:
        povlens.render(SCENE, outdir=out, scheduler=client, shared_dir=True, **RENDER)
        assert client.status == "running"                # the caller's client: left open
    assert _timing(out)["bundle_bytes"] == 0
    assert _close(read_image(out / "image.exr"), local_image)


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
    # a focus pull too: before its first frame
    args[args.index("--focus") + 1] = "2:6"
    args[args.index("-o") + 1] = str(tmp_path / "f")
    assert main(args + ["--frames", "2"]) == 2
    assert "no Dask scheduler answered" in capsys.readouterr().err
    assert not (tmp_path / "f" / "frames.json").exists()


@pytest.mark.parametrize("extra, message", [
    (["--scheduler", "nonsense"], "--scheduler nonsense: not a scheduler address"),
    (["--shared-dir"], "--shared-dir needs --scheduler"),
    (["--group-size", "2"], "--group-size needs --scheduler"),
])
def test_bad_cluster_options_through_the_cli(tmp_path, capsys, monkeypatch, extra, message):
    monkeypatch.delenv("POVLENS_SCHEDULER", raising=False)
    args = ["render", str(SCENE), "--lens", "dgauss.50mm", "--focus", "4", "--method", "mesh",
            "--samples", "2", "--width", "32", "--height", "24", "-o", str(tmp_path / "c"),
            *extra]
    assert main(args) == 2
    err = capsys.readouterr().err
    assert message in err and "Traceback" not in err


def test_a_group_size_below_one_is_refused_by_the_cli(tmp_path, capsys):
    args = ["render", str(SCENE), "--lens", "dgauss.50mm", "--focus", "4", "-o",
            str(tmp_path / "c"), "--scheduler", "tcp://127.0.0.1:1", "--group-size", "0"]
    assert main(args) == 2                             # the option's own check, as a flag
    assert "--group-size 0: must be at least 1" in capsys.readouterr().err


def test_shared_dir_without_a_scheduler_through_the_api(tmp_path, monkeypatch):
    monkeypatch.delenv("POVLENS_SCHEDULER", raising=False)
    with pytest.raises(ParameterError, match="'shared_dir' needs 'scheduler'"):
        povlens.render(SCENE, outdir=tmp_path / "o", shared_dir=True, **RENDER)
    with pytest.raises(ParameterError, match="'group_size' needs 'scheduler'"):
        povlens.render(SCENE, outdir=tmp_path / "o", group_size=2, **RENDER)
    with pytest.raises(ParameterError, match="'group_size' needs 'scheduler'"):
        povlens.render_frames(SCENE, outdir=tmp_path / "f", group_size=2, frames=2,
                              focus=(2, 4), **{k: v for k, v in RENDER.items() if k != "focus"})


def test_a_bad_group_size_is_a_clear_error(cluster, tmp_path):
    out = tmp_path / "o"
    povlens.convert(SCENE, outdir=out, lens="dgauss.50mm", focus=4, method="mesh", samples=2,
                    width=32, height=24)
    with pytest.raises(ParameterError, match="group_size=0: not a whole number >= 1") as e:
        render_outdir_on_cluster(out, cluster.address, group_size=0)
    assert e.value.parameter == "group_size"


def test_a_new_replica_deletes_the_stale_ones_a_killed_worker_left(tmp_path, monkeypatch):
    """A replica whose render's end never reached this machine (its worker was killed)
    is deleted when the next replica is unpacked, once untouched for a day; one in use
    is touched by every task and stays."""
    out = tmp_path / "o"
    povlens.convert(SCENE, outdir=out, lens="dgauss.50mm", focus=4, method="mesh", samples=2,
                    width=32, height=24)
    key, data = make_bundle(out, read_plan(out))
    monkeypatch.setattr(bundle_module.tempfile, "gettempdir", lambda: str(tmp_path / "tmp"))
    base = tmp_path / "tmp" / "povlens-cluster"
    old = time.time() - bundle_module.STALE_REPLICA_S - 60
    stale, busy, fresh, half = (base / n for n in ("a" * 64, "b" * 64, "c" * 64, ".dddd.x1"))
    for d in (stale, busy, fresh, half):
        (d / "samples").mkdir(parents=True)
    for d in (stale, busy, half):
        os.utime(d, (old, old))
    assert bundle_module.replica_root("b" * 64, b"", str(out)) == busy   # in use: touched
    root = bundle_module.replica_root(key, data, str(out))               # unpacks: prunes
    assert (root / "plan.json").exists() or any(root.rglob("plan.json"))
    assert not stale.exists() and not half.exists()
    assert busy.exists() and fresh.exists()
    assert bundle_module.remove_replica(key) and not root.exists()


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
    assert _close(read_image(dist.image_exr), read_image(local.image_exr))


def test_a_focus_pull_on_the_cluster_equals_the_local_pull(cluster, tmp_path, capsys,
                                                           monkeypatch):
    monkeypatch.delenv("POVLENS_SCHEDULER", raising=False)
    opts = dict(lens="dgauss.50mm", method="mesh", samples=4, width=48, height=36)
    local = povlens.render_frames(SCENE, outdir=tmp_path / "local", focus=(2, 6), frames=2,
                                  **opts)
    args = ["render", str(SCENE), "--lens", "dgauss.50mm", "--focus", "2:6", "--frames", "2",
            "--method", "mesh", "--samples", "4", "--width", "48", "--height", "36",
            "-o", str(tmp_path / "dist"), "--scheduler", cluster.address, "--group-size", "1"]
    assert main(args) == 0
    assert "image.0002.exr" in capsys.readouterr().out
    a = [read_image(p) for p in local.images_exr]
    b = [read_image(tmp_path / "dist" / f"image.{i:04d}.exr") for i in (1, 2)]
    assert not np.array_equal(a[0], a[1])                  # the focus moved
    assert all(np.array_equal(x, y) for x, y in zip(a, b))  # group size 1: bit for bit
    for i in (1, 2):                                        # each frame went to the cluster
        assert _timing(tmp_path / "dist" / f"frame-{i:04d}")["samples"] == 4
    grouped = povlens.render_frames(SCENE, outdir=tmp_path / "api", focus=(2, 6), frames=2,
                                    scheduler=cluster.address, **opts)
    assert all(_close(read_image(p), x) for p, x in zip(grouped.images_exr, a))


def test_a_scene_under_an_odd_path_renders_on_the_workers_as_here(cluster, tmp_path):
    """Spaces and non-ASCII letters in the scene's folder, its include folder and the
    render folder (issue 24 item 2, on the cluster): the workers' copy renders the image
    the local render does."""
    folder = tmp_path / "mes scènes" / "boîte à 'outils'"
    scene = _scene_with_include_and_map(folder)
    # (POV-Ray reads a scene's strings as ASCII: the include's own name has a space only)
    (folder / "parts").rename(folder / "parts dir")
    scene.write_text(scene.read_text().replace('"parts/look.inc"', '"parts dir/look.inc"'))
    opts = dict(lens="dgauss.50mm", focus=6, method="mesh", samples=3, width=80, height=60)
    a, b = render_here_and_there(scene, cluster, tmp_path / "ici é", tmp_path / "là bas",
                                 **opts)
    assert a[..., 0].max() > 0.5 and a[..., 2].max() > 0.5     # the map's two colours
    assert np.array_equal(a, b)


def test_the_shared_radiosity_travels_with_the_bundle(cluster, tmp_path):
    """A radiosity scene (issue 25): the client computes the pretrace's radiosity samples
    once and they travel with the bundle, so no worker redoes them; the image is the
    local render's within radiosity's noise (the two pretraces ran separately)."""
    import io
    import tarfile
    from tests.rendering.test_radiosity_cache import RADIOSITY_SCENE
    scene = tmp_path / "rad.pov"
    scene.write_text(RADIOSITY_SCENE)
    opts = dict(lens="dgauss.50mm", method="mesh", samples=4, width=48, height=36)
    out = tmp_path / "there"
    a, b = render_here_and_there(scene, cluster, tmp_path / "here", out, group_size=2, **opts)
    assert (out / "radiosity.rca").stat().st_size > 0
    _, data = make_bundle(out, read_plan(out))
    with tarfile.open(fileobj=io.BytesIO(data)) as tar:
        assert any(n.endswith("/radiosity.rca") for n in tar.getnames())
    assert abs(b[..., :3].mean() / a[..., :3].mean() - 1.0) < 0.03
