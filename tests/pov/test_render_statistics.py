"""POV-Ray's render statistics read as numbers (issue 25): a real run's phases and ray
counts, and when they are complete."""

from __future__ import annotations

import shutil
import subprocess

import pytest

from povlens.pov.render_statistics import (RenderStatistics, phase_seconds,
                                           render_statistics, statistics_complete)

needs_povray = pytest.mark.skipif(shutil.which("povray") is None, reason="POV-Ray not installed")

SCENE = """#version 3.7;
global_settings { radiosity { pretrace_start 0.08 pretrace_end 0.04 count 40
  nearest_count 5 error_bound 0.8 recursion_limit 1 } }
camera { location <0, 1.2, -3.5> look_at <0, 0.8, 0> }
light_source { <1, 3, -2> rgb 1 }
box { <-2, 0, -4>, <2, 3, 2> inverse pigment { rgb 0.8 } }
sphere { <0, 0.6, 0>, 0.6 pigment { rgb <0.2, 0.6, 0.9> } }
"""


@needs_povray
def test_a_radiosity_run_reports_its_phases_and_rays(tmp_path):
    (tmp_path / "s.pov").write_text(SCENE)
    r = subprocess.run(["povray", "-D", "-V", "-GR", "+GS", "+WT1", "+W64", "+H48", "-A",
                        "+Is.pov", "+Oo.png"], cwd=tmp_path, capture_output=True, text=True,
                       timeout=120)
    assert r.returncode == 0, r.stderr
    assert statistics_complete(r.stderr)
    st = render_statistics(r.stderr)
    assert st.trace_s > 0 and st.trace_cpu_s > 0
    assert st.rays >= 64 * 48 and 0 < st.radiosity_rays < st.rays
    assert 0 <= st.final_radiosity_rays <= st.radiosity_rays
    assert st.radiosity_cpu_s <= st.radiosity_work_cpu_s <= st.radiosity_cpu_s + st.trace_cpu_s
    assert st.phases_s >= st.trace_s
    # cut before the trace's CPU line: not complete yet
    assert not statistics_complete(r.stderr[:r.stderr.index("Trace Time")])


def test_missing_phases_and_counts_are_zero():
    text = ("  Photon Time:      No photons\n  Trace Time:       0 hours  0 minutes  2 seconds "
            "(2.500 seconds)\n              using 2 thread(s) with 4.900 CPU-seconds total\n")
    assert phase_seconds(text, "Trace Time") == (2.5, 4.9)
    assert phase_seconds(text, "Radiosity Time") == (0.0, 0.0)
    st = render_statistics(text)
    assert st == RenderStatistics(trace_s=2.5, trace_cpu_s=4.9)
    assert st.radiosity_work_cpu_s == 0.0 and statistics_complete(text)


def test_radiosity_work_counts_the_final_trace_share():
    """Samples computed as the image is traced count as trace time: their rays' share
    of the final trace's rays is radiosity work (stackerday.pov: 99.5 %)."""
    st = RenderStatistics(radiosity_cpu_s=1.0, trace_cpu_s=4.0, rays=1000, radiosity_rays=700,
                          final_radiosity_rays=300)
    # final trace: 1000 - (700 - 300) = 600 rays, 300 of them radiosity's
    assert st.radiosity_work_cpu_s == pytest.approx(1.0 + 4.0 * 0.5)
