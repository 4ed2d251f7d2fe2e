import sys, time, json
import povlens.api as api
lens, out = sys.argv[1], sys.argv[2]
w, h = int(sys.argv[3]), int(sys.argv[4])
t=time.time()
plan = api.convert('scenes/paper.pov', lens=lens, outdir=out, focus=4.0, method='mesh',
                   width=w, height=h, samples=4, location=(0,1.5,-3), look_at=(0,0.7,5))
print(time.time()-t)
