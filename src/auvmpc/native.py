"""C compiled with the system compiler into shared libraries, cached on disk, called by ctypes.

Three users: the real-time nmpc's C controller (controllers/compiled_nmpc.py, the step export-c
ships), the real-time iteration's QP step (solvers/compiled_qp_step.py, CasADi-generated stage
data and an HPIPM driver) and :func:`native_function`, a CasADi function generated to C and
called without CasADi's Python layer. Calling a CasADi ``Function`` from Python costs about
35 us whatever it computes (argument conversion to and from DM); the RK4 step of the 3-DOF
model it evaluates takes well under 1 us in C. Through ctypes with buffers allocated once a
call costs a few microseconds.

A library is built the first time it is needed and kept in a cache folder
(``$AUVMPC_CACHE_DIR``, else ``$XDG_CACHE_HOME/auvmpc`` or ``~/.cache/auvmpc``; the system's
temporary folder if that cannot be written), named by a hash of everything that goes into it,
so later processes (and campaign workers) load it at once. Where there is no C compiler the
builders return None and callers keep CasADi's evaluation of the same functions.
"""

from __future__ import annotations

import ctypes
import functools
import hashlib
import os
import re
import shutil
import subprocess
import tempfile
import threading
from collections.abc import Sequence
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path

import casadi as ca
import numpy as np

__all__ = ["NativeFunction", "cache_folder", "compiler", "native_function", "shared_library"]

# -O2 as for the JIT'd model functions (no -march=native: a cache folder may be shared by
# machines of different CPUs); -Bsymbolic keeps each library's own generated functions when
# several with the same names are loaded in one process.
FLAGS = ("-O2", "-fPIC", "-shared", "-Wl,-Bsymbolic")
_COMPILE_FLAGS, _LINK_FLAGS = FLAGS[:2], FLAGS[2:]
# Libraries of one kind kept in the cache folder, the least recently used dropped beyond it:
# one is 0.1-0.2 MB and a sweep over random vehicles builds one per vehicle.
_CACHE_LIMIT = 256
_HASH_DIGITS = 24  # of the configuration's hash in a library's name


@functools.cache
def compiler() -> str | None:
    """The system C compiler, or None."""
    for name in (os.environ.get("CC"), "cc", "gcc", "clang"):
        if name and shutil.which(name):
            return shutil.which(name)
    return None


def cache_folder() -> Path:
    """Where built libraries are kept (module docstring)."""
    explicit = os.environ.get("AUVMPC_CACHE_DIR")
    if explicit:
        return Path(explicit)
    base = os.environ.get("XDG_CACHE_HOME") or Path.home() / ".cache"
    return Path(base) / "auvmpc"


def shared_library(
    kind: str,
    sources: Sequence[Path],
    options: Sequence[str] = (),
    salt: Sequence[str] = (),
) -> ctypes.CDLL | None:
    """``sources`` compiled and linked into ``<kind>-<hash>.so`` in the cache folder, loaded.

    ``options``: compiler options after the sources (include folders, libraries), not
    hashed, since they may name a temporary folder; ``salt``: whatever else the library
    depends on that the sources do not show (a library folder baked in by -rpath). The
    headers beside the sources are hashed with them. None without a compiler or when it
    refuses the sources.
    """
    cc = compiler()
    if cc is None:
        return None
    digest = hashlib.sha256()
    headers = sorted({h for s in sources for h in Path(s).parent.glob("*.h")})
    for part in (
        *(Path(p).read_bytes() for p in (*sources, *headers)),
        *(s.encode() for s in salt),
        ca.__version__.encode(),
        cc.encode(),
        " ".join(FLAGS).encode(),
    ):
        digest.update(part)
    name = f"{kind}-{digest.hexdigest()[:_HASH_DIGITS]}.so"
    with tempfile.TemporaryDirectory(prefix=f"auvmpc-{kind}-") as scratch:
        built = Path(scratch) / name
        for folder in (cache_folder(), Path(tempfile.gettempdir()) / f"auvmpc-{os.getuid()}"):
            target = folder / name
            try:
                folder.mkdir(mode=0o700, parents=True, exist_ok=True)
                if not _private(folder):
                    continue  # a library there could be anybody's code
                if not target.exists():
                    if not built.exists():
                        _build(cc, sources, options, built)
                    # Atomic: another process may be building the same library.
                    partial = target.with_suffix(f".{os.getpid()}.part")
                    shutil.copyfile(built, partial)
                    os.replace(partial, target)
                    _prune(folder, kind)
                os.utime(target)  # its last use, for _prune
                return ctypes.CDLL(str(target))
            except subprocess.SubprocessError:
                return None  # the compiler refused: no folder helps
            except OSError:
                continue  # an unwritable cache folder: try the next one
    return None


def _build(cc: str, sources: Sequence[Path], options: Sequence[str], built: Path) -> None:
    """Each source compiled to an object, side by side (a generated file takes seconds and
    there is a core for each of the largest two on the machines this runs on), then linked
    into ``built``; a SubprocessError if the compiler refuses."""
    objects = [built.with_name(f"{i}-{Path(s).stem}.o") for i, s in enumerate(sources)]

    def compile_one(source_and_object: tuple[Path, Path]) -> None:
        source, target = source_and_object
        command = [cc, *_COMPILE_FLAGS, "-c", str(source), *options, "-o", str(target)]
        subprocess.run(command, check=True, capture_output=True, timeout=300)

    with ThreadPoolExecutor(max_workers=max(1, min(len(sources), os.cpu_count() or 1))) as pool:
        list(pool.map(compile_one, zip(sources, objects, strict=True)))
    link = [cc, *_LINK_FLAGS, *map(str, objects), *options, "-lm", "-o", str(built)]
    subprocess.run(link, check=True, capture_output=True, timeout=300)


class NativeFunction:
    """A CasADi function with dense inputs and outputs, compiled, called through ctypes.

    Called with one array per input (any shape holding the input's values in CasADi's
    column-major order: a vector, or a C-ordered array of its transpose); returns a copy of
    the first output, flat, or a tuple of all outputs when there are several.
    """

    def __init__(self, library: ctypes.CDLL, function: ca.Function) -> None:
        self._library = library  # kept alive as long as the buffers' users
        self.name = function.name()
        self._inputs = [np.zeros(function.nnz_in(i)) for i in range(function.n_in())]
        self._outputs = [np.zeros(function.nnz_out(i)) for i in range(function.n_out())]
        arg = (ctypes.c_void_p * max(function.sz_arg(), 1))()
        res = (ctypes.c_void_p * max(function.sz_res(), 1))()
        for i, buffer in enumerate(self._inputs):
            arg[i] = buffer.ctypes.data
        for i, buffer in enumerate(self._outputs):
            res[i] = buffer.ctypes.data
        self._iw = np.zeros(max(function.sz_iw(), 1), dtype=np.int64)  # casadi_int
        self._w = np.zeros(max(function.sz_w(), 1))
        self._arg, self._res = arg, res
        self._evaluate = getattr(library, self.name)
        self._evaluate.restype = ctypes.c_int
        self._evaluate.argtypes = [ctypes.c_void_p] * 4 + [ctypes.c_int]
        self._call = (arg, res, self._iw.ctypes.data, self._w.ctypes.data, 0)
        # One set of buffers per function, and functions are shared per process (cached) while
        # ctypes releases the GIL: threads (e.g. a Dask worker's) take turns, or one thread's
        # inputs land in another's call (measured: 54 wrong results in 40 000 threaded calls).
        self._lock = threading.Lock()

    def __call__(self, *inputs: np.ndarray) -> np.ndarray | tuple[np.ndarray, ...]:
        with self._lock:
            for buffer, values in zip(self._inputs, inputs, strict=True):
                np.copyto(buffer, np.ravel(values))
            if self._evaluate(*self._call):
                raise RuntimeError(f"the compiled {self.name} reported an evaluation error")
            if len(self._outputs) == 1:
                return self._outputs[0].copy()
            return tuple(o.copy() for o in self._outputs)


def native_function(function: ca.Function) -> NativeFunction | None:
    """``function`` compiled (cached on disk), or None without a C compiler."""
    dense = all(function.sparsity_in(i).is_dense() for i in range(function.n_in())) and all(
        function.sparsity_out(i).is_dense() for i in range(function.n_out())
    )
    if not dense:
        raise ValueError(f"{function.name()}: native_function needs dense inputs and outputs")
    if compiler() is None:
        return None
    with tempfile.TemporaryDirectory(prefix="auvmpc-native-") as scratch:
        source = f"{function.name()}.c"
        generator = ca.CodeGenerator(source, {"casadi_int": "long long int"})
        generator.add(function)
        generator.generate(scratch + os.sep)
        library = shared_library("fn", [Path(scratch) / source])
    if library is None:
        return None
    return NativeFunction(library, function)


def _private(folder: Path) -> bool:
    """Whether only this user can write into ``folder`` (a library loaded from it runs as
    this user)."""
    status = folder.stat()
    return status.st_uid == os.getuid() and not status.st_mode & 0o022


def _prune(folder: Path, kind: str) -> None:
    """Drop the least recently used libraries of ``kind`` beyond _CACHE_LIMIT (only files
    named as :func:`shared_library` names them; a library another process has loaded stays
    usable). Another process may be pruning the same folder: a file gone already is skipped."""

    def last_use(path: Path) -> float:
        try:
            return path.stat().st_mtime
        except FileNotFoundError:
            return 0.0

    # Exactly the names shared_library gives (kind, dash, 24 hex digits): a user's own
    # "kind-something.so" in the same folder is not ours to delete.
    ours = re.compile(rf"{re.escape(kind)}-[0-9a-f]{{{_HASH_DIGITS}}}\.so")
    libraries = sorted(
        (path for path in folder.glob(f"{kind}-*.so") if ours.fullmatch(path.name)),
        key=last_use,
        reverse=True,
    )
    for stale in libraries[_CACHE_LIMIT:]:
        stale.unlink(missing_ok=True)
