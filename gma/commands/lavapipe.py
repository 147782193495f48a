"""``gma lavapipe status|install``: which software Vulkan driver GMA renders with on a machine without a
GPU, and fetching the newer lavapipe on Debian 12 and 13 (see :mod:`gma.gpu.lavapipe`)."""

from __future__ import annotations

import argparse


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("lavapipe", help="the CPU Vulkan driver: status, or fetch a newer one (Debian 12, 13)",
                       description="On Debian 12, `install` fetches Mesa 25's lavapipe from bookworm-backports, "
                                   "on Debian 13 Mesa 26's from trixie-backports (checked against Debian's "
                                   "signed index) into GMA's cache; GMA then renders with it instead of the "
                                   "system's Mesa (which stays installed). Elsewhere it does nothing. "
                                   "`status` says what wgpu picks.")
    p.add_argument("action", choices=("status", "install"))
    p.add_argument("--force", action="store_true",
                   help="install even where the system's Mesa would be kept (not Debian 12 or 13, or its Mesa "
                        "is as new as the backport's major)")
    p.add_argument("--with-dependencies", action="store_true",
                   help="apt-get install the packages the backport links against that are missing (as root)")
    p.add_argument("--update", action="store_true", help="look for a newer backport even with one cached")
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    from gma.gpu.adapter import describe, select_adapter
    from gma.gpu.lavapipe import cache_root, cached_manifest, install

    if args.action == "install":
        install(force=args.force, update=args.update, with_dependencies=args.with_dependencies)
        return 0
    manifest = cached_manifest()
    print(f"cached lavapipe: {manifest.parent if manifest else 'none'} (cache {cache_root()})")
    adapter = select_adapter()
    print(f"wgpu picks: {describe(adapter)}; {adapter.info.get('description', '')}")
    return 0
