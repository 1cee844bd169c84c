"""Jobs: every long action (bake, fit, analysis) is a generator that yields :class:`Progress`
and returns its result, so one piece of code serves all three ways in:

* the panel's modal operators step it on a timer (progress bar, status text, Esc closes it);
* the CLI and scripts drive it to the end with :func:`run` (Ctrl-C closes it);
* tests call :func:`run` on it directly.

Closing a job (``generator.close()``) runs its ``finally`` blocks, which restore the scene and
drop temporary files, so a cancelled job leaves nothing behind.
"""

from __future__ import annotations

from ...lt_addon.progress import Progress  # noqa: F401  (the core's jobs yield it too)


def run(generator, on_progress=None, should_cancel=None):
    """Drive a job to the end; returns its result, or None if cancelled.

    ``on_progress(progress)`` is called for every step; ``should_cancel()`` is checked after
    each step and closes the generator (restoring the scene) when it returns True.
    """
    try:
        while True:
            step = next(generator)
            if on_progress is not None:
                on_progress(step)
            if should_cancel is not None and should_cancel():
                generator.close()
                return None
    except StopIteration as stop:
        return stop.value
