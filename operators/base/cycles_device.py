"""Which device Cycles bakes on: the user's choice (``--device auto|cpu|gpu``, the panel's
*Device*), resolved once per bake into a :class:`Device` that every Cycles bake session of this
process applies (:class:`cycles_bake.EnvironmentBake` reads :func:`current`) and every report
records.

* ``auto`` (the default) uses what the user chose. In Blender (the UI, or ``blender -b …
  --command relight``): the scene's Cycles device, with the compute backend and devices enabled
  in Preferences > System; a scene set to GPU with no usable device there bakes on the CPU and
  says so. In the venv CLI (the bpy module, factory preferences): the first backend Cycles finds
  (OptiX, CUDA, HIP, Metal, oneAPI) with all its devices, else the CPU, with a one-line note.
* ``cpu`` forces the CPU.
* ``gpu`` requires a GPU: the backend enabled in the preferences, else the first one Cycles
  finds; with none, :class:`DeviceError` says so in one line before any bake call.

The preferences' backend and device switches are changed only for the bake and restored by
:func:`applied`, like the scene's own ``cycles.device``.

CPU and GPU bakes of one seed are different sample sets: chunks record the device that baked
them (:attr:`Device.id`), and a resumed bake rebakes another device's chunks unless told to mix
them (``--mix-devices``).
"""

from __future__ import annotations

import contextlib
from dataclasses import dataclass, field

import bpy

#: The choices of the setting (CLI ``--device``, panel *Device*).
CHOICES = ("auto", "cpu", "gpu")
#: Cycles' GPU backends, in the order ``auto`` / ``gpu`` try them when the preferences name none.
BACKENDS = ("OPTIX", "CUDA", "HIP", "METAL", "ONEAPI")


class DeviceError(ValueError):
    """The device asked for cannot be had (one line, for the CLI and the panel)."""


@dataclass(frozen=True)
class Device:
    """A resolved device. ``kind`` "CPU" or "GPU"; ``backend`` "NONE" or Cycles'
    ``compute_device_type``; ``names`` the devices used; ``note`` why it is not what was asked
    (or None); ``choice`` the setting it was resolved from."""

    kind: str
    backend: str = "NONE"
    names: tuple = ()
    note: str | None = None
    choice: str = "auto"
    cpu_name: str = field(default="", compare=False)
    #: reuse chunks another device baked (``--mix-devices``; by default they are baked again)
    mix_devices: bool = field(default=False, compare=False)
    #: CPU threads of the bake (``--threads``; the panel: Render > Performance's Fixed count):
    #: Cycles, the ray engine and BLAS's fit; 0 = every core (see :func:`thread_plan`)
    threads: int = field(default=0, compare=False)

    @property
    def id(self) -> str:
        """What a chunk records: "CPU" or "GPU:<backend>" (the sample set depends on it)."""
        return "CPU" if self.kind == "CPU" else f"GPU:{self.backend}"

    def report(self) -> dict:
        """The device as a bake report records it."""
        names = list(self.names) if self.kind == "GPU" else [self.cpu_name or "CPU"]
        return {"device": self.kind, "backend": self.backend, "names": names,
                "choice": self.choice, **({"note": self.note} if self.note else {}),
                "threads": thread_plan(self)}

    def describe(self) -> str:
        """One line for the panel and the CLI: ``CPU (AMD EPYC)``, ``GPU OPTIX (RTX 4090)``."""
        if self.kind == "CPU":
            return f"CPU ({self.cpu_name})" if self.cpu_name else "CPU"
        return f"GPU {self.backend} ({', '.join(self.names)})"


def cores() -> int:
    """The cores this process may run on."""
    import os

    try:
        return len(os.sched_getaffinity(0))
    except (AttributeError, OSError):
        return os.cpu_count() or 1


def blas_policy() -> bool:
    """Whether a bake sets BLAS's threads (on; ``RELIGHT_BLAS_POLICY=off`` leaves them as NumPy
    started them, for benchmarks/bench_threads.py)."""
    import os

    return os.environ.get("RELIGHT_BLAS_POLICY", "on") != "off"


def thread_plan(device: "Device") -> dict:
    """The threads a bake on ``device`` uses, as its report records them. Measured on 2 cores
    (benchmarks/bench_threads.py, docs/device.md): BLAS at one thread while Cycles renders and
    the ray engine casts (their threads have the cores), every core (or ``--threads``) for the
    fit."""
    from ...lt_addon import blas_threads

    n = device.threads or cores()
    policy = blas_policy()
    return {"cores": cores(), "cycles": n, "rays": n,
            "blas_while_cycles_and_rays": 1 if policy else "unchanged",
            "blas_fit": n if (policy and device.threads) else "unchanged (every core)",
            "blas_libraries": sorted(blas_threads.threads())}


def _cycles_prefs():
    addon = bpy.context.preferences.addons.get("cycles")
    return addon.preferences if addon is not None else None


def _gpu_devices(prefs, backend: str) -> list:
    """The devices of ``backend`` Cycles finds (no CPU entries); [] when it has none."""
    try:
        found = prefs.get_devices_for_type(backend)
    except Exception:   # a backend this build does not know (e.g. METAL off macOS)
        return []
    return [d for d in found if d.type == backend]


def _cpu_name(prefs) -> str:
    try:
        return next((d.name for d in prefs.get_devices_for_type("CPU")), "")
    except Exception:
        return ""


def _module_mode() -> bool:
    """True in the bpy module (venv CLI, pytest): no Blender binary, factory preferences."""
    return not bpy.app.binary_path


def resolve(choice: str = "auto", scene=None) -> Device:
    """The device ``choice`` gives on this machine (see the module docstring). Raises
    :class:`DeviceError` for an unknown choice, or ``gpu`` with no GPU."""
    if choice not in CHOICES:
        raise DeviceError(f"device must be one of {', '.join(CHOICES)}, got {choice!r}")
    prefs = _cycles_prefs()
    cpu = _cpu_name(prefs) if prefs is not None else ""
    if choice == "cpu":
        return Device("CPU", choice=choice, cpu_name=cpu)
    if prefs is None:   # Cycles disabled: nothing but its CPU path could bake anyway
        if choice == "gpu":
            raise DeviceError("--device gpu: the Cycles add-on is not enabled")
        return Device("CPU", note="the Cycles add-on is not enabled", choice=choice,
                      cpu_name=cpu)
    chosen = prefs.compute_device_type
    if chosen != "NONE":
        enabled = [d for d in _gpu_devices(prefs, chosen) if d.use]
        wants_gpu = choice == "gpu" or _module_mode() or (
            scene is not None and scene.cycles.device == "GPU")
        if enabled and wants_gpu:
            return Device("GPU", chosen, tuple(d.name for d in enabled), choice=choice,
                          cpu_name=cpu)
    if choice == "auto" and not _module_mode():
        asked_gpu = scene is not None and scene.cycles.device == "GPU"
        note = None
        if asked_gpu:   # the CLI line and the report say CPU next to it
            note = ("the scene asks for the GPU, but Preferences > System "
                    + (f"enables no {chosen} device" if chosen != "NONE"
                       else "names no compute backend"))
        return Device("CPU", note=note, choice=choice, cpu_name=cpu)
    for backend in BACKENDS:
        found = _gpu_devices(prefs, backend)
        if found:
            return Device("GPU", backend, tuple(d.name for d in found), choice=choice,
                          cpu_name=cpu)
    if choice == "gpu":
        raise DeviceError("--device gpu: Cycles finds no GPU on this machine (tried "
                          f"{', '.join(BACKENDS)}); use --device cpu or auto")
    return Device("CPU", note=f"no GPU found ({', '.join(BACKENDS)} tried)",
                  choice=choice, cpu_name=cpu)


#: The device the bakes of this process use (set by :func:`use` around a bake; the CPU when
#: nothing set it: a bake run from a script that never chose behaves as before).
_CURRENT: Device | None = None


def current() -> Device:
    """The device the next Cycles bake session uses."""
    return _CURRENT if _CURRENT is not None else Device("CPU", choice="cpu")


@contextlib.contextmanager
def use(device: Device):
    """Bake on ``device`` inside the block (the bake verbs, the panel's job, a Dask chunk)."""
    global _CURRENT
    before, _CURRENT = _CURRENT, device
    try:
        yield device
    finally:
        _CURRENT = before


def applied(scene, device: Device, save_attr) -> None:
    """Set ``scene.cycles.device`` and, for a GPU, the preferences' backend and device switches
    through ``save_attr(owner, name, value)`` (which restores each when the session ends)."""
    save_attr(scene.cycles, "device", device.kind)
    if device.kind != "GPU":
        return
    prefs = _cycles_prefs()
    save_attr(prefs, "compute_device_type", device.backend)
    for d in _gpu_devices(prefs, device.backend):
        save_attr(d, "use", d.name in device.names)


def stepped(gen, device: Device):
    """``gen`` (a job generator) with ``device`` current during each of its steps: the panel's
    modal operator runs one step per timer tick, between which other code runs. Closing the
    wrapper (Esc) closes ``gen``, which restores the scene."""
    try:
        while True:
            with use(device):
                try:
                    step = next(gen)
                except StopIteration as stop:
                    return stop.value
            yield step
    finally:
        gen.close()
