/* A filter covariance kept a covariance (estimation/ekf.py, condition_covariance): its
 * symmetric part with the eigenvalues clipped to [floor, ceiling], rebuilt only when a bound
 * is crossed. For the exported depth filter (auvmpc_depth.c); n <= AUVMPC_COVARIANCE_MAX. */
#ifndef AUVMPC_COVARIANCE_H
#define AUVMPC_COVARIANCE_H

#define AUVMPC_COVARIANCE_MAX 9

/* m: n x n, row-major; out: the conditioned covariance (may be m). */
void auvmpc_condition_covariance(int n, const double *m, double floor, double ceiling,
                                 double *out);

#endif
