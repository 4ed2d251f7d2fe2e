"""One photon map for every lens sample of a mesh render.

A mesh render runs POV-Ray once per lens sample, and each run of a scene with photons
shoots them again; the photon map depends on the scene's lights and objects, not on the
camera (issue 25). So one small pinhole render shoots them and saves the map, and every
lens sample loads it. POV-Ray 3.7 saves and loads a map through the ``photons`` block
of ``global_settings`` (``save_file`` / ``load_file``), and a second such block after
the scene replaces the scene's photons settings whole, so the wrappers repeat the
scene's own items before the file name (:func:`povlens.pov.mesh.photon_map_block`;
the plan records them, ``plan.povray.photon_settings``). Measured on
``lights/glassthing.pov`` (POV-Ray 3.7.0.10): the saving render shoots the scene's
29,127 photons, and a render loading the map is identical to the scene's own render
(RMSE 0); on ``advanced/grenadine/grenadine.pov`` the photons are 4.3 s of a 7.1 s
render at 320x240.

The map does not depend on the image's size: the saving render is
:data:`MAP_RENDER_SIZE` pixels. It writes under a name of its own
(``RenderFolder.photon_map_partial``) and the file is renamed into place when
complete, so renders racing to make it waste time, never read half a map.
"""

from __future__ import annotations

import os
import secrets
from pathlib import Path

from povlens.plan.render_folder import RenderFolder
from povlens.plan.schema import Plan
from povlens.plan.options import povray_options_of
from povlens.rendering.pinhole_products import (PinholeProduct, cancel_product, product_ready,
                                                start_product, wait_product)

__all__ = ["photon_map_for", "photon_load_args", "start_photon_map", "photon_map_ready",
           "cancel_photon_map", "MAP_RENDER_SIZE"]

#: The size of the render that shoots and saves the photon map, pixels.
MAP_RENDER_SIZE = (32, 24)


def photon_map_for(plan: Plan, outdir: str | os.PathLike) -> Path | None:
    """The folder's photon map, shot now if the plan shares one and it is missing;
    None when the plan does not share one.

    Parameters
    ----------
    plan : the folder's plan.
    outdir : the render folder.

    Returns
    -------
    Path or None
        ``RenderFolder(outdir).photon_map``, made by one render of the folder's
        ``pinhole.pov`` (its photons block saving) at :data:`MAP_RENDER_SIZE`, or by
        the one :func:`start_photon_map` started, waited for.
    """
    if not plan.povray.photon_settings:
        return None
    start_photon_map(outdir, plan.inputs.scene, povray_options_of(plan.inputs))
    return wait_product(RenderFolder(outdir).photon_map)


def _start(outdir, scene, povray_options) -> PinholeProduct:
    """The render shooting the folder's photons and saving their map."""
    folder = RenderFolder(outdir)
    number = 100_000 + secrets.randbelow(900_000)   # six digits: SDL's str() prints it whole
    flag = RenderFolder.photon_map_names()["save_flag"]
    return PinholeProduct(outdir, folder.photon_map_partial(number), folder.photon_map,
                          MAP_RENDER_SIZE, [f"Declare={flag}={number}"], scene,
                          povray_options)


def start_photon_map(outdir: str | os.PathLike, scene: str, povray_options) -> None:
    """Start shooting the folder's photons (its ``pinhole.pov`` written with the photons
    block that saves them) unless the map is in place or being shot, and return at
    once: :func:`photon_map_for` waits for it,
    :func:`photon_map_ready` says whether it is done, :func:`cancel_photon_map` stops
    it.  ``povlens render`` starts it as soon as the scene and camera are read
    (``lights/glassthing.pov``: 0.6 s, while the plan and the first meshes take 1 s)."""
    start_product(RenderFolder(outdir).photon_map,
                  lambda: _start(outdir, scene, povray_options))


def photon_map_ready(plan: Plan, outdir: str | os.PathLike) -> bool:
    """False while the photons :func:`start_photon_map` started are being shot; never
    blocks."""
    return not plan.povray.photon_settings or product_ready(RenderFolder(outdir).photon_map)


def cancel_photon_map(outdir: str | os.PathLike) -> None:
    """Stop shooting the photons :func:`start_photon_map` started, if nothing waited
    for them."""
    cancel_product(RenderFolder(outdir).photon_map)


def photon_load_args(photon_map: Path | None) -> list[str]:
    """POV-Ray's switches that make a lens sample's wrapper load ``photon_map`` (none
    without one)."""
    if photon_map is None:
        return []
    return [f"Declare={RenderFolder.photon_map_names()['load_flag']}=1"]
