"""Final per-sample timing, dgauss.50mm focused at 4 m, scenes/paper.pov, POV-Ray +WT1.
CPU = user+sys of the POV-Ray process (rusage); runs interleaved, minimum kept."""
import sys, json, re, time
import numpy as np
from timing import *
from povrun import run

def d3_animation(s, W, H, G, k, eps=0.01):
    """k lens samples as k frames of one POV-Ray run; returns POV cpu/sample and the
    Python cost per sample (vertex rays, fit, weights, mesh text)."""
    model = uv_model(W, H, 0.37, 0.61)
    RB = bounding_disc_radius_mm(s.table); A = np.pi * RB * RB
    py = dict(rays=0.0, fit=0.0, weights=0.0, write=0.0)
    for f in range(k):
        P = pupil_point(((f + 0.5) / k, (0.3 + 0.618 * f) % 1), RB)
        t0 = time.perf_counter(); m = build_mesh(s, P, model, G, area_mm2=A)
        t1 = time.perf_counter(); e = fit_normals(s, P, m, encode(m, s.placement.basis, eps), model, sub=3)
        t2 = time.perf_counter(); w, st = sample_weights(s, P, m, model, A)
        t3 = time.perf_counter()
        (WORK / f'anim_{f}.inc').write_text(mesh_text('M', m, e) + '#declare Cam = ' + camera_text('M', e))
        t4 = time.perf_counter()
        for kk, dt in zip(py, (t1 - t0, t2 - t1, t3 - t2, t4 - t3)):
            py[kk] += dt / k
    pov = WORK / 'anim.pov'
    pov.write_text(wrapper('#include concat("anim_", str(frame_number, 0, 0), ".inc")\ncamera { Cam }\n'))
    r = run(pov, WORK / 'anim.exr', model.povray_switches() + ['+FE', '+KFI0', f'+KFF{k-1}', '+KI0', f'+KF{k-1}'])
    tr = [float(x) for x in re.findall(r'Trace Time:.*?with ([\d.]+) CPU', r['log'], re.S)]
    return dict(cpu=r['cpu'] / k, trace=float(np.mean(tr)), wall=r['wall'] / k, rss_mb=r['maxrss_kb'] / 1024,
                python=sum(py.values()), **{f'py_{a}': b for a, b in py.items()}, faces=len(m.faces))

def main(W, H, G, fb_multi, reps, k):
    s = load_setup(f'conv_dgauss.50mm_{640 if W * 3 == H * 4 else 1920}').with_size(W, H)
    res = {}
    def keep(name, r):
        r.pop('log', None)
        old = res.get(name)
        if old is None or r['cpu'] < old['cpu']:
            res[name] = r
    for rep in range(reps):
        keep('pinhole', focal_blur(s, W, H, 0))
        keep('fb4', focal_blur(s, W, H, 4))
        keep('d3_single', mesh_render(s, W, H, G))
    for N in fb_multi:
        keep(f'fb{N}', focal_blur(s, W, H, N))
    keep('d3_anim', d3_animation(s, W, H, G, k))
    for n, r in res.items():
        print(W, H, n, {a: (round(b, 3) if isinstance(b, float) else b) for a, b in r.items()}, flush=True)
    json.dump(res, open(f'final_{W}x{H}.json', 'w'), indent=1, default=float)

if __name__ == '__main__':
    W, H, G = int(sys.argv[1]), int(sys.argv[2]), int(sys.argv[3])
    main(W, H, G, [int(n) for n in sys.argv[4].split(',')], int(sys.argv[5]), int(sys.argv[6]))
