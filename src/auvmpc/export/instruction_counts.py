"""Instructions executed per controller step of an exported replay: the portable cost
figure beside wall time (``auvmpc verify-c --instructions``, benchmarks/onboard_targets.py).

Natively valgrind's callgrind counts inside ``auvmpc_step`` only, one dump per call. For an
emulated target (aarch64 on an x86-64) QEMU's user-mode emulator runs the replay with a small
TCG plugin of auvmpc's (qemu_step_counter.c, built here with the host's compiler), which
counts the guest instructions between the replay's two clock readings around each step: the
step and the few instructions of the clock call's return and entry (about 20).
"""

from __future__ import annotations

import re
import shutil
import subprocess
from pathlib import Path

from auvmpc.errors import ConfigError, RunFailed
from auvmpc.native import compiler

__all__ = ["QEMU_SYSROOT", "emulator_command", "step_instructions"]

QEMU_SYSROOT = "/usr/aarch64-linux-gnu"  # Debian's libc6-arm64-cross: the guest's libraries
_PLUGIN_SOURCE = Path(__file__).with_name("qemu_step_counter.c")


def emulator_command(machine: str) -> list[str]:
    """The command prefix that runs a ``machine`` program on this computer under QEMU's
    user-mode emulator, or one line naming the Debian packages that are missing."""
    emulator = shutil.which(f"qemu-{machine}")
    if emulator is None or not Path(QEMU_SYSROOT).is_dir():
        raise ConfigError(
            "--target", machine,
            f"needs qemu-{machine} and {QEMU_SYSROOT} (Debian: apt-get install qemu-user "
            "libc6-dev-arm64-cross gcc-aarch64-linux-gnu)",
        )  # fmt: skip
    return [emulator, "-L", QEMU_SYSROOT]


def step_instructions(
    program: list[str], emulated: str | None, scratch: Path, function: str = "auvmpc_step"
) -> list[int]:
    """The instructions of each call of the step ``function`` (a six-dof export's is
    ``auvmpc_six_dof_step``) of the replay command ``program``; ``emulated``: the machine it
    is emulated as (None: native; emulated, the replay's clock readings mark the step)."""
    if emulated is None:
        return _callgrind(program, scratch, function)
    return _qemu_plugin(program, emulated, scratch)


def _callgrind(program: list[str], scratch: Path, function: str) -> list[int]:
    if shutil.which("valgrind") is None:
        raise ConfigError("--instructions", "valgrind", "not on the PATH (Debian: valgrind)")
    out = scratch / "cg"
    _run(["valgrind", "--tool=callgrind", f"--callgrind-out-file={out}",
          f"--dump-after={function}", f"--toggle-collect={function}", *program])  # fmt: skip
    dumps = sorted(scratch.glob("cg.*"), key=lambda p: int(p.suffix[1:]))
    return [int(re.search(r"^totals: (\d+)", d.read_text(), re.M).group(1)) for d in dumps]


def _qemu_plugin(program: list[str], machine: str, scratch: Path) -> list[int]:
    cc = compiler()
    if cc is None:
        raise ConfigError("--instructions", machine, "needs a C compiler for QEMU's plugin")
    plugin, out = scratch / "qemu_step_counter.so", scratch / "readings.txt"
    _run([cc, "-std=c99", "-O2", "-fPIC", "-shared", "-fvisibility=hidden",
          str(_PLUGIN_SOURCE), "-o", str(plugin)])  # fmt: skip
    _run([*emulator_command(machine), "-plugin", f"{plugin},out={out}", *program])
    readings = [int(line) for line in out.read_text().split()]
    # one reading before and one after each step
    return [after - before for before, after in zip(readings[::2], readings[1::2], strict=True)]


def _run(command: list[str]) -> None:
    done = subprocess.run(command, capture_output=True, text=True)
    if done.returncode:
        last = (done.stderr.strip().splitlines() or ["no message"])[-1]
        raise RunFailed(f"{Path(command[0]).name} failed: {last}")
