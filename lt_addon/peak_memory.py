"""The process's peak anonymous resident memory during a job, sampled by a thread (bpy-free).

A bake's memory peaks inside a stage (a QR, a sparse matrix's construction), not between
stages, so a reading at each stage's end misses it: on the statue demo at 1024^2 the reports
said 1.48 GB above the start while a 10 ms sampler saw 2.93 GB. :class:`PeakMemory` samples every
``interval`` seconds and keeps the peak of each stage the job names.

What is counted: ``RssAnon`` of ``/proc/self/status`` -- the memory the process holds. Pages of
memory-mapped files (a transport store being read) are page cache the kernel can drop, so they
are not (``VmRSS`` would count them). Where ``/proc`` is missing (macOS, Windows) every reading
is 0 and the figures say nothing; :attr:`PeakMemory.available` tells.

Units: MiB.
"""

from __future__ import annotations

import threading


def rss_anon_mb() -> float:
    """The process's anonymous resident memory now (MiB); 0.0 where /proc is missing."""
    try:
        with open("/proc/self/status") as fh:
            for line in fh:
                if line.startswith("RssAnon:"):
                    return int(line.split()[1]) / 1024.0
    except OSError:
        pass
    return 0.0


class PeakMemory:
    """Peak :func:`rss_anon_mb` from :meth:`start` to :meth:`stop`, overall and per stage.

    ``base`` is the reading at start; :attr:`peak_mb` the highest reading since; ``by_stage``
    {stage: highest reading while it was current}; :meth:`stage` names the current stage."""

    def __init__(self, interval: float = 0.01):
        self.interval = float(interval)
        self.base = 0.0
        self.peak_mb = 0.0
        self.by_stage: dict = {}
        self._stage = "start"
        self._stop = threading.Event()
        self._thread = None

    @property
    def available(self) -> bool:
        return self.base > 0.0

    def read(self) -> float:
        """A reading now, counted into the peaks (MiB)."""
        now = rss_anon_mb()
        self.peak_mb = max(self.peak_mb, now)
        self.by_stage[self._stage] = max(self.by_stage.get(self._stage, 0.0), now)
        return now

    def stage(self, name: str) -> None:
        """From now on, readings count for stage ``name`` (the previous one read once more)."""
        self.read()
        self._stage = name
        self.read()

    def start(self) -> "PeakMemory":
        self.base = self.peak_mb = rss_anon_mb()
        self.by_stage = {}
        self._stop.clear()

        def sample():
            while not self._stop.wait(self.interval):
                self.read()

        self._thread = threading.Thread(target=sample, name="relight-peak-memory", daemon=True)
        self._thread.start()
        return self

    def stop(self) -> None:
        self._stop.set()
        if self._thread is not None:
            self._thread.join()
            self._thread = None
        self.read()

    def above_base(self) -> dict:
        """{stage: peak above the start} in MiB, rounded to 0.1."""
        return {k: round(max(0.0, v - self.base), 1) for k, v in self.by_stage.items()}
