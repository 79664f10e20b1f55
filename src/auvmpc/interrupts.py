"""Ctrl-C (SIGINT) and SIGTERM: stop promptly, even inside a compiled solver.

CasADi's IPOPT interface calls Python's signal check between iterations, so our
handler runs and its exception stops IPOPT; but CasADi then catches it and returns a
solve with status ``NonIpopt_Exception_Thrown``, which a controller takes for a
failed solve and covers with a fallback step. Without more, the run would finish and
write a complete-looking result that the interrupt changed.

So the handler also records the signal, and the closed loop calls :func:`check` after
every step: a recorded signal raises :class:`Interrupted` there, before any result
exists. CasADi also prints a ``WARNING("KeyboardInterruptException")`` line on stderr
(through Python's ``sys.stderr``); once we know why, it is noise, and that one line is
dropped so that an interrupted command prints one line. Nothing half-written is left
either (:mod:`auvmpc.experiments.outputs` stages every folder). The command line reports what was
kept and exits ``128 + signal`` (130 for SIGINT, 143 for SIGTERM).
"""

from __future__ import annotations

import contextlib
import signal
import sys
import threading
from collections.abc import Callable, Iterator
from pathlib import Path

__all__ = [
    "Interrupted",
    "check",
    "describe_kept",
    "install",
    "kept",
    "requested",
    "reset",
    "restore",
]

_SIGNALS = (signal.SIGINT, signal.SIGTERM)
_requested: int | None = None
_kept: str | None = None


class Interrupted(KeyboardInterrupt):
    """The user (SIGINT) or the system (SIGTERM) asked auvmpc to stop."""

    def __init__(self, signum: int) -> None:
        super().__init__(signal.Signals(signum).name)
        self.signum = signum

    @property
    def exit_code(self) -> int:
        return 128 + self.signum


def _handler(signum: int, frame) -> None:
    global _requested
    _requested = signum
    if frame is not None and "casadi" in Path(frame.f_code.co_filename).parts:
        if not isinstance(sys.stderr, _WithoutCasadiInterruptNote):
            sys.stderr = _WithoutCasadiInterruptNote(sys.stderr)
    raise Interrupted(signum)


class _WithoutCasadiInterruptNote:
    """Forwards text to ``stream`` line by line, except CasADi's note that it caught our
    KeyboardInterrupt (CasADi writes it in pieces, so whole lines are collected first)."""

    _NOTE = "KeyboardInterruptException"

    def __init__(self, stream) -> None:
        self._stream = stream
        self._line = ""

    def write(self, text: str) -> int:
        self._line += text
        while "\n" in self._line:
            line, self._line = self._line.split("\n", 1)
            if not (line.startswith("CasADi - ") and self._NOTE in line):
                self._stream.write(line + "\n")
        if self._line and not "CasADi - ".startswith(self._line[:9]):
            self._stream.write(self._line)  # not CasADi's: no need to hold it back
            self._line = ""
        return len(text)

    def flush(self) -> None:
        self._stream.flush()

    def __getattr__(self, name: str):
        return getattr(self._stream, name)


def install() -> dict[int, object]:
    """Handle SIGINT and SIGTERM in this (main-thread) process; returns the handlers
    replaced (for :func:`restore`)."""
    if threading.current_thread() is not threading.main_thread():
        return {}
    return {signum: signal.signal(signum, _handler) for signum in _SIGNALS}


def restore(previous: dict[int, object]) -> None:
    """Put back the handlers :func:`install` replaced."""
    for signum, handler in previous.items():
        signal.signal(signum, handler)


def requested() -> int | None:
    """The signal received since the last :func:`reset`, if any."""
    return _requested


def check() -> None:
    """Raise :class:`Interrupted` if a signal arrived, even if a solver swallowed it."""
    if _requested is not None:
        raise Interrupted(_requested)


def reset() -> None:
    global _requested, _kept
    _requested = _kept = None


@contextlib.contextmanager
def describe_kept(describe: Callable[[], str]) -> Iterator[None]:
    """If an interrupt ends the block, :func:`kept` reports ``describe()``."""
    global _kept
    try:
        yield
    except KeyboardInterrupt:
        with contextlib.suppress(Exception):
            _kept = describe()
        raise


def kept() -> str:
    """One line on what an interrupted command leaves behind."""
    return _kept or "nothing was written (results are saved only when complete)"
