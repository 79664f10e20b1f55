"""Fetch a BLASFEO built for one CPU kind, for ``auvmpc export-c --blasfeo DIR``: x86-64 with
AVX2 and FMA (BLASFEO's X64_INTEL_HASWELL target) or 64-bit Arm with NEON (ARMV8A_ARM_CORTEX_A57,
which every ARMv8-A core runs: Raspberry Pi 4's Cortex-A72, Jetson's Cortex-A78AE).

The casadi wheels' BLASFEO is the portable GENERIC build. PyPI's ``comma-deps-acados`` wheels
ship BLASFEO built for those targets with their headers; this script downloads the one for
``--machine`` (a pinned version, from the package registry, not installed: it also carries a
casadi of its own that must not replace auvmpc's) and unpacks only ``libblasfeo.so`` and
``blasfeo_target.h`` into DIR. Run it once; nothing is fetched at run time.

    python benchmarks/blasfeo_tuned.py --out .venv/blasfeo-x64-haswell
    python benchmarks/blasfeo_tuned.py --machine aarch64 --out .venv/blasfeo-armv8a-a57
    auvmpc export-c paper-obstacles --blasfeo .venv/blasfeo-x64-haswell --out X
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from pinned_wheel import empty_folder_or_exit, unpack_members

WHEEL = "comma-deps-acados==0.2.2.post92"
# per machine: the wheel's platform and sha256, which pip checks the download against (the
# wheels measured on 2026-11-24 and 2026-11-27), so a replaced file on the registry is refused
BUILDS = {
    "x86_64": ("manylinux_2_28_x86_64",  # TARGET_X64_INTEL_HASWELL
               "fb317ea65c68d410e19b46f824c333203a097d02dac6fbbdc1f378c2b32b456f"),
    "aarch64": ("manylinux_2_28_aarch64",  # TARGET_ARMV8A_ARM_CORTEX_A57
                "d71088e2cd2d92f9ad046700f39eaa45e40109d20eefc05a034b0c4cbbdd12d8"),
}  # fmt: skip
MEMBERS = {
    "acados/install/lib/libblasfeo.so": "libblasfeo.so",
    "acados/install/include/blasfeo/include/blasfeo_target.h": "blasfeo_target.h",
}


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--out", type=Path, required=True, help="folder to unpack into")
    parser.add_argument("--machine", choices=sorted(BUILDS), default="x86_64")
    arguments = parser.parse_args()
    out = arguments.out
    empty_folder_or_exit(out)
    platform, sha256 = BUILDS[arguments.machine]
    missing = unpack_members(WHEEL, sha256, platform, MEMBERS, out)
    if missing:
        print(f"error: {WHEEL} no longer holds {missing}", file=sys.stderr)
        return 1
    print(f"wrote {out}: {', '.join(MEMBERS.values())}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
