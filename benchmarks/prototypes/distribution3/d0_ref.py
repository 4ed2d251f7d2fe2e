"""Today's per-pixel distribution-0 sample at 640x480, for the same-session reference."""
import time
import numpy as np
from timing import *
from povlens.pupil.rays import sample_points, sample_rays
from povlens.pov.mesh import write_ray_mesh, default_sink_centre
s = load_setup('conv_dgauss.50mm_640')
W, H = 640, 480
t0 = time.perf_counter()
pts = sample_points(16, H, W, 0)(3)
rays = sample_rays(s.lens, s.film_distance_mm, s.film, s.table, s.placement, pts)
t1 = time.perf_counter()
sink = np.array(s.plan['sink_centre'])
T = write_ray_mesh(WORK / 'd0.inc', 'R', rays.origin, rays.direction, rays.valid, sink_centre=sink)
t2 = time.perf_counter()
(WORK / 'd0.pov').write_text(wrapper(
    f'sphere {{ <{sink[0]},{sink[1]},{sink[2]}>, 1 pigment {{ rgb 0 }} finish {{ ambient 0 diffuse 0 }} no_shadow no_reflection }}\n'
    '#include "d0.inc"\n'
    f'camera {{ mesh_camera {{ 1 0 mesh {{ R translate <{T[0]:.17g},{T[1]:.17g},{T[2]:.17g}> }} }} }}\n'))
r = run(WORK / 'd0.pov', WORK / 'd0.exr', [f'+W{W}', f'+H{H+1}', '+SR2', '+FE'])
print('distribution 0, 640x480: python rays %.3f s, mesh write %.3f s (%.0f MB); POV cpu %.3f (parse %.3f, trace %.3f), wall %.2f, rss %d MB'
      % (t1 - t0, t2 - t1, (WORK / 'd0.inc').stat().st_size / 1e6, r['cpu'], r['parse'], r['trace'], r['wall'], r['maxrss_kb'] // 1024))
