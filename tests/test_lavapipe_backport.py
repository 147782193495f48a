"""The opt-in newer lavapipe (scripts/lavapipe_backport.py, outside the package): parsing Debian's index
and the .deb, checking every download against the index, installing completely or not at all, listing
the driver in the Vulkan loader's per-user folder and taking it out again; and the adapter choice
preferring the newer Mesa. Offline: downloads are served from memory (`make install LAVAPIPE=backports`
does the real fetch)."""

from __future__ import annotations

import hashlib
import importlib.util
import io
import json
import lzma
import os
import shutil
import subprocess
import sys
import tarfile
from pathlib import Path
from types import SimpleNamespace

import pytest

from gma.gpu import adapter as adapter_mod

SCRIPT = Path(__file__).resolve().parents[1] / "scripts" / "lavapipe_backport.py"


def _load_script():
    spec = importlib.util.spec_from_file_location("lavapipe_backport", SCRIPT)
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


lavapipe = _load_script()
LavapipeInstallError = lavapipe.LavapipeInstallError


def _tar_xz(files: dict[str, bytes]) -> bytes:
    buf = io.BytesIO()
    with tarfile.open(fileobj=buf, mode="w:xz") as tar:
        for name, data in files.items():
            info = tarfile.TarInfo(name)
            info.size = len(data)
            tar.addfile(info, io.BytesIO(data))
    return buf.getvalue()


def _ar(members: dict[str, bytes]) -> bytes:
    out = bytearray(b"!<arch>\n")
    for name, data in members.items():
        out += f"{name + '/':<16}{0:<12}{0:<6}{0:<6}{100644:<8}{len(data):<10}`\n".encode()
        out += data + (b"\n" if len(data) % 2 else b"")  # odd sizes are padded to 2 bytes
    return bytes(out)


LIB = b"\x7fELF fake lavapipe" * 7  # odd length: exercises the ar padding
ICD = json.dumps({"file_format_version": "1.0.0", "ICD": {"library_path": "libvulkan_lvp.so",
                                                          "api_version": "1.4.305"}}).encode()


def _deb() -> bytes:
    data = _tar_xz({"./usr/lib/x86_64-linux-gnu/libvulkan_lvp.so": LIB,
                    "./usr/lib/x86_64-linux-gnu/libvulkan_radeon.so": b"other driver",
                    "./usr/share/vulkan/icd.d/lvp_icd.json": ICD,
                    "./usr/share/vulkan/icd.d/radeon_icd.json": b"{}"})
    return _ar({"debian-binary": b"2.0\n", "control.tar.xz": _tar_xz({"./control": b"Package: x\n"}),
                "data.tar.xz": data})


def _packages(deb: bytes) -> str:
    return ("Package: libvulkan1\nVersion: 1.3.0\nFilename: pool/x.deb\nSHA256: 00\n\n"
            "Package: mesa-vulkan-drivers\nVersion: 24.2.8-1~bpo12+1\nFilename: pool/old.deb\nSHA256: 00\n\n"
            f"Package: mesa-vulkan-drivers\nVersion: 25.0.7-2~bpo12+1\nSize: {len(deb)}\n"
            f"Filename: pool/main/m/mesa/new.deb\nSHA256: {hashlib.sha256(deb).hexdigest()}\n")


def _release(packages_xz: bytes) -> str:
    return ("Origin: Debian Backports\nSuite: bookworm-backports\nMD5Sum:\n 00 1 main/binary-amd64/Packages.xz\n"
            f"SHA256:\n 11 5 main/binary-arm64/Packages.xz\n {hashlib.sha256(packages_xz).hexdigest()} "
            f"{len(packages_xz)} main/binary-amd64/Packages.xz\n")


def test_mesa_version_from_adapters_and_packages():
    assert lavapipe.mesa_version("Mesa 25.0.7-2~bpo12+1 (LLVM 15.0.6)") == (25, 0, 7)
    assert lavapipe.mesa_version("Mesa 22.3.6 (LLVM 15.0.6)") == (22, 3, 6)
    assert lavapipe.mesa_version("4.5 (Core Profile) Mesa 25.0.7") == (25, 0, 7)  # not the GL version
    assert lavapipe.package_version("25.0.7-2~bpo12+1") == (25, 0, 7)
    assert lavapipe.package_version("25.0.7-2_bpo12_1") == (25, 0, 7)  # the cache folder's name
    assert lavapipe.mesa_version("NVIDIA driver") == ()
    assert lavapipe.mesa_version("560.35.03") == ()  # a version, but not Mesa's


def test_index_parsing_picks_the_newest_package_and_its_checksum():
    deb = _deb()
    stanza = lavapipe.package_stanza(_packages(deb))
    assert stanza["Version"] == "25.0.7-2~bpo12+1" and stanza["Filename"].endswith("new.deb")
    with pytest.raises(LavapipeInstallError, match="not in"):
        lavapipe.package_stanza("Package: other\nVersion: 1\n")
    xz = lzma.compress(_packages(deb).encode())
    assert lavapipe.release_sha256(_release(xz), "main/binary-amd64/Packages.xz") == \
        (hashlib.sha256(xz).hexdigest(), len(xz))
    with pytest.raises(LavapipeInstallError, match="not listed"):
        lavapipe.release_sha256(_release(xz), "main/binary-riscv64/Packages.xz")


def test_an_expired_release_is_refused():
    from datetime import datetime, timezone

    release = "Suite: bookworm-backports\nValid-Until: Fri, 04 Dec 2026 02:10:32 UTC\n"
    lavapipe.check_fresh(release, datetime(2026, 12, 1, tzinfo=timezone.utc))
    with pytest.raises(LavapipeInstallError, match="expired"):
        lavapipe.check_fresh(release, datetime(2026, 12, 5, tzinfo=timezone.utc))


def test_deb_unpacking_takes_only_lavapipe():
    library, manifest = lavapipe.lavapipe_files(_deb())
    assert library == LIB and json.loads(manifest)["ICD"]["library_path"] == "libvulkan_lvp.so"
    with pytest.raises(LavapipeInstallError, match="not a .deb"):
        lavapipe.lavapipe_files(b"PK\x03\x04 a zip")
    with pytest.raises(LavapipeInstallError, match="no lavapipe"):
        lavapipe.lavapipe_files(_ar({"data.tar.xz": _tar_xz({"./usr/share/doc/x": b"x"})}))


@pytest.mark.skipif(not (shutil.which("gpgv") or shutil.which("sqv")) or not lavapipe.KEYRING.is_file(),
                    reason="needs gpgv or sqv, and Debian's keyring")
def test_an_unsigned_release_is_refused():
    forged = b"-----BEGIN PGP SIGNED MESSAGE-----\nHash: SHA256\n\nSHA256:\n 00 1 x\n" \
             b"-----BEGIN PGP SIGNATURE-----\n\niQIzBAEBCAAdFiEE\n-----END PGP SIGNATURE-----\n"
    with pytest.raises(LavapipeInstallError, match="signature"):
        lavapipe.verified_release(forged)


def _serve(monkeypatch, tmp_path, codename="bookworm", depends=""):
    """install() against an in-memory mirror of ``codename``'s backports; returns the files it serves
    (tests may corrupt them)."""
    deb = _deb()
    packages = _packages(deb) + (f"Depends: {depends}\n" if depends else "")
    xz = lzma.compress(packages.encode())
    dists = f"dists/{codename}-backports"
    files = {f"{dists}/InRelease": b"signed", f"{dists}/main/binary-amd64/Packages.xz": xz,
             "pool/main/m/mesa/new.deb": deb}
    monkeypatch.setattr(lavapipe, "_fetch", lambda url, timeout=60.0: files[url.removeprefix(lavapipe.MIRROR + "/")])
    monkeypatch.setattr(lavapipe, "verified_release", lambda signed: _release(xz))
    monkeypatch.setattr(lavapipe, "_dpkg", lambda *a: "amd64")
    monkeypatch.setattr(lavapipe, "_os_release", lambda: {"VERSION_CODENAME": codename})
    monkeypatch.setattr(lavapipe, "_works", lambda manifest, version: f"Mesa {version} (LLVM 15.0.6)")
    monkeypatch.setenv("GMA_LAVAPIPE_DIR", str(tmp_path / "cache"))
    return files


@pytest.fixture
def served(monkeypatch, tmp_path):
    return _serve(monkeypatch, tmp_path)


def test_install_unpacks_a_complete_driver_with_an_absolute_library_path(served, tmp_path):
    manifest = lavapipe.install(force=True)
    folder = tmp_path / "cache" / "25.0.7-2_bpo12_1"
    assert manifest == folder / "lvp_icd.json"
    assert (folder / "libvulkan_lvp.so").read_bytes() == LIB
    assert json.loads(manifest.read_text())["ICD"]["library_path"] == str(folder / "libvulkan_lvp.so")
    assert json.loads((folder / "source.json").read_text())["version"] == "25.0.7-2~bpo12+1"
    assert sorted(p.name for p in (tmp_path / "cache").iterdir()) == [folder.name]  # no partial folder left
    assert lavapipe.cached_manifest() == manifest
    del served["pool/main/m/mesa/new.deb"]  # a second run fetches nothing
    assert lavapipe.install(force=True) == manifest
    assert lavapipe.install(force=True, update=True) == manifest  # the index has nothing newer


def test_install_refuses_a_download_that_does_not_match_the_index(served, tmp_path):
    served["pool/main/m/mesa/new.deb"] = served["pool/main/m/mesa/new.deb"][:-1] + b"X"
    with pytest.raises(LavapipeInstallError, match="checksum"):
        lavapipe.install(force=True)
    assert lavapipe.cached_manifest() is None


def test_a_driver_that_does_not_start_is_removed(served, monkeypatch, tmp_path):
    monkeypatch.setattr(lavapipe, "_works", lambda manifest, version: None)
    with pytest.raises(LavapipeInstallError, match="did not start"):
        lavapipe.install(force=True)
    assert list((tmp_path / "cache").iterdir()) == []


def test_install_keeps_the_system_driver_where_it_is_not_needed(monkeypatch, capsys):
    monkeypatch.setattr(lavapipe, "_os_release", lambda: {"VERSION_CODENAME": "noble"})
    assert lavapipe.install() is None
    assert "system lavapipe kept: not Debian 12 or 13 (noble)" in capsys.readouterr().out
    monkeypatch.setattr(lavapipe.shutil, "which", lambda name: "/usr/bin/" + name)
    for codename, system_mesa, kept in (("bookworm", "22.3.6-1+deb12u1", False), ("bookworm", "24.2.8-1", True),
                                        ("trixie", "25.0.7-2", False), ("trixie", "26.1.6-1", True),
                                        ("noble", "25.0.7-0ubuntu1", True), ("", "22.3.6", True)):
        monkeypatch.setattr(lavapipe, "_os_release", lambda c=codename: {"VERSION_CODENAME": c})
        monkeypatch.setattr(lavapipe, "_dpkg", lambda *a, v=system_mesa: f"Package: x\nVersion: {v}\n")
        assert (lavapipe._why_not_needed() is not None) == kept, (codename, system_mesa)


def test_debian_13_fetches_trixie_backports(monkeypatch, tmp_path):
    _serve(monkeypatch, tmp_path, codename="trixie")
    assert lavapipe.backports_suite() == "trixie-backports"
    manifest = lavapipe.install(force=True)
    assert manifest.parent.name == "25.0.7-2_bpo12_1"   # (the fake index's version)
    assert lavapipe.built_for(manifest.parent) == "trixie-backports" and lavapipe.cached_manifest() == manifest


def test_missing_dependencies_are_named_or_installed(monkeypatch, tmp_path):
    depends = "libvulkan1, libc6 (>= 2.39), libdisplay-info2 (>= 0.2.0), libelf1t64 | libelf1, libllvm19:any"
    _serve(monkeypatch, tmp_path, codename="trixie", depends=depends)
    assert lavapipe._dependency_names(depends) == [["libvulkan1"], ["libc6"], ["libdisplay-info2"],
                                                   ["libelf1t64", "libelf1"], ["libllvm19"]]
    installed = {"libvulkan1": "installed", "libc6": "installed", "libelf1": "installed",
                 "libllvm19": "config-files"}
    monkeypatch.setattr(lavapipe, "_dpkg_query", lambda names: {n: installed[n] for n in names if n in installed})
    asked = []
    monkeypatch.setattr(lavapipe, "_apt_install", asked.append)
    monkeypatch.setattr(lavapipe, "_works", lambda manifest, version: None)   # (a missing library)
    with pytest.raises(LavapipeInstallError, match="did not start here .*depends on libdisplay-info2 libllvm19"):
        lavapipe.install(force=True)
    assert lavapipe.cached_manifest() is None and asked == []
    monkeypatch.setattr(lavapipe, "_works", lambda manifest, version: f"Mesa {version} (LLVM 19.1.7)")
    assert lavapipe.install(force=True, with_dependencies=True) is not None
    assert asked == [["libdisplay-info2", "libllvm19"]]


def _cache_with(tmp_path, *versions, complete=True, suite=None):
    for v in versions:
        d = tmp_path / v
        d.mkdir(parents=True)
        (d / "lvp_icd.json").write_text("{}")
        if complete:
            (d / "libvulkan_lvp.so").write_bytes(b"x")
        if suite:
            (d / "source.json").write_text(json.dumps({"version": v, "suite": suite}))
    return tmp_path


@pytest.fixture(autouse=True)
def _debian_12(monkeypatch):
    """These tests describe a Debian 12 machine unless they say otherwise."""
    monkeypatch.setattr(lavapipe, "_os_release", lambda: {"VERSION_CODENAME": "bookworm"})


def test_each_release_registers_only_drivers_fetched_for_it(monkeypatch, tmp_path):
    """A home folder shared by a Debian 12 and a Debian 13 machine caches both releases' drivers; Debian
    13's would not load on Debian 12 (older C library), so each machine takes its own."""
    _cache_with(tmp_path, "25.0.7-2_bpo12_1")   # cached before source.json named the suite: Debian 12's
    _cache_with(tmp_path, "26.1.6-1_bpo13_1", suite="trixie-backports")
    monkeypatch.setenv("GMA_LAVAPIPE_DIR", str(tmp_path))
    assert lavapipe.cached_manifest().parent.name == "25.0.7-2_bpo12_1"
    monkeypatch.setattr(lavapipe, "_os_release", lambda: {"VERSION_CODENAME": "trixie"})
    assert lavapipe.cached_manifest().parent.name == "26.1.6-1_bpo13_1"


def test_the_driver_is_listed_for_the_loader_and_taken_out_again(monkeypatch, tmp_path):
    """install lists the cached driver's manifest in the loader's per-user folder ($XDG_DATA_HOME), as one
    file replaced whole; remove takes it out and leaves the cache."""
    monkeypatch.setenv("GMA_LAVAPIPE_DIR", str(_cache_with(tmp_path / "cache", "24.2.8-1", "25.0.7-2_bpo12_1")))
    monkeypatch.setenv("XDG_DATA_HOME", str(tmp_path / "data"))
    folder = tmp_path / "data" / "vulkan" / "icd.d"
    assert lavapipe.loader_folder() == folder
    monkeypatch.setattr(lavapipe, "_why_not_needed", lambda: None)
    assert lavapipe.main(["install"]) == 0
    listed = folder / lavapipe.LISTING
    assert listed.read_text() == (tmp_path / "cache" / "25.0.7-2_bpo12_1" / "lvp_icd.json").read_text()
    assert lavapipe.main(["install"]) == 0 and sorted(p.name for p in folder.iterdir()) == [listed.name]
    assert lavapipe.main(["remove"]) == 0 and not listed.exists()
    assert lavapipe.cached_manifest() is not None
    monkeypatch.delenv("XDG_DATA_HOME")
    assert lavapipe.loader_folder() == Path.home() / ".local" / "share" / "vulkan" / "icd.d"


def test_a_failed_install_is_one_line_and_lists_nothing(served, monkeypatch, tmp_path, capsys):
    served["pool/main/m/mesa/new.deb"] = b"corrupt"
    monkeypatch.setenv("XDG_DATA_HOME", str(tmp_path / "data"))
    assert lavapipe.main(["install", "--force"]) == 1
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "checksum" in err[0]
    assert not (tmp_path / "data").exists()


def test_an_incomplete_cache_folder_is_ignored(monkeypatch, tmp_path):
    monkeypatch.setenv("GMA_LAVAPIPE_DIR", str(_cache_with(tmp_path, "25.0.7-2", complete=False)))
    assert lavapipe.cached_manifest() is None


def test_the_script_runs_without_gma():
    """It runs before GMA is installed: the standard library only (a bad action: argparse's exit 2)."""
    out = subprocess.run([sys.executable, "-I", str(SCRIPT), "status"], capture_output=True, text=True,
                         timeout=60, env={**os.environ, "PYTHONPATH": ""})
    assert out.returncode == 0 and "cached lavapipe:" in out.stdout, out.stderr
    bad = subprocess.run([sys.executable, "-I", str(SCRIPT), "fetch"], capture_output=True, text=True, timeout=60)
    assert bad.returncode == 2 and "Traceback" not in bad.stderr


def test_adapter_choice_prefers_hardware_then_the_newer_mesa():
    def fake(kind, description, backend="Vulkan"):
        return SimpleNamespace(info={"adapter_type": kind, "backend_type": backend, "description": description})

    old, new = fake("CPU", "Mesa 22.3.6 (LLVM 15.0.6)"), fake("CPU", "Mesa 25.0.7-2~bpo12+1 (LLVM 15.0.6)")
    gl = fake("CPU", "4.5 (Core Profile) Mesa 25.0.7", backend="OpenGL")
    gpu = fake("DiscreteGPU", "NVIDIA 560.35.03")
    assert min([old, gl, new], key=adapter_mod._rank) is new
    assert adapter_mod.mesa_version("Mesa 25.0.7-2~bpo12+1 (LLVM 15.0.6)") == (25, 0, 7)
    assert adapter_mod.mesa_version("NVIDIA driver") == ()
    assert min([old, new, gpu], key=adapter_mod._rank) is gpu


@pytest.mark.gpu
def test_gma_gpu_names_the_adapter_and_the_loader_variables(tmp_path):
    """``gma gpu`` lists the adapters, the one GMA renders with (its driver) and the loader's variables;
    a driver listed in the loader's per-user folder is seen without GMA doing anything."""
    env = {**os.environ, "VK_ADD_DRIVER_FILES": str(tmp_path / "absent.json"), "PYTHONPATH": str(SCRIPT.parents[1])}
    out = subprocess.run([sys.executable, "-m", "gma.cli", "gpu"], capture_output=True, text=True, timeout=120,
                         env=env, cwd=SCRIPT.parents[1])
    if "No usable GPU adapter" in out.stderr:
        pytest.skip("no adapter")
    assert out.returncode == 0, out.stderr
    assert "seen: " in out.stdout and "renders with: " in out.stdout
    assert f"VK_ADD_DRIVER_FILES={tmp_path / 'absent.json'}" in out.stdout
