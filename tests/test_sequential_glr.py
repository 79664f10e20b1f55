"""The sequential stuck and loss test (estimation/sequential_glr.py): its recursion against the
batch statement it stands for, its estimates against noise-free truth, a loss in white noise
found within the delay its statistics give, and, in the 6-DOF detector, a stern plane jammed
near the angles it is commanded to found where the 2 s window alone does not find it, while a
healthy fin is left alone."""

from __future__ import annotations

import numpy as np
import pytest

from auvmpc.estimation.fault_detection import (
    LOSS_MOST,
    LOSS_SIGMAS,
    SIX_DOF_LOSS_FOUND,
    SixDofFaultDetector,
)
from auvmpc.estimation.sequential_glr import SequentialGLR, innovations, window_gain
from auvmpc.models.six_dof import SIX_DOF, integrate, six_dof_model, stable_substeps
from auvmpc.models.vehicle import load_vehicle

# Sums of squares of a few dozen O(1) terms, computed recursively and in one go.
ROUND_OFF = 1e-9
PROPELLER, STERN_PLANES = 0, 2
SAMPLE_TIME = 0.25
# The presets' navigation noise (remus100-stuck-fin: u, v 0.01 m/s, r 0.005 rad/s), weighted
# as the session weights the whole-vehicle detector's rows (w as v; p, q as r).
PRESET_NOISE = np.array([0.01, 0.01, 0.01, 0.005, 0.005, 0.005])
# The fins commanded at random within this of 0 (deg): six-dof-nmpc, not knowing of a jam near
# trim, moves the stern planes further than that (remus100-stuck-fin at -4.24 deg: from -1 to
# +20 deg within 6 s); within +-3 deg (its moves about trim before the fault) 20 s of random
# commands do not reach the threshold with the 10 s memory (best scores 8.5 to 11.1).
COMMAND_SPREAD_DEG = 6.0
JAM_DEG = 2.5  # as far from the commands' mean as the campaign's -5.09 deg jam from the trim
FAILS_AT = 40  # samples: the window full and 10 s of healthy samples before
SAMPLES = 120
# Found within the test's memory (10 s, 40 samples) of the onset.
MEMORY_SAMPLES = 40
# The stuck value found, refined on the nominal model, within this of the truth (deg). Looser
# than the window fit's 0.5 (tests/test_fin_faults.py): once the filter's mean has taken up
# the jam's constant wrench (mean age 3.5 samples), the value rests on the few samples after the
# onset, here among random +-6 deg commands; measured at most 1.65 off over seeds 0-9 (seed 8
# the worst, 0.51 for seed 0). On remus100-stuck-fin, where the controller moves the planes
# far from the jam at once, 0.02 to 0.23 off (docs/faults.md).
SEQUENTIAL_ANGLE_TOLERANCE_DEG = 2.0
# Half the presets' noise (a DVL's): the propeller at half its wrench, its rpm moved +-50
# at random (no controller raising it, as six-dof-nmpc does on remus100-stuck-fin), is found
# by the window alone in 2 of seeds 0-3 (3 samples after), by the sequential test in all 4
# (3 to 4 samples; at the presets' noise its best score is 8 to 10 there, the window's 6 to 7).
HALF_PRESET_NOISE = PRESET_NOISE / 2
# The share it is found keeping, against the truth: 0.48 to 0.57 over seeds 0-3.
PROPELLER_SHARE_TOLERANCE = 0.1


def _problem(rng, samples=30, rows=6, inputs=3):
    """Random weighted Jacobians (K, m, n) and commands (K, n)."""
    return rng.normal(size=(samples, rows, inputs)), rng.normal(size=(samples, inputs)) * 3.0


def _fed(residuals, jacobians, commands, gain=0.3, memory=40, losses=None):
    glr = SequentialGLR(jacobians.shape[2], jacobians.shape[1], gain, memory)
    losses = np.zeros_like(jacobians) if losses is None else losses
    for r, b, g, f in zip(residuals, jacobians, losses, commands, strict=True):
        glr.update(r, b, g, f)
    return glr


def test_a_stuck_value_is_recovered_exactly_from_noise_free_residuals():
    """Against known truth: residuals a constant nuisance plus, from sample 18, input 1 stuck
    at 2.5 (r_k = c + B_k1 (s - F_k1)). At the true onset the stuck fit leaves nothing
    (the filter's mean of the nuisance is exact), so its value is s to round-off and no
    onset scores higher."""
    rng = np.random.default_rng(3)
    jacobians, commands = _problem(rng)
    onset, stuck, i = 18, 2.5, 1
    residuals = np.tile(rng.normal(size=6), (len(commands), 1))
    residuals[onset:] += jacobians[onset:, :, i] * (stuck - commands[onset:, i])[:, None]
    fits = _fed(residuals, jacobians, commands).fits()
    true_age = len(commands) - onset
    row = int(np.flatnonzero(fits.ages == true_age)[0])
    assert fits.stuck_at[row, i] == pytest.approx(stuck, abs=ROUND_OFF)
    assert int(fits.ages[np.argmax(fits.score[:, i])]) == true_age


def test_the_recursion_is_the_batch_least_squares_on_the_filters_innovations():
    """Against the batch statement (module docstring): for each onset, the least-squares s
    minimises the sum of squares of the exponentially weighted filter's innovations of
    r - B (s - F) [k >= onset], and the score's gain is the drop from s's absence; both
    computed here with :func:`innovations` on the whole sequence and ``numpy.linalg.lstsq``."""
    rng = np.random.default_rng(5)
    jacobians, commands = _problem(rng)
    residuals = rng.normal(size=(len(commands), 6))
    gain, i = 0.3, 2
    fits = _fed(residuals, jacobians, commands, gain=gain).fits()
    healthy = innovations(residuals, gain)
    # A row before the first, the filter's start (r_0, and no stuck signal yet): an onset
    # at the first sample acts from its first innovation on.
    lead = np.vstack([residuals[:1], residuals])
    for row, age in enumerate(fits.ages):
        on = np.arange(len(commands)) >= len(commands) - age
        part = np.vstack([np.zeros((1, 6)), on[:, None] * jacobians[:, :, i]])  # B_ki [k >= j]
        # r - B (s - F): innovations linear in s, so one column and a right-hand side.
        column = innovations(part, gain)[1:][on].ravel()
        target = innovations(lead + part * np.r_[0.0, commands[:, i]][:, None], gain)
        target = target[1:][on].ravel()
        (stuck,), rss, *_ = np.linalg.lstsq(column[:, None], target, rcond=None)
        drop = np.sum(healthy[on] ** 2) - rss[0]
        scatter = max(rss[0] / (6 * age - 1), 1.0)
        assert fits.stuck_at[row, i] == pytest.approx(stuck, abs=ROUND_OFF)
        assert fits.score[row, i] == pytest.approx(np.sqrt(max(drop, 0.0) / scatter), abs=1e-6)


def test_a_lost_share_is_recovered_exactly_from_noise_free_residuals():
    """Against known truth: residuals a constant nuisance plus, from sample 18, input 2's loss
    regressors times lambda = 0.4 (r_k = c + lambda g_k2). At the true onset the loss fit
    leaves nothing, so its lambda is 0.4 to round-off and no onset scores higher."""
    rng = np.random.default_rng(4)
    jacobians, commands = _problem(rng)
    losses = rng.normal(size=jacobians.shape)
    onset, lost, i = 18, 0.4, 2
    residuals = np.tile(rng.normal(size=6), (len(commands), 1))
    residuals[onset:] += lost * losses[onset:, :, i]
    fits = _fed(residuals, jacobians, commands, losses=losses).fits()
    row = int(np.flatnonzero(fits.ages == len(commands) - onset)[0])
    assert fits.lost[row, i] == pytest.approx(lost, abs=ROUND_OFF)
    assert fits.loss_rss[row, i] == pytest.approx(0.0, abs=ROUND_OFF)
    assert int(np.argmax(fits.loss_score[:, i])) == row


def test_the_loss_recursion_is_the_batch_least_squares_on_the_filters_innovations():
    """Against the batch statement (module docstring): for each onset, the least-squares
    lambda minimises the sum of squares of the filter's innovations of r - lambda g [k >=
    onset]; its residual sum of squares and score (the drop from lambda's absence in the fit's
    scatter) as ``numpy.linalg.lstsq`` on :func:`innovations` of the whole sequence gives."""
    rng = np.random.default_rng(6)
    jacobians, commands = _problem(rng)
    losses = rng.normal(size=jacobians.shape)
    residuals = rng.normal(size=(len(commands), 6))
    gain, i = 0.3, 0
    fits = _fed(residuals, jacobians, commands, gain=gain, losses=losses).fits()
    healthy = innovations(residuals, gain)
    for row, age in enumerate(fits.ages):
        on = np.arange(len(commands)) >= len(commands) - age
        part = np.vstack([np.zeros((1, 6)), on[:, None] * losses[:, :, i]])  # g [k >= j]
        column = innovations(part, gain)[1:][on].ravel()
        (lost,), rss, *_ = np.linalg.lstsq(column[:, None], healthy[on].ravel(), rcond=None)
        drop = np.sum(healthy[on] ** 2) - rss[0]
        # (the onsets older than the sequence begin with it: their sums are its samples')
        scatter = max(rss[0] / (6 * on.sum() - 1), 1.0)
        assert fits.lost[row, i] == pytest.approx(lost, abs=ROUND_OFF)
        assert fits.loss_rss[row, i] == pytest.approx(rss[0], abs=ROUND_OFF)
        assert fits.loss_score[row, i] == pytest.approx(np.sqrt(drop / scatter), abs=1e-6)


# A loss in unit white noise (module docstring's statistics): the filter of gain K takes the
# loss's step up, so what adds up is its regressor's changes (the command moving). Noise-free,
# the loss's signature at the true onset is the filter's innovations of lambda g [k >= j]; n
# samples after the onset its squared size is S_n, and the score there is (sqrt(S_n) + z) /
# sqrt(scatter) with z of about the innovations' std, sqrt(2 / (2 - K)) (1.04 at K = 2/13),
# and the scatter about its square. Found, at the latest, when sqrt(S_n) reaches the threshold
# plus NOISE_MARGIN standard deviations, both in SCATTER_MARGIN times that std (the scatter
# from 6 n values, and z's own correlation over the filtered samples).
NOISE_MARGIN = 5.0
SCATTER_MARGIN = 1.5
WHITE_ROWS = 6
LOSS_GAIN = window_gain(12)  # the 6-DOF detector's loss test at 0.25 s (LOSS_NUISANCE_S 3 s)
REGRESSOR_NORM = 16.0  # the loss regressor's size in noise units (an input's whole wrench)
MODULATION = 0.9  # each input's regressor moves within this share of its size, at random


def _white(rng, samples, lost, onset, drift=0.0):
    """Unit white noise on WHITE_ROWS rows about a nuisance (a random walk of ``drift`` a
    sample from a random start); three inputs whose loss regressors are fixed directions of
    norm REGRESSOR_NORM scaled by 1 +- MODULATION at random each sample; input 0 losing
    ``lost`` from ``onset`` on (None: healthy). The regressors (samples, rows, 3) and the
    first sample whose fits hold a loss the detector would take (a score of at least
    LOSS_SIGMAS, lambda between SIX_DOF_LOSS_FOUND and LOSS_MOST): (sample, input, lambda,
    score), or None."""
    directions = rng.normal(size=(WHITE_ROWS, 3))
    directions *= REGRESSOR_NORM / np.linalg.norm(directions, axis=0)
    losses = directions * (1.0 + MODULATION * rng.uniform(-1, 1, (samples, 1, 3)))
    glr = SequentialGLR(3, WHITE_ROWS, LOSS_GAIN, MEMORY_SAMPLES)
    nuisance, found = rng.normal(size=WHITE_ROWS) * 10.0, None
    for k in range(samples):
        nuisance = nuisance + drift * rng.normal(size=WHITE_ROWS)
        residual = nuisance + rng.normal(size=WHITE_ROWS)
        if lost is not None and k >= onset:
            residual += lost * losses[k, :, 0]
        glr.update(residual, np.zeros((WHITE_ROWS, 3)), losses[k], np.zeros(3))
        fits = glr.fits()
        taken = (fits.lost >= SIX_DOF_LOSS_FOUND) & (fits.lost <= LOSS_MOST)
        scores = np.where(taken, fits.loss_score, 0.0)
        if scores.max() >= LOSS_SIGMAS:
            onset_row, i = np.unravel_index(np.argmax(scores), scores.shape)
            found = (k, int(i), float(fits.lost[onset_row, i]), float(scores[onset_row, i]))
            break
    return losses, found


@pytest.mark.parametrize("seed", range(4))
def test_a_loss_in_white_noise_is_found_within_its_statistical_delay(seed):
    """Against the statistics (the comment above): input 0 keeps half its wrench from sample
    40. The delay bound follows from S_n, computed from the noise-free signature; the loss is
    found no later, as input 0's, its lambda within NOISE_MARGIN of its standard errors
    (lambda over its score: the score is lambda over its standard error). Measured over seeds
    0-9: found 0 to 5 samples after the onset (the step is 8 noise std), bounds 17 to 36,
    lambda 0.47 to 0.57."""
    lost, onset = 0.5, 40
    losses, found = _white(np.random.default_rng(seed), onset + MEMORY_SAMPLES, lost, onset)
    part = np.vstack([np.zeros((1, WHITE_ROWS)), lost * losses[onset:, :, 0]])
    signature = innovations(part, LOSS_GAIN)[1:]  # the filter's mean starts at the onset
    size = np.sqrt(np.cumsum(np.sum(signature**2, axis=1)))  # sqrt(S_n), n = 1, 2, ...
    needed = (LOSS_SIGMAS + NOISE_MARGIN) * np.sqrt(2.0 / (2.0 - LOSS_GAIN)) * SCATTER_MARGIN
    assert size[-1] >= needed  # the bound is inside the test's memory
    bound = int(np.argmax(size >= needed)) + 1
    assert found is not None, "nothing found"
    k, i, estimate, score = found
    assert onset <= k < onset + bound
    assert i == 0
    assert estimate == pytest.approx(lost, abs=NOISE_MARGIN * estimate / score)


@pytest.mark.parametrize("seed", range(4))
def test_white_noise_about_a_drifting_nuisance_is_not_found_weakened(seed):
    """Healthy: the same three inputs, no loss, the nuisance a random walk of half the noise
    a sample (what the filter follows) for 400 samples: no loss reaches the threshold."""
    _, found = _white(np.random.default_rng(seed), 400, None, 0, drift=0.5)
    assert found is None


def test_the_filters_mean_age_is_the_windows():
    """The exponentially weighted mean's gain for a window of W samples: mean age (1 - K) / K
    equal to the window's (W - 1) / 2."""
    gain = window_gain(8)
    assert (1 - gain) / gain == pytest.approx((8 - 1) / 2, abs=ROUND_OFF)


def _watched(jam_deg, seed, sequential=True, propeller_share=None, noise=PRESET_NOISE, planes=None):
    """The REMUS 100's nominal 6-DOF model as the plant in a 0.3 m/s cross current, the fins
    moved at random within COMMAND_SPREAD_DEG of 0 and the propeller about 900 rpm, the
    velocity ``noise``; the stern planes held at ``jam_deg`` from FAILS_AT on (None:
    healthy), or the propeller making ``propeller_share`` of its wrench; ``planes(k, drawn)``:
    the planes' command at sample k instead, from the random one drawn. What the detector
    found, (sample, FaultFound) each."""
    vehicle = load_vehicle("remus100")
    substeps = stable_substeps(vehicle, SAMPLE_TIME)
    detector = SixDofFaultDetector(vehicle, SAMPLE_TIME, substeps, noise)
    if not sequential:
        detector._found_sequentially = lambda row: None  # the window fit alone
    plant, current = six_dof_model(vehicle), np.array([0.0, 0.3, 0.0])
    rng = np.random.default_rng(seed)
    state = np.zeros(SIX_DOF.size)
    state[SIX_DOF.index("z")], state[SIX_DOF.index("u")] = 5.0, 1.5
    state[SIX_DOF.index("v")] = 0.3  # moving with the water
    found, told_stuck, told = [], np.full(3, np.nan), np.ones(3)
    for k in range(SAMPLES):
        measured = state.copy()
        measured[SIX_DOF.nu] += rng.normal(0.0, noise)
        result = detector.check(measured)
        if result is not None:  # told as the session tells the controller
            found.append((k, result))
            told_stuck[result.index] = result.stuck_at
            told[result.index] *= result.remaining
        spread = [50.0, COMMAND_SPREAD_DEG, COMMAND_SPREAD_DEG]
        command = np.array([900.0, 0.0, 0.0]) + rng.uniform(-1, 1, 3) * spread
        if planes is not None:
            command[STERN_PLANES] = planes(k, command[STERN_PLANES])
        detector.held(command, told, told_stuck)
        acting, effectiveness = command.copy(), None
        if jam_deg is not None and k >= FAILS_AT:
            acting[STERN_PLANES] = jam_deg
        if propeller_share is not None and k >= FAILS_AT:
            effectiveness = np.array([propeller_share, 1.0, 1.0])
        state = integrate(plant, state, acting, SAMPLE_TIME, substeps, held_current=current,
                          effectiveness=effectiveness)  # fmt: skip
    return found


@pytest.mark.parametrize("seed", [0, 8])
def test_a_fin_jammed_near_its_commands_is_found_where_the_window_alone_misses_it(seed):
    """Against known truth: the stern planes jammed 2.5 deg from the mean of their random
    commands, at the presets' noise. The window fit alone finds nothing in the 20 s after the
    onset (its 2 s hold too little of the evidence: measured, 1 of seeds 0-9 found, 16 s
    late); with the sequential test the planes are found stuck within the test's memory, at
    their angle, and nothing else is found."""
    assert _watched(JAM_DEG, seed, sequential=False) == []
    found = _watched(JAM_DEG, seed)
    assert found, "nothing found"
    (k, result), *later = found
    assert FAILS_AT < k <= FAILS_AT + MEMORY_SAMPLES
    assert result.index == STERN_PLANES and result.lost is None and not later
    assert result.stuck_at == pytest.approx(JAM_DEG, abs=SEQUENTIAL_ANGLE_TOLERANCE_DEG)


@pytest.mark.parametrize("seed", [0, 5])
def test_a_healthy_fin_commanded_at_random_is_not_found_stuck(seed):
    """No fault, the same random commands and noise for 30 s: nothing is found (the
    sequential test's best score measured 3.2 to 4.6 over seeds 0-9, threshold 12), stuck or
    weakened, at the presets' noise or half of it."""
    assert _watched(None, seed) == []
    assert _watched(None, seed, noise=HALF_PRESET_NOISE) == []


@pytest.mark.parametrize("seed", [1, 2])
def test_a_propeller_keeping_half_its_thrust_is_found_where_the_window_alone_misses_it(seed):
    """Against known truth: the propeller makes half its wrench from FAILS_AT, at
    HALF_PRESET_NOISE. The window fit alone finds nothing on these seeds; with the sequential
    loss test the propeller is found within the test's memory, as a loss, keeping half to
    PROPELLER_SHARE_TOLERANCE, and nothing else."""
    weak = {"propeller_share": 0.5, "noise": HALF_PRESET_NOISE}
    assert _watched(None, seed, sequential=False, **weak) == []
    found = _watched(None, seed, **weak)
    assert found, "nothing found"
    (k, result), *later = found
    assert FAILS_AT < k <= FAILS_AT + MEMORY_SAMPLES
    assert result.index == PROPELLER and result.stuck_at is None and not later
    assert result.remaining == pytest.approx(0.5, abs=PROPELLER_SHARE_TOLERANCE)


# Run 47 of the fin-jam campaign (docs/faults.md): the stern planes jam at -10 deg in the turn,
# 6 deg below where they are commanded (about -4 deg), and the controller, not knowing, moves
# them away (to +11 deg) only after the onset has left the window fit's 2 s.
LATE_JAM_DEG, LATE_TRIM_DEG, LATE_MOVED_TO_DEG = -10.0, -4.0, 11.0
LATE_MOVE_AFTER = 10  # samples after the onset (2.5 s), then a ramp of LATE_RAMP samples
LATE_RAMP = 4
# Measured (seeds 0-7, moves 8, 10 and 12 samples after the onset, 24 cases): before the
# sequential test chose the kind, 5 of the 24 were found a loss of 0.85 to 0.99 of the planes'
# wrench; now none, and with the move at 10 every one stuck within 0.65 deg (with the move at
# 8 or 12, 5 are still found stuck 3.6 to 8.2 deg off by the window fit: docs/faults.md).


def _moved_late(k, drawn):
    """The planes about LATE_TRIM_DEG (the random draw scaled to +-1 deg), moved to
    LATE_MOVED_TO_DEG from LATE_MOVE_AFTER samples after the onset on."""
    ramp = np.clip((k - FAILS_AT - LATE_MOVE_AFTER + 1) / LATE_RAMP, 0.0, 1.0)
    return LATE_TRIM_DEG + drawn / COMMAND_SPREAD_DEG + ramp * (LATE_MOVED_TO_DEG - LATE_TRIM_DEG)


@pytest.mark.parametrize("seed", [3, 7])
def test_a_jam_found_after_its_onset_left_the_window_is_found_stuck_at_its_angle(seed):
    """Against known truth (run 47's case, above): the window fit scores the fault high enough
    only once the command has moved, when it can no longer tell a jam from the loss of all the
    fin's wrench (these seeds: found a loss of 0.99 and 0.85 before); the sequential test,
    which remembers the onset, says which: stuck, at the jam's angle."""
    found = _watched(LATE_JAM_DEG, seed, planes=_moved_late)
    assert found, "nothing found"
    (k, result), *later = found
    assert FAILS_AT < k <= FAILS_AT + MEMORY_SAMPLES
    assert result.index == STERN_PLANES and result.lost is None and not later
    assert result.stuck_at == pytest.approx(LATE_JAM_DEG, abs=SEQUENTIAL_ANGLE_TOLERANCE_DEG)
