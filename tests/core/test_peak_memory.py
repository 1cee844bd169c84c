"""The bake's peak-memory sampler sees a peak inside a stage that no reading at a stage's end
would see (lt_addon/peak_memory.py)."""

import sys
import time

import numpy as np
import pytest

from relightable_textures.lt_addon.peak_memory import PeakMemory, rss_anon_mb

pytestmark = pytest.mark.skipif(not sys.platform.startswith("linux"), reason="reads /proc")


def test_a_transient_inside_a_stage_is_counted_for_that_stage():
    mem = PeakMemory(interval=0.005).start()
    try:
        mem.stage("small")
        mem.stage("transient")
        a = np.ones(200 << 17)            # 200 MiB of float64, touched
        time.sleep(0.1)                   # the thread reads while it is held
        del a
        time.sleep(0.02)
        after = rss_anon_mb()
        mem.stage("after")                # this stage's own readings come after the free
    finally:
        mem.stop()
    peaks = mem.above_base()
    # glibc returns an array this large to the system when it is freed (mmap), so readings at
    # the stage boundaries could not see it: only the sampling thread did
    assert after - mem.base < 50, (after, mem.base)
    assert 190 < peaks["transient"] < 260, peaks
    assert peaks["small"] < 50 and peaks["after"] < 50, peaks
    assert mem.peak_mb - mem.base == pytest.approx(peaks["transient"], abs=0.2)
