"""A BLASFEO built for the target CPU, linked by a C export under the casadi wheel's HPIPM.

The casadi wheel's BLASFEO is the portable GENERIC build (no SIMD): on an x86-64 with AVX2
and FMA, HPIPM's median step takes twice the instructions it needs there
(docs/performance.md, "The exported step and the 0.2 ms floor"). BLASFEO is meant to be
built per CPU (its ``TARGET``), so ``export-c --blasfeo DIR`` links the one in DIR instead:
HPIPM stays the wheel's, the linear algebra under it is the target's. Its
``blasfeo_target.h`` says which instruction-set features it needs; a replay on a CPU without
them would stop on an illegal instruction, so ``verify-c`` checks them first.
"""

from __future__ import annotations

import re
from pathlib import Path

from auvmpc.errors import ConfigError

__all__ = ["LIBRARY", "blasfeo_folder", "missing_features", "required_features"]

LIBRARY = "libblasfeo.so"
_HEADER = "blasfeo_target.h"
_FEATURE = re.compile(r"#define\s+TARGET_NEED_FEATURE_(\w+)\s+1\b")
# BLASFEO's feature names -> the flags /proc/cpuinfo lists for them (x86: flags, Arm: Features).
_CPUINFO_FLAGS = {
    "SSE3": ("pni",),
    "AVX": ("avx",),
    "AVX2": ("avx2",),
    "FMA": ("fma",),
    "AVX512F": ("avx512f",),
    "VFPv3": ("vfpv3", "vfp"),
    "VFPv4": ("vfpv4",),
    "NEON": ("neon", "asimd"),
    "NEONv2": ("asimd",),
}


def blasfeo_folder(path: Path | str) -> Path:
    """The folder ``path`` (absolute), if it holds a ``libblasfeo.so``; else one line."""
    folder = Path(path).expanduser().resolve()
    if not (folder / LIBRARY).is_file():
        raise ConfigError("--blasfeo", str(path), f"no {LIBRARY} in that folder")
    return folder


def required_features(folder: Path) -> tuple[str, ...]:
    """The CPU features the BLASFEO in ``folder`` was built to need (its ``blasfeo_target.h``
    beside it or in an ``include`` folder next to it; none found: none known)."""
    for candidate in (folder / _HEADER, folder / "include" / _HEADER,
                      folder.parent / "include" / _HEADER):  # fmt: skip
        if candidate.is_file():
            return tuple(_FEATURE.findall(candidate.read_text()))
    return ()


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
