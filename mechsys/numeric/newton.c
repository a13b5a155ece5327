/* Deflated damped Newton for the multistart of steady motions (analysis/equilibrium/equilibria.py, _newton),
 * over compiled straight-line programs (numeric/native.py, program_source): the loop that the Python version
 * runs with a dozen numpy calls per evaluation, here with none. Built once per machine (numeric/native.py,
 * newton_library); the caller polishes and normalizes the result in Python.
 *
 * The unknowns z enter the program's argument vector by position: args = base, args[pos[k]] = z[k]. The
 * residual F(z) is the first `size` outputs of `values(args)`; the Jacobian dF/dz is gathered from the output of
 * `full(args)` (followed by a zero): J[i][k] = raw[jindex[i*nz + k]] * jsign[i*nz + k].
 *
 * The algorithm is the Python one, step for step: deflation mu = prod_r (1/|z - r|^2 + 1) over the roots found
 * (angles compared on the circle), G = mu F, dG/dz = mu J + F (mu grad log mu)^T, the least-squares Newton step
 * (minimum-norm, singular values below eps max(m, n) s_max dropped: numpy's lstsq), backtracking on |G| from the
 * full step by halves down to 1e-4, failure after 4 consecutive steps shorter than 1e-2 or a non-finite G or
 * dG/dz, convergence when the step is below 1e-12 (1 + |z|) in the max norm. Round-off differs from numpy's.
 */
#include <math.h>
#include <stdlib.h>
#include <string.h>
#include <float.h>

typedef void (*program_fn)(const double *a, double *out);

typedef struct {
    program_fn values, full;
    int nargs, nz, size, full_size, nknown;
    const double *base;
    const long *pos;
    const long *jindex;
    const double *jsign;
    const double *known;   /* nknown x nz, row major */
    const unsigned char *is_angle;
    double *args, *out, *raw;
} problem_t;

static double wrap(double d) {
    /* numpy.remainder(d + pi, 2 pi) - pi: the floored modulo (fmod, then the divisor's sign) */
    const double two_pi = 2.0 * M_PI;
    double r = fmod(d + M_PI, two_pi);
    if (r != 0.0 && r < 0.0) r += two_pi;
    return r - M_PI;
}

/* F(z) into f (size); 0 when not finite */
static int residual(problem_t *P, const double *z, double *f) {
    memcpy(P->args, P->base, sizeof(double) * P->nargs);
    for (int k = 0; k < P->nz; k++) P->args[P->pos[k]] = z[k];
    P->values(P->args, P->out);
    for (int i = 0; i < P->size; i++) {
        f[i] = P->out[i];
        if (!isfinite(f[i])) return 0;
    }
    return 1;
}

/* J(z) (size x nz, row major), after residual() at the same z (the arguments are in place) */
static void jacobian(problem_t *P, double *J) {
    P->full(P->args, P->raw);
    P->raw[P->full_size] = 0.0;
    for (int i = 0; i < P->size * P->nz; i++) J[i] = P->raw[P->jindex[i]] * P->jsign[i];
}

/* mu, and grad log mu into grad (when not NULL) */
static double deflation(problem_t *P, const double *z, double *d, double *grad) {
    double mu = 1.0;
    if (grad) for (int k = 0; k < P->nz; k++) grad[k] = 0.0;
    for (int r = 0; r < P->nknown; r++) {
        const double *root = P->known + (size_t)r * P->nz;
        double d2 = 0.0;
        for (int k = 0; k < P->nz; k++) {
            double dk = z[k] - root[k];
            if (P->is_angle[k]) dk = wrap(dk);
            d[k] = dk;
            d2 += dk * dk;
        }
        if (d2 < 1e-28) d2 = 1e-28;
        double factor = 1.0 / d2 + 1.0;
        mu *= factor;
        if (grad) {
            double w = -2.0 / (d2 * d2 * factor);
            for (int k = 0; k < P->nz; k++) grad[k] += w * d[k];
        }
    }
    return mu;
}

static double norm2(const double *x, int n) {
    double s = 0.0;
    for (int i = 0; i < n; i++) s += x[i] * x[i];
    return sqrt(s);
}

/* One-sided Jacobi SVD of A (m x n, row major, overwritten by A V = U S), V (n x n); singular values in s. */
static void jacobi_svd(double *A, int m, int n, double *V, double *s) {
    for (int i = 0; i < n * n; i++) V[i] = 0.0;
    for (int i = 0; i < n; i++) V[i * n + i] = 1.0;
    for (int sweep = 0; sweep < 60; sweep++) {
        int rotated = 0;
        for (int i = 0; i < n - 1; i++) {
            for (int j = i + 1; j < n; j++) {
                double alpha = 0.0, beta = 0.0, gamma = 0.0;
                for (int r = 0; r < m; r++) {
                    double ai = A[r * n + i], aj = A[r * n + j];
                    alpha += ai * ai;
                    beta += aj * aj;
                    gamma += ai * aj;
                }
                if (gamma == 0.0 || fabs(gamma) <= DBL_EPSILON * sqrt(alpha * beta)) continue;
                rotated = 1;
                double zeta = (beta - alpha) / (2.0 * gamma);
                double t = (zeta >= 0.0 ? 1.0 : -1.0) / (fabs(zeta) + sqrt(1.0 + zeta * zeta));
                double c = 1.0 / sqrt(1.0 + t * t), sn = c * t;
                for (int r = 0; r < m; r++) {
                    double ai = A[r * n + i], aj = A[r * n + j];
                    A[r * n + i] = c * ai - sn * aj;
                    A[r * n + j] = sn * ai + c * aj;
                }
                for (int r = 0; r < n; r++) {
                    double vi = V[r * n + i], vj = V[r * n + j];
                    V[r * n + i] = c * vi - sn * vj;
                    V[r * n + j] = sn * vi + c * vj;
                }
            }
        }
        if (!rotated) break;
    }
    for (int j = 0; j < n; j++) {
        double q = 0.0;
        for (int r = 0; r < m; r++) q += A[r * n + j] * A[r * n + j];
        s[j] = sqrt(q);
    }
}

/* Minimum-norm least-squares solution x (n) of A x = b (A m x n, destroyed), as numpy's lstsq with rcond=None:
 * Householder QR when A has clearly full column rank (m >= n), the Jacobi SVD otherwise. */
static void lstsq(double *A, int m, int n, const double *b, double *x, double *work) {
    double *R = work;               /* m x n copy for QR */
    double *qb = R + (size_t)m * n; /* m */
    int qr_ok = m >= n;
    if (qr_ok) {
        memcpy(R, A, sizeof(double) * m * n);
        memcpy(qb, b, sizeof(double) * m);
        double dmax = 0.0, dmin = INFINITY;
        for (int k = 0; k < n; k++) {
            double nrm = 0.0;
            for (int r = k; r < m; r++) nrm += R[r * n + k] * R[r * n + k];
            nrm = sqrt(nrm);
            if (nrm == 0.0) { qr_ok = 0; break; }
            double alpha = R[k * n + k] > 0.0 ? -nrm : nrm;
            /* v = x - alpha e1, stored in column k below (and at) the diagonal */
            R[k * n + k] -= alpha;
            double vnorm2 = 0.0;
            for (int r = k; r < m; r++) vnorm2 += R[r * n + k] * R[r * n + k];
            if (vnorm2 > 0.0) {
                for (int j = k + 1; j < n; j++) {
                    double dot = 0.0;
                    for (int r = k; r < m; r++) dot += R[r * n + k] * R[r * n + j];
                    double w = 2.0 * dot / vnorm2;
                    for (int r = k; r < m; r++) R[r * n + j] -= w * R[r * n + k];
                }
                double dot = 0.0;
                for (int r = k; r < m; r++) dot += R[r * n + k] * qb[r];
                double w = 2.0 * dot / vnorm2;
                for (int r = k; r < m; r++) qb[r] -= w * R[r * n + k];
            }
            R[k * n + k] = alpha;
            double a = fabs(alpha);
            if (a > dmax) dmax = a;
            if (a < dmin) dmin = a;
        }
        /* a diagonal of R far from rank deficiency: the least-squares solution is unique, QR's equals the SVD's */
        if (qr_ok && dmin > 1e-10 * dmax) {
            for (int k = n - 1; k >= 0; k--) {
                double s = qb[k];
                for (int j = k + 1; j < n; j++) s -= R[k * n + j] * x[j];
                x[k] = s / R[k * n + k];
            }
            return;
        }
    }
    double *V = work, *s = V + (size_t)n * n;
    jacobi_svd(A, m, n, V, s);
    double smax = 0.0;
    for (int j = 0; j < n; j++) if (s[j] > smax) smax = s[j];
    double cut = DBL_EPSILON * (m > n ? m : n) * smax;
    for (int k = 0; k < n; k++) x[k] = 0.0;
    for (int j = 0; j < n; j++) {
        if (!(s[j] > cut)) continue;
        double c = 0.0;  /* (A V)_j . b / s_j^2 */
        for (int r = 0; r < m; r++) c += A[r * n + j] * b[r];
        c /= s[j] * s[j];
        for (int k = 0; k < n; k++) x[k] += V[k * n + j] * c;
    }
}

/* lstsq for tests (tests/test_compiled_newton.py): A (m x n, destroyed), work of mechsys_newton_work(m, n, 0, 0, 0) */
void mechsys_lstsq(double *A, int m, int n, const double *b, double *x, double *work) {
    lstsq(A, m, n, b, x, work);
}

/* Returns 1 when the iteration ended (converged or max_iter: polish next), 0 when it failed; z in place.
 * work: at least 8 (size + nz) + 3 size nz + 2 nz^2 + nargs + full_size + 1 + out doubles (mechsys_newton_work). */
int mechsys_newton_work(int size, int nz, int nargs, int full_size, int out_size) {
    return 8 * (size + nz) + 3 * size * nz + 2 * nz * nz + 2 * (size + nz) + nargs + full_size + 1 + out_size + 16;
}

int mechsys_deflated_newton(program_fn values, program_fn full, int nargs, const double *base, const long *pos,
                            int nz, int size, int full_size, int out_size, const long *jindex, const double *jsign,
                            const double *known, int nknown, const unsigned char *is_angle, int max_iter,
                            double *z, double *work) {
    problem_t P = {values, full, nargs, nz, size, full_size, nknown, base, pos, jindex, jsign, known, is_angle,
                   NULL, NULL, NULL};
    double *w = work;
    double *F = w; w += size;
    double *G = w; w += size;
    double *J = w; w += (size_t)size * nz;
    double *JG = w; w += (size_t)size * nz;
    double *grad = w; w += nz;
    double *d = w; w += nz;
    double *step = w; w += nz;
    double *trial = w; w += nz;
    double *Ft = w; w += size;
    double *rhs = w; w += size;
    double *lwork = w; w += (size_t)size * nz + 2 * (size + nz) + 2 * (size_t)nz * nz;
    P.args = w; w += nargs;
    P.raw = w; w += full_size + 1;
    P.out = w; w += out_size;
    int stalls = 0;
    for (int it = 0; it < max_iter; it++) {
        int finite = residual(&P, z, F);
        jacobian(&P, J);
        if (!finite) return 0;
        double mu = deflation(&P, z, d, grad);
        for (int i = 0; i < size; i++) {
            G[i] = mu * F[i];
            rhs[i] = -G[i];
            for (int k = 0; k < nz; k++) JG[i * nz + k] = mu * J[i * nz + k] + F[i] * (mu * grad[k]);
        }
        for (int i = 0; i < size; i++) {
            if (!isfinite(G[i])) return 0;
            for (int k = 0; k < nz; k++) if (!isfinite(JG[i * nz + k])) return 0;
        }
        lstsq(JG, size, nz, rhs, step, lwork);
        double scale = 1.0, g0 = norm2(G, size);
        while (scale > 1e-4) {
            for (int k = 0; k < nz; k++) trial[k] = z[k] + scale * step[k];
            double g1 = INFINITY;
            if (residual(&P, trial, Ft)) {
                double m = nknown ? deflation(&P, trial, d, NULL) : 1.0;
                for (int i = 0; i < size; i++) Ft[i] *= m;
                g1 = norm2(Ft, size);
            }
            if (isfinite(g1) && g1 <= (1.0 - 1e-4 * scale) * g0 + 1e-300) break;
            scale *= 0.5;
        }
        stalls = scale < 1e-2 ? stalls + 1 : 0;
        if (stalls >= 4) return 0;
        double smax = 0.0, zmax = 0.0;
        for (int k = 0; k < nz; k++) {
            z[k] += scale * step[k];
            if (!isfinite(z[k])) return 0;  /* the next G, or the polish, would reject it */
            if (fabs(scale * step[k]) > smax) smax = fabs(scale * step[k]);
            if (fabs(z[k]) > zmax) zmax = fabs(z[k]);
        }
        if (smax < 1e-12 * (1.0 + zmax)) break;
    }
    return 1;
}
