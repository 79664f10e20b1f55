"""Angles wrapped to (-pi, pi], written once for every module that compares headings (the
CasADi form the stabilising feedback needs is controllers/tracking_law.py's)."""

from __future__ import annotations

import math

import numpy as np
from numpy.typing import ArrayLike

__all__ = ["wrap_angle"]

_TWO_PI = 2.0 * math.pi


def wrap_angle(angle: ArrayLike) -> np.ndarray:
    """``angle`` (rad; a number or an array) in (-pi, pi]: pi - ((pi - angle) mod 2 pi)."""
    return math.pi - np.mod(math.pi - np.asarray(angle, dtype=float), _TWO_PI)
