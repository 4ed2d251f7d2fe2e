"""POV-Ray trace CPU of distribution-3 meshes vs the pinhole render: the per-pixel
face lookup cost as a function of the face count (interleaved, min of reps)."""
import sys
from timing import *
W, H = int(sys.argv[1]), int(sys.argv[2]); Gs = [int(g) for g in sys.argv[3].split(',')]; reps = int(sys.argv[4])
s = load_setup(f'conv_dgauss.50mm_{W}').with_size(W, H)
best = {}
for rep in range(reps):
    for key in ['pinhole'] + Gs:
        r = focal_blur(s, W, H, 0) if key == 'pinhole' else mesh_render(s, W, H, key, tag=f'l{key}')
        r.pop('log')
        if key not in best or r['trace'] < best[key]['trace']:
            best[key] = r
p = best['pinhole']
print(f'{W}x{H} pinhole: trace {p["trace"]:.3f} s, total POV cpu {p["cpu"]:.3f} s')
for G in Gs:
    r = best[G]
    print(f'{W}x{H} G={G} ({r["faces"]} faces): trace {r["trace"]:.3f} s (+{(r["trace"] - p["trace"]) / (W * H) * 1e6:.3f} us/px), '
          f'parse {r["parse"]:.3f}, POV cpu {r["cpu"]:.3f} s, POV rss {r["maxrss_kb"]/1024:.0f} MB')
