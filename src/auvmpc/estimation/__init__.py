"""State and disturbance estimation: the offset-free EKF, the disturbance observer and the
obstacle tracker's Kalman filter (:mod:`.ekf`); the 6-DOF state and current EKF
(:mod:`.six_dof_current`)."""

from auvmpc.estimation.ekf import *  # noqa: F403 -- the package is the module's public names
from auvmpc.estimation.ekf import __all__  # noqa: F401
