"""Fault injection for the transaction tests: ``RELIGHT_FAULT=<stage>:<kill|raise>[,...]``.

A bake calls :func:`checkpoint` at each stage (``directions``, ``indirect``, ``fit``, ``write``,
``preview``, ``commit``, ``blend``); with the variable unset it returns at once. ``kill`` ends
the process as ``kill -9`` would (SIGKILL: no ``finally``, no atexit), ``raise`` raises
:class:`InjectedFault` there, ``eacces`` / ``enospc`` raise the OSError a denied permission or a
full disk gives (for machines where the tests run as root, whom permissions do not stop), ``sigint``
sends this process the SIGINT a Ctrl-C sends (the bake goes on to its next cancellation point). The
tests run real bakes in subprocesses with it set and check
that the previous bake is intact byte for byte (tests/blender/test_bake_faults.py).
"""

from __future__ import annotations

import os

ENV = "RELIGHT_FAULT"
STAGES = ("directions", "indirect", "fit", "write", "preview", "commit", "blend")


class InjectedFault(RuntimeError):
    """Raised at a checkpoint named by :data:`ENV` with ``raise``."""


def checkpoint(stage: str, path: str | None = None) -> None:
    """Kill the process or raise here when :data:`ENV` names ``stage`` (``path``: the file an
    injected OSError names)."""
    spec = os.environ.get(ENV)
    if not spec:
        return
    for item in spec.split(","):
        name, _, action = item.strip().partition(":")
        if name != stage:
            continue
        if action == "sigint":
            import signal

            os.kill(os.getpid(), signal.SIGINT)
            continue
        if action == "kill":
            import signal

            if hasattr(signal, "SIGKILL"):
                os.kill(os.getpid(), signal.SIGKILL)
            os._exit(137)
        if action in ("eacces", "enospc"):
            import errno

            code = errno.EACCES if action == "eacces" else errno.ENOSPC
            raise OSError(code, os.strerror(code), path or f"<{stage}>")
        raise InjectedFault(f"injected fault at the {stage} stage ({ENV}={spec})")
