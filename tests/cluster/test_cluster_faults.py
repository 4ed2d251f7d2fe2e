"""Faults of the Dask cluster (issue 24 item 7): a failed task's POV-Ray stopped
before its folder goes, links and hidden files in the scene's folder, replica keys,
bundle members, the scheduler hint and TLS.  A scheduler and two workers on
127.0.0.1 (test_cluster.Cluster), tiny images, every wait bounded."""

from __future__ import annotations

import datetime
import hashlib
import io
import os
import shutil
import subprocess
import sys
import tarfile
import time
from pathlib import Path

import numpy as np
import pytest

pytest.importorskip("distributed")
pytestmark = pytest.mark.skipif(shutil.which("povray") is None, reason="POV-Ray not installed")

import povlens                                                    # noqa: E402
from povlens.cluster import bundle as bundle_module               # noqa: E402
from povlens.cluster.bundle import make_bundle                    # noqa: E402
from povlens.cluster.client import render_outdir_on_cluster       # noqa: E402
from povlens.errors import PovlensError, PovrayError              # noqa: E402
from povlens.plan.schema import read_plan                         # noqa: E402
from povlens.util.images import read_image, write_png_srgb        # noqa: E402

from conftest import ROOT                                         # noqa: E402
from test_cluster import START_TIMEOUT_S, Cluster, _close, _free_port  # noqa: E402

SCENE = ROOT / "scenes" / "paper.pov"
SMALL = ["--lens", "dgauss.50mm", "--method", "mesh", "--width", "32", "--height", "24"]


@pytest.fixture(scope="module")
def cluster(tmp_path_factory):
    c = Cluster(tmp_path_factory.mktemp("faults"))
    try:
        c.add_worker()
        c.add_worker()
        c.wait_for_workers(2)
        yield c
    finally:
        c.stop()


def _povlens(*args: str, env: dict | None = None, timeout_s: float = 120):
    """The povlens command in a subprocess: (exit code, stderr, seconds)."""
    t0 = time.perf_counter()
    r = subprocess.run([sys.executable, "-m", "povlens", *args], capture_output=True,
                       text=True, timeout=timeout_s, env=env, cwd=ROOT)
    return r.returncode, r.stderr, time.perf_counter() - t0


def _povray_under(cluster: Cluster) -> list:
    """The POV-Ray processes the cluster's workers started."""
    import psutil
    found = []
    for p in cluster.procs:
        try:
            found += [c for c in psutil.Process(p.pid).children(recursive=True)
                      if "povray" in c.name()]
        except psutil.Error:
            pass
    return found


def test_a_failed_task_leaves_no_povray_running_and_the_next_render_works(cluster, tmp_path):
    # sample 0 fails at once; sample 1's POV-Ray parses for about a minute: when the
    # client gives up on the render, that POV-Ray must be stopped, not left spinning in
    # a deleted replica with the worker's only thread waiting for it
    scene = tmp_path / "scene" / "fails.pov"
    scene.parent.mkdir()
    body = ("camera { location <0, 0, -5> look_at 0 }\nsphere { 0, 1 pigment { rgb 1 } }\n"
            "light_source { <0, 5, -5> rgb 1 }\n")
    scene.write_text(body)
    out = tmp_path / "o"
    povlens.convert(scene, outdir=out, lens="dgauss.50mm", focus=5, method="mesh",
                    samples=2, width=32, height=24)
    scene.write_text("#version 3.7;\n#ifdef (PovlensFrame)\n#if (PovlensFrame = 0)\n"
                     "#error \"sample 0 fails on purpose\"\n#end\n#end\n"
                     "#declare I = 0; #while (I < 60000000) #declare I = I + 1; #end\n" + body)
    t0 = time.perf_counter()
    with pytest.raises(PovrayError, match="lens sample 0 on worker"):
        render_outdir_on_cluster(out, cluster.address, group_size=1, quiet=True)
    assert time.perf_counter() - t0 < 45                  # bounded, not a minute's parse
    deadline = time.monotonic() + 10
    while _povray_under(cluster) and time.monotonic() < deadline:
        time.sleep(0.1)
    assert not _povray_under(cluster), "a POV-Ray process outlived its render"
    # the same workers render the next job (the command, as a user would run it)
    code, err, seconds = _povlens("render", str(SCENE), *SMALL, "--focus", "4", "--samples",
                                  "4", "-q", "-o", str(tmp_path / "next"), "--scheduler",
                                  cluster.address, "--group-size", "1", timeout_s=120)
    assert code == 0, err
    assert (tmp_path / "next" / "image.exr").exists() and not _povray_under(cluster)
    assert not list((cluster.tmp / "workers" / "povlens-cluster").glob("[0-9a-f]*"))
