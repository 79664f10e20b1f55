"""The computers an export of the C controller builds for (``make TARGET=name``), and the
HPIPM and BLASFEO it carries for each (docs/onboard.md).

An export is self-contained: for every target it holds HPIPM's and BLASFEO's shared libraries
(``lib/NAME/libhpipm.so``, ``lib/NAME/libblasfeo.so.0``, which HPIPM finds beside itself),
their headers (``include/``) and licences (``licenses/``), copied at export time from
packages auvmpc already uses: the installed casadi wheel (this computer's instruction set),
the aarch64 casadi wheel of the same version fetched once by ``make hpipm-aarch64``
(benchmarks/hpipm_aarch64.py), and a BLASFEO built for one CPU (``--blasfeo``). HPIPM and
BLASFEO are BSD-2-Clause: redistributable with their licence.

Targets: ``x86-64-generic`` and ``aarch64`` (the wheels' portable builds, GENERIC BLASFEO, no
instruction beyond the base instruction set but the x86-64 wheel's HPIPM's, which is built
with AVX: docs/onboard.md), and ``x86-64-tuned`` or ``aarch64-tuned``: the
wheel's HPIPM over the ``--blasfeo`` library, compiled for that BLASFEO's CPU.

Since the generic x86-64 build needs AVX anyway, it can carry a BLASFEO built for AVX
(``--generic-blasfeo``, X64_INTEL_SANDY_BRIDGE) instead of the GENERIC one: the same CPUs, a
faster step (docs/onboard.md, measured).

The generic x86-64 build also carries a tuned x86-64 BLASFEO where there is one, in
``lib/x86-64-generic/glibc-hwcaps/x86-64-vN/``: glibc's loader (2.33 on) takes a library from
there instead on a CPU of that level (x86-64-v3: AVX2 and FMA, Haswell on), and the GENERIC
one elsewhere, so the one portable program steps at about the tuned build's speed where the
CPU allows (docs/onboard.md, measured).
"""

from __future__ import annotations

import dataclasses
import platform
import shutil
from dataclasses import dataclass
from pathlib import Path

from auvmpc.errors import ConfigError
from auvmpc.solvers.blasfeo_target import LIBRARY, blasfeo_target, required_features

__all__ = [
    "AARCH64_VERSION_FILE",
    "Target",
    "aarch64_target",
    "generic_with",
    "host_machine",
    "hwcaps_level",
    "makefile_table",
    "tuned_target",
    "wheel_target",
    "write_solver_files",
]

AARCH64_VERSION_FILE = "casadi-version"  # written by benchmarks/hpipm_aarch64.py
_HPIPM, _BLASFEO = "libhpipm.so", "libblasfeo.so.0"  # the names HPIPM links and looks for
# ELF e_machine -> the machine names uname and Debian's cross compilers use
_ELF_MACHINES = {62: "x86_64", 183: "aarch64"}
_PORTABLE = {"x86_64": ("x86-64-generic", "-march=x86-64 -mtune=generic"),
             "aarch64": ("aarch64", "-march=armv8-a -mtune=generic")}  # fmt: skip
# A tuned BLASFEO's target -> gcc's flags for the same CPU (others: the portable flags)
_TUNED_FLAGS = {
    "X64_INTEL_HASWELL": "-march=haswell",
    "X64_INTEL_SANDY_BRIDGE": "-march=sandybridge",
    "X64_AMD_BULLDOZER": "-march=bdver1",
    "ARMV8A_ARM_CORTEX_A57": "-mcpu=cortex-a57",
    "ARMV8A_ARM_CORTEX_A53": "-mcpu=cortex-a53",
    "ARMV8A_APPLE_M1": "-mcpu=apple-m1",
}
_LICENCES = {"hpipm": "HPIPM-LICENSE.txt", "blasfeo": "BLASFEO-LICENSE.txt"}
# The CPU features each portable target's program already needs: the x86-64 casadi wheel's
# libhpipm.so has AVX instructions (docs/onboard.md: it runs under qemu's SandyBridge, not
# its Nehalem), so a BLASFEO that needs no more narrows none of the CPUs it runs on
_PORTABLE_FEATURES = {"x86_64": ("AVX",)}
# BLASFEO's x86 feature names -> the x86-64 microarchitecture level that has them
_X86_LEVELS = {"SSE3": 2, "AVX": 3, "AVX2": 3, "FMA": 3, "AVX512F": 4}


@dataclass(frozen=True)
class Target:
    """One ``make TARGET=name`` of an export."""

    name: str
    machine: str  # uname -m of the computers it runs on: x86_64 or aarch64
    flags: str  # gcc's instruction-set flags
    hpipm: Path  # the libhpipm.so copied into lib/NAME
    blasfeo: Path  # the BLASFEO copied beside it as libblasfeo.so.0
    blasfeo_target: str  # BLASFEO's TARGET_... (GENERIC: portable)
    blasfeo_features: tuple[str, ...]  # the CPU features that BLASFEO needs

    def record(self) -> dict:
        """What export.json says of it (no path: the folder is copied elsewhere)."""
        return {"machine": self.machine, "flags": self.flags,
                "blasfeo_target": self.blasfeo_target,
                "blasfeo_features": list(self.blasfeo_features)}  # fmt: skip


def host_machine() -> str:
    machine = platform.machine().lower()
    return "aarch64" if machine in ("aarch64", "arm64") else machine


def elf_machine(library: Path, field: str) -> str:
    """The instruction set a shared library was built for (its ELF header), or one line."""
    header = library.read_bytes()[:20]
    if header[:4] != b"\x7fELF" or header[5] != 1:
        raise ConfigError(field, str(library), "not a little-endian ELF shared library")
    machine = _ELF_MACHINES.get(int.from_bytes(header[18:20], "little"))
    if machine is None:
        raise ConfigError(field, str(library), "built for neither x86-64 nor aarch64")
    return machine


def wheel_target(libraries: Path, include: Path) -> Target:
    """The installed casadi wheel's HPIPM and BLASFEO: this computer's portable target."""
    hpipm = libraries / _HPIPM
    machine = elf_machine(hpipm, "casadi")
    name, flags = _PORTABLE[machine]
    blasfeo = next(iter(sorted(libraries.glob("libblasfeo.so*"))))
    return Target(name, machine, flags, hpipm, blasfeo, blasfeo_target(include), ())


def aarch64_target(folder: Path | str, version: str, include: Path) -> Target:
    """The aarch64 HPIPM and BLASFEO in ``folder`` (benchmarks/hpipm_aarch64.py), which must
    be of the casadi ``version`` auvmpc runs with (the headers are shared)."""
    folder = Path(folder).expanduser().resolve()
    for name in (_HPIPM, _BLASFEO, AARCH64_VERSION_FILE):
        if not (folder / name).is_file():
            raise ConfigError(
                "--aarch64", str(folder),
                f"no {name} in that folder (make hpipm-aarch64 writes it)",
            )  # fmt: skip
    fetched = (folder / AARCH64_VERSION_FILE).read_text().strip()
    if fetched != version:
        raise ConfigError(
            "--aarch64", str(folder),
            f"holds casadi {fetched}'s HPIPM, auvmpc runs with {version}: fetch it again",
        )  # fmt: skip
    hpipm = folder / _HPIPM
    if elf_machine(hpipm, "--aarch64") != "aarch64":
        raise ConfigError("--aarch64", str(folder), "its libhpipm.so is not built for aarch64")
    name, flags = _PORTABLE["aarch64"]
    return Target(name, "aarch64", flags, hpipm, folder / _BLASFEO, blasfeo_target(include), ())


def tuned_target(folder: Path, portable: dict[str, Target]) -> Target:
    """A BLASFEO built for one CPU (``--blasfeo``, already checked by blasfeo_folder) under
    the portable HPIPM of its instruction set (``portable``: by machine)."""
    library = folder / LIBRARY
    machine = elf_machine(library, "--blasfeo")
    if machine not in portable:
        raise ConfigError(
            "--blasfeo", str(folder),
            f"an {machine} library: give --aarch64 too, for the HPIPM it runs under",
        )  # fmt: skip
    target = blasfeo_target(folder)
    base = portable[machine]
    flags = _TUNED_FLAGS.get(target, base.flags)
    name = ("x86-64" if machine == "x86_64" else machine) + "-tuned"
    return Target(name, machine, flags, base.hpipm, library, target, required_features(folder))


def generic_with(portable: Target, folder: Path) -> Target:
    """The portable target with the BLASFEO in ``folder`` (``--generic-blasfeo``, already
    checked by blasfeo_folder) instead of the wheel's GENERIC one: a library for its
    instruction set that needs no CPU feature its HPIPM does not already need (AVX on x86-64,
    nothing on aarch64)."""
    library = folder / LIBRARY
    if elf_machine(library, "--generic-blasfeo") != portable.machine:
        raise ConfigError("--generic-blasfeo", str(folder), f"not a library for {portable.machine}")
    features = required_features(folder)
    beyond = [f for f in features if f not in _PORTABLE_FEATURES.get(portable.machine, ())]
    if beyond:
        raise ConfigError(
            "--generic-blasfeo", str(folder),
            f"its BLASFEO needs {', '.join(beyond)}, which {portable.name} does not: give it "
            "as --blasfeo (the tuned target)",
        )  # fmt: skip
    return dataclasses.replace(
        portable, blasfeo=library, blasfeo_target=blasfeo_target(folder),
        blasfeo_features=features,
    )  # fmt: skip


def hwcaps_level(target: Target) -> str | None:
    """The glibc-hwcaps folder (``x86-64-vN``) a tuned x86-64 BLASFEO can go into beside the
    generic one: the level that has every feature it needs; None for another target."""
    if target.machine != "x86_64" or not target.name.endswith("-tuned"):
        return None
    levels = [_X86_LEVELS.get(feature) for feature in target.blasfeo_features]
    if not levels or None in levels:
        return None
    return f"x86-64-v{max(levels)}"


def write_solver_files(targets: list[Target], include: Path, folder: Path) -> None:
    """HPIPM and BLASFEO into the export: each target's libraries (a tuned x86-64 BLASFEO
    also under the generic one's glibc-hwcaps), the headers, the licences."""
    for target in targets:
        lib = folder / "lib" / target.name
        lib.mkdir(parents=True)
        shutil.copyfile(target.hpipm, lib / _HPIPM)
        shutil.copyfile(target.blasfeo, lib / _BLASFEO)
    generic = _PORTABLE["x86_64"][0]
    if any(t.name == generic for t in targets):
        for target in targets:
            level = hwcaps_level(target)
            if level is not None:
                hwcaps = folder / "lib" / generic / "glibc-hwcaps" / level
                hwcaps.mkdir(parents=True)
                shutil.copyfile(target.blasfeo, hwcaps / _BLASFEO)
    headers = folder / "include"
    headers.mkdir()
    for header in (*include.glob("hpipm_*.h"), *include.glob("blasfeo*.h")):
        shutil.copyfile(header, headers / header.name)
    licences = folder / "licenses"
    licences.mkdir()
    for project, name in _LICENCES.items():
        shutil.copyfile(include / "licenses" / f"{project}-external" / "LICENSE.txt",
                        licences / name)  # fmt: skip


def makefile_table(targets: list[Target]) -> str:
    """The Makefile's per-target lines (Makefile.in's @TARGET_TABLE@)."""
    lines = []
    for t in targets:
        lines.append(f"# {t.name}: BLASFEO {t.blasfeo_target}")
        lines.append(f"TARGET_MACHINE_{t.name} = {t.machine}")
        lines.append(f"TARGET_ARCH_{t.name} = {t.flags}")
    return "\n".join(lines)
