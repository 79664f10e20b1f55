"""A BLASFEO built for the target CPU, linked under the casadi wheel's HPIPM instead of the
wheel's own: by a C export (``export-c --blasfeo DIR``) and by the real-time nmpc's compiled
QP step in Python (``AUVMPC_BLASFEO_DIR=DIR``).

The casadi wheel's BLASFEO is the portable GENERIC build (no SIMD): on an x86-64 with AVX2
and FMA, HPIPM's median step takes twice the instructions it needs there
(docs/performance.md, "The exported step and the 0.2 ms floor"). BLASFEO is meant to be
built per CPU (its ``TARGET``), so the one in DIR can be linked instead: HPIPM stays the
wheel's, the linear algebra under it is the target's. Its
``blasfeo_target.h`` says which instruction-set features it needs; a replay on a CPU without
them would stop on an illegal instruction, so ``verify-c`` checks them first. The wheel's
HPIPM was compiled for BLASFEO's panel-major matrices of the wheel's panel size, so a target
with another panel size (AVX-512's SKYLAKE_X: 8 doubles, not 4) is refused at export.
"""

from __future__ import annotations

import os
import re
from pathlib import Path

from auvmpc.errors import ConfigError

__all__ = [
    "BLASFEO_ENV",
    "LIBRARY",
    "blasfeo_folder",
    "blasfeo_target",
    "missing_features",
    "required_features",
    "runtime_blasfeo",
]

LIBRARY = "libblasfeo.so"
# Where the Python side's compiled QP step takes its BLASFEO from (unset: the wheel's).
BLASFEO_ENV = "AUVMPC_BLASFEO_DIR"
_HEADER = "blasfeo_target.h"
_FEATURE = re.compile(r"#define\s+TARGET_NEED_FEATURE_(\w+)\s+1\b")
# BLASFEO's feature names -> the flags /proc/cpuinfo lists for them (x86: flags, Arm: Features).
_CPUINFO_FLAGS = {
    "SSE3": ("pni",),
    "AVX": ("avx",),
    "AVX2": ("avx2",),
    "FMA": ("fma",),
    "AVX512F": ("avx512f",),
    # 64-bit Arm lists "fp" (VFPv4 and more) and "asimd" (NEON) where 32-bit Arm lists these
    "VFPv3": ("vfpv3", "fp"),
    "VFPv4": ("vfpv4", "fp"),
    "NEON": ("neon", "asimd"),
    "NEONv2": ("asimd",),
}


def runtime_blasfeo(wheel_include: Path) -> Path | None:
    """The BLASFEO folder ``$AUVMPC_BLASFEO_DIR`` names for this process's compiled QP steps,
    checked as :func:`blasfeo_folder` does and for this CPU's features; None when unset."""
    value = os.environ.get(BLASFEO_ENV, "")
    if not value:
        return None
    folder = blasfeo_folder(value, wheel_include, field=BLASFEO_ENV)
    missing = missing_features(required_features(folder))
    if missing:
        raise ConfigError(
            BLASFEO_ENV, value,
            f"its BLASFEO needs CPU features this machine lacks ({', '.join(missing)})",
        )  # fmt: skip
    return folder


def blasfeo_folder(path: Path | str, wheel_include: Path, field: str = "--blasfeo") -> Path:
    """The folder ``path`` (absolute), if it holds a ``libblasfeo.so`` whose target header is
    found and whose panel size is that of the wheel's BLASFEO (``wheel_include``, the folder
    of the headers the wheel's HPIPM was built with); else one line naming ``field``."""
    folder = Path(path).expanduser().resolve()
    if not (folder / LIBRARY).is_file():
        raise ConfigError(field, str(path), f"no {LIBRARY} in that folder")
    header = _target_header(folder)
    if header is None:
        raise ConfigError(
            field, str(path),
            f"no {_HEADER} beside {LIBRARY} or in an include/ folder next to it: the CPU "
            "features that library needs cannot be checked",
        )  # fmt: skip
    target, wheel_target = _target(header), _target(wheel_include / _HEADER)
    sizes = _panel_sizes(wheel_include / "blasfeo_block_size.h")
    if sizes.get(target) != sizes.get(wheel_target):
        raise ConfigError(
            field, str(path),
            f"its target {target} packs {sizes.get(target, 'an unknown number of')} doubles per "
            f"panel; the casadi wheel's HPIPM was built for {sizes.get(wheel_target)} "
            f"({wheel_target}): choose a target with that panel size",
        )  # fmt: skip
    return folder


def required_features(folder: Path) -> tuple[str, ...]:
    """The CPU features the BLASFEO in ``folder`` was built to need (its target header)."""
    header = _target_header(folder)
    return () if header is None else tuple(_FEATURE.findall(header.read_text()))


def blasfeo_target(folder: Path) -> str:
    """The TARGET_... the BLASFEO in ``folder`` was built for (its target header), e.g.
    ``GENERIC`` or ``X64_INTEL_HASWELL``; "unknown" without a header."""
    header = _target_header(folder)
    return "unknown" if header is None else _target(header)


def _target_header(folder: Path) -> Path | None:
    """``blasfeo_target.h`` beside the library, in ``include/`` in it, or in ``../include``."""
    for candidate in (folder / _HEADER, folder / "include" / _HEADER,
                      folder.parent / "include" / _HEADER):  # fmt: skip
        if candidate.is_file():
            return candidate
    return None


def _target(header: Path) -> str:
    """The TARGET_... a ``blasfeo_target.h`` defines (the first; TARGET_NEED_* are not)."""
    for name in re.findall(r"#define\s+TARGET_(\w+)", header.read_text()):
        if not name.startswith("NEED_"):
            return name
    return "unknown"


def _panel_sizes(block_size_header: Path) -> dict[str, int]:
    """Each target's double-precision panel size (``D_PS``) in ``blasfeo_block_size.h``."""
    sizes, targets = {}, []
    for line in block_size_header.read_text().splitlines():
        named = re.findall(r"defined\s*\(\s*TARGET_(\w+)\s*\)", line)
        if named:
            targets = named
        panel = re.match(r"#define\s+D_PS\s+(\d+)", line)
        if panel:
            sizes.update(dict.fromkeys(targets, int(panel.group(1))))
    return sizes


def missing_features(features: tuple[str, ...], cpuinfo: Path = Path("/proc/cpuinfo")) -> list[str]:
    """Which of ``features`` this CPU lacks, by its /proc/cpuinfo flags (all of them where
    that cannot be read)."""
    try:
        words = set(cpuinfo.read_text().lower().split())
    except OSError:
        return list(features)
    return [
        name for name in features
        if not any(flag in words for flag in _CPUINFO_FLAGS.get(name, (name.lower(),)))
    ]  # fmt: skip
