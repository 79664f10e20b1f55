"""Heave identification (issue 27, the depth model): the manoeuvre on the vertical thrusters
inside their limits and a box of depth, played by a depth scenario; the heave regression
against analytic truth; excite -> run -> identify round trips on two vehicles of very
different size, from a noisy depth sensor alone and from depth and heave rate."""

from __future__ import annotations

import numpy as np
import pytest

from auvmpc.identification.excitation import Dof, design_excitation
from auvmpc.models.vehicle import load_vehicle

# Thrust rate per sample within round-off of the limit.
LIMIT_TOL_N = 1e-9


@pytest.mark.parametrize("name", ["bluerov2-heavy", "jmse2210"])
def test_the_heave_manoeuvre_stays_within_the_vertical_limits_and_the_depth_box(name):
    heave = load_vehicle(name).heave
    excitation = design_excitation(load_vehicle(name), 60.0, box_m=2.0, dof=Dof.HEAVE)
    thrust = excitation.thrust
    low, high = heave.thrust_limits
    assert thrust.shape[1] == heave.thruster_count
    assert thrust.min() >= low - LIMIT_TOL_N and thrust.max() <= high + LIMIT_TOL_N
    steps = np.diff(np.vstack([np.zeros(heave.thruster_count), thrust]), axis=0)
    assert np.abs(steps).max() <= heave.thrust_rate_limit * excitation.sample_time + LIMIT_TOL_N
    assert np.abs(thrust[-1]).max() <= LIMIT_TOL_N  # faded out: it ends at rest
    assert excitation.excursion_m <= 2.0
    # Every thruster pushes alike, about the trim that holds the nominal net buoyancy.
    np.testing.assert_array_equal(thrust, np.repeat(thrust[:, :1], heave.thruster_count, 1))
    assert np.abs(thrust).max() > 0.2 * min(-low, high)
