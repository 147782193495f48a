"""Loading WGSL: one file per pass, ``#include "common/x.wgsl"`` resolved by name, compile-time
defines prepended as ``const`` declarations, ``#if NAME`` / ``#else`` / ``#endif`` blocks kept or
dropped by a define's truth (for variants that change bindings or entry-point builtins, which WGSL
itself cannot express), and compile errors reported with numbered source.

The sources are found in one place: ``gma/_shaders/wgsl`` inside an installed wheel, otherwise the
checkout's top-level ``shaders/wgsl``.
"""

from __future__ import annotations

import os
import re
from pathlib import Path

import wgpu

_INCLUDE = re.compile(r'^\s*#include\s+"([^"]+)"\s*$')
_IF = re.compile(r"^\s*#if\s+(!?)(\w+)\s*$")
_ELSE = re.compile(r"^\s*#else\s*$")
_ENDIF = re.compile(r"^\s*#endif\s*$")


def shader_root() -> Path:
    """Directory holding the WGSL sources (``$GMA_SHADER_DIR`` overrides, for shader development)."""
    override = os.environ.get("GMA_SHADER_DIR")
    if override:
        return Path(override)
    package_dir = Path(__file__).resolve().parents[1]
    bundled = package_dir / "_shaders" / "wgsl"
    if bundled.is_dir():
        return bundled
    checkout = package_dir.parent / "shaders" / "wgsl"
    if checkout.is_dir():
        return checkout
    raise FileNotFoundError(f"WGSL sources not found in {bundled} nor {checkout}; the install is incomplete")


class ShaderCompileError(RuntimeError):
    """A WGSL module failed to compile; the message holds naga's error and the numbered source."""


def _format_define(name: str, value) -> str:
    if isinstance(value, bool):
        return f"const {name}: bool = {'true' if value else 'false'};"
    if isinstance(value, int):
        if value < 0:
            return f"const {name}: i32 = {value}i;"
        return f"const {name}: u32 = {value}u;"
    if isinstance(value, float):
        return f"const {name}: f32 = {value!r};"
    raise TypeError(f"shader define {name} has unsupported type {type(value).__name__}")


def _select_conditionals(lines: list[str], defines: dict, rel: str) -> list[str]:
    """Keep the lines of ``#if NAME`` / ``#if !NAME`` blocks whose condition holds (nesting allowed)."""
    out: list[str] = []
    stack: list[bool] = []  # per open block: is its current branch active?
    for line in lines:
        if m := _IF.match(line):
            value = bool(defines.get(m.group(2), False)) != (m.group(1) == "!")
            stack.append(value)
        elif _ELSE.match(line):
            if not stack:
                raise ValueError(f"{rel}: #else without #if")
            stack[-1] = not stack[-1]
        elif _ENDIF.match(line):
            if not stack:
                raise ValueError(f"{rel}: #endif without #if")
            stack.pop()
        elif all(stack):
            out.append(line)
    if stack:
        raise ValueError(f"{rel}: #if without #endif")
    return out


def number_lines(source: str) -> str:
    return "\n".join(f"{i + 1:4d} | {line}" for i, line in enumerate(source.splitlines()))


class ShaderLibrary:
    """Reads WGSL files once, resolves includes, and builds shader modules per (file, defines)."""

    def __init__(self, root: Path | None = None):
        self.root = Path(root) if root is not None else shader_root()
        self._text: dict[str, str] = {}

    def _read(self, rel: str) -> str:
        text = self._text.get(rel)
        if text is None:
            path = self.root / rel
            if not path.is_file():
                raise FileNotFoundError(f"WGSL file {rel!r} not found under {self.root}")
            text = path.read_text()
            self._text[rel] = text
        return text

    def source(self, rel: str, defines: dict | None = None) -> str:
        """Full source of ``rel``: defines first, then the file with every include inlined once."""
        return self._expand(rel, self._read(rel), defines)

    def source_text(self, text: str, defines: dict | None = None) -> str:
        """Like :meth:`source` for WGSL held in a string (a benchmark's probe kernel), whose includes are
        this library's files."""
        return self._expand("<text>", text, defines)

    def _expand(self, rel: str, text: str, defines: dict | None) -> str:
        """``text`` (the source of ``rel``) with its includes inlined once, conditionals selected and the
        defines prepended."""
        seen: set[str] = set()

        def expand(name: str, stack: tuple[str, ...]) -> list[str]:
            if name in stack:
                raise ValueError(f"WGSL include cycle: {' -> '.join(stack + (name,))}")
            if name in seen:
                return []
            seen.add(name)
            out = [f"// ---- {name}"]
            for line in (text if name == rel else self._read(name)).splitlines():
                m = _INCLUDE.match(line)
                out.extend(expand(m.group(1), stack + (name,)) if m else [line])
            return out

        body = _select_conditionals(expand(rel, ()), defines or {}, rel)
        # Directives such as `enable subgroups;` must precede every declaration, defines included.
        directives = sorted({line.strip() for line in body if line.lstrip().startswith("enable ")})
        body = [line for line in body if not line.lstrip().startswith("enable ")]
        header = [_format_define(k, v) for k, v in sorted((defines or {}).items())]
        return "\n".join(directives + header + body)

    def module(self, device: wgpu.GPUDevice, rel: str, defines: dict | None = None) -> wgpu.GPUShaderModule:
        code = self.source(rel, defines)
        try:
            return device.create_shader_module(label=rel, code=code)
        except Exception as exc:  # wgpu raises GPUValidationError carrying naga's report
            raise ShaderCompileError(
                f"WGSL compile error in {rel} (defines={defines}):\n{exc}\n\n{number_lines(code)}"
            ) from exc
