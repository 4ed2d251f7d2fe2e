"""Run POV-Ray (one thread) and read the result; timings from POV-Ray's statistics."""
import os, re, subprocess, time, resource
from pathlib import Path
import numpy as np

def run(pov: Path, out: Path, switches, threads=1, extra=()):
    cmd = ["/usr/bin/time", "-f", "MAXRSS_KB=%M", "povray", "-D", "-V", "-GR", "+GS", f"+I{pov.name}", f"+O{out.name}",
           "-A", f"+WT{threads}", *switches, *extra]
    t0 = time.perf_counter()
    r0 = resource.getrusage(resource.RUSAGE_CHILDREN)
    p = subprocess.run(cmd, cwd=pov.parent, capture_output=True, text=True)
    r1 = resource.getrusage(resource.RUSAGE_CHILDREN)
    wall = time.perf_counter() - t0
    if p.returncode != 0:
        raise RuntimeError(p.stderr[-3000:])
    txt = p.stderr + p.stdout
    def grab(label):
        m = re.search(label + r" Time:\s+\d+ hours\s+\d+ minutes\s+\d+ seconds \(([\d.]+) seconds\)\s+using \d+ thread\(s\) with ([\d.]+) CPU", txt)
        return (float(m.group(1)), float(m.group(2))) if m else (None, None)
    return dict(wall=wall, cpu=(r1.ru_utime - r0.ru_utime) + (r1.ru_stime - r0.ru_stime),
                parse=grab("Parse")[1], bound=grab("Bounding")[1], trace=grab("Trace")[1],
                maxrss_kb=int(re.search(r"MAXRSS_KB=(\d+)", txt).group(1)), log=txt)

def read16(path):
    import OpenImageIO as oiio
    buf = oiio.ImageBuf(str(path))
    return buf.get_pixels(oiio.FLOAT)
