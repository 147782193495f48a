"""``gma gpu``: the adapters wgpu sees, the one GMA renders with and the driver it runs, and the Vulkan
loader's variables in effect. GMA installs no driver; on Debian 12 and 13 a faster lavapipe than the
system's can be installed beside it (``make install LAVAPIPE=backports``, scripts/lavapipe_backport.py)."""

from __future__ import annotations

import argparse
import os

# The Vulkan loader's variables that choose or add drivers (GMA only reads them).
LOADER_VARIABLES = ("VK_DRIVER_FILES", "VK_ICD_FILENAMES", "VK_ADD_DRIVER_FILES", "GMA_ADAPTER")
SLOW_MESA = (24,)   # software adapters of older Mesa: the backport script's hint


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("gpu", help="which adapter and driver GMA renders with",
                       description="Lists the adapters wgpu sees and the one GMA picks (GMA_ADAPTER forces "
                                   "one), with its driver. Which drivers exist is the Vulkan loader's choice "
                                   "(VK_DRIVER_FILES, VK_ADD_DRIVER_FILES and its folders).")
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    import wgpu

    from gma.gpu.adapter import describe, mesa_version, select_adapter

    for adapter in wgpu.gpu.enumerate_adapters_sync():
        print(f"seen: {describe(adapter)}")
    chosen = select_adapter()
    description = str(chosen.info.get("description", ""))
    print(f"renders with: {describe(chosen)}; {description}")
    for name in LOADER_VARIABLES:
        if os.environ.get(name):
            print(f"{name}={os.environ[name]}")
    mesa = mesa_version(description)
    if chosen.info.get("adapter_type") == "CPU" and mesa and mesa[:1] < SLOW_MESA:
        print(f"Mesa {'.'.join(map(str, mesa))}'s lavapipe is markedly slower than newer ones: on Debian 12 or 13, "
              "`make install LAVAPIPE=backports` (scripts/lavapipe_backport.py) installs the backports' beside it")
    return 0
