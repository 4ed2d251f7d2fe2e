"""Per-sample cost: distribution-3 meshes vs focal_blur, scenes/paper.pov, +WT1.
Each configuration is run `reps` times; the minimum CPU is kept (the machine is shared)."""
import sys, json, time
import numpy as np
from timing import *

def best(fn, reps):
    rs = [fn() for _ in range(reps)]
    for r in rs: r.pop('log', None)
    return min(rs, key=lambda r: r['cpu']), [round(r['cpu'], 3) for r in rs]

def main(W, H, Gs, Ns, reps=3, lens='dgauss.50mm'):
    s = load_setup(f'conv_{lens}_{640 if W * 3 == H * 4 else 1920}').with_size(W, H)
    out = {}
    for N in Ns:
        r, all_ = best(lambda: focal_blur(s, W, H, N), reps if N <= 4 else 1)
        out[f'fb{N}'] = r
        print(f'{W}x{H} {"pinhole" if N == 0 else f"focal_blur {N},{N}"}: cpu {r["cpu"]:.3f} s (runs {all_}), '
              f'trace {r["trace"]:.3f}, wall {r["wall"]:.2f}, rss {r["maxrss_kb"]/1024:.0f} MB', flush=True)
    for G in Gs:
        r, all_ = best(lambda: mesh_render(s, W, H, G), reps)
        out[f'G{G}'] = r
        py = r['trace_s'] + r['fit_s'] + r['write_s'] + r['weights_s']
        print(f'{W}x{H} mesh d3 G={G} ({r["faces"]} faces, {r["inc_bytes"]/1e3:.0f} kB): POV cpu {r["cpu"]:.3f} s '
              f'(runs {all_}), parse {r["parse"]:.3f}, trace {r["trace"]:.3f}; python {py:.3f} '
              f'(rays {r["trace_s"]:.3f}, fit {r["fit_s"]:.3f}, write {r["write_s"]:.3f}, weights {r["weights_s"]:.3f}); '
              f'rss {r["maxrss_kb"]/1024:.0f} MB', flush=True)
    return out

if __name__ == '__main__':
    W, H = int(sys.argv[1]), int(sys.argv[2])
    Gs = [int(g) for g in sys.argv[3].split(',') if g]
    Ns = [int(n) for n in sys.argv[4].split(',') if n]
    out = main(W, H, Gs, Ns, reps=int(sys.argv[5]) if len(sys.argv) > 5 else 3)
    json.dump(out, open(f'bench_{W}x{H}_{int(time.time())}.json', 'w'), indent=1, default=float)
