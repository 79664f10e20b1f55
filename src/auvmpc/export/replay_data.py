"""The replay driver's input (``replay_data.txt``): a header, the initial command, and at every
sample the reference preview and the obstacles as the closed loop sees them (sim/session.py).
The horizontal and the six-dof exports write it alike, each with its own header and preview."""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from auvmpc.environment.obstacles import visible_obstacles

__all__ = ["replay_data"]


def replay_data(header: str, initial: Sequence[float], reference, preview: int,
                steps: int, sample_time: float, obstacles) -> str:  # fmt: skip
    """``header``, then ``initial``, then per sample k the ``preview + 1`` rows of
    ``reference.states`` from ``k * sample_time`` on, the count of ``obstacles`` visible
    then and each one's centre, velocity and radius."""
    offsets = sample_time * np.arange(preview + 1)
    lines = [header, _row(initial)]
    for k in range(steps):
        t = sample_time * k
        lines.extend(_row(values) for values in reference.states(t + offsets))
        visible = visible_obstacles(obstacles, t)
        lines.append(str(len(visible)))
        lines.extend(_row([*o.center, *o.velocity, o.radius]) for o in visible)
    return "\n".join(lines) + "\n"


def _row(values) -> str:
    """One line of numbers, each to the last bit."""
    return " ".join(f"{float(v):.17g}" for v in np.ravel(values))
