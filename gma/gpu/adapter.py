"""Choosing a wgpu adapter: a real GPU first, Mesa's lavapipe (CPU) as the fallback.

``GMA_ADAPTER`` forces the choice: ``gpu`` (any hardware adapter), ``cpu`` (a software adapter such as
lavapipe), or any other text, matched case-insensitively against the adapter's device/vendor name.
Which drivers exist is the Vulkan loader's business (its ``VK_DRIVER_FILES`` / ``VK_ADD_DRIVER_FILES``
and its search folders); GMA changes nothing there. Among software adapters the newest Mesa wins: where a
user installed a newer lavapipe beside the system's (``scripts/lavapipe_backport.py`` on Debian 12 and
13), that one. :func:`describe` names the driver an adapter runs.
"""

from __future__ import annotations

import os
import re

import wgpu

from gma.core.errors import DeviceError

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


def mesa_version(description: str) -> tuple[int, ...]:
    """``(25, 0, 7)`` from an adapter description such as ``Mesa 25.0.7-2~bpo12+1 (LLVM 15.0.6)`` (also
    the GL adapter's ``4.5 (Core Profile) Mesa 25.0.7``); ``()`` for a driver that is not Mesa."""
    match = re.search(r"Mesa\s+(\d+)\.(\d+)(?:\.(\d+))?", description)
    return tuple(int(g) for g in match.groups() if g is not None) if match else ()


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


def select_adapter(preference: str | None = None) -> wgpu.GPUAdapter:
    """Return the best adapter, honouring ``preference`` (default: ``$GMA_ADAPTER`` or ``auto``)."""
    wanted = (preference or os.environ.get("GMA_ADAPTER") or "auto").strip().lower()
    adapters = list(wgpu.gpu.enumerate_adapters_sync())
    if wanted != "auto":
        adapters = [a for a in adapters if _matches(a, wanted)]
    if not adapters:
        found = ", ".join(describe(a) for a in wgpu.gpu.enumerate_adapters_sync()) or "none"
        raise NoAdapterError(f"{INSTALL_HINT}\n(GMA_ADAPTER={wanted!r}; adapters seen: {found})")
    return min(adapters, key=_rank)
