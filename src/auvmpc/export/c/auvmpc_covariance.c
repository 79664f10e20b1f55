/* The covariance kept symmetric with bounded eigenvalues (auvmpc_covariance.h). The
 * eigenvalues by cyclic Jacobi rotations: a few hundred operations at the depth filter's
 * 3 x 3, where the Python takes LAPACK's (numpy.linalg.eigvalsh); the two agree to round-off,
 * so the bounds are crossed at the same samples but for a tie within it. */
#include "auvmpc_covariance.h"

#include <math.h>
#include <string.h>

#define MAX AUVMPC_COVARIANCE_MAX
#define AT(a, i, j) (a)[(i) * MAX + (j)]

/* Eigenvalues of the symmetric a (n x n, stride MAX; destroyed) by cyclic Jacobi rotations;
 * with vectors (columns, stride MAX) when v is not NULL. */
static void jacobi_eigen(int n, double *a, double *values, double *v) {
    if (v)
        for (int i = 0; i < n; ++i)
            for (int j = 0; j < n; ++j) AT(v, i, j) = i == j;
    for (int sweep = 0; sweep < 100; ++sweep) {
        double off = 0.0, scale = 0.0;
        for (int i = 0; i < n; ++i)
            for (int j = 0; j < n; ++j) {
                if (i != j) off += AT(a, i, j) * AT(a, i, j);
                scale += AT(a, i, j) * AT(a, i, j);
            }
        if (off <= 1e-32 * scale) break;
        for (int p = 0; p < n - 1; ++p)
            for (int q = p + 1; q < n; ++q) {
                if (AT(a, p, q) == 0.0) continue;
                double theta = (AT(a, q, q) - AT(a, p, p)) / (2.0 * AT(a, p, q));
                double t = (theta >= 0.0 ? 1.0 : -1.0) / (fabs(theta) + sqrt(theta * theta + 1.0));
                double cs = 1.0 / sqrt(t * t + 1.0), sn = t * cs;
                for (int k = 0; k < n; ++k) { /* columns p, q */
                    double kp = AT(a, k, p), kq = AT(a, k, q);
                    AT(a, k, p) = cs * kp - sn * kq;
                    AT(a, k, q) = sn * kp + cs * kq;
                }
                for (int k = 0; k < n; ++k) { /* rows p, q */
                    double pk = AT(a, p, k), qk = AT(a, q, k);
                    AT(a, p, k) = cs * pk - sn * qk;
                    AT(a, q, k) = sn * pk + cs * qk;
                }
                if (v)
                    for (int k = 0; k < n; ++k) {
                        double kp = AT(v, k, p), kq = AT(v, k, q);
                        AT(v, k, p) = cs * kp - sn * kq;
                        AT(v, k, q) = sn * kp + cs * kq;
                    }
            }
    }
    for (int i = 0; i < n; ++i) values[i] = AT(a, i, i);
}

void auvmpc_condition_covariance(int n, const double *m, double floor, double ceiling,
                                 double *out) {
    double symmetric[MAX * MAX], work[MAX * MAX], vectors[MAX * MAX], values[MAX];
    for (int i = 0; i < n; ++i)
        for (int j = 0; j < n; ++j) AT(symmetric, i, j) = 0.5 * (m[i * n + j] + m[j * n + i]);
    memcpy(work, symmetric, sizeof work);
    jacobi_eigen(n, work, values, NULL);
    double low = values[0], high = values[0];
    for (int i = 1; i < n; ++i) {
        low = fmin(low, values[i]);
        high = fmax(high, values[i]);
    }
    if (!(low >= floor && high <= ceiling)) {
        memcpy(work, symmetric, sizeof work);
        jacobi_eigen(n, work, values, vectors);
        for (int i = 0; i < n; ++i) values[i] = fmin(fmax(values[i], floor), ceiling);
        for (int i = 0; i < n; ++i)
            for (int j = 0; j < n; ++j) {
                double sum = 0.0;
                for (int k = 0; k < n; ++k) sum += AT(vectors, i, k) * values[k] * AT(vectors, j, k);
                AT(work, i, j) = sum;
            }
        for (int i = 0; i < n; ++i)
            for (int j = 0; j < n; ++j) AT(symmetric, i, j) = 0.5 * (AT(work, i, j) + AT(work, j, i));
    }
    for (int i = 0; i < n; ++i)
        for (int j = 0; j < n; ++j) out[i * n + j] = AT(symmetric, i, j);
}
