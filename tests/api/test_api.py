"""The package-root API, used as a script would (the README's example)."""
from __future__ import annotations

import math

import numpy as np
import pytest

import povlens
from conftest import ROOT


def test_read_lens_and_focus():
    lens = povlens.read_lens("dgauss.50mm")
    assert isinstance(lens, povlens.LensPrescription)
    near = povlens.focus(lens, 4, units="m")
    far = povlens.focus("dgauss.50mm", math.inf)
    # focusing nearer moves the film away from the lens
    assert near.exact_film_distance_mm > far.exact_film_distance_mm > 0


def test_focus_rejects_an_unknown_unit():
    with pytest.raises(povlens.ParameterError) as e:
        povlens.focus("dgauss.50mm", 4, units="furlong")
    assert e.value.parameter == "units"


def test_convert_rejects_an_unknown_option(tmp_path):
    with pytest.raises(povlens.ParameterError) as e:
        povlens.convert(ROOT / "scenes" / "paper.pov", lens="dgauss.50mm", focus=4,
                        outdir=tmp_path, method="pinhole", sampels=4)
    assert e.value.parameter == "sampels"


def test_render_composite_and_compare(tmp_path):
    scene = ROOT / "scenes" / "paper.pov"
    mesh = povlens.render(scene, lens="dgauss.50mm", focus=4, outdir=tmp_path / "mesh",
                          method="mesh", samples=4, width=48, height=36)
    assert mesh.image_exr.exists() and mesh.image_png.exists()
    assert mesh.plan.inputs.method == "mesh"
    pin = povlens.render(scene, lens="dgauss.50mm", focus=4, outdir=tmp_path / "pin",
                         method="pinhole", width=48, height=36)
    again = povlens.composite(tmp_path / "mesh")
    assert again.shape == (36, 48, 3) and np.isfinite(again).all()
    same = povlens.compare(mesh.image_exr, mesh.image_exr)
    assert same["rmse"] == 0
    diff = povlens.compare(pin.image_exr, mesh.image_exr)
    # the same view: close, but a real lens is not a pinhole
    assert 0 < diff["rmse"] < 0.5


def test_api_names_survive_the_import_of_every_subpackage():
    # a subpackage named like an API function would replace it on import
    import importlib
    import pkgutil
    for mod in pkgutil.walk_packages(povlens.__path__, "povlens."):
        if not mod.name.endswith("__main__"):
            importlib.import_module(mod.name)
    for name in povlens.__all__:
        if name != "__version__":
            assert not isinstance(getattr(povlens, name), type(povlens)), name


def test_compare_names_an_image_with_non_finite_pixels(tmp_path):
    """The API's compare refuses a NaN image by name, as the command does (issue 24)."""
    import numpy as np
    from povlens.report.compare import CompareError
    from povlens.util.images import write_exr

    a = np.full((6, 8, 3), 0.5, np.float32)
    b = a.copy()
    b[2, 3, 1] = np.nan
    path = write_exr(tmp_path / "broken.exr", b)
    assert povlens.compare(a, a)["rmse"] == 0.0
    with pytest.raises(CompareError, match=r"broken\.exr holds 1 non-finite pixel"):
        povlens.compare(a, path)
