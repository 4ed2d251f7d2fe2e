"""POV-Ray cost of distribution-3 meshes on scenes/paper.pov, one thread."""
import sys, time, json
from pathlib import Path
import numpy as np
from lensfield import load_setup, bounding_disc_radius_mm, pupil_point
from mesh3 import uv_model, build_mesh, encode, mesh_text, camera_text, fit_normals
from vignette import sample_weights_fast as sample_weights
from povrun import run

SCENE = 'scenes/paper.pov'
WORK = Path('timing'); WORK.mkdir(exist_ok=True)

def wrapper(body):
    return f'#include "{SCENE}"\n#declare PovlensSceneVersion = version;\n#version 3.7;\n' + body

def focal_blur(s, W, H, N):
    pc = s.plan['povray_camera']
    pl = s.placement
    C = pl.film_centre + pl.forward * s.plan['thin_lens']['centre_z_mm'] / pl.mm_per_unit
    R = pl.basis
    right = np.array(pc['right'])[0] * R[0] * (W / H) / (640 / 480)
    up = np.array(pc['up'])[1] * R[1]
    body = (f"camera {{ perspective location <{C[0]:.17g},{C[1]:.17g},{C[2]:.17g}> "
            f"direction <{R[2][0]:.17g},{R[2][1]:.17g},{R[2][2]:.17g}> "
            f"right <{right[0]:.17g},{right[1]:.17g},{right[2]:.17g}> up <{up[0]:.17g},{up[1]:.17g},{up[2]:.17g}>\n")
    if N:
        fp = C + pc['focal_distance'] * R[2]
        body += f" aperture {pc['aperture']:.17g} focal_point <{fp[0]:.17g},{fp[1]:.17g},{fp[2]:.17g}> blur_samples {N}, {N}\n"
    body += "}\n"
    pov = WORK / f'fb{N}_{W}.pov'
    pov.write_text(wrapper(body))
    return run(pov, WORK / f'fb{N}_{W}.png', [f'+W{W}', f'+H{H}'])

def mesh_render(s, W, H, G, eps=0.01, u=(0.5, 0.5), fit=True, tag='m', weights=True):
    model = uv_model(W, H, 0.37, 0.61)
    RB = bounding_disc_radius_mm(s.table); A = np.pi * RB * RB
    P = pupil_point(u, RB)
    t0 = time.perf_counter()
    m = build_mesh(s, P, model, G, area_mm2=A)
    t1 = time.perf_counter()
    e = encode(m, s.placement.basis, eps)
    if fit:
        e = fit_normals(s, P, m, e, model)
    t2 = time.perf_counter()
    inc = WORK / f'{tag}.inc'
    inc.write_text(mesh_text('M', m, e))
    t3 = time.perf_counter()
    if weights:
        w, st = sample_weights(s, P, m, model, A)
    t4 = time.perf_counter()
    pov = WORK / f'{tag}.pov'
    pov.write_text(wrapper(f'#include "{inc.name}"\n' + camera_text('M', e)))
    r = run(pov, WORK / f'{tag}.exr', model.povray_switches() + ['+FE'])
    r.update(trace_s=t1 - t0, fit_s=t2 - t1, write_s=t3 - t2, weights_s=t4 - t3, faces=len(m.faces),
             inc_bytes=inc.stat().st_size)
    return r

if __name__ == '__main__':
    W, H = int(sys.argv[1]), int(sys.argv[2])
    s = load_setup('conv_dgauss.50mm_640').with_size(W, H)
    what = sys.argv[3]
    if what == 'fb':
        for N in [int(n) for n in sys.argv[4].split(',')]:
            r = focal_blur(s, W, H, N); r.pop('log')
            print('focal_blur', N, W, H, {k: (round(v, 3) if isinstance(v, float) else v) for k, v in r.items()}, flush=True)
    else:
        for G in [int(n) for n in sys.argv[4].split(',')]:
            r = mesh_render(s, W, H, G); r.pop('log')
            print('mesh G', G, W, H, {k: (round(v, 3) if isinstance(v, float) else v) for k, v in r.items()}, flush=True)
