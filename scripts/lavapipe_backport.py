#!/usr/bin/env python3
"""A newer lavapipe for Debian 12 and 13, installed for this user beside the system's Mesa (opt-in:
``make install LAVAPIPE=backports`` runs it; GMA itself never fetches or registers drivers).

Debian 12 ships Mesa 22.3; its backports carry Mesa 25, whose lavapipe runs the renderer's passes
markedly faster on the same CPU. Debian 13 ships Mesa 25.0; its backports carry Mesa 26, whose lavapipe
compiles a load or store with a lane-varying address as one vector gather or scatter instead of a loop
over the lanes (docs/design.md, "The lavapipe GMA runs on"). Getting either system-wide means adding an
apt source and upgrading every Mesa Vulkan driver on the machine, so instead ``install`` fetches the
backports package, checks it against Debian's signed archive index (gpgv or sqv and the Debian archive
keyring, as apt would), unpacks only the lavapipe library and its driver manifest into
``~/.cache/gma/lavapipe/<version>/`` (``$GMA_LAVAPIPE_DIR``), and lists that manifest where the Vulkan
loader looks for this user's drivers: ``$XDG_DATA_HOME/vulkan/icd.d/`` (``~/.local/share/vulkan/icd.d``).
Every Vulkan application of this user then sees both lavapipes; GMA's adapter choice takes the newer Mesa
among software adapters. The system's lavapipe stays installed: it supplies the libraries the newer one
links against and is the fallback. ``remove`` takes the listing out again (the cache stays), and the
loader's own ``VK_DRIVER_FILES`` picks drivers for one process.

    python3 scripts/lavapipe_backport.py status
    python3 scripts/lavapipe_backport.py install [--force] [--update] [--with-dependencies]
    python3 scripts/lavapipe_backport.py remove

Standard library only (it runs before GMA is installed); ``status`` says what is cached and listed.
"""

from __future__ import annotations

import hashlib
import io
import json
import lzma
import os
import re
import shutil
import subprocess
import sys
import tarfile
import tempfile
import urllib.request
from datetime import datetime, timezone
from email.utils import parsedate_to_datetime
from pathlib import Path

MIRROR = "http://deb.debian.org/debian"
# Debian release -> (the backports suite fetched from, the system Mesa from which on the system's is kept).
# Debian 12: Mesa 22.3 against bookworm-backports' 25.0; Debian 13: Mesa 25.0 against trixie-backports' 26.1
# (vector gathers and scatters, see the module docstring). Other systems keep their own Mesa.
BACKPORTS = {"bookworm": ("bookworm-backports", (24,)), "trixie": ("trixie-backports", (26,))}
PACKAGE = "mesa-vulkan-drivers"
KEYRING = Path("/usr/share/keyrings/debian-archive-keyring.gpg")
LIBRARY = "libvulkan_lvp.so"
MANIFEST = "lvp_icd.json"
LISTING = "gma_lavapipe_backport.json"   # the manifest's name in the loader's folder


class LavapipeInstallError(Exception):
    """Why the newer lavapipe was not installed (one line; the system's lavapipe stays in use)."""


def cache_root() -> Path:
    """``$GMA_LAVAPIPE_DIR``, else ``~/.cache/gma/lavapipe`` (beside anny's cache)."""
    return Path(os.environ.get("GMA_LAVAPIPE_DIR") or Path.home() / ".cache" / "gma" / "lavapipe")


def _numbers(match: re.Match | None) -> tuple[int, ...]:
    return tuple(int(g) for g in match.groups() if g is not None) if match else ()


def mesa_version(description: str) -> tuple[int, ...]:
    """``(25, 0, 7)`` from an adapter description such as ``Mesa 25.0.7-2~bpo12+1 (LLVM 15.0.6)`` (also
    the GL adapter's ``4.5 (Core Profile) Mesa 25.0.7``); ``()`` for a driver that is not Mesa."""
    return _numbers(re.search(r"Mesa\s+(\d+)\.(\d+)(?:\.(\d+))?", description))


def package_version(version: str) -> tuple[int, ...]:
    """``(25, 0, 7)`` from a Debian package version such as ``25.0.7-2~bpo12+1`` (or a cache folder's name)."""
    return _numbers(re.match(r"\s*(\d+)\.(\d+)(?:\.(\d+))?", version))


def built_for(folder: Path) -> str:
    """The backports suite a cached driver came from (its ``source.json``; drivers cached before GMA fetched
    for Debian 13 came from bookworm-backports)."""
    try:
        return str(json.loads((folder / "source.json").read_text()).get("suite", BACKPORTS["bookworm"][0]))
    except (OSError, ValueError, AttributeError):
        return BACKPORTS["bookworm"][0]


def cached_manifest(root: Path | None = None) -> Path | None:
    """The driver manifest of the newest complete lavapipe in the cache that was fetched for this Debian
    release, or None. (A home folder shared by machines of both releases holds both; Debian 13's backport
    does not load on Debian 12, whose C library is older.)"""
    root = root or cache_root()
    suite = backports_suite()
    found = [p for p in root.glob(f"*/{MANIFEST}")
             if (p.parent / LIBRARY).is_file() and built_for(p.parent) == suite] if root.is_dir() else []
    return max(found, key=lambda p: package_version(p.parent.name), default=None)


def loader_folder(environ=os.environ) -> Path:
    """Where the Vulkan loader looks for this user's drivers: ``$XDG_DATA_HOME/vulkan/icd.d`` (by default
    ``~/.local/share/vulkan/icd.d``)."""
    data_home = environ.get("XDG_DATA_HOME") or str(Path.home() / ".local" / "share")
    return Path(data_home) / "vulkan" / "icd.d"


def list_with_loader(manifest: Path, folder: Path | None = None) -> Path:
    """Write ``manifest`` (whose library path is absolute) into the loader's folder, atomically; its path."""
    folder = folder or loader_folder()
    folder.mkdir(parents=True, exist_ok=True)
    target = folder / LISTING
    tmp = target.with_name(f".{LISTING}.partial")
    tmp.write_text(manifest.read_text())
    tmp.replace(target)
    return target


def unlist(folder: Path | None = None) -> bool:
    """Take the listing out of the loader's folder; whether there was one."""
    target = (folder or loader_folder()) / LISTING
    if not target.is_file():
        return False
    target.unlink()
    return True


# -- install --------------------------------------------------------------------------------------------
def _os_release() -> dict[str, str]:
    try:
        text = Path("/etc/os-release").read_text()
    except OSError:
        return {}
    return dict(line.split("=", 1) for line in text.splitlines() if "=" in line and not line.startswith("#"))


def _dpkg(*args: str) -> str:
    if not shutil.which("dpkg"):   # (install --force on a system without dpkg)
        return ""
    return subprocess.run(["dpkg", *args], capture_output=True, text=True, check=False).stdout.strip()


def _codename() -> str:
    return _os_release().get("VERSION_CODENAME", "").strip('"')


def backports_suite() -> str:
    """The backports suite for this Debian release (Debian 12's for other systems, as with ``--force``)."""
    return BACKPORTS.get(_codename(), BACKPORTS["bookworm"])[0]


def _why_not_needed() -> str | None:
    """None when this machine is one the newer lavapipe is for (Debian 12 or 13 with an older system Mesa
    than their backports carry)."""
    codename = _codename()
    if codename not in BACKPORTS:
        return f"not Debian 12 or 13 ({codename or 'unknown system'}): its own Mesa is used"
    if not shutil.which("dpkg"):
        return "no dpkg"
    system = _dpkg("-s", PACKAGE)
    version = re.search(r"^Version:\s*(\S+)", system, re.M)
    if version is None:
        return f"{PACKAGE} is not installed (install it first: the newer lavapipe uses its libraries)"
    if package_version(version.group(1))[:1] >= BACKPORTS[codename][1]:
        return f"the system's Mesa {version.group(1)} is new enough"
    return None


def _dependency_names(depends: str) -> list[list[str]]:
    """A Depends field as groups of alternatives: ``a (>= 1), b:any | c`` -> [[a], [b, c]]."""
    groups = []
    for group in depends.split(","):
        names = [re.split(r"[\s(:]", alt.strip(), maxsplit=1)[0] for alt in group.split("|")]
        if names := [n for n in names if n]:
            groups.append(names)
    return groups


def missing_packages(depends: str) -> list[str]:
    """Packages of a Depends field of which no alternative is installed (presence only: the versions the
    backport was built against are newer than the release's, and the lavapipe library runs with the
    release's). Debian 13's backport links against libdisplay-info2, which Debian 13's own Mesa does not
    pull in."""
    groups = _dependency_names(depends)
    names = sorted({n for g in groups for n in g})
    if not names:
        return []
    listed = _dpkg_query(names)
    return [g[0] for g in groups if not any(listed.get(n) == "installed" for n in g)]


def _dpkg_query(names: list[str]) -> dict[str, str]:
    """{package: status} for the packages dpkg knows (installed, config-files, ...)."""
    if not shutil.which("dpkg-query"):
        return {}
    r = subprocess.run(["dpkg-query", "-W", "-f=${Package} ${db:Status-Status}\n", *names],
                       capture_output=True, text=True, check=False)
    return dict(line.split(" ", 1) for line in r.stdout.splitlines() if " " in line)


def _apt_install(packages: list[str]) -> None:
    if os.geteuid() != 0 or not shutil.which("apt-get"):
        raise LavapipeInstallError(f"the newer lavapipe needs {' '.join(packages)}: install them as root "
                                   f"(apt-get install {' '.join(packages)}); the system's lavapipe stays in use")
    print(f"[lavapipe] apt-get install {' '.join(packages)} (libraries the newer lavapipe links against)")
    env = {**os.environ, "DEBIAN_FRONTEND": "noninteractive"}
    # (A fresh container has no package lists yet; install.sh updates them only for its own packages.)
    subprocess.run(["apt-get", "update", "-qq"], env=env, capture_output=True, check=False)
    r = subprocess.run(["apt-get", "install", "-y", "-qq", *packages], env=env, capture_output=True, text=True,
                       check=False)
    if r.returncode != 0:
        raise LavapipeInstallError(f"apt-get install {' '.join(packages)} failed: "
                                   f"{(r.stderr.strip().splitlines() or ['?'])[-1]}")


def _fetch(url: str, timeout: float = 60.0) -> bytes:
    try:
        with urllib.request.urlopen(url, timeout=timeout) as r:  # noqa: S310 (a fixed https/http mirror)
            return r.read()
    except OSError as e:
        raise LavapipeInstallError(f"cannot download {url}: {e}") from None


def _verifier(keyring: Path, signed: Path, out: Path) -> list[str] | None:
    """The command that checks a clearsigned file against ``keyring`` as apt would: gpgv (Debian 12's apt),
    or sqv (Debian 13's apt uses Sequoia's sqv, and gpgv may be absent); None when neither is installed."""
    if shutil.which("gpgv"):
        return ["gpgv", "--keyring", str(keyring), "--output", str(out), str(signed)]
    if shutil.which("sqv"):
        return ["sqv", f"--keyring={keyring}", f"--output={out}", "--cleartext", str(signed)]
    return None


def verified_release(signed: bytes, keyring: Path = KEYRING) -> str:
    """The text of a clearsigned ``InRelease`` file after gpgv or sqv has checked its signature against the
    Debian archive keyring (what apt does); raises when it cannot be checked."""
    with tempfile.TemporaryDirectory() as tmp:
        src, out = Path(tmp) / "InRelease", Path(tmp) / "Release"
        command = _verifier(keyring, src, out)
        if command is None or not keyring.is_file():
            raise LavapipeInstallError(f"gpgv or sqv, or {keyring}, missing: cannot check Debian's signature")
        src.write_bytes(signed)
        r = subprocess.run(command, capture_output=True, text=True, check=False)
        if r.returncode != 0 or not out.is_file():
            why = r.stderr.strip().splitlines()[-1:]
            raise LavapipeInstallError(f"bad signature on {backports_suite()}'s InRelease: {why}")
        return out.read_text()


def check_fresh(release: str, now: datetime | None = None) -> None:
    """Refuse a Release file past its ``Valid-Until`` (an old, once-signed index replayed by a mirror or
    a proxy would otherwise pass the signature check; apt refuses it too)."""
    field = re.search(r"^Valid-Until:\s*(.+)$", release, re.M)
    if field is None:
        return
    until = parsedate_to_datetime(field.group(1).strip())
    if (now or datetime.now(timezone.utc)) > until:
        raise LavapipeInstallError(f"{backports_suite()}'s Release file expired on {field.group(1).strip()} "
                                   "(a stale mirror?)")


def release_sha256(release: str, path: str) -> tuple[str, int]:
    """(sha256, size) that a Release file's SHA256 section lists for ``path``."""
    section = release.split("\nSHA256:", 1)[-1] if "\nSHA256:" in release else ""
    for line in section.splitlines()[1:]:
        if not line.startswith(" "):
            break
        digest, size, name = line.split()
        if name == path:
            return digest, int(size)
    raise LavapipeInstallError(f"{path} is not listed in {backports_suite()}'s Release file")


def package_stanza(packages: str, name: str = PACKAGE) -> dict[str, str]:
    """The newest stanza for ``name`` in a Packages index (fields as a dict)."""
    best: dict[str, str] | None = None
    for block in packages.split("\n\n"):
        fields = dict(re.findall(r"^([A-Za-z0-9-]+):\s*(.*)$", block, re.M))
        if fields.get("Package") == name and (best is None or package_version(fields.get("Version", ""))
                                              > package_version(best.get("Version", ""))):
            best = fields
    if best is None or not {"Filename", "SHA256", "Version"} <= best.keys():
        raise LavapipeInstallError(f"{name} is not in {backports_suite()}")
    return best


def _checked(data: bytes, digest: str, what: str) -> bytes:
    if hashlib.sha256(data).hexdigest() != digest:
        raise LavapipeInstallError(f"{what}: checksum does not match Debian's index")
    return data


def deb_members(deb: bytes) -> dict[str, bytes]:
    """The members of a .deb (an ``ar`` archive): name -> bytes."""
    if not deb.startswith(b"!<arch>\n"):
        raise LavapipeInstallError("not a .deb (ar) archive")
    members, pos = {}, 8
    while pos + 60 <= len(deb):
        header = deb[pos:pos + 60]
        name, size = header[:16].decode().strip().rstrip("/"), int(header[48:58].decode().strip())
        members[name] = deb[pos + 60:pos + 60 + size]
        pos += 60 + size + (size & 1)  # members are 2-byte aligned
    return members


def lavapipe_files(deb: bytes) -> tuple[bytes, bytes]:
    """(the lavapipe library, its driver manifest) from a mesa-vulkan-drivers .deb."""
    members = deb_members(deb)
    data = next((members[n] for n in ("data.tar.xz", "data.tar.gz") if n in members), None)
    if data is None:
        raise LavapipeInstallError(f"the package holds none of data.tar.xz/gz ({sorted(members)})")
    library = manifest = None
    with tarfile.open(fileobj=io.BytesIO(data)) as tar:
        for info in tar:
            base = Path(info.name).name
            if info.isfile() and base == LIBRARY:
                library = tar.extractfile(info).read()
            elif info.isfile() and re.fullmatch(r"lvp_icd(\.[a-z0-9_]+)?\.json", base):
                manifest = tar.extractfile(info).read()
    if library is None or manifest is None:
        raise LavapipeInstallError("the package holds no lavapipe library or manifest")
    return library, manifest


def _works(manifest: Path, version: str) -> str | None:
    """Start wgpu in a child process with only this driver; its adapter description, or None."""
    env = {**os.environ, "VK_ICD_FILENAMES": str(manifest), "VK_DRIVER_FILES": str(manifest)}
    code = ("import wgpu; a = [a.info['description'] for a in wgpu.gpu.enumerate_adapters_sync() "
            "if a.info['backend_type'] == 'Vulkan']; print(a[0] if a else '')")
    r = subprocess.run([sys.executable, "-c", code], env=env, capture_output=True, text=True, timeout=120,
                       check=False)
    described = r.stdout.strip().splitlines()[-1:] if r.returncode == 0 else []
    return described[0] if described and mesa_version(described[0])[:2] == package_version(version)[:2] else None


def install(root: Path | None = None, force: bool = False, update: bool = False,
            with_dependencies: bool = False) -> Path | None:
    """Fetch, check and unpack the newer lavapipe; return its manifest (None when not needed here).
    With one already cached nothing is fetched unless ``update`` (then a newer backport is added). Packages
    the backport depends on that are not installed are installed with apt-get first when
    ``with_dependencies`` (as root); otherwise a driver that then does not start is reported with them."""
    root = root or cache_root()
    if not force and (reason := _why_not_needed()):
        print(f"[lavapipe] system lavapipe kept: {reason}")
        return None
    if not update and (cached := cached_manifest(root)) is not None:
        return cached  # no network once one is cached
    arch = _dpkg("--print-architecture") or "amd64"
    suite = backports_suite()
    release = verified_release(_fetch(f"{MIRROR}/dists/{suite}/InRelease"))
    check_fresh(release)
    index = f"main/binary-{arch}/Packages.xz"
    digest, _ = release_sha256(release, index)
    packages = lzma.decompress(_checked(_fetch(f"{MIRROR}/dists/{suite}/{index}"), digest, index)).decode()
    stanza = package_stanza(packages)
    version = stanza["Version"]
    target = root / version.replace("~", "_").replace("+", "_")
    if (target / MANIFEST).is_file() and (target / LIBRARY).is_file():
        print(f"[lavapipe] Mesa {version} already in {target}")
        return target / MANIFEST
    missing = missing_packages(stanza.get("Depends", ""))
    if missing and with_dependencies:
        _apt_install(missing)
        missing = []
    print(f"[lavapipe] fetching Mesa {version}'s lavapipe from {suite} ({int(stanza.get('Size', 0)) >> 20} MB)")
    deb = _checked(_fetch(f"{MIRROR}/{stanza['Filename']}", timeout=300), stanza["SHA256"], stanza["Filename"])
    library, manifest_text = lavapipe_files(deb)
    root.mkdir(parents=True, exist_ok=True)
    tmp = Path(tempfile.mkdtemp(prefix=".partial-", dir=root))
    try:
        (tmp / LIBRARY).write_bytes(library)
        spec = json.loads(manifest_text)
        spec["ICD"]["library_path"] = str(target / LIBRARY)  # absolute: the loader needs no search path
        (tmp / MANIFEST).write_text(json.dumps(spec, indent=2))
        (tmp / "source.json").write_text(json.dumps(
            {"package": PACKAGE, "version": version, "suite": suite, "url": f"{MIRROR}/{stanza['Filename']}",
             "sha256": stanza["SHA256"]}, indent=2))
        shutil.rmtree(target, ignore_errors=True)
        try:
            tmp.rename(target)  # complete or absent: cached_manifest never sees half a driver
        except OSError:
            if not (target / LIBRARY).is_file():  # (else another install, e.g. a second `make`, won the race)
                raise
    finally:
        shutil.rmtree(tmp, ignore_errors=True)
    described = _works(target / MANIFEST, version)
    if described is None:
        shutil.rmtree(target, ignore_errors=True)
        # (Only now: the backport's Depends also lists what its other drivers need, which lavapipe may not.)
        hint = (f" (it depends on {' '.join(missing)}, not installed here: apt-get install {' '.join(missing)}, "
                "or `scripts/lavapipe_backport.py install --with-dependencies` as root)") if missing else ""
        raise LavapipeInstallError(f"Mesa {version}'s lavapipe did not start here{hint}; the system's stays in use")
    print(f"[lavapipe] installed {described} in {target}")
    return target / MANIFEST


def status() -> None:
    manifest = cached_manifest()
    listed = loader_folder() / LISTING
    print(f"cached lavapipe: {manifest.parent if manifest else 'none'} (cache {cache_root()})")
    print(f"listed for the Vulkan loader: {listed if listed.is_file() else 'no'}")
    if reason := _why_not_needed():
        print(f"not needed here: {reason}")


def main(argv: list[str] | None = None) -> int:
    import argparse

    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("action", choices=("status", "install", "remove"))
    p.add_argument("--force", action="store_true",
                   help="install even where the system's Mesa would be kept (not Debian 12 or 13, or its Mesa "
                        "is as new as the backport's major)")
    p.add_argument("--with-dependencies", action="store_true",
                   help="apt-get install the packages the backport links against that are missing (as root)")
    p.add_argument("--update", action="store_true", help="look for a newer backport even with one cached")
    args = p.parse_args(argv)
    if args.action == "status":
        status()
        return 0
    if args.action == "remove":
        print(f"[lavapipe] {'unlisted' if unlist() else 'nothing listed in'} {loader_folder()}")
        return 0
    try:
        manifest = install(force=args.force, update=args.update, with_dependencies=args.with_dependencies)
    except LavapipeInstallError as e:
        print(f"[lavapipe] {e}", file=sys.stderr)
        return 1
    if manifest is not None:
        print(f"[lavapipe] listed {manifest.parent.name} for the Vulkan loader: {list_with_loader(manifest)}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
