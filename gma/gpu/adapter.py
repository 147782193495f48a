"""Choosing a wgpu adapter: a real GPU first, Mesa's lavapipe (CPU) as the fallback.

``GMA_ADAPTER`` forces the choice: ``gpu`` (any hardware adapter), ``cpu`` (a software adapter such as
lavapipe), or any other text, matched case-insensitively against the adapter's device/vendor name.
Among software adapters the newest Mesa wins: on Debian 12 that is the lavapipe ``scripts/install.sh``
keeps in GMA's cache (:mod:`gma.gpu.lavapipe`) rather than the system's older one.
"""

from __future__ import annotations

import os
import tempfile

import wgpu

from gma.core.errors import DeviceError
from gma.gpu.lavapipe import mesa_version, register

# Explicit graphics APIs beat the GL compatibility path, which lacks storage buffers in many places.
_BACKEND_RANK = {"Vulkan": 0, "Metal": 0, "D3D12": 0, "DX12": 0, "OpenGL": 2, "GL": 2}
_TYPE_RANK = {"DiscreteGPU": 0, "IntegratedGPU": 1, "VirtualGPU": 2, "Unknown": 3, "CPU": 4}

INSTALL_HINT = (
    "No usable GPU adapter was found by wgpu. Install a Vulkan driver: on Debian/Ubuntu without a GPU, "
    "`apt-get install mesa-vulkan-drivers` gives Mesa's lavapipe CPU driver (`bash scripts/install.sh` "
    "does this); with an NVIDIA/AMD/Intel GPU install its Vulkan driver. Set GMA_ADAPTER=cpu or =gpu to "
    "force a kind, or a name fragment to pick one adapter."
)


class NoAdapterError(DeviceError):
    """Raised when no adapter matches; the message says how to install a driver."""


def describe(adapter: wgpu.GPUAdapter) -> str:
    info = adapter.info
    mesa = ".".join(map(str, mesa_version(str(info.get("description", "")))))
    driver = f", Mesa {mesa}" if mesa else ""
    return f"{info.get('device', '?')} [{info.get('adapter_type', '?')}, {info.get('backend_type', '?')}{driver}]"


def _rank(adapter: wgpu.GPUAdapter) -> tuple:
    info = adapter.info
    software = info.get("adapter_type") == "CPU"  # two lavapipes (system, cached): the newer Mesa
    newer_first = tuple(-v for v in mesa_version(str(info.get("description", "")))) if software else ()
    return (
        _BACKEND_RANK.get(info.get("backend_type", ""), 1),
        _TYPE_RANK.get(info.get("adapter_type", "Unknown"), 3),
        newer_first,
    )


def _matches(adapter: wgpu.GPUAdapter, wanted: str) -> bool:
    info = adapter.info
    kind = info.get("adapter_type", "")
    if wanted == "gpu":
        return kind != "CPU"
    if wanted in ("cpu", "lavapipe", "llvmpipe", "software"):
        return kind == "CPU"
    text = " ".join(str(info.get(k, "")) for k in ("device", "vendor", "description", "backend_type"))
    return wanted in text.lower()


def _runtime_dir() -> None:
    """Mesa's Vulkan drivers print "XDG_RUNTIME_DIR is invalid" on every start without a private runtime
    folder (containers, CI, cron); give them one when the session has none."""
    current = os.environ.get("XDG_RUNTIME_DIR")
    if current and os.path.isdir(current) and os.access(current, os.W_OK):
        return
    # One folder per user, reused by every run (the Makefile's choice too), private as the spec asks.
    user = os.getuid() if hasattr(os, "getuid") else 0
    folder = os.path.join(tempfile.gettempdir(), f"gma-xdg-{user}")
    os.makedirs(folder, mode=0o700, exist_ok=True)
    os.environ["XDG_RUNTIME_DIR"] = folder


def select_adapter(preference: str | None = None) -> wgpu.GPUAdapter:
    """Return the best adapter, honouring ``preference`` (default: ``$GMA_ADAPTER`` or ``auto``)."""
    wanted = (preference or os.environ.get("GMA_ADAPTER") or "auto").strip().lower()
    _runtime_dir()
    register()  # the cached newer lavapipe, if any (before wgpu starts the Vulkan loader)
    adapters = list(wgpu.gpu.enumerate_adapters_sync())
    if wanted != "auto":
        adapters = [a for a in adapters if _matches(a, wanted)]
    if not adapters:
        found = ", ".join(describe(a) for a in wgpu.gpu.enumerate_adapters_sync()) or "none"
        raise NoAdapterError(f"{INSTALL_HINT}\n(GMA_ADAPTER={wanted!r}; adapters seen: {found})")
    return min(adapters, key=_rank)
