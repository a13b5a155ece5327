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

/* ---------------------------------------------------------------------------------------------------------------
 * The continuation's corrector. A sweep's unknowns x (the problem's, divided by D) and the parameter p:
 * args = base + (p - p_ref) slope, args[pos[k]] = D[k] (z[k] s[k]). F is the rows `rows` of the program's first
 * outputs; dF/dx gathered as in the Newton above, times D and s; dF/dp = dE/d(q, u) . slope (the given rates that
 * follow p) plus, when E reads a parameter that follows p, the central difference of E along the parameters'
 * slope with the step of NonholonomicProblem.Fp_along.
 */
typedef struct {
    program_fn values, full;
    int nargs, nz, size, full_size, out_size, n, jac_offset, pfirst, fp_params;
    double p_ref, tol;
    const double *base, *slope;   /* nargs */
    const long *pos;              /* nz */
    const double *D, *s;          /* nz */
    const double *r;              /* nz + 1: z -> tolerance units */
    const long *rows;             /* nz */
    const long *jindex;           /* size x nz */
    const double *jsign;          /* size x nz */
} corrector_t;

typedef struct {
    double *args, *args2, *out, *out2, *raw, *fp;
} cwork_t;

static void corrector_args(const corrector_t *C, const double *z, double *args) {
    double dp = z[C->nz] - C->p_ref;
    for (int j = 0; j < C->nargs; j++) args[j] = C->slope[j] != 0.0 ? C->base[j] + dp * C->slope[j] : C->base[j];
    for (int k = 0; k < C->nz; k++) args[C->pos[k]] = C->D[k] * (z[k] * C->s[k]);
}

/* F(z) (nz) into f; 0 when not finite. Leaves the arguments in W->args. */
static int corrector_residual(const corrector_t *C, cwork_t *W, const double *z, double *f) {
    corrector_args(C, z, W->args);
    C->values(W->args, W->out);
    int ok = 1;
    for (int i = 0; i < C->nz; i++) {
        f[i] = W->out[C->rows[i]];
        if (!isfinite(f[i])) ok = 0;
    }
    return ok;
}

/* [dF/dx s | dF/dp] (nz x (nz + 1), row major) at the arguments in W->args; 0 when not finite */
static int corrector_jacobian(const corrector_t *C, cwork_t *W, double *A) {
    int nz = C->nz, n = C->n;
    C->full(W->args, W->raw);
    W->raw[C->full_size] = 0.0;
    for (int i = 0; i < C->size; i++) W->fp[i] = 0.0;
    if (C->fp_params) {
        double pn = 0.0, dn = 0.0;
        for (int j = C->pfirst; j < C->nargs; j++) {
            pn += W->args[j] * W->args[j];
            dn += C->slope[j] * C->slope[j];
        }
        double h = 1e-6 * (sqrt(pn) > 1.0 ? sqrt(pn) : 1.0) / sqrt(dn);
        memcpy(W->args2, W->args, sizeof(double) * C->nargs);
        for (int j = C->pfirst; j < C->nargs; j++) W->args2[j] = W->args[j] + h * C->slope[j];
        C->values(W->args2, W->out);
        for (int j = C->pfirst; j < C->nargs; j++) W->args2[j] = W->args[j] - h * C->slope[j];
        C->values(W->args2, W->out2);
        for (int i = 0; i < C->size; i++) W->fp[i] = (W->out[i] - W->out2[i]) / (2.0 * h);
    }
    for (int j = 0; j < 2 * n; j++) {
        if (C->slope[j] == 0.0) continue;
        for (int i = 0; i < C->size; i++) W->fp[i] += W->raw[C->jac_offset + (size_t)i * 2 * n + j] * C->slope[j];
    }
    int ok = 1;
    for (int i = 0; i < nz; i++) {
        long row = C->rows[i];
        for (int k = 0; k < nz; k++) {
            long at = row * nz + k;
            double v = W->raw[C->jindex[at]] * C->jsign[at] * C->D[k] * C->s[k];
            A[i * (nz + 1) + k] = v;
            if (!isfinite(v)) ok = 0;
        }
        A[i * (nz + 1) + nz] = W->fp[row];
        if (!isfinite(W->fp[row])) ok = 0;
    }
    return ok;
}

/* LU with partial pivoting of A (n x n, in place, row swaps in piv); 0 when a pivot is exactly 0 (where
 * numpy.linalg.solve raises) */
static int lu_factor(double *A, int n, int *piv) {
    for (int k = 0; k < n; k++) {
        int p = k;
        double big = fabs(A[k * n + k]);
        for (int i = k + 1; i < n; i++) {
            if (fabs(A[i * n + k]) > big) { big = fabs(A[i * n + k]); p = i; }
        }
        piv[k] = p;
        if (big == 0.0) return 0;
        if (p != k) {
            for (int j = 0; j < n; j++) { double t = A[k * n + j]; A[k * n + j] = A[p * n + j]; A[p * n + j] = t; }
        }
        for (int i = k + 1; i < n; i++) {
            double f = A[i * n + k] /= A[k * n + k];
            if (f == 0.0) continue;
            for (int j = k + 1; j < n; j++) A[i * n + j] -= f * A[k * n + j];
        }
    }
    return 1;
}

/* B (n x nrhs, row major) := A^-1 B from lu_factor's A and piv */
static void lu_apply(const double *LU, int n, const int *piv, double *B, int nrhs) {
    for (int k = 0; k < n; k++) {  /* the row swaps of the whole factorization first: P B */
        if (piv[k] != k) {
            for (int j = 0; j < nrhs; j++) {
                double t = B[k * nrhs + j]; B[k * nrhs + j] = B[piv[k] * nrhs + j]; B[piv[k] * nrhs + j] = t;
            }
        }
    }
    for (int k = 0; k < n; k++) {
        for (int i = k + 1; i < n; i++) {
            double f = LU[i * n + k];
            if (f != 0.0) for (int j = 0; j < nrhs; j++) B[i * nrhs + j] -= f * B[k * nrhs + j];
        }
    }
    for (int k = n - 1; k >= 0; k--) {
        for (int j = 0; j < nrhs; j++) {
            double t = B[k * nrhs + j];
            for (int i = k + 1; i < n; i++) t -= LU[k * n + i] * B[i * nrhs + j];
            B[k * nrhs + j] = t / LU[k * n + k];
        }
    }
}

/* x of the square system A x = b (A n x n, destroyed); 0 when a pivot is exactly 0 */
static int lu_solve(double *A, int n, const double *b, double *x, int *piv) {
    if (!lu_factor(A, n, piv)) return 0;
    for (int i = 0; i < n; i++) x[i] = b[i];
    lu_apply(A, n, piv, x, 1);
    return 1;
}

int mechsys_corrector_work(int nz, int nargs, int full_size, int out_size, int size) {
    int m = nz + 1;
    return 2 * nargs + 2 * out_size + full_size + 1 + size + 4 * m * m + 7 * m + 16;
}

/* Newton on [F(z); border . (z - z_guess)] = 0 from z_guess (in z, nz + 1), as _Tracer.newton: the step from
 * the square bordered system (LU; numpy's minimum-norm least squares where LU meets a zero pivot or gives a
 * non-finite step), convergence when max |dz r| <= tol (1 + max |z r|) and the residual then passes the test
 * max |F| <= 1e3 tol (1 + max |A / r| (1 + max |z r|)); failure on a non-finite F, Jacobian or step, on
 * max_iter, and (monotone) on a step more than twice the previous one. Returns 1 with z, the iterations in
 * *iters and the Jacobian [dF/dx s | dF/dp] at z in jac (nz x (nz + 1)); 0 on failure. */
int mechsys_corrector(const corrector_t *C, double *z, const double *border, int max_iter, int monotone,
                      double *jac, int *iters, double *work) {
    int nz = C->nz, m = nz + 1;
    cwork_t W;
    double *w = work;
    W.args = w; w += C->nargs;
    W.args2 = w; w += C->nargs;
    W.out = w; w += C->out_size;
    W.out2 = w; w += C->out_size;
    W.raw = w; w += C->full_size + 1;
    W.fp = w; w += C->size;
    double *A = w; w += (size_t)m * m;
    double *B = w; w += (size_t)m * m;
    double *lwork = w; w += 2 * (size_t)m * m + 2 * m;
    double *res = w; w += m;
    double *dz = w; w += m;
    double *guess = w; w += m;
    int *piv = (int *)w; w += m;  /* m ints in m doubles */
    memcpy(guess, z, sizeof(double) * m);
    double prev = INFINITY;
    for (int k = 1; k <= max_iter; k++) {
        if (!corrector_residual(C, &W, z, res)) return 0;
        if (!corrector_jacobian(C, &W, A)) return 0;
        double b = 0.0;
        for (int j = 0; j < m; j++) {
            A[nz * m + j] = border[j];
            b += border[j] * (z[j] - guess[j]);
        }
        res[nz] = b;
        for (int i = 0; i < m; i++) res[i] = -res[i];
        memcpy(B, A, sizeof(double) * m * m);
        int solved = lu_solve(B, m, res, dz, piv);
        for (int i = 0; solved && i < m; i++) if (!isfinite(dz[i])) solved = 0;
        if (!solved) {
            memcpy(B, A, sizeof(double) * m * m);
            lstsq(B, m, m, res, dz, lwork);
            for (int i = 0; i < m; i++) if (!isfinite(dz[i])) return 0;
        }
        double step = 0.0, zmax = 0.0;
        for (int j = 0; j < m; j++) {
            z[j] += dz[j];
            if (fabs(dz[j] * C->r[j]) > step) step = fabs(dz[j] * C->r[j]);
            if (fabs(z[j] * C->r[j]) > zmax) zmax = fabs(z[j] * C->r[j]);
        }
        zmax += 1.0;
        if (step <= C->tol * zmax) {
            /* a least-squares step on a singular Jacobian can be tiny without solving F = 0: check F */
            if (!corrector_residual(C, &W, z, res)) return 0;
            double rmax = 0.0, amax = 0.0;
            for (int i = 0; i < nz; i++) if (fabs(res[i]) > rmax) rmax = fabs(res[i]);
            for (int i = 0; i < nz; i++)
                for (int j = 0; j < m; j++) {
                    double a = fabs(A[i * m + j] / C->r[j]);
                    if (a > amax) amax = a;
                }
            if (!(rmax <= 1e3 * C->tol * (1.0 + amax * zmax))) return 0;
            *iters = k;
            /* the Jacobian at z (the arguments are in place): the tangent and det of the point read it next */
            if (jac != NULL && !corrector_jacobian(C, &W, jac)) {
                for (int i = 0; i < nz * m; i++) jac[i] = NAN;
            }
            return 1;
        }
        if (monotone && k >= 2 && step > 2.0 * prev) return 0;
        prev = step;
    }
    return 0;
}

/* ---------------------------------------------------------------------------------------------------------------
 * The linearization about a steady motion on the constraint manifold (analysis/equilibrium/nonholonomic.py,
 * linearize_steady and _deflate, the same steps) from a point's evaluated pieces `raw` (the program's full output
 * followed by a zero): E (size) at 0, M (n x n) at size, A (m x n) at size + n n, dE/d(q, u) (size x 2n) at jac.
 * Index lists are ints; every matrix is row major.
 */
typedef struct {
    int n, m, mh, size, jac, nI, nkeep, nxi, nign, nz, nfam, nt;
    int hfirst;           /* first row of the holonomic constraints in dE/dq (when mh) */
    double rtol;          /* the singular-value tests' (LINEARIZATION_RTOL) */
    const int *I, *D, *keep, *elim, *rows_q, *cols_all, *cols_ign;
    const long *jindex;   /* size x nz: dE/dz of the steady-motion unknowns, gathered from raw (times jsign) */
    const double *jsign;
    const long *rhs;      /* nfam x size: raw index of the family's column of dE/du (a rate) or dE/dq */
    const int *tsrc;      /* nt: the unknown (index into z) each entry of a family's direction reads, -1: 0 */
    const int *tone;      /* nfam: the entry set to 1 (along the given rate or coordinate itself), -1: none */
    const double *rinv;   /* size: 1 / each row's size, nz: each unknown's size (equation_scales; ones at */
    const double *zsize;  /* ordinary units): a family's direction solved in the rows' and unknowns' own sizes */
} lin_t;

/* The smallest singular value of the square block (rows first.., columns cols) of the matrix at raw + offset
 * (row stride `stride`), and in *scale the largest entry of those rows over their first `width` columns */
static double smallest_singular(const double *raw, int offset, int stride, int width, int first, int nrows,
                                const int *cols, double *scale, double *work) {
    double big = 0.0;
    for (int r = 0; r < nrows; r++)
        for (int j = 0; j < width; j++) {
            double a = fabs(raw[offset + (size_t)(first + r) * stride + j]);
            if (a > big) big = a;
        }
    *scale = big;
    if (nrows == 1) return fabs(raw[offset + (size_t)first * stride + cols[0]]);
    double *B = work, *V = B + nrows * nrows, *sv = V + nrows * nrows;
    for (int r = 0; r < nrows; r++)
        for (int c = 0; c < nrows; c++) B[r * nrows + c] = raw[offset + (size_t)(first + r) * stride + cols[c]];
    jacobi_svd(B, nrows, nrows, V, sv);
    double lo = INFINITY;
    for (int c = 0; c < nrows; c++) if (sv[c] < lo) lo = sv[c];
    return lo;
}

int mechsys_linearize_work(int n, int m, int size, int nz, int nt) {
    int N = n + m, big = N > nz ? N : nz;
    if (size > big) big = size;
    return 4 * N * N + 2 * N * 2 * n + 8 * n * n + 4 * size * nz + 2 * size + 6 * nt * nt + 6 * nt + 6 * big * big + 64;
}

/* Returns 0 with Jw (nt x nt, nt = nxi + nI), Mr (nI x nI), Kf (nI x nxi), Cf (nI x nI), the deflated block
 * (nt - k square, k families deflated) and deflated[f] per family; 1 + b when singular-value test b failed (b: 0
 * the holonomic block, 1 the velocity constraints'), 10 when a solve meets a zero pivot, 11 when the reduced
 * equations depend on an ignorable coordinate, 12 when a number is not finite. *k_out: the families deflated. */
int mechsys_linearize(const lin_t *L, const double *raw, double *Jw, double *Mr, double *Kf, double *Cf,
                      double *deflated, int *fam_deflated, int *k_out, double *work) {
    int n = L->n, m = L->m, mh = L->mh, N = n + m, nI = L->nI, nk = L->nkeep, nxi = L->nxi, nt = L->nt;
    const double *M = raw + L->size, *A = raw + L->size + n * n;
    for (int i = 0; i < L->jac + L->size * 2 * n; i++) if (!isfinite(raw[i])) return 12;
    double *w = work;
    int *piv = (int *)w; w += N;
    /* the singular-value tests (NonholonomicProblem.singular_block), in its order */
    for (int b = 0; b < 2; b++) {
        if ((b == 0 && !mh) || (b == 1 && !m)) continue;
        double scale, lo;
        if (b == 0) lo = smallest_singular(raw, L->jac, 2 * n, n, L->hfirst, mh, L->elim, &scale, w);
        else lo = smallest_singular(raw, L->size + n * n, n, n, 0, m, L->D, &scale, w);
        if (scale < 1e-300) scale = 1e-300;
        if (!isfinite(lo) || lo <= L->rtol * scale) return 1 + b;
    }
    /* P = -K^-1 [Eq; Eu] rows 0..n+m (only the first n rows kept), K = [[M, -A^T], [A, 0]] */
    double *K = w; w += N * N;
    double *P = w; w += N * 2 * n;
    for (int i = 0; i < N * N; i++) K[i] = 0.0;
    for (int i = 0; i < n; i++) for (int j = 0; j < n; j++) K[i * N + j] = M[i * n + j];
    for (int i = 0; i < m; i++) {
        for (int j = 0; j < n; j++) {
            K[j * N + n + i] = -A[i * n + j];
            K[(n + i) * N + j] = A[i * n + j];
        }
    }
    for (int i = 0; i < N; i++) for (int j = 0; j < 2 * n; j++) P[i * 2 * n + j] = raw[L->jac + (size_t)i * 2 * n + j];
    if (!lu_factor(K, N, piv)) return 10;
    lu_apply(K, N, piv, P, 2 * n);
    for (int i = 0; i < n * 2 * n; i++) P[i] = -P[i];   /* Pq = P[:, :n], Pu = P[:, n:] (rows < n) */
    /* Uq (n x n), UI (n x nI): rates per coordinate and per independent speed */
    double *Uq = w; w += n * n;
    double *UI = w; w += n * nI;
    for (int i = 0; i < n * n; i++) Uq[i] = 0.0;
    for (int i = 0; i < n * nI; i++) UI[i] = 0.0;
    for (int c = 0; c < nI; c++) UI[L->I[c] * nI + c] = 1.0;
    if (m) {
        double *AD = w; w += m * m;
        double *W = w; w += m * (n + nI);
        for (int i = 0; i < m; i++) {
            for (int c = 0; c < m; c++) AD[i * m + c] = A[i * n + L->D[c]];
            for (int j = 0; j < n; j++) W[i * (n + nI) + j] = raw[L->jac + (size_t)(n + m + i) * 2 * n + j];
            for (int c = 0; c < nI; c++) W[i * (n + nI) + n + c] = A[i * n + L->I[c]];
        }
        if (!lu_factor(AD, m, piv)) return 10;
        lu_apply(AD, m, piv, W, n + nI);
        for (int i = 0; i < m; i++) {
            for (int j = 0; j < n; j++) Uq[L->D[i] * n + j] = -W[i * (n + nI) + j];
            for (int c = 0; c < nI; c++) UI[L->D[i] * nI + c] = -W[i * (n + nI) + n + c];
        }
    }
    /* Qm (n x nkeep): coordinates per kept coordinate, the eliminated ones from the holonomic constraints */
    double *Qm = w; w += n * nk;
    for (int i = 0; i < n * nk; i++) Qm[i] = 0.0;
    for (int c = 0; c < nk; c++) Qm[L->keep[c] * nk + c] = 1.0;
    if (mh) {
        double *Pe = w; w += mh * mh;
        double *Pk = w; w += mh * nk;
        int first = L->hfirst;
        for (int i = 0; i < mh; i++) {
            for (int c = 0; c < mh; c++) Pe[i * mh + c] = raw[L->jac + (size_t)(first + i) * 2 * n + L->elim[c]];
            for (int c = 0; c < nk; c++) Pk[i * nk + c] = raw[L->jac + (size_t)(first + i) * 2 * n + L->keep[c]];
        }
        if (!lu_factor(Pe, mh, piv)) return 10;
        lu_apply(Pe, mh, piv, Pk, nk);
        for (int i = 0; i < mh; i++) for (int c = 0; c < nk; c++) Qm[L->elim[i] * nk + c] = -Pk[i * nk + c];
    }
    /* dq_dxi = Uq Qm (n x nkeep); acc_q = (Pq Qm + Pu dq_dxi) (n x nkeep); PuUI = Pu UI (n x nI) */
    double *dq = w; w += n * nk;
    double *acc = w; w += n * nk;
    double *PuUI = w; w += n * nI;
    for (int i = 0; i < n; i++) for (int c = 0; c < nk; c++) {
        double t = 0.0;
        for (int j = 0; j < n; j++) t += Uq[i * n + j] * Qm[j * nk + c];
        dq[i * nk + c] = t;
    }
    for (int i = 0; i < n; i++) {
        for (int c = 0; c < nk; c++) {
            double t = 0.0, u = 0.0;
            for (int j = 0; j < n; j++) {
                t += P[i * 2 * n + j] * Qm[j * nk + c];
                u += P[i * 2 * n + n + j] * dq[j * nk + c];
            }
            acc[i * nk + c] = t + u;
        }
        for (int c = 0; c < nI; c++) {
            double t = 0.0;
            for (int j = 0; j < n; j++) t += P[i * 2 * n + n + j] * UI[j * nI + c];
            PuUI[i * nI + c] = t;
        }
    }
    /* Jw = [[dq_dxi[rows_q][:, cols_all], UI[rows_q]], [acc_q[I][:, cols_all], PuUI[I]]] */
    for (int r = 0; r < nxi; r++) {
        for (int c = 0; c < nxi; c++) Jw[r * nt + c] = dq[L->rows_q[r] * nk + L->cols_all[c]];
        for (int c = 0; c < nI; c++) Jw[r * nt + nxi + c] = UI[L->rows_q[r] * nI + c];
    }
    for (int r = 0; r < nI; r++) {
        for (int c = 0; c < nxi; c++) Jw[(nxi + r) * nt + c] = acc[L->I[r] * nk + L->cols_all[c]];
        for (int c = 0; c < nI; c++) Jw[(nxi + r) * nt + nxi + c] = PuUI[L->I[r] * nI + c];
    }
    double scale = 1.0;
    for (int i = 0; i < nt * nt; i++) { if (!isfinite(Jw[i])) return 12; if (fabs(Jw[i]) > scale) scale = fabs(Jw[i]); }
    /* the ignorable coordinates must not enter: their columns vanish (a check of the split) */
    for (int c = 0; c < L->nign; c++) {
        for (int r = 0; r < nxi; r++) if (fabs(dq[L->rows_q[r] * nk + L->cols_ign[c]]) > 1e-7 * scale) return 11;
        for (int r = 0; r < nI; r++) if (fabs(acc[L->I[r] * nk + L->cols_ign[c]]) > 1e-7 * scale) return 11;
    }
    /* Mr = UI^T M UI; Kf = -Mr Jw[nxi:, :nxi]; Cf = -Mr Jw[nxi:, nxi:] */
    double *MU = w; w += n * nI;
    for (int i = 0; i < n; i++) for (int c = 0; c < nI; c++) {
        double t = 0.0;
        for (int j = 0; j < n; j++) t += M[i * n + j] * UI[j * nI + c];
        MU[i * nI + c] = t;
    }
    for (int a = 0; a < nI; a++) for (int c = 0; c < nI; c++) {
        double t = 0.0;
        for (int i = 0; i < n; i++) t += UI[i * nI + a] * MU[i * nI + c];
        Mr[a * nI + c] = t;
    }
    for (int a = 0; a < nI; a++) for (int c = 0; c < nt; c++) {
        double t = 0.0;
        for (int b = 0; b < nI; b++) t += Mr[a * nI + b] * Jw[(nxi + b) * nt + c];
        if (c < nxi) Kf[a * nxi + c] = -t; else Cf[a * nI + c - nxi] = -t;
    }
    /* _deflate: the direction of each family from the steady-motion equations, J_z dz = -column */
    int nz = L->nz, k = 0;
    double *Jz = w; w += L->size * nz;
    double *Jc = w; w += L->size * nz;
    double *col = w; w += L->size;
    double *dz = w; w += nz > 0 ? nz : 1;
    double *T = w; w += nt * (L->nfam > 0 ? L->nfam : 1);
    double *t = w; w += nt;
    size_t wide = L->size > nz ? L->size : nz;
    double *lwork = w; w += 2 * wide * wide + 2 * (L->size + nz);
    for (int i = 0; i < L->size * nz; i++)
        Jz[i] = raw[L->jindex[i]] * L->jsign[i] * L->rinv[i / nz] * L->zsize[i % nz];
    for (int f = 0; f < L->nfam; f++) {
        for (int i = 0; i < L->size; i++) col[i] = -raw[L->rhs[f * L->size + i]] * L->rinv[i];
        if (nz) {
            memcpy(Jc, Jz, sizeof(double) * L->size * nz);
            lstsq(Jc, L->size, nz, col, dz, lwork);
            for (int j = 0; j < nz; j++) dz[j] *= L->zsize[j];
        }
        for (int e = 0; e < nt; e++) {
            int src = L->tsrc[e];
            t[e] = src >= 0 ? dz[src] : 0.0;
        }
        if (L->tone[f] >= 0) t[L->tone[f]] = 1.0;
        double jt = 0.0, tn = 0.0;
        for (int r = 0; r < nt; r++) {
            double s = 0.0;
            for (int c = 0; c < nt; c++) s += Jw[r * nt + c] * t[c];
            jt += s * s;
            tn += t[r] * t[r];
        }
        jt = sqrt(jt); tn = sqrt(tn);
        fam_deflated[f] = jt <= 1e-8 * scale * (tn > 1e-300 ? tn : 1e-300);
        if (fam_deflated[f]) {
            for (int e = 0; e < nt; e++) T[e * L->nfam + k] = t[e] / tn;  /* column k of T (nt x nfam) */
            k++;
        }
    }
    *k_out = k;
    /* C: the last nt - k columns of the Householder product that makes T upper triangular; deflated = C^T Jw C */
    double *Q = w; w += nt * nt;
    double *R = w; w += nt * (k > 0 ? k : 1);
    double *v = w; w += nt;
    double *JC = w; w += nt * nt;
    for (int i = 0; i < nt * nt; i++) Q[i] = 0.0;
    for (int i = 0; i < nt; i++) Q[i * nt + i] = 1.0;
    for (int i = 0; i < nt; i++) for (int c = 0; c < k; c++) R[i * k + c] = T[i * L->nfam + c];
    for (int j = 0; j < k; j++) {
        double nrm = 0.0;
        for (int i = j; i < nt; i++) nrm += R[i * k + j] * R[i * k + j];
        nrm = sqrt(nrm);
        for (int i = j; i < nt; i++) v[i] = R[i * k + j];
        v[j] += copysign(nrm, v[j]);
        double beta = 0.0;
        for (int i = j; i < nt; i++) beta += v[i] * v[i];
        if (beta == 0.0) continue;
        for (int c = j; c < k; c++) {
            double d = 0.0;
            for (int i = j; i < nt; i++) d += v[i] * R[i * k + c];
            d *= 2.0 / beta;
            for (int i = j; i < nt; i++) R[i * k + c] -= d * v[i];
        }
        for (int r = 0; r < nt; r++) {
            double d = 0.0;
            for (int i = j; i < nt; i++) d += Q[r * nt + i] * v[i];
            d *= 2.0 / beta;
            for (int i = j; i < nt; i++) Q[r * nt + i] -= d * v[i];
        }
    }
    int nd = nt - k;
    for (int r = 0; r < nt; r++) for (int c = 0; c < nd; c++) {
        double s = 0.0;
        for (int i = 0; i < nt; i++) s += Jw[r * nt + i] * Q[i * nt + k + c];
        JC[r * nd + c] = s;
    }
    for (int a = 0; a < nd; a++) for (int c = 0; c < nd; c++) {
        double s = 0.0;
        for (int r = 0; r < nt; r++) s += Q[r * nt + k + a] * JC[r * nd + c];
        deflated[a * nd + c] = s;
    }
    return 0;
}
