import sys, time
import numpy as np
from lensfield import *
from mesh3 import *
from vignette import sample_weights, sample_weights_fast as sample_weights
from err_scan import US
rng = np.random.default_rng(5)
W, H = int(sys.argv[1]), int(sys.argv[2])
for lens, G in ([('dgauss.50mm', 24), ('wide.22mm', 32), ('fisheye.10mm', 64)] if W == 640 else [('dgauss.50mm', 32), ('wide.22mm', 48), ('fisheye.10mm', 112)]):
    s = load_setup(f'conv_{lens}_{W}')
    RB = bounding_disc_radius_mm(s.table); A = np.pi * RB * RB
    model = uv_model(W, H, 0.3, 0.7)
    bad = 0; fr = []; tt = []
    for k in range(12 if W == 640 else 6):
        u = US[k] if k < len(US) else tuple(rng.random(2))
        P = pupil_point(u, RB)
        m = build_mesh(s, P, model, G, area_mm2=A)
        t = time.perf_counter()
        w, st = sample_weights(s, P, m, model, A)
        tt.append(time.perf_counter() - t)
        jj, ii = np.mgrid[0:H, 0:W].astype(float)
        ex = trace_field(s, P, ii + model.jx, jj + model.jy, A).weight.reshape(H, W)
        bad += int(np.sum((w > 0) != (ex > 0)))
        assert np.allclose(w, ex, rtol=1e-6, atol=0)
        fr.append(st['traced'])
    print(lens, 'G', G, 'mismatching pixels', bad, 'fraction traced exactly: mean %.3f max %.3f' % (np.mean(fr), np.max(fr)),
          'time per sample %.3f s' % np.median(tt))
