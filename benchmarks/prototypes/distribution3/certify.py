"""Max ray error of the chosen grids over 17 pupil points (centre, 8 at half radius,
8 at 0.99 of the radius: concentric-map u), LS-fitted normals (sub=3), jitter (0.37, 0.61)."""
import math, sys, json
from err_scan import scan
US17 = [(0.5, 0.5)] + [(0.5 + r * math.cos(a) / max(abs(math.cos(a)), abs(math.sin(a))),
                         0.5 + r * math.sin(a) / max(abs(math.cos(a)), abs(math.sin(a))))
                        for r in (0.25, 0.495) for a in [k * math.pi / 4 + 0.2 for k in range(8)]]
CHOICE = {640: [('dgauss.50mm', 20, 0.01), ('wide.22mm', 28, 0.01), ('fisheye.10mm', 64, 1.0)],
          1920: [('dgauss.50mm', 36, 0.01), ('wide.22mm', 48, 0.01), ('fisheye.10mm', 112, 1.0)]}
W = int(sys.argv[1]); H = 480 if W == 640 else 1080
out = {}
for lens, G, eps in CHOICE[W]:
    r = scan(lens, W, H, [G], [eps], us=US17, jit=(0.37, 0.61), verbose=False)
    (d, o), = r.values()
    out[lens] = dict(G=G, eps=eps, dir_px=d, orig_mm=o)
    print(f'CERT {lens} {W}x{H} G={G} eps={eps}: max dir error {d:.4f} px, max origin offset {o:.2e} mm', flush=True)
json.dump(out, open(f'certify_{W}.json', 'w'), indent=1, default=float)
