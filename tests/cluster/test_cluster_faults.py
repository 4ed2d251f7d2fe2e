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
from test_cluster import (START_TIMEOUT_S, Cluster, _close, _free_port,  # noqa: E402
                          render_here_and_there, two_workers)

SCENE = ROOT / "scenes" / "paper.pov"
SMALL = ["--lens", "dgauss.50mm", "--method", "mesh", "--width", "32", "--height", "24"]


@pytest.fixture(scope="module")
def cluster(tmp_path_factory):
    with two_workers(tmp_path_factory.mktemp("faults")) as c:
        yield c


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


def _checker_scene(folder: Path, elsewhere: Path) -> Path:
    """A scene whose include file and image map are reached only through links: an
    inside relative link (alias.inc -> parts/look.inc), an absolute link leaving the
    folder (parts/look.inc -> ELSEWHERE/look.inc) and a relative folder link leaving it
    (maps -> ../shared_maps)."""
    (folder / "parts").mkdir(parents=True)
    (elsewhere / "shared_maps").mkdir(parents=True)
    y, x = np.mgrid[0:16, 0:16]
    checker = ((x // 4 + y // 4) % 2).astype(np.float64)
    write_png_srgb(elsewhere / "shared_maps" / "checker.png",
                   np.stack([checker, 0.3 + 0 * checker, 1 - checker], axis=-1))
    (elsewhere / "look.inc").write_text(
        "#declare Look = texture { pigment { image_map { png \"maps/checker.png\" } "
        "translate <-0.5, -0.5, 0> scale 4 } finish { ambient 1 diffuse 0 } }\n")
    (folder / "parts" / "look.inc").symlink_to(elsewhere / "look.inc")      # absolute
    (folder / "alias.inc").symlink_to(Path("parts") / "look.inc")            # inside
    (folder / "maps").symlink_to(os.path.relpath(elsewhere / "shared_maps", folder))
    scene = folder / "main.pov"
    scene.write_text("#version 3.7;\n#include \"alias.inc\"\n"
                     "camera { location <0, 0, -6> look_at <0, 0, 0> }\n"
                     "plane { z, 0 texture { Look } }\n")
    return scene


def test_links_in_the_scene_folder_arrive_as_the_files_they_lead_to(cluster, tmp_path):
    scene = _checker_scene(tmp_path / "scene", tmp_path / "elsewhere")
    opts = dict(lens="dgauss.50mm", focus=6, method="mesh", samples=2, width=48, height=36)
    a, b = render_here_and_there(scene, cluster, tmp_path / "local", tmp_path / "dist", **opts)
    assert b[..., 0].max() > 0.5 and b[..., 2].max() > 0.5      # the map's two colours
    assert np.array_equal(a, b)                                 # group size 1: bit for bit
    key, data = make_bundle(tmp_path / "dist", read_plan(tmp_path / "dist"))
    with tarfile.open(fileobj=io.BytesIO(data)) as tar:
        members = tar.getmembers()
    assert all(m.isfile() or m.isdir() for m in members)        # no link travels
    names = {m.name for m in members}
    base = str(tmp_path / "scene").lstrip("/")
    # the files the scene names, under the names it reads them by
    assert {f"{base}/main.pov", f"{base}/alias.inc", f"{base}/maps/checker.png"} <= names
    # an include named by an expression: the folder's tree, links followed the same way
    scene.write_text(scene.read_text().replace('"alias.inc"', 'concat("alias", ".inc")'))
    files = bundle_module.bundle_files(tmp_path / "dist", read_plan(tmp_path / "dist"))
    assert "names a file by an expression ('#include concat" in files.trees_because
    assert {tmp_path / "scene" / n for n in ("alias.inc", "parts/look.inc", "maps/checker.png")
            } <= set(files.files)


def test_a_link_to_a_hidden_file_is_refused_naming_the_link(cluster, tmp_path):
    scene = tmp_path / "scene" / "s.pov"
    scene.parent.mkdir()
    scene.write_text("camera { location <0, 0, -5> look_at 0 }\n"
                     "sphere { 0, 1 pigment { rgb 1 } }\nlight_source { <0, 5, -5> rgb 1 }\n")
    (tmp_path / "home" / ".ssh").mkdir(parents=True)
    (tmp_path / "home" / ".ssh" / "id_rsa").write_text("// secret\n")
    (scene.parent / "key.inc").symlink_to(tmp_path / "home" / ".ssh" / "id_rsa")
    scene.write_text(scene.read_text() + "#include \"key.inc\"\n")
    code, err, _ = _povlens("render", str(scene), *SMALL, "--focus", "5", "--samples", "2",
                            "-q", "-o", str(tmp_path / "o"), "--scheduler", cluster.address)
    assert code == 2, err
    assert f"{scene.parent / 'key.inc'} is a link to" in err and "hidden '.ssh'" in err
    assert "running again resumes" not in err and "Traceback" not in err


def test_hidden_files_and_folders_never_travel(tmp_path):
    scene = tmp_path / "home" / "s.pov"                 # a scene in a home folder
    scene.parent.mkdir()
    scene.write_text("camera { location <0, 0, -5> look_at 0 }\n#include \"part.inc\"\n"
                     "light_source { <0, 5, -5> rgb 1 }\n")
    (scene.parent / "part.inc").write_text("sphere { 0, 1 pigment { rgb 1 } }\n")
    for hidden in (".ssh/id_rsa", ".env", "textures/.cache/big.bin", ".git/config",
                   "unread/notes.txt"):
        (scene.parent / hidden).parent.mkdir(parents=True, exist_ok=True)
        (scene.parent / hidden).write_text("secret\n")
    out = tmp_path / "o"
    povlens.convert(scene, outdir=out, lens="dgauss.50mm", focus=5, method="mesh",
                    samples=2, width=32, height=24)
    base = str(scene.parent).lstrip("/")
    text = scene.read_text()
    # the files the scene names; and, an include named by an expression, the tree
    for include, unread_sent in (('"part.inc"', False), ('concat("part", ".inc")', True)):
        scene.write_text(text.replace('"part.inc"', include))
        _, data = make_bundle(out, read_plan(out))
        with tarfile.open(fileobj=io.BytesIO(data)) as tar:
            names = tar.getnames()
        assert not [n for n in names if any(p.startswith(".") for p in n.split("/"))]
        assert f"{base}/s.pov" in names and f"{base}/part.inc" in names
        assert (f"{base}/unread/notes.txt" in names) == unread_sent
        # the size reported is what travels
        files = bundle_module.bundle_files(out, read_plan(out))
        assert files.size_bytes == sum(p.stat().st_size for p in files.files.values())
        assert len(files.files) == len([n for n in names if n != "povlens-paths.json"])
    # a scene naming a hidden file: refused, naming it
    scene.write_text(text + '#include ".ssh/id_rsa"\n')
    with pytest.raises(PovlensError, match=r"the scene reads .*id_rsa .*which is hidden"):
        make_bundle(out, read_plan(out))


def test_remove_replica_refuses_what_is_not_a_bundle_key(tmp_path, monkeypatch):
    monkeypatch.setattr(bundle_module.tempfile, "gettempdir", lambda: str(tmp_path / "tmp"))
    (tmp_path / "tmp" / "povlens-cluster").mkdir(parents=True)
    victim = tmp_path / "tmp" / "x"                      # povlens-cluster/../x
    (victim / "keep").mkdir(parents=True)
    for key in ("../x", str(victim), "", "A" * 64, "shared-0123"):
        with pytest.raises(PovlensError, match="is not a bundle key"):
            bundle_module.remove_replica(key)
    assert (victim / "keep").is_dir()
    assert bundle_module.remove_replica("a" * 64) is False        # a key, no replica


def _tar(*members) -> bytes:
    buf = io.BytesIO()
    with tarfile.open(fileobj=buf, mode="w:gz") as tar:
        for info, data in members:
            tar.addfile(info, None if data is None else io.BytesIO(data))
    return buf.getvalue()


def _member(name: str, kind=tarfile.REGTYPE, data: bytes | None = b"x", link: str = ""):
    info = tarfile.TarInfo(name)
    info.type, info.linkname = kind, link
    info.size = len(data) if kind == tarfile.REGTYPE and data else 0
    return info, data if kind == tarfile.REGTYPE else None


@pytest.mark.parametrize("bad, why", [
    (_member("/abs/evil"), "an absolute name"),
    (_member("../evil"), "a '..' in its name"),
    (_member("a/../../evil"), "a '..' in its name"),
    (_member("evil", tarfile.SYMTYPE, link="/etc"), "a link"),
    (_member("evil", tarfile.SYMTYPE, link="../../.."), "a link"),
    (_member("evil", tarfile.LNKTYPE, link="../outside"), "a link"),
    (_member("evil", tarfile.CHRTYPE), "a device"),
    (_member("evil", tarfile.FIFOTYPE), "a device"),
])
def test_unpacking_refuses_members_leaving_the_replica_without_data_filter(
        tmp_path, monkeypatch, bad, why):
    # as on Python < 3.11.4, which has no tarfile.data_filter
    monkeypatch.delattr(tarfile, "data_filter", raising=False)
    monkeypatch.setattr(bundle_module.tempfile, "gettempdir", lambda: str(tmp_path / "tmp"))
    data = _tar(_member("ok.txt"), bad)
    key = hashlib.sha256(data).hexdigest()
    with pytest.raises(PovlensError, match=f"is {why}.*nothing was unpacked"):
        bundle_module.replica_root(key, data, "/o")
    assert not (tmp_path / "evil").exists() and not (tmp_path / "tmp" / "evil").exists()
    assert not list((tmp_path / "tmp" / "povlens-cluster").iterdir())   # nothing left


def test_the_scheduler_hint_binds_to_a_named_host(tmp_path):
    address = f"tcp://127.0.0.1:{_free_port()}"            # nothing listens there
    code, err, _ = _povlens("render", str(SCENE), *SMALL, "--focus", "4", "--samples", "2",
                            "-o", str(tmp_path / "o"), "--scheduler", address,
                            "--scheduler-timeout", "1")
    assert code == 2 and "no Dask scheduler answered" in err
    assert "'dask scheduler --host HOST'" in err and "0.0.0.0" not in err


def _self_signed(folder: Path) -> list[str]:
    """A certificate for 127.0.0.1 that is its own CA, and its key: the TLS options of
    ``dask scheduler`` and ``dask worker``."""
    import ipaddress
    from cryptography import x509
    from cryptography.hazmat.primitives import hashes, serialization
    from cryptography.hazmat.primitives.asymmetric import ec
    from cryptography.x509.oid import NameOID
    key = ec.generate_private_key(ec.SECP256R1())
    name = x509.Name([x509.NameAttribute(NameOID.COMMON_NAME, "povlens-test")])
    now = datetime.datetime.now(datetime.timezone.utc)
    cert = (x509.CertificateBuilder().subject_name(name).issuer_name(name)
            .public_key(key.public_key()).serial_number(x509.random_serial_number())
            .not_valid_before(now - datetime.timedelta(hours=1))
            .not_valid_after(now + datetime.timedelta(days=1))
            .add_extension(x509.BasicConstraints(ca=True, path_length=None), critical=True)
            .add_extension(x509.SubjectAlternativeName(
                [x509.DNSName("localhost"), x509.IPAddress(ipaddress.ip_address("127.0.0.1"))]),
                critical=False)
            .sign(key, hashes.SHA256()))
    (folder / "cert.pem").write_bytes(cert.public_bytes(serialization.Encoding.PEM))
    (folder / "key.pem").write_bytes(key.private_bytes(
        serialization.Encoding.PEM, serialization.PrivateFormat.PKCS8,
        serialization.NoEncryption()))
    return ["--tls-ca-file", str(folder / "cert.pem"), "--tls-cert", str(folder / "cert.pem"),
            "--tls-key", str(folder / "key.pem")]


class TlsCluster(Cluster):
    """A scheduler and a worker speaking TLS on 127.0.0.1 (the README's recipe)."""

    def __init__(self, tmp: Path):
        self.tmp, self.procs = tmp, []
        self.tls = _self_signed(tmp)
        port = _free_port()
        self.address = f"tls://127.0.0.1:{port}"
        self.env = dict(os.environ, TMPDIR=str(tmp / "workers"))
        (tmp / "workers").mkdir()
        self.scheduler = self._start("dask_scheduler", "--host", "127.0.0.1", "--port",
                                     str(port), "--protocol", "tls", *self.tls,
                                     "--no-dashboard")

    def add_worker(self):
        return self._start("dask_worker", self.address, "--nthreads", "1", "--no-nanny",
                           "--no-dashboard", "--host", "127.0.0.1", *self.tls,
                           "--local-directory", str(self.tmp / "workers"))

    def wait_for_workers(self, n: int) -> None:
        from distributed import Client, Security
        ca, cert, key = self.tls[1], self.tls[3], self.tls[5]
        security = Security(tls_ca_file=ca, tls_client_cert=cert, tls_client_key=key,
                            require_encryption=True)
        with Client(self.address, timeout=f"{START_TIMEOUT_S}s", set_as_default=False,
                    security=security) as c:
            c.wait_for_workers(n, timeout=START_TIMEOUT_S)


def test_a_tls_scheduler_through_dasks_own_configuration(tmp_path):
    tls = TlsCluster(tmp_path)
    try:
        tls.add_worker()
        tls.wait_for_workers(1)
        args = ["render", str(SCENE), *SMALL, "--focus", "4", "--samples", "2", "-q",
                "--scheduler", tls.address, "--scheduler-timeout", "5"]
        # without the client's TLS settings: a clear error, before converting
        env = {k: v for k, v in os.environ.items() if not k.startswith("DASK_")}
        code, err, _ = _povlens(*args, "-o", str(tmp_path / "none"), env=env)
        assert code == 2 and "a tls:// scheduler, but Dask has no TLS configuration" in err
        assert "DASK_DISTRIBUTED__COMM__TLS__CA_FILE" in err and "Traceback" not in err
        # with them, as Dask reads them (distributed.comm.tls.*): rendered
        env.update(DASK_DISTRIBUTED__COMM__TLS__CA_FILE=tls.tls[1],
                   DASK_DISTRIBUTED__COMM__TLS__CLIENT__CERT=tls.tls[3],
                   DASK_DISTRIBUTED__COMM__TLS__CLIENT__KEY=tls.tls[5])
        code, err, _ = _povlens(*args, "-o", str(tmp_path / "o"), env=env)
        assert code == 0, err
        local = povlens.render(SCENE, outdir=tmp_path / "local", lens="dgauss.50mm", focus=4,
                               method="mesh", samples=2, width=32, height=24)
        assert _close(read_image(tmp_path / "o" / "image.exr"), read_image(local.image_exr))
    finally:
        tls.stop()
