"""kill_descendants: nothing below the process survives it, even a process a thread was
starting at that moment; and no process starts afterwards."""
from __future__ import annotations

import subprocess
import sys

from conftest import ROOT

# A thread starts processes (a 30 s sleep each, through start_povray as POV-Ray is)
# as fast as it can; the main thread kills what is below it meanwhile.
RACE = r"""
import os, shutil, sys, tempfile, threading, time
from povlens.pov.process import start_povray
from povlens.util.signals import ProcessesStopped, descendants, kill_descendants, _running
started, refused = [], []
def starter():
    err = tempfile.TemporaryFile()
    end = time.monotonic() + 2.0
    while time.monotonic() < end:
        try:
            started.append(start_povray([shutil.which("sleep"), "30"], ".", err))
        except ProcessesStopped:
            refused.append(1)
            return
t = threading.Thread(target=starter, daemon=True)
t.start()
while len(started) < 3:
    time.sleep(0.001)
kill_descendants()
time.sleep(0.3)          # the thread would have started many more by now
alive = [p for p in descendants() if _running(p)]
print(len(started), len(refused), len(alive))
for p in alive:          # (only when the test fails)
    os.kill(p, 9)
"""


def test_no_process_outlives_kill_descendants_or_starts_after_it():
    r = subprocess.run([sys.executable, "-c", RACE], cwd=ROOT, capture_output=True,
                       text=True, timeout=60)
    assert r.returncode == 0, r.stderr
    started, refused, alive = map(int, r.stdout.split())
    assert alive == 0, f"{alive} of {started} processes still running"
    assert refused == 1
