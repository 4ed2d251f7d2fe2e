import sys, time
from pathlib import Path
import numpy as np
from timing import *
from povrun import run

W, H = int(sys.argv[1]), int(sys.argv[2])
G = int(sys.argv[3]) if len(sys.argv) > 3 else 32
s = load_setup('conv_dgauss.50mm_640').with_size(W, H)
for rep in range(2):
    r = mesh_render(s, W, H, G); r.pop('log')
    print('single sample', {k: (round(v, 3) if isinstance(v, float) else v) for k, v in r.items()}, flush=True)
# the process + scene overhead: the same wrapper at 1x2 pixels
pov = WORK / 'm.pov'
r = run(pov, WORK / 'tiny.exr', ['+W1', '+H2', '+FE']); r.pop('log')
print('same wrapper 1x2 px', {k: (round(v, 3) if isinstance(v, float) else v) for k, v in r.items()})
# animation: k frames, each its own mesh (frame_number)
k = 4
model = uv_model(W, H)
RB = bounding_disc_radius_mm(s.table)
t0 = time.perf_counter()
for f in range(k):
    P = pupil_point(((f + 0.5) / k, 0.37), RB)
    m = build_mesh(s, P, model, G)
    e = fit_normals(s, P, m, encode(m, s.placement.basis, 0.01), model)
    (WORK / f'anim_{f}.inc').write_text(mesh_text('M', m, e) + '#declare Cam = ' +
        camera_text('M', e).replace('camera {', 'camera {', 1) )
py = time.perf_counter() - t0
pov = WORK / 'anim.pov'
pov.write_text(wrapper('#include concat("anim_", str(frame_number, 0, 0), ".inc")\ncamera { Cam }\n'))
r = run(pov, WORK / 'anim.exr', model.povray_switches() + ['+FE', '+KFI0', f'+KFF{k-1}', '+KI0', f'+KF{k-1}']); log = r.pop('log')
print(f'animation of {k} frames', {kk: (round(v, 3) if isinstance(v, float) else v) for kk, v in r.items()}, 'python', round(py, 3))
import re
print('  per-frame trace CPU:', re.findall(r'Trace Time:.*?with ([\d.]+) CPU', log, re.S))
