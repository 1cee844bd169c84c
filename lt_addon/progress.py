"""One step of a job: every long action (bake, fit, export) is a generator that yields these and
returns its result; the bpy layer's modal operators, the CLI and the tests drive it
(``operators/base/jobs.py``)."""

from __future__ import annotations

from dataclasses import dataclass


@dataclass
class Progress:
    """One step of a job: ``done`` of ``total`` units, and what it is doing now."""
    done: int
    total: int
    message: str
