"""A sequential test for an input stuck at a value or weakened: the generalised likelihood
ratio of "input i has been stuck at s since sample j" and of "input i has made only (1 -
lambda) of its wrench since sample j" against "healthy", kept up to date sample by sample for
every onset j of the last :data:`MEMORY_S` (a window-limited GLR: Willsky and Jones, "A
generalized likelihood ratio approach to the detection and estimation of jumps in linear
systems", IEEE TAC 21(1), 1976; Lai, "Sequential changepoint detection in quality control
and dynamical systems", JRSS B 57(4), 1995).

Why beside the 6-DOF detector's window fit (fault_detection.py): a fin that jams a degree or
two from where it is commanded gives a small residual at the onset, and by the time the
controller, not knowing, has moved its command far enough for the fit to be sure, the onset
has left the 2 s window; from then on the fit reads the jam's constant wrench as its window's
constant ``c``. What still tells the jam then is that the input no longer answers its
command's changes. This test keeps that evidence for as long as the onset is remembered. A
propeller that loses half its thrust is the other case: the window holds too few samples of
the step for its score (measured on remus100-stuck-fin: 11.6 against 12), and a nuisance
followed more slowly than the window's constant lets the step's evidence add up for longer.

The residual r_k (measured less predicted velocities, noise-weighted, as the window fit's)
carries a slowly varying unknown ``c_k`` (a current, the model's own error), taken as a random
walk and followed by the exponentially weighted mean ``c_{k+1} = c_k + K (r_k - c_k)`` (the
steady-state Kalman filter of a random walk in white noise), its gain K given (the stuck test's
:func:`window_gain` of the window fit's length: what the window's constant absorbed, this
absorbs). Healthy, the filter's innovations ``nu_k = r_k - c_k`` are the noise. Stuck at s
from j, the residual has in addition ``m_k = B_ki (s - F_ki)`` for k >= j (B: the step's
Jacobian in the command, as in the window fit), and the same filter run on ``r - m`` has the
innovations ``nu_k - rho_k(s)``, where the signature ``rho_k = m_k - (the filter's mean of m up
to k)`` is linear in s: ``rho_k = s rho^B_k + rho^A_k`` with the signatures of ``B_ki`` and of
``-B_ki F_ki``. A loss of a share lambda of the input's wrench (the window fit's secant
regressor ``g_ki``) has the signature ``lambda rho^g_k``. For each onset and input the
least-squares s and lambda and the drops in the innovations' sum of squares (the GLR's gains,
twice their logs) follow from a few running sums.

The scores are the window fit's: each hypothesis's gain in its own fit's scatter (at least the
noise), so the same threshold reads the same way; it is measured on the healthy presets
(docs/faults.md).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

__all__ = ["SequentialFits", "SequentialGLR", "innovations", "window_gain"]

# How far back an onset is remembered (s): long enough for a controller that does not know
# of the jam to move its command well away from it (measured on remus100-stuck-fin: 2 to 6 s
# after a jam 1.6 to 2.5 deg from trim, docs/faults.md), short enough that the model's own
# error does not add up over a manoeuvre.
MEMORY_S = 10.0


@dataclass(frozen=True)
class SequentialFits:
    """Each remembered onset's (rows) fits of each input (columns): the onset ``ages``
    (onsets,) in samples (1: the last sample); stuck: the least-squares ``stuck_at``, its
    ``score``, the RMS distance ``gap`` of the commands since the onset from it, its
    innovations' sum of squares over a loss's at the same onset (``versus_loss``), and how
    much less that sum is than the loss's, in the stuck fit's scatter (``over_loss``: the
    log-likelihood ratio of stuck against lost, twice, as ``score`` squared is against
    healthy); lost: the least-squares share ``lost`` (lambda), its ``loss_score`` and its
    innovations' sum of squares ``loss_rss``."""

    ages: np.ndarray
    stuck_at: np.ndarray
    score: np.ndarray
    gap: np.ndarray
    versus_loss: np.ndarray
    over_loss: np.ndarray
    lost: np.ndarray
    loss_score: np.ndarray
    loss_rss: np.ndarray


def window_gain(window: int) -> float:
    """The exponentially weighted mean's gain whose mean age, (1 - K) / K, is that of a
    window of ``window`` samples, (window - 1) / 2."""
    return 2.0 / (window + 1.0)


def innovations(residuals: np.ndarray, gain: float) -> np.ndarray:
    """The innovations ``r_k - c_k`` (K, m) of the residuals (K, m) about their exponentially
    weighted mean ``c_{k+1} = c_k + gain (r_k - c_k)``, from ``c_0 = r_0``: what
    :class:`SequentialGLR` tests, for a whole sequence at once (linear in the residuals)."""
    out = np.empty_like(residuals, dtype=float)
    mean = np.array(residuals[0], dtype=float)
    for k, residual in enumerate(residuals):
        out[k] = residual - mean
        mean = mean + gain * out[k]
    return out


class SequentialGLR:
    """The window-limited GLR (module docstring) over ``n_inputs`` inputs and ``n_rows``
    residual rows, its nuisance followed with ``gain`` K, onsets remembered ``memory``
    samples."""

    def __init__(self, n_inputs: int, n_rows: int, gain: float, memory: int) -> None:
        self.n_inputs, self.n_rows, self.gain, self.memory = n_inputs, n_rows, gain, memory
        self.reset()

    def reset(self) -> None:
        """Forget every onset (a fault was found: the next one starts afresh)."""
        n, m, onsets = self.n_inputs, self.n_rows, self.memory
        self._mean: np.ndarray | None = None  # the healthy filter's c_k
        self._count = np.zeros(onsets)  # samples since each onset (0: not begun)
        # Each onset's filter means of the signals B_ki, -B_ki F_ki and the loss's g_ki.
        self._means = np.zeros((3, onsets, n, m))
        # Running sums: rho^B.rho^B, rho^B.(nu - rho^A), |nu - rho^A|^2, rho^g.rho^g,
        # rho^g.nu, F, F^2 per onset and input; |nu|^2 per onset.
        self._sums = np.zeros((7, onsets, n))
        self._innovation = np.zeros(onsets)

    def update(
        self,
        residual: np.ndarray,
        jacobian: np.ndarray,
        loss: np.ndarray,
        command: np.ndarray,
    ) -> None:
        """One sample: the weighted ``residual`` (m,), the weighted ``jacobian`` in the
        command (m, n) and loss regressors (m, n), and the ``command`` (n,) the inputs
        were to follow."""
        if self._mean is None:  # the first sample sets the nuisance's level
            self._mean = np.array(residual, dtype=float)
        nu = residual - self._mean
        self._mean = self._mean + self.gain * nu
        # A new onset at this sample, the oldest forgotten.
        self._count = np.roll(self._count, 1)
        self._means = np.roll(self._means, 1, axis=1)
        self._sums = np.roll(self._sums, 1, axis=1)
        self._innovation = np.roll(self._innovation, 1)
        self._count[0], self._means[:, 0], self._sums[:, 0], self._innovation[0] = 0, 0, 0, 0
        signals = np.stack([jacobian.T, -(jacobian * command).T, loss.T])  # (3, n, m)
        signatures = signals[:, None] - self._means  # (3, onsets, n, m)
        self._means += self.gain * signatures
        rho_b, rho_a, rho_g = signatures
        unexplained = nu - rho_a  # nu less the command's part of a stuck signature
        sums = self._sums
        sums[0] += np.einsum("oim,oim->oi", rho_b, rho_b)
        sums[1] += np.einsum("oim,oim->oi", rho_b, unexplained)
        sums[2] += np.einsum("oim,oim->oi", unexplained, unexplained)
        sums[3] += np.einsum("oim,oim->oi", rho_g, rho_g)
        sums[4] += np.einsum("oim,m->oi", rho_g, nu)
        sums[5] += command
        sums[6] += command**2
        self._innovation += float(nu @ nu)
        self._count += 1

    def fits(self) -> SequentialFits | None:
        """Every remembered onset's stuck and loss fits of every input; None before the first
        sample."""
        begun = self._count > 0
        if not begun.any():
            return None
        bb, bv, vv1, gg, gv, f, ff = (s[begun] for s in self._sums)
        count = self._count[begun][:, None]
        innovation = self._innovation[begun][:, None]
        usable = bb > 1e-12
        stuck = np.where(usable, bv / np.where(usable, bb, 1.0), 0.0)
        rss = vv1 - stuck * bv  # |nu - rho(s)|^2 at the least-squares s
        gain = np.where(usable, innovation - rss, 0.0)
        dof = np.maximum(self.n_rows * count - 1.0, 1.0)
        scatter = np.maximum(rss / dof, 1.0)
        lossy = gg > 1e-12
        lost = np.where(lossy, gv / np.where(lossy, gg, 1.0), 0.0)
        loss_gain = lost * gv  # gv^2 / gg: the drop in the innovations' sum of squares
        loss_rss = innovation - loss_gain
        loss_scatter = np.maximum(loss_rss / dof, 1.0)
        return SequentialFits(
            ages=np.flatnonzero(begun) + 1,
            stuck_at=stuck,
            score=np.where(usable, np.sqrt(np.maximum(gain, 0.0) / scatter), 0.0),
            gap=np.sqrt(np.maximum(ff / count - 2.0 * stuck * f / count + stuck**2, 0.0)),
            versus_loss=rss / np.maximum(loss_rss, 1e-300),
            over_loss=np.where(usable, (loss_rss - rss) / scatter, 0.0),
            lost=lost,
            loss_score=np.where(lossy, np.sqrt(np.maximum(loss_gain, 0.0) / loss_scatter), 0.0),
            loss_rss=loss_rss,
        )
