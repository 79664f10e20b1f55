"""Which actuator stopped delivering its command, found from the model's one-step prediction
residual (issue 26's fault detection).

Each sample the nominal model predicts the velocities from the last measurement under the
command held since, with the actuators as the controller assumes them (effectiveness e: the
share of its wrench each makes). If input i makes only (1 - lambda) of that from sample j on,
the measured velocities miss what its lost share would have given, to first order
``-lambda B_i e_i F_i`` (B: the sampled model's Jacobian in the acting thrust). Over a
sliding window, for each input i and each onset j inside the window (a single fault, at an
unknown time), the residuals are fitted by least squares to

    r_k = c + lambda g_ki [k >= j],      g_ki = -B_k[:, i] e_i F_ki,

with ``c`` constant over the window: a current, the model's own error and anything else
slow, which would otherwise read as a fault of whichever thruster pushes against it. The
(i, j) with the smallest residual sum of squares is the likeliest single fault. This is
fault detection by parameter estimation on a parity residual (Isermann, *Fault-Diagnosis
Systems*, 2006): an input is found failed when its lambda is between :data:`LOSS_FOUND` and
:data:`LOSS_MOST` and its score reaches :data:`LOSS_SIGMAS`; one sample is enough, as the
fault must first be isolated to one input (:data:`ISOLATION`). Found, it is taken as dead:
the controller stops relying on it, the window restarts, and the prediction leaves it out
(a second fault is found the same way). That is the horizontal detector's rule;
the 6-DOF detector's (below) reports the share left instead.
Dead, not its estimated share: a single sample's estimate is rough (a first version of this
detector, one joint fit of every input, read a dead thruster on the BlueROV2 Heavy's helix
as 58 % lost, and the controller, relying on the rest, let the heading go 0.5 rad off until
a second detection 4 s later), and three of a vectored four-thruster vehicle's thrusters
still span surge, sway and yaw, so the error on the safe side costs a weak thruster's
remaining force, the other one the vehicle's heading.

:class:`FaultDetector` watches the horizontal thrusters on the 3-DOF model.
:class:`SixDofFaultDetector` watches every input of the 6-DOF model (thrusters, a propeller,
fins: ``vehicle.six_dof_actuators``) with the same fit, on the six body velocities. Its
inputs need not be linear (a propeller's thrust grows with rpm squared, a fin's lift with
the flow's speed squared), so its loss regressor is the secant ``g_ki = x(F_k; e_i = 0) -
x(F_k; e)``, the input's whole wrench taken away: lambda g_ki is then the loss of lambda of
its wrench to first order in the state's change over one sample, where the tangent times the
command is not (at cruise, the REMUS 100 propeller's tangent times its rpm is 3.6 times its
thrust). A loss found keeps 1 - lambda of the wrench assumed (clipped to [0, 1]): the
torpedo's propeller is its only thrust, and a weak one taken as dead leaves the controller
none; the loss is reported from :data:`SIX_DOF_LOSS_FOUND` on, its score the guard against
model error. And it has a second hypothesis, an input stuck at a value s whatever it is
commanded (a fin jammed at an angle, whose lift still acts):

    r_k = c + [k >= j] (x(F_k; F_ki = s) - x(F_k)) ~ c + [k >= j] B_k[:, i] (s - F_ki),

linear in s (B: the Jacobian in the command); each input's likelier hypothesis is its fit:
the stuck one only where its residual sum of squares is at most :data:`ISOLATION` of the
loss's (a propeller whose rpm barely moves, made weak, fits a lower rpm held almost as well,
and held there it could not speed up; a loss keeps it commanded). A stuck input is found
when its score (the fit's gain over no fault, in the window's scatter: :data:`LOSS_SIGMAS` as
for a loss) is high enough, s is inside its limits, and the commands it failed to follow
were on average :data:`STUCK_FOUND` of its range or more away from s; s is then refined by
Gauss-Newton on the model itself (the tangent's error for a propeller) and told to the
controller (``Observation.stuck_at``). Beside the window, a sequential test
(estimation/sequential_glr.py) keeps the evidence of an onset for
:data:`~auvmpc.estimation.sequential_glr.MEMORY_S`: the inputs that can jam
(``Actuator.jams``) are tested stuck, so a fin jammed near its command is found once the
controller has moved the command away, after the onset has left the window; the others
(a propeller, thrusters) are tested weakened, their nuisance followed more slowly
(:data:`LOSS_NUISANCE_S`), so a propeller that keeps half its thrust, whose step the window
holds too briefly, is found as the step's evidence adds up.

Limits, by design: a lost share below :data:`LOSS_FOUND` (the 6-DOF detector's
:data:`SIX_DOF_LOSS_FOUND`) is not reported (model error of the size the presets carry,
20-30 %, must not read as a fault); an input that is not commanded away from a constant over
the window cannot be told from the constant ``c`` and is found only once its command moves.
"""

from __future__ import annotations

from collections import deque
from dataclasses import dataclass, replace
from functools import partial

import casadi as ca
import numpy as np

from auvmpc.estimation.sequential_glr import (
    MEMORY_S,
    SequentialFits,
    SequentialGLR,
    innovations,
    window_gain,
)
from auvmpc.models.discrete import DISTURBANCE_NAMES, horizontal_model
from auvmpc.models.integrators import rk4
from auvmpc.models.layout import HORIZONTAL
from auvmpc.models.six_dof import SIX_DOF, six_dof_model
from auvmpc.models.vehicle import VehicleParams

__all__ = ["FaultDetector", "FaultFound", "SixDofFaultDetector"]

# An input is reported failed when at least this share of its assumed force is missing.
LOSS_FOUND = 0.5
# The 6-DOF detector reports a lost share from this on: it reports the share left (a weak
# propeller is the torpedo's only thrust), and its score alone kept the presets' model error
# from reading as a fault (docs/faults.md, measured).
SIX_DOF_LOSS_FOUND = 0.2
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
# A stuck input is reported when the commands it failed to follow were on average (RMS) at
# least this share of its range away from the value it is found stuck at (model error must
# not read as a jammed fin): measured, docs/faults.md.
STUCK_FOUND = 0.05
# The sequential stuck test's threshold (estimation/sequential_glr.py), its score read as the
# window fit's: measured on the healthy presets (docs/faults.md).
STUCK_SIGMAS = LOSS_SIGMAS
# The sequential loss test follows its nuisance with the gain of a window this long (s), not
# the window fit's 2 s: a weak propeller's step then adds evidence for longer (remus100-stuck-
# fin's propeller at 0.5: best score 13.6 with 2 s, 16.6 with 3 s, 20.8 with 5 s) while the
# model's error in the healthy presets' turns and dives scores no more than 4.4 with 3 s
# (6.6 with 5 s): measured, docs/faults.md. Its threshold is the window fit's, LOSS_SIGMAS.
LOSS_NUISANCE_S = 3.0
# A stuck value this share of the range beyond the input's limits is no jammed actuator
# (the model missed something else); within it, the value is clipped into the limits.
STUCK_BEYOND = 0.25
# Gauss-Newton steps that refine a stuck value on the model itself, at most, and the step
# (a share of the input's range) below which it has converged. From the tangent's estimate a
# dead propeller's 0 rpm is a few steps away (its thrust is convex in rpm).
STUCK_REFINEMENTS = 20
STUCK_CONVERGED = 1e-6
_NU = HORIZONTAL.nu


@dataclass(frozen=True)
class FaultFound:
    """One detection: input ``index`` has failed: it keeps ``remaining`` of the wrench it was
    assumed to make from then on, or is stuck at ``stuck_at`` (its own unit)."""

    index: int
    lost: float | None  # lambda: the share of the assumed force found missing (None: stuck)
    sigmas: float  # its score: its gain over no fault in the window's scatter (LOSS_SIGMAS)
    stuck_at: float | None = None  # the value it holds whatever commanded (None: a loss)
    # The share of its assumed wrench the controller is to take it as making from then on:
    # 0 (dead) for the horizontal detector and a stuck input, 1 - lambda for a 6-DOF loss.
    remaining: float = 0.0


@dataclass(frozen=True)
class _Fit:
    """The best fit of one input's hypotheses over the window's onsets."""

    rss: float
    index: int
    onset: int  # the window's row from which it acts
    sigmas: float
    lost: float | None = None  # a loss's lambda
    stuck_at: float | None = None  # a stuck input's value
    gap: float = 0.0  # a stuck input's RMS distance from its commands, from the onset on
    opposed: bool = False  # its value of the other sign than those commands' mean


@dataclass
class _Row:
    """One sample of the window: its weighted residual and regressors, and what they came
    from (a stuck value is refined on the model)."""

    residual: np.ndarray  # (m,) measured less predicted velocities, noise-weighted
    loss: np.ndarray  # (m, n) the loss regressors g_ki
    jacobian: np.ndarray | None  # (m, n) B_k: the velocities' Jacobian in the command
    command: np.ndarray  # (n,) F_k: what the inputs were to follow (a known stuck one's value)
    effectiveness: np.ndarray  # (n,) e: the share of its wrench each was taken to make
    watched: np.ndarray  # (n,) bool: inputs not known stuck
    before: np.ndarray  # the measured state the prediction started from
    measured: np.ndarray  # (m,) the measured velocities it is compared with


class FaultDetector:
    """The horizontal model's fault detector (module docstring) on ``model`` (the controller's
    nominal vehicle), sampled every ``sample_time`` with ``substeps`` RK4 steps;
    ``velocity_noise``: the std of the measured ``u, v, r``."""

    #: Whether an input stuck at a value is a hypothesis beside a loss.
    finds_stuck = False
    #: The least lost share reported (module docstring).
    loss_found = LOSS_FOUND
    #: The state :meth:`check` is given, by name, and where its velocities are in it.
    state_names = HORIZONTAL.names
    velocities: slice | np.ndarray = _NU

    def __init__(
        self,
        model: VehicleParams,
        sample_time: float,
        substeps: int,
        velocity_noise: np.ndarray,
    ) -> None:
        self._step = horizontal_model(model, sample_time, substeps, jit=False).linearised_step
        self._healthy = np.ones(model.n_thrusters)
        self._watch(model.n_thrusters, HORIZONTAL.size, sample_time, velocity_noise)

    def _watch(
        self, n_inputs: int, n_states: int, sample_time: float, velocity_noise: np.ndarray
    ) -> None:
        """The window and weights every detector has."""
        self.n_inputs = n_inputs
        self._weights = 1.0 / np.maximum(np.asarray(velocity_noise, dtype=float), NOISE_FLOOR)
        self.window = max(MIN_WINDOW_SAMPLES, round(WINDOW_S / sample_time))
        self._rows: deque[_Row] = deque(maxlen=self.window)
        self._state = np.zeros(n_states)
        self._held: tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray] | None = None

    def check(self, state: np.ndarray) -> FaultFound | None:
        """The measured ``state`` of this sample (the horizontal ``[x, y, psi, u, v, r]``; a
        6-DOF detector's whole state), after the command :meth:`held` since the last: a
        detection, if this sample confirms one."""
        found = None if self._held is None else self._fit(state, *self._held)
        self._state = np.array(state, dtype=float)
        self._held = None
        return found

    def held(
        self,
        command: np.ndarray,
        effectiveness: np.ndarray,
        stuck_at: np.ndarray | None = None,
    ) -> None:
        """The command held from the sample last checked, with the effectiveness the
        controller assumed for it; ``stuck_at``: each input's value where it is known stuck
        (NaN where free; None: none), which acts in full whatever commanded and is not
        watched."""
        command, effectiveness = np.array(command, dtype=float), np.array(effectiveness)
        watched = np.ones(self.n_inputs, dtype=bool)
        if stuck_at is not None:
            known = np.isfinite(stuck_at)
            command = np.where(known, stuck_at, command)
            effectiveness = np.where(known, 1.0, effectiveness)
            watched = ~known
        self._held = (self._state, command, effectiveness, watched)

    def _predict(
        self, before: np.ndarray, command: np.ndarray, effectiveness: np.ndarray
    ) -> tuple[np.ndarray, np.ndarray, np.ndarray | None]:
        """The velocities predicted from ``before`` under ``command`` with ``effectiveness``
        (m,), the loss regressors (m, n) and, for a detector that finds stuck inputs, the
        velocities' Jacobian in the command (m, n)."""
        still = np.zeros(len(DISTURBANCE_NAMES))  # the window's constant takes any force
        acting = effectiveness * command  # a thruster's force is linear in its command
        predicted, _, jacobian = self._step(before, acting, still, self._healthy)
        return np.asarray(predicted).ravel()[_NU], -np.asarray(jacobian)[_NU, :] * acting, None

    def _fit(
        self,
        state: np.ndarray,
        before: np.ndarray,
        command: np.ndarray,
        effectiveness: np.ndarray,
        watched: np.ndarray,
    ) -> FaultFound | None:
        predicted, loss, jacobian = self._predict(before, command, effectiveness)
        measured = np.asarray(state, dtype=float)[self.velocities]
        residual = (measured - predicted) * self._weights
        regressors = loss * self._weights[:, None]
        if jacobian is not None:
            jacobian = jacobian * self._weights[:, None]
        if not (np.isfinite(residual).all() and np.isfinite(regressors).all()):
            return None  # a state the model cannot step from says nothing of the thrusters
        row = _Row(
            residual, regressors, jacobian, command, effectiveness, watched, before, measured
        )
        self._rows.append(row)
        self._follow(row)
        found = self._found_in_window() if len(self._rows) == self.window else None
        if found is None:
            found = self._found_sequentially(row)
        if found is not None:  # the next fault starts afresh
            self._rows.clear()
            self._forget()
        return found

    def _found_in_window(self) -> FaultFound | None:
        """The window fit's detection (module docstring), if this sample confirms one."""
        best = self._likeliest_fault()
        if best is None or not self._found(best):
            return None
        stuck_at = None if best.stuck_at is None else self._refined(best)
        remaining = 0.0 if stuck_at is not None else self._remaining(best.lost)
        return FaultFound(best.index, best.lost, best.sigmas, stuck_at, remaining)

    def _follow(self, row: _Row) -> None:
        """A sequential test's update with this sample (none on the horizontal model)."""

    def _found_sequentially(self, row: _Row) -> FaultFound | None:
        """A sequential test's detection, if this sample confirms one (none here)."""
        return None

    def _forget(self) -> None:
        """A sequential test's restart after a detection (none here)."""

    def _remaining(self, lost: float) -> float:
        """The share of its assumed wrench a lost input is taken to keep: none (module
        docstring: why dead)."""
        return 0.0

    def _found(self, fit: _Fit) -> bool:
        """Whether ``fit`` is a fault to report (module docstring)."""
        if fit.stuck_at is None:
            return self.loss_found <= fit.lost <= LOSS_MOST and fit.sigmas >= LOSS_SIGMAS
        return fit.sigmas >= LOSS_SIGMAS and self._stuck_plausible(fit)

    def _stuck_plausible(self, fit: _Fit) -> bool:
        return False  # the horizontal detector has no stuck hypothesis

    def _refined(self, fit: _Fit) -> float:
        return float(fit.stuck_at)

    def _likeliest_fault(self) -> _Fit | None:
        """The single fault that best explains the window: for each input i and each onset
        j, the fit r_k = c + lambda g_ki [k >= j] (and, where stuck inputs are found, the
        stuck fit); the (i, j) of the smallest residual sum of squares. None if no input was
        commanded in the window."""
        residuals = np.array([row.residual for row in self._rows])  # (W, m)
        regressors = np.array([row.loss for row in self._rows])  # (W, m, n)
        watched = np.all([row.watched for row in self._rows], axis=0)  # (n,)
        window, rows = residuals.shape
        # Onsets j = 1..W-1, inside the window: a fault is a change, and one that began
        # before the window (j = 0) reads like the model's own error, which the window's
        # constant and LOSS_FOUND are there to leave alone.
        onsets = np.arange(window)[:, None] >= np.arange(1, window)[None, :]  # [k, j]
        centred_r = residuals - residuals.mean(axis=0)
        fits: list[_Fit] = []  # the best per input
        dof = window * rows - rows - 1
        for i in range(self.n_inputs):
            if not watched[i]:
                continue
            loss = self._loss_fit(i, onsets, regressors[:, :, i], centred_r, dof)
            stuck = self._stuck_fit(i, onsets, residuals, dof) if self.finds_stuck else None
            opposed = stuck is not None and stuck.opposed and loss is not None and loss.lost > 1
            clearer = loss is None or stuck is not None and stuck.rss <= ISOLATION * loss.rss
            if stuck is not None and (clearer or opposed):
                # (stuck only where it explains the window clearly better than a loss: module
                # docstring. A loss of more than all the force, where the stuck fit's value is
                # of the other sign than the commands, is the input pushing against its
                # command: a jam the other way, which a command held still cannot tell from a
                # loss)
                fits.append(stuck)
            elif loss is not None:
                fits.append(loss)
        if not fits:
            return None
        fits.sort(key=lambda fit: (fit.rss, fit.index))
        if len(fits) > 1 and fits[0].rss > ISOLATION * fits[1].rss:
            return None  # two inputs explain the window about as well: not isolated yet
        return fits[0]

    @staticmethod
    def _loss_fit(
        i: int, onsets: np.ndarray, regressor: np.ndarray, centred_r: np.ndarray, dof: int
    ) -> _Fit | None:
        """Input i's loss: lambda for each onset, the onset of the smallest residual sum of
        squares (None: the input was not commanded in the window)."""
        # (j, W, m): the regressor switched on from onset j, each centred over k.
        x = onsets.T[:, :, None] * regressor[None, :, :]
        x = x - x.mean(axis=1, keepdims=True)
        spread = np.einsum("jkm,jkm->j", x, x)
        usable = spread > 1e-12 * max(float(spread.max()), 1e-300)
        if not usable.any():
            return None
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
        return _Fit(float(rss[j]), i, j + 1, float(lost[j] / error), lost=float(lost[j]))

    def _stuck_fit(
        self, i: int, onsets: np.ndarray, residuals: np.ndarray, dof: int
    ) -> _Fit | None:
        """Input i stuck at s from onset j: r_k + [k >= j] B_ki F_ki = c + s [k >= j] B_ki
        (module docstring), fitted for each onset; the onset of the smallest residual sum of
        squares, its score the fit's gain over no fault in the window's scatter."""
        jacobian = np.array([row.jacobian[:, i] for row in self._rows])  # (W, m)
        commanded = np.array([row.command[i] for row in self._rows])  # (W,)
        on = onsets.T[:, :, None]  # (j, W, 1)
        x = on * jacobian[None]
        y = residuals[None] + x * commanded[None, :, None]
        x = x - x.mean(axis=1, keepdims=True)
        y = y - y.mean(axis=1, keepdims=True)
        spread = np.einsum("jkm,jkm->j", x, x)
        usable = spread > 1e-12 * max(float(spread.max()), 1e-300)
        if not usable.any():
            return None
        stuck = np.where(usable, np.einsum("jkm,jkm->j", x, y) / np.where(usable, spread, 1.0), 0)
        rss = np.einsum("jkm,jkm->j", *(2 * [y - stuck[:, None, None] * x]))
        rss = np.where(usable, rss, np.inf)
        j = int(np.argmin(rss))
        centred = residuals - residuals.mean(axis=0)
        gain = max(float(np.einsum("km,km->", centred, centred)) - float(rss[j]), 0.0)
        sigmas = np.sqrt(gain / max(rss[j] / dof, 1.0))
        after = commanded[j + 1 :]
        gap = float(np.sqrt(np.mean((stuck[j] - after) ** 2)))
        opposed = bool(stuck[j] * np.mean(after) < 0.0)
        return _Fit(
            float(rss[j]), i, j + 1, float(sigmas), stuck_at=float(stuck[j]), gap=gap,
            opposed=opposed,
        )  # fmt: skip


def _centred(residuals: np.ndarray) -> np.ndarray:
    """The residuals (W, m) less the window's constant, their mean."""
    return residuals - residuals.mean(axis=0)


def _six_dof_one_step(model: VehicleParams, sample_time: float, substeps: int) -> ca.Function:
    """(x, F, e) -> (nu_next (6,), its Jacobian in F (6, n), the secants nu_next(e_i = 0) -
    nu_next(e) (6, n)): the 6-DOF model's RK4 step in still water under the commands F, each
    input making the share e of its wrench."""
    derivative = six_dof_model(model).derivative_with_effectiveness
    n = model.six_dof_actuators.size
    x, command, e = ca.SX.sym("x", SIX_DOF.size), ca.SX.sym("F", n), ca.SX.sym("e", n)
    still = ca.DM.zeros(3)  # the window's constant takes the current's share

    def velocities(share):
        following = rk4(lambda s, u: derivative(s, u, still, still, share), x, command,
                        sample_time, substeps)  # fmt: skip
        return following[SIX_DOF.nu]

    following = velocities(e)
    without = [
        velocities(ca.vertcat(*(0 if j == i else e[j] for j in range(n)))) - following
        for i in range(n)
    ]
    return ca.Function(
        "fault_one_step", [x, command, e],
        [following, ca.jacobian(following, command), ca.horzcat(*without)],
    )  # fmt: skip


class SixDofFaultDetector(FaultDetector):
    """The fault detector (module docstring) on every input of ``model``'s 6-DOF model (the
    controller's nominal vehicle), sampled every ``sample_time`` with ``substeps`` RK4
    steps; ``velocity_noise``: the std of the measured body velocities ``u, v, w, p, q, r``.
    :meth:`check` takes the whole measured 6-DOF state."""

    finds_stuck = True
    loss_found = SIX_DOF_LOSS_FOUND
    state_names = SIX_DOF.names
    velocities = SIX_DOF.nu

    def __init__(
        self,
        model: VehicleParams,
        sample_time: float,
        substeps: int,
        velocity_noise: np.ndarray,
    ) -> None:
        inputs = model.six_dof_actuators
        self._one_step = _six_dof_one_step(model, sample_time, substeps)
        limits = inputs.limits
        self._jams = inputs.jams
        self._lower = np.broadcast_to(np.asarray(limits.lower, dtype=float), (inputs.size,))
        self._upper = np.broadcast_to(np.asarray(limits.upper, dtype=float), (inputs.size,))
        self._watch(inputs.size, SIX_DOF.size, sample_time, velocity_noise)
        memory = max(self.window, round(MEMORY_S / sample_time))
        rows = len(velocity_noise)
        self._glr = SequentialGLR(inputs.size, rows, window_gain(self.window), memory)
        slower = max(self.window, round(LOSS_NUISANCE_S / sample_time))
        self._loss_glr = SequentialGLR(inputs.size, rows, window_gain(slower), memory)
        # The rows the sequential test remembers, and a window before (its stuck value is
        # refined on them, the filter's mean settled over that window first).
        self._history: deque[_Row] = deque(maxlen=memory + self.window)

    def _follow(self, row: _Row) -> None:
        for glr in (self._glr, self._loss_glr):
            glr.update(row.residual, row.jacobian, row.loss, row.command)
        self._history.append(row)

    def _forget(self) -> None:
        self._glr.reset()
        self._loss_glr.reset()
        self._history.clear()

    def _found_sequentially(self, row: _Row) -> FaultFound | None:
        """The sequential test's detection: a stuck input (:meth:`_found_stuck`) or else a
        weakened one (:meth:`_found_weak`)."""
        found = self._found_stuck(row)
        return found if found is not None else self._found_weak(row)

    def _found_weak(self, row: _Row) -> FaultFound | None:
        """The sequential loss test's weakened input (estimation/sequential_glr.py), among
        those that cannot jam (a fin's fault is a jam, :meth:`_found_stuck`): the highest score
        at least :data:`LOSS_SIGMAS` whose lost share is between the detector's least
        (:data:`SIX_DOF_LOSS_FOUND`) and :data:`LOSS_MOST`, isolated as the window fit's is
        (its fit leaves at most :data:`ISOLATION` of what any other input's likelier
        hypothesis leaves at the same onset). It keeps 1 - lambda, as the window fit's loss."""
        fits = self._loss_glr.fits()
        if fits is None:
            return None
        likelier = np.minimum(fits.loss_rss, fits.versus_loss * fits.loss_rss)
        likelier = np.where(row.watched, likelier, np.inf)
        # Each input against the best of the others at the same onset (none: infinitely far).
        ranked = np.sort(np.column_stack([likelier, np.full(len(likelier), np.inf)]), axis=1)
        others = np.where(likelier <= ranked[:, :1], ranked[:, 1:2], ranked[:, :1])
        candidate = (
            row.watched
            & ~self._jams
            & (fits.loss_score >= LOSS_SIGMAS)
            & (fits.lost >= self.loss_found)
            & (fits.lost <= LOSS_MOST)
            & (fits.loss_rss <= ISOLATION * others)
        )
        if not candidate.any():
            return None
        onset, i = np.unravel_index(
            np.argmax(np.where(candidate, fits.loss_score, -1.0)), candidate.shape
        )
        lost = float(fits.lost[onset, i])
        return FaultFound(
            int(i), lost, float(fits.loss_score[onset, i]), None, self._remaining(lost)
        )

    def _found_stuck(self, row: _Row) -> FaultFound | None:
        """The sequential test's stuck input (estimation/sequential_glr.py), among those that can
        jam (``Actuator.jams``): the highest score at least :data:`STUCK_SIGMAS` whose value
        is inside the input's limits and far enough from its commands since (as the window
        fit's, :meth:`_stuck_plausible`), and whose fit is the likelier of stuck and lost.
        Likelier, not clearly better as in the window: once the filter has taken up the jam's
        constant wrench, what is left of a jam is that the input stopped answering its
        command, which a loss of all its wrench fits as well but for the step at the onset;
        a jam is what a fin's fault is, and inputs that fail by weakening are not tested."""
        fits = self._glr.fits()
        if fits is None:
            return None
        candidate = row.watched & (fits.score >= STUCK_SIGMAS) & self._stuck_likelier(fits)
        return self._stuck_since(fits, candidate)

    def _found_in_window(self) -> FaultFound | None:
        """The window fit's detection; a loss of an input that can jam told as the
        sequential test's stuck fit instead, at the remembered onset where stuck is likeliest
        against a loss (:attr:`SequentialFits.over_loss`), where any
        onset finds it likelier stuck (:meth:`_stuck_likelier`). The window tells a jam from
        a loss of all the input's wrench only by the step at the onset: a jam the window
        scores high enough only after the onset has left it (the command moved away late: in
        a turn, 2.5 s after a -10 deg stern-plane jam on remus100-stuck-fin) is read as the
        loss of all the fin's wrench, the jam's constant wrench taken by the window's
        constant; the controller then flies a fin whose jammed lift still acts as dead, and
        loses the depth (docs/faults.md). The sequential test remembers the onset: the
        window's score says there is a fault, the test which kind, and where."""
        found = super()._found_in_window()
        if found is None or found.stuck_at is not None or not self._jams[found.index]:
            return found  # (a stuck fit the window found has its onset in view: kept)
        fits = self._glr.fits()
        if fits is None:
            return found
        candidate = self._stuck_likelier(fits) & (np.arange(self.n_inputs) == found.index)
        stuck = self._stuck_since(fits, candidate)
        return found if stuck is None else replace(stuck, sigmas=found.sigmas)

    def _stuck_likelier(self, fits: SequentialFits) -> np.ndarray:
        """(onsets, inputs): where the sequential test's stuck fit is of an input that can
        jam, plausible (:meth:`_plausible`) and likelier than a loss at the same onset."""
        return self._jams & self._plausible(fits.stuck_at, fits.gap) & (fits.versus_loss < 1.0)

    def _stuck_since(self, fits: SequentialFits, candidate: np.ndarray) -> FaultFound | None:
        """The stuck input of the sequential test's ``fits`` among the ``candidate`` (onsets,
        inputs) where stuck is likeliest against a loss (``over_loss``: the onset's step is
        what tells the two apart, and its value; the highest score alone picked, after the
        command had moved, an onset just before the move and the value the fin was
        commanded to there: measured, tests/test_sequential_glr.py), the value refined on the
        rows since; None without a candidate."""
        if not candidate.any():
            return None
        onset, i = np.unravel_index(
            np.argmax(np.where(candidate, fits.over_loss, -np.inf)), candidate.shape
        )
        onset, i = int(onset), int(i)
        age = int(fits.ages[onset])
        rows = list(self._history)[-(age + self.window) :]
        on = np.arange(len(rows)) >= len(rows) - age
        filtered = partial(innovations, gain=self._glr.gain)
        stuck_at = self._gauss_newton(i, float(fits.stuck_at[onset, i]), rows, on, filtered)
        return FaultFound(i, None, float(fits.score[onset, i]), stuck_at, 0.0)

    def _predict(
        self, before: np.ndarray, command: np.ndarray, effectiveness: np.ndarray
    ) -> tuple[np.ndarray, np.ndarray, np.ndarray | None]:
        predicted, jacobian, secants = self._one_step(before, command, effectiveness)
        return (
            np.asarray(predicted).ravel(), np.asarray(secants), np.asarray(jacobian)
        )  # fmt: skip

    def _remaining(self, lost: float) -> float:
        """The share of its assumed wrench a lost input keeps: 1 - lambda, in [0, 1] (module
        docstring: a weak propeller is the torpedo's only thrust)."""
        return float(np.clip(1.0 - lost, 0.0, 1.0))

    def _stuck_plausible(self, fit: _Fit) -> bool:
        return bool(self._plausible(fit.stuck_at, fit.gap, fit.index))

    def _plausible(self, stuck_at, gap, inputs: int | slice = slice(None)):
        """Whether a value found stuck (of the inputs ``inputs``; arrays: input-wise) is
        inside the input's limits (to STUCK_BEYOND of its range) and ``gap``, how far the
        commands it did not follow were from it, at least STUCK_FOUND of its range."""
        lower, upper = self._lower[inputs], self._upper[inputs]
        beyond = STUCK_BEYOND * (upper - lower)
        inside = (stuck_at >= lower - beyond) & (stuck_at <= upper + beyond)
        return inside & (gap >= STUCK_FOUND * (upper - lower))

    def _refined(self, fit: _Fit) -> float:
        """The stuck value by Gauss-Newton on the model from the linear fit's (the window's
        constant refitted each step), to convergence, clipped into the input's limits."""
        rows = list(self._rows)
        on = np.arange(len(rows)) >= fit.onset
        return self._gauss_newton(fit.index, float(fit.stuck_at), rows, on, _centred)

    def _gauss_newton(
        self, i: int, stuck: float, rows: list[_Row], on: np.ndarray, nuisance
    ) -> float:
        """Input i's stuck value, from ``stuck``, by Gauss-Newton on the model over ``rows``,
        stuck in those ``on``; ``nuisance`` takes the nuisance's estimate out of a sequence
        of weighted residuals (rows by sample), and is linear."""
        for _ in range(STUCK_REFINEMENTS):
            errors, columns = [], []
            for row, acts in zip(rows, on, strict=True):
                command = row.command.copy()
                if acts:
                    command[i] = stuck
                predicted, jacobian, _ = self._one_step(row.before, command, row.effectiveness)
                errors.append((row.measured - np.asarray(predicted).ravel()) * self._weights)
                columns.append(acts * np.asarray(jacobian)[:, i] * self._weights)
            error, column = nuisance(np.array(errors)), nuisance(np.array(columns))
            spread = float(np.einsum("km,km->", column, column))
            if not spread > 0.0:
                break
            step = float(np.einsum("km,km->", column, error)) / spread
            stuck += step
            if abs(step) <= STUCK_CONVERGED * (self._upper[i] - self._lower[i]):
                break
        return float(np.clip(stuck, self._lower[i], self._upper[i]))
