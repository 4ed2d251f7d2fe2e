"""Interpolation error of uniform distribution-3 grids against the exact tracer."""
import sys, time
import numpy as np
from lensfield import load_setup, bounding_disc_radius_mm, pupil_point
from mesh3 import uv_model, build_mesh, emulate, ray_errors, encode, locate, fit_normals

import math
# pupil points: centre, half radius, and 8 on the rim (concentric map of u)
US = [(0.5, 0.5), (0.75, 0.5), (0.3, 0.2)] + [
    (0.5 + 0.495 * math.cos(a) / max(abs(math.cos(a)), abs(math.sin(a))),
     0.5 + 0.495 * math.sin(a) / max(abs(math.cos(a)), abs(math.sin(a))))
    for a in [k * math.pi / 4 + 0.3 for k in range(8)]]

def scan(lens, W, H, Gs, eps_list, us=US, jit=(0.5, 0.5), offset_t=0.0, verbose=True, fit=True):
    s = load_setup(f'conv_{lens}_{640 if W * 3 == H * 4 else 1920}').with_size(W, H)
    RB = bounding_disc_radius_mm(s.table)
    out = {}
    for G in Gs:
        for u in us:
            P = pupil_point(u, RB)
            model = uv_model(W, H, *jit)
            m = build_mesh(s, P, model, G)
            loc = locate(m, *model.pixel_uv())
            for eps in eps_list:
                e = encode(m, s.placement.basis, eps, offset_t)
                if fit:
                    e = fit_normals(s, P, m, e, model, sub=3)
                org, d, found, face = emulate(m, e, model, loc=loc)
                r = ray_errors(s, P, model, org, d, found)
                p = r['passed']
                assert found.all(), 'pixels without a face'
                dmax = r['dir_px'][p].max() if p.any() else 0
                omax = r['orig_mm'][p].max() if p.any() else 0
                w = out.get((G, eps), (0, 0))
                out[(G, eps)] = (max(w[0], dmax), max(w[1], omax))
                if verbose:
                    k = np.unravel_index(np.argmax(np.where(p, r['dir_px'], -1)), p.shape)
                    print(f'{lens} {W}x{H} G={G} eps={eps:g} u={u} faces={len(m.faces)} pass={p.mean():.3f} '
                          f'missing={int((~m.geom_ok).sum())} dir max {dmax:.4f} px at {tuple(int(i) for i in k)} '
                          f'p99 {np.percentile(r["dir_px"][p], 99) if p.any() else 0:.4f}  orig max {omax:.2e} mm', flush=True)
    return out

if __name__ == '__main__':
    lens = sys.argv[1]; W, H = int(sys.argv[2]), int(sys.argv[3])
    Gs = [int(g) for g in sys.argv[4].split(',')]
    eps = [float(g) for g in sys.argv[5].split(',')] if len(sys.argv) > 5 else [1.0]
    res = scan(lens, W, H, Gs, eps, verbose='-q' not in sys.argv, fit='--interp' not in sys.argv)
    for k, v in res.items():
        print('WORST', lens, f'{W}x{H}', 'G=%d eps=%g' % k, 'dir %.4f px  orig %.2e mm' % v)
