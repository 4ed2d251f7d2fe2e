"""Several lens samples in one POV-Ray run with distribution 3."""
import re, sys, time
import numpy as np
from timing import *
from mesh3 import RayMesh, UVModel
from povrun import run

W, H = int(sys.argv[1]), int(sys.argv[2]); G = int(sys.argv[3]); k = int(sys.argv[4])
s = load_setup(f'conv_dgauss.50mm_{640 if W * 3 == H * 4 else 1920}').with_size(W, H)
RB = bounding_disc_radius_mm(s.table)
Ps = [pupil_point(((f + 0.5) / k, (0.3 + 0.618 * f) % 1), RB) for f in range(k)]
model = uv_model(W, H)
meshes = []
for f, P in enumerate(Ps):
    m = build_mesh(s, P, model, G)
    e = fit_normals(s, P, m, encode(m, s.placement.basis, 0.01), model)
    meshes.append((m, e))

def show(tag, r):
    print(tag, 'cpu %.3f trace %.3f parse %.3f wall %.2f rss %d MB' % (r['cpu'], r['trace'] or 0, r['parse'] or 0, r['wall'], r['maxrss_kb'] // 1024), flush=True)

# (a) rays_per_pixel k with k meshes, distribution 3
txt = ''.join(mesh_text(f'M{f}', m, e) for f, (m, e) in enumerate(meshes))
(WORK / 'rpp.inc').write_text(txt)
e0 = meshes[0][1]
mats = [', '.join('%.17g' % v for v in list(e.mat3.ravel()) + list(e.T)) for _, e in meshes]
cam = 'camera { mesh_camera { %d 3 %s smooth } }\n' % (k, ' '.join(f'mesh {{ M{f} matrix <{mt}> }}' for f, mt in enumerate(mats)))
(WORK / 'rpp.pov').write_text(wrapper('#include "rpp.inc"\n' + cam))
try:
    run(WORK / 'rpp.pov', WORK / 'rpp.exr', model.povray_switches() + ['+FE'])
except RuntimeError as err:
    print(f'(a) RPP {k}, distribution 3:', [l for l in str(err).splitlines() if 'Error' in l])
cam1 = cam.replace('mesh_camera { %d 3' % k, 'mesh_camera { 1 3')
(WORK / 'rpp.pov').write_text(wrapper('#include "rpp.inc"\n' + cam1))
r = run(WORK / 'rpp.pov', WORK / 'rpp.exr', model.povray_switches() + ['+FE'])
print(f'(a) RPP 1 with {k} meshes, distribution 3: warnings', [l.strip() for l in r['log'].replace('\n ', ' ').splitlines() if 'meshes' in l])
(WORK / 'one.inc').write_text(mesh_text('M0', *meshes[0]))
(WORK / 'one.pov').write_text(wrapper('#include "one.inc"\n' + camera_text('M0', e0)))
r1 = run(WORK / 'one.pov', WORK / 'one.exr', model.povray_switches() + ['+FE'])
from povlens.util.images import read_image
a, b = read_image(WORK / 'rpp.exr'), read_image(WORK / 'one.exr')
print('   RPP render == mesh 0 alone: max |diff| %.3g' % np.abs(a - b).max())

# (b) animation: frame f includes mesh f
for f, (m, e) in enumerate(meshes):
    (WORK / f'anim_{f}.inc').write_text(mesh_text('M', m, e) + '#declare Cam = ' + camera_text('M', e))
(WORK / 'anim.pov').write_text(wrapper('#include concat("anim_", str(frame_number, 0, 0), ".inc")\ncamera { Cam }\n'))
sep = []
for f in range(k):
    (WORK / f'sep_{f}.pov').write_text(wrapper(f'#include "anim_{f}.inc"\ncamera {{ Cam }}\n'))
    sep.append(run(WORK / f'sep_{f}.pov', WORK / f'sep_{f}.exr', model.povray_switches() + ['+FE']))
show(f'(b0) {k} separate processes, per sample:', {kk: (sum(x[kk] or 0 for x in sep) / k if kk != 'maxrss_kb' else max(x[kk] for x in sep)) for kk in ('cpu', 'trace', 'parse', 'wall', 'maxrss_kb')})
r = run(WORK / 'anim.pov', WORK / 'anim.exr', model.povray_switches() + ['+FE', '+KFI0', f'+KFF{k-1}', '+KI0', f'+KF{k-1}'])
tr = [float(x) for x in re.findall(r'Trace Time:.*?with ([\d.]+) CPU', r['log'], re.S)]
r2 = dict(r); r2['cpu'] /= k; r2['wall'] /= k; r2['trace'] = sum(tr) / len(tr)
show(f'(b) animation of {k} frames, per sample:', r2)

# (c) k bands in one tall image: UV band f = sample f
Wb, Hb = W, k * H
big = uv_model(W, k * H)        # W+1 x kH+1 rendered, row 0 dropped
faces, uvs, verts, norms = [], [], [], []
nv = 0
for f, P in enumerate(Ps):
    # sample f occupies output rows [f H, (f+1) H): its own UV model is the big one shifted
    mb = UVModel(W, H, W + 1, k * H + 1, 1 + f * H, 0.5, 0.5)
    # uv grid of this band only: v in [1 - ((f+1) H + 1)/(kH+1), 1 - (f H + 1)/(kH+1)] ~ band, widened by 1 px
    from mesh3 import uniform_uv_grid, fill_missing
    from lensfield import trace_field
    gx, gy = G, max(1, round(G * H / W))
    u0 = -0.25 / mb.render_w
    v_lo = max(0.0, 1 - ((f + 1) * H + 1.5) / (k * H + 1)); v_hi = min(1.0, 1 - (f * H + 0.5) / (k * H + 1))
    U, V = np.meshgrid(np.linspace(u0, 1, gx + 1), np.linspace(v_lo, v_hi, gy + 1))
    uv = np.stack([U.ravel(), V.ravel()], 1)
    idx = np.arange((gx + 1) * (gy + 1)).reshape(gy + 1, gx + 1)
    a_, b_, c_, d_ = idx[:-1, :-1].ravel(), idx[:-1, 1:].ravel(), idx[1:, :-1].ravel(), idx[1:, 1:].ravel()
    fc = np.concatenate([np.stack([a_, b_, d_], 1), np.stack([a_, d_, c_], 1)])
    x, y = mb.uv_to_image(uv[:, 0], uv[:, 1])
    fld = trace_field(s, P, x, y, 1.0)
    m = RayMesh(uv, np.stack([x, y], 1), fill_missing(fld.world_origin, fld.geom_ok, gx, gy),
                fill_missing(fld.world_direction, fld.geom_ok, gx, gy), fc, fld.geom_ok, fld.margin)
    e = encode(m, s.placement.basis, 0.01)
    # one shared transform: re-encode every band with band 0's T
    if f == 0:
        T0 = e.T
    q = e.q + ((e.T - T0) @ s.placement.basis.T) / np.array([0.01, 0.01, 1.0])
    faces.append(fc + nv); uvs.append(uv); verts.append(q); norms.append(e.n); nv += len(uv)
from mesh3 import Encoded, _fmt_rows
E = Encoded(np.concatenate(verts), np.concatenate(norms), e.mat3, T0, 0.0)
M = RayMesh(np.concatenate(uvs), None, None, None, np.concatenate(faces), None, None)
(WORK / 'bands.inc').write_text(mesh_text('MB', M, E))
(WORK / 'bands.pov').write_text(wrapper('#include "bands.inc"\n' + camera_text('MB', E)))
r = run(WORK / 'bands.pov', WORK / 'bands.exr', big.povray_switches() + ['+FE'])
r2 = dict(r); r2['cpu'] /= k; r2['wall'] /= k; r2['trace'] /= k
show(f'(c) {k} bands in one {W}x{k*H} image ({len(M.faces)} faces), per sample:', r2)
