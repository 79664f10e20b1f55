"""Which actuator stopped delivering its command, found from the model's one-step prediction
residual (issue 26's fault detection).

Each sample the nominal model predicts the velocities from the last measurement under the
command held since, with the actuators as the controller assumes them (effectiveness e).
If input i delivers only (1 - lambda) of that from sample j on, the measured velocities miss
what its lost share would have given, to first order ``-lambda B_i e_i F_i`` (B: the sampled
model's Jacobian in the acting thrust). Over a sliding window, for each input i and each
onset j inside the window (a single fault, at an unknown time), the residuals are fitted by
least squares to

    r_k = c + lambda g_ki [k >= j],      g_ki = -B_k[:, i] e_i F_ki,

with ``c`` constant over the window: a current, the model's own error and anything else
slow, which would otherwise read as a fault of whichever thruster pushes against it. The
(i, j) with the smallest residual sum of squares is the likeliest single fault. This is
fault detection by parameter estimation on a parity residual (Isermann, *Fault-Diagnosis
Systems*, 2006): an input is found failed when its lambda is between :data:`LOSS_FOUND` and
:data:`LOSS_MOST` and its score reaches :data:`LOSS_SIGMAS`; one sample is enough, as the
fault must first be isolated to one input (:data:`ISOLATION`). Found, it is taken as dead:
the controller stops relying on it, the window restarts, and the prediction leaves it out
(a second fault is found the same way).
Dead, not its estimated share: a single sample's estimate is rough (a first version of this
detector, one joint fit of every input, read a dead thruster on the BlueROV2 Heavy's helix
as 58 % lost, and the controller, relying on the rest, let the heading go 0.5 rad off until
a second detection 4 s later), and three of a vectored four-thruster vehicle's thrusters
still span surge, sway and yaw, so the error on the safe side costs a weak thruster's
remaining force, the other one the vehicle's heading.

Limits, by design: a lost share below :data:`LOSS_FOUND` is not reported (model error of
the size the presets carry, 20-30 %, must not read as a fault); an input that is not
commanded away from a constant over the window cannot be told from the constant ``c``
and is found only once its command moves.
"""

from __future__ import annotations

from collections import deque
from dataclasses import dataclass

import numpy as np

from auvmpc.models.discrete import DISTURBANCE_NAMES, horizontal_model
from auvmpc.models.layout import HORIZONTAL
from auvmpc.models.vehicle import VehicleParams

__all__ = ["FaultDetector", "FaultFound"]

# An input is reported failed when at least this share of its assumed force is missing.
LOSS_FOUND = 0.5
# A loss estimate beyond this is not an actuator that stopped (it cannot lose more than
# its force, 1, by more than the estimate's scatter): the model missed something else.
LOSS_MOST = 1.5
# ... and its score, lambda over its standard error as the window's scatter about the fit
# gives it (at least the sensor's noise), is at least this. A score, not a probability: the
# model's own error is not noise, successive residuals share a measurement, and the fit
# picks the best of every input and onset. The threshold is measured: with
# fault_detection on and no fault, `benchmarks/fault_detection.py --presets --sigmas 5`
# finds healthy thrusters failed, and `--sigmas 12` finds none (docs/faults.md).
LOSS_SIGMAS = 12.0
# A fault is isolated to one input when its fit leaves at most this share of the residual
# sum of squares the next best input's leaves; closer, the two are not told apart yet.
ISOLATION = 0.7
# The window: this long, and at least MIN_WINDOW_SAMPLES (each fit has the window's
# constant, 3 values, and lambda).
WINDOW_S = 2.0
MIN_WINDOW_SAMPLES = 8
# Residual rows are weighted by the velocity sensor's noise, at least this (m/s, rad/s).
NOISE_FLOOR = 1e-3
_NU = HORIZONTAL.nu


@dataclass(frozen=True)
class FaultFound:
    """One detection: input ``index`` has failed (taken as dead from then on)."""

    index: int
    lost: float  # lambda: the share of the assumed force found missing
    sigmas: float  # its score: lambda over its standard error (LOSS_SIGMAS)


class FaultDetector:
    """The horizontal model's fault detector (module docstring) on ``model`` (the controller's
    nominal vehicle), sampled every ``sample_time`` with ``substeps`` RK4 steps;
    ``velocity_noise``: the std of the measured ``u, v, r``."""

    def __init__(
        self,
        model: VehicleParams,
        sample_time: float,
        substeps: int,
        velocity_noise: np.ndarray,
    ) -> None:
        self._step = horizontal_model(model, sample_time, substeps, jit=False).linearised_step
        self.n_inputs = model.n_thrusters
        self._weights = 1.0 / np.maximum(np.asarray(velocity_noise, dtype=float), NOISE_FLOOR)
        self.window = max(MIN_WINDOW_SAMPLES, round(WINDOW_S / sample_time))
        self._rows: deque[tuple[np.ndarray, np.ndarray]] = deque(maxlen=self.window)
        self._healthy = np.ones(self.n_inputs)
        self._state = np.zeros(HORIZONTAL.size)
        self._held: tuple[np.ndarray, np.ndarray, np.ndarray] | None = None

    def check(self, state: np.ndarray) -> FaultFound | None:
        """The measured horizontal ``state`` ``[x, y, psi, u, v, r]`` of this sample, after
        the command :meth:`held` since the last: a detection, if this sample confirms one."""
        found = None if self._held is None else self._fit(state, *self._held)
        self._state = np.array(state, dtype=float)
        self._held = None
        return found

    def held(self, command: np.ndarray, effectiveness: np.ndarray) -> None:
        """The command held from the sample last checked, with the effectiveness the
        controller assumed for it."""
        self._held = (self._state, np.array(command, dtype=float), np.array(effectiveness))

    def _fit(
        self, state: np.ndarray, before: np.ndarray, command: np.ndarray, effectiveness: np.ndarray
    ) -> FaultFound | None:
        acting = effectiveness * command
        still = np.zeros(len(DISTURBANCE_NAMES))  # the window's constant takes any force
        predicted, _, jacobian = self._step(before, acting, still, self._healthy)
        residual = (state[_NU] - np.asarray(predicted).ravel()[_NU]) * self._weights
        regressors = -np.asarray(jacobian)[_NU, :] * acting * self._weights[:, None]
        if not (np.isfinite(residual).all() and np.isfinite(regressors).all()):
            return None  # a state the model cannot step from says nothing of the thrusters
        self._rows.append((residual, regressors))
        if len(self._rows) < self.window:
            return None
        best = self._likeliest_fault()
        if best is None:
            return None
        index, lost, sigmas = best
        if not (LOSS_FOUND <= lost <= LOSS_MOST and sigmas >= LOSS_SIGMAS):
            return None
        self._rows.clear()
        return FaultFound(index, lost, sigmas)

    def _likeliest_fault(self) -> tuple[int, float, float] | None:
        """The single fault that best explains the window: for each input i and each onset
        j, the fit r_k = c + lambda g_ki [k >= j]; the (i, j) of the smallest residual sum
        of squares, as (i, lambda, lambda over its standard error). None if no input was
        commanded in the window."""
        residuals = np.array([r for r, _ in self._rows])  # (W, m)
        regressors = np.array([g for _, g in self._rows])  # (W, m, n)
        window, rows = residuals.shape
        # Onsets j = 1..W-1, inside the window: a fault is a change, and one that began
        # before the window (j = 0) reads like the model's own error, which the window's
        # constant and LOSS_FOUND are there to leave alone.
        onsets = np.arange(window)[:, None] >= np.arange(1, window)[None, :]  # [k, j]
        centred_r = residuals - residuals.mean(axis=0)
        fits: list[tuple[float, int, float, float]] = []  # (rss, i, lambda, sigmas) per input
        dof = window * rows - rows - 1
        for i in range(self.n_inputs):
            # (j, W, m): the regressor switched on from onset j, each centred over k.
            x = onsets.T[:, :, None] * regressors[None, :, :, i]
            x = x - x.mean(axis=1, keepdims=True)
            spread = np.einsum("jkm,jkm->j", x, x)
            usable = spread > 1e-12 * max(float(spread.max()), 1e-300)
            if not usable.any():
                continue
            lost = np.where(
                usable, np.einsum("jkm,km->j", x, centred_r) / np.where(usable, spread, 1.0), 0.0
            )
            rss = np.einsum("jkm,jkm->j", *(2 * [centred_r[None] - lost[:, None, None] * x]))
            rss = np.where(usable, rss, np.inf)
            j = int(np.argmin(rss))
            # The scatter in noise units (rows weighted by the sensor's noise): never
            # below 1, however smooth the window, so a small regressor's lambda is not
            # trusted beyond what the noise allows.
            error = np.sqrt(max(rss[j] / dof, 1.0) / spread[j])
            fits.append((float(rss[j]), i, float(lost[j]), float(lost[j] / error)))
        if not fits:
            return None
        fits.sort()
        if len(fits) > 1 and fits[0][0] > ISOLATION * fits[1][0]:
            return None  # two inputs explain the window about as well: not isolated yet
        return fits[0][1:]
