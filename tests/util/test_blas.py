"""BLAS on one thread while povlens works (util/blas.py)."""
from __future__ import annotations

import os

import numpy as np
from threadpoolctl import threadpool_info

import povlens
from conftest import ROOT
from povlens.util.blas import one_blas_thread


def _blas_threads() -> list[int]:
    return [i["num_threads"] for i in threadpool_info() if i["user_api"] == "blas"]


def test_one_blas_thread_limits_and_restores(monkeypatch):
    monkeypatch.setenv("OPENBLAS_NUM_THREADS", "7")
    np.linalg.cholesky(np.eye(3))          # numpy's BLAS is loaded
    before = _blas_threads()
    assert before
    with one_blas_thread():
        assert _blas_threads() == [1] * len(before)
        assert os.environ["OPENBLAS_NUM_THREADS"] == "1"    # a BLAS loaded now starts so
    assert _blas_threads() == before
    assert os.environ["OPENBLAS_NUM_THREADS"] == "7"


def test_a_render_runs_its_linear_algebra_on_one_thread(tmp_path):
    seen = []
    before = _blas_threads()
    result = povlens.render(ROOT / "scenes" / "paper.pov", lens="dgauss.50mm", focus=4,
                            outdir=tmp_path / "r", method="mesh", samples=2, width=48,
                            height=36, on_plan=lambda plan: seen.append(_blas_threads()))
    assert result.image_exr.is_file()
    assert seen and all(n == 1 for n in seen[0])
    assert _blas_threads() == before
