"""The REMUS 100 numbers that Fossen's MSS ``remus100.m`` computes rather than states.

    python benchmarks/remus100_parameters.py

MSS (github.com/cybergalactic/MSS, ``CRAFT/AUV/models/remus100.m``, read at commit 736a3d1)
builds the vehicle from a prolate spheroid (``spheroid.m``: mass and inertia; ``imlay61.m``:
added mass from Lamb's k-factors), linear damping from time constants and damping ratios
(``Dmtrx.m``), axial drag from Allen et al. (2000)'s C_d = 0.42 and the propeller from a
Wageningen B-series fit. This prints them as the numbers a vehicle file holds (Fossen's
signs: added mass and damping negative), for docs/remus100.md. It mirrors the MSS formulas
line by line; the line numbers are remus100.m's.
"""

from __future__ import annotations

import math

# remus100.m, lines 98, 131-138
RHO = 1026.0
LENGTH, DIAMETER = 1.6, 0.19
A = 1.0096 * LENGTH / 2  # spheroid semi-axes scaled to give m = 31.9 kg
B = 1.0096 * DIAMETER / 2
R44 = 0.3  # added roll inertia A44 = r44 Ix
Z_G = 0.02  # CG below the CO (r_bG); CB at the CO
# gravity.m at Trondheim's latitude (line 96)
MU = math.radians(63.446827)
G = (
    9.7803253359
    * (1 + 0.001931850400 * math.sin(MU) ** 2)
    / math.sqrt(1 - 0.006694384442 * math.sin(MU) ** 2)
)


def spheroid(rho: float) -> tuple[float, float, float]:
    """Mass and inertia of the spheroid (spheroid.m uses rho 1025, imlay61.m 1026)."""
    mass = 4 / 3 * math.pi * rho * A * B**2
    return mass, 2 / 5 * mass * B**2, 1 / 5 * mass * (A**2 + B**2)


def main() -> None:
    mass, ix, iy = spheroid(1025.0)
    # imlay61.m: Lamb's k-factors on its own (rho 1026) spheroid
    mass_a, ix_a, iy_a = spheroid(RHO)
    e = math.sqrt(1 - (B / A) ** 2)
    log = math.log((1 + e) / (1 - e))
    alpha_0 = 2 * (1 - e**2) / e**3 * (0.5 * log - e)
    beta_0 = 1 / e**2 - (1 - e**2) / (2 * e**3) * log
    k1, k2 = alpha_0 / (2 - alpha_0), beta_0 / (2 - beta_0)
    spread = beta_0 - alpha_0
    k_prime = e**4 * spread / ((2 - e**2) * (2 * e**2 - (2 - e**2) * spread))
    added = [mass_a * k1, mass_a * k2, mass_a * k2, R44 * ix_a, k_prime * iy_a, k_prime * iy_a]
    # M = MRB + MA about the CO; MRB's diagonal gains m z_g^2 in roll and pitch (Hmtrx).
    rigid = [mass, mass, mass, ix + mass * Z_G**2, iy + mass * Z_G**2, iy]
    total = [r + a for r, a in zip(rigid, added, strict=True)]
    # Dmtrx.m with T1 = T2 = 20 s, T6 = 1 s, zeta4 = 0.3, zeta5 = 0.8 (lines 192-196, 214);
    # W = m g, W = B, so the righting arm is z_g.
    weight = mass * G
    w4, w5 = math.sqrt(weight * Z_G / total[3]), math.sqrt(weight * Z_G / total[4])
    linear = [total[0] / 20, total[1] / 20, total[2] / 20, total[3] * 2 * 0.3 * w4,
              total[4] * 2 * 0.8 * w5, total[5] / 1]  # fmt: skip
    # Axial drag F = 1/2 rho C_d (pi b^2) U^2 with C_d = 0.42 (lines 143-144, forceLiftDrag).
    x_uu = -0.5 * RHO * 0.42 * math.pi * B**2
    # Propeller thrust at the top speed (lines 147-177, 247): 1525 rpm, 2.5 m/s.
    n = 1525 / 60
    j = 0.944 * 2.5 / (n * 0.14)
    thrust = RHO * 0.14**4 * (0.4566 + (0.1798 - 0.4566) / 0.6632 * j) * n**2
    # The shaft speed that holds 1.5 m/s against that drag: (1 - t) T = -X_uu u^2, a quadratic
    # in n (rev/s) once J = V_a / (n D) is multiplied out.
    slope = (0.1798 - 0.4566) / 0.6632
    a, b, c = 0.9 * RHO * 0.14**4 * 0.4566, 0.9 * RHO * 0.14**3 * slope * 0.944 * 1.5, x_uu * 1.5**2
    cruise_rpm = 60 * (-b + math.sqrt(b * b - 4 * a * c)) / (2 * a)
    # The speed 1525 rpm holds against that drag: a quadratic in U at fixed n.
    a, b, c = x_uu, 0.9 * RHO * 0.14**3 * slope * 0.944 * n, 0.9 * RHO * 0.14**4 * 0.4566 * n**2
    top_speed = (-b - math.sqrt(b * b - 4 * a * c)) / (2 * a)
    # crossFlowDrag.m ('cylinder', line 219): 21 strips of L/20 from -L/2 to L/2, 2-D drag
    # coefficient C_d(Re) kappa(L/D); below Re 2e5 (cross-flow < 0.125 m/s) C_d ~ 1.21 and
    # kappa(L/D = 8.4) = 0.62 + (0.68 - 0.62) (L/D - 5) / 5 (cylinderDrag.m's tables).
    strips = [-LENGTH / 2 + i * LENGTH / 20 for i in range(21)]
    kappa = 0.62 + (0.68 - 0.62) * (LENGTH / DIAMETER - 5) / 5
    per_length = -0.5 * 1025.0 * DIAMETER * 1.21 * kappa * LENGTH / 20
    y_vv = per_length * len(strips)
    n_rr = per_length * sum(abs(x) ** 3 for x in strips)

    rows = [
        ("g (m/s2)", G),
        ("m (kg), spheroid at rho 1025", mass),
        ("Ix, Iy = Iz (kg m2) about the CG", (ix, iy)),
        ("X_udot, Y_vdot = Z_wdot (kg)", (-added[0], -added[1])),
        ("K_pdot, M_qdot = N_rdot (kg m2)", (-added[3], -added[4])),
        ("X_u, Y_v = Z_w (N s/m), X_u fades as exp(-3 U)", (-linear[0], -linear[1])),
        ("K_p, M_q, N_r (N m s)", (-linear[3], -linear[4], -linear[5])),
        ("X_uu (kg/m)", x_uu),
        ("roll, pitch natural frequency (rad/s)", (w4, w5)),
        ("Y_vv = Z_ww (kg/m), N_rr = M_qq (kg m2), subcritical", (y_vv, n_rr)),
        ("net thrust (1 - t) T at 1525 rpm, 2.5 m/s (N)", 0.9 * thrust),
        ("shaft speed for 1.5 m/s (rpm)", cruise_rpm),
        ("speed at 1525 rpm (m/s)", top_speed),
        ("axial drag at 2.5 m/s (N)", -x_uu * 2.5**2),
    ]
    for name, value in rows:
        values = value if isinstance(value, tuple) else (value,)
        print(f"{name:54s} " + ", ".join(f"{v:.4g}" for v in values))


if __name__ == "__main__":
    main()
