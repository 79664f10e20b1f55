"""An extended Kalman filter of the whole 6-DOF state and the horizontal water current.

The state is ``[x, y, z, phi, theta, psi, u, v, w, p, q, r, c_north, c_east]``: the 6-DOF
state (models/six_dof.py, SIX_DOF) and the world-frame horizontal current, a random walk.
The prediction is the caller's own one-step model (six-dof-nmpc's RK4 step, with the applied
command and the actuators' effectiveness), its Jacobian from CasADi; the measurement is the
whole 6-DOF state (H = [I 0]). The filter itself is :class:`~auvmpc.estimation.ekf.AugmentedEkf`
(Joseph-form update, bounded covariance), the one the 3-DOF offset-free MPC uses. The
process noise is a fixed covariance plus, where the caller gives one, the outer product of a
``model_spread`` (x, u, v_c, e) -> (12, k) each sample: how far the prediction moves under
each of k plausible errors of the model, so the filter trusts the model where it is right
and follows the measurements where it is not.

Why one filter rather than a position filter and a separate current observer in a chain: the
gains then come from the sensors' noise weighed against the model's error, jointly for every
state and the current, instead of from hand-set shares; the chain's current estimate carried
the sway velocity's noise into the crab heading (docs/remus100.md).
"""

from __future__ import annotations

import casadi as ca
import numpy as np

from auvmpc.estimation.ekf import AugmentedEkf
from auvmpc.models.six_dof import SIX_DOF

__all__ = ["SixDofCurrentEkf"]

NX = SIX_DOF.size
# The estimated current: world north and east (m/s); the vertical is taken as still.
NC = 2


class SixDofCurrentEkf:
    """EKF on [6-DOF state; horizontal current] (module docstring).

    ``step`` is a CasADi function (x, u, v_c, e) -> x_next over one sample (v_c the world
    current [north, east, down], e the actuators' effectiveness); the standard deviations are
    per sample (process) or per measurement, in SIX_DOF's order.
    """

    def __init__(
        self,
        step: ca.Function,
        sample_time: float,
        measurement_std: np.ndarray,
        process_std: np.ndarray,
        current_rate_std: float,
        initial_current_std: float,
        model_spread: ca.Function | None = None,
    ) -> None:
        self._spread = model_spread
        z = ca.SX.sym("z", NX + NC)
        u = ca.SX.sym("u", step.size1_in(1))
        share = ca.SX.sym("e", step.size1_in(3))
        water = ca.vertcat(z[NX:], 0.0)
        following = ca.vertcat(step(z[:NX], u, water, share), z[NX:])
        augmented = ca.Function(
            "augmented_step", [z, u, share], [following, ca.jacobian(following, z)]
        )
        measurement = np.square(np.asarray(measurement_std, dtype=float))
        walk = np.full(NC, current_rate_std**2 * sample_time)
        prior_current = np.full(NC, initial_current_std**2)
        self._filter = AugmentedEkf(
            augmented,
            NX,
            np.diag(np.concatenate([np.square(process_std), walk])),
            np.diag(measurement),
            np.diag(np.concatenate([measurement, prior_current])),
            angle_index=SIX_DOF.index("psi"),
        )

    @property
    def filter(self) -> AugmentedEkf:
        return self._filter

    def reset(self, initial_state: np.ndarray) -> None:
        """Start again: the next measurement is the state, the current zero with its prior."""
        self._filter.reset(np.concatenate([np.asarray(initial_state, float), np.zeros(NC)]))

    def correct(self, measured_state: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Fuse a measurement of the whole state; returns (state estimate (12,), current
        estimate [north, east] (m/s))."""
        estimate = self._filter.correct(measured_state)
        return estimate[:NX].copy(), estimate[NX:].copy()

    def predict(self, applied_input: np.ndarray, effectiveness: np.ndarray) -> None:
        """Propagate over one sample with the input that acted, at ``effectiveness``; the
        model's spread where the estimate was (``model_spread``) adds to the covariance."""
        added = None
        if self._spread is not None:
            estimate = self._filter.estimate
            water = np.concatenate([estimate[NX:], [0.0]])
            spread = np.asarray(self._spread(estimate[:NX], applied_input, water, effectiveness))
            added = np.zeros((NX + NC, NX + NC))
            added[:NX, :NX] = spread @ spread.T
        self._filter.predict(applied_input, effectiveness, added)
