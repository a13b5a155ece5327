/* mechsys native integrator: the model's staged Kane terms (generated above this template), mass-matrix
 * assembly and an LU solve, and an explicit Runge-Kutta 8(5,3) of Dormand and Prince (DOP853) with dense
 * output.  Step-size control, initial step and dense output follow scipy.integrate's DOP853 line by line, so
 * the compiled loop takes the same steps as `--method DOP853` (to rounding).
 *
 * The generated part defines: N (coordinates), NOUT (number of staged terms), NB (bodies), LAYOUT[2*NB]
 * (has mass, has inertia per body), pieces(t, q, u, p, out), NCON (constraint rows) and
 * constraint_rows(t, q, u, p, out) writing A (NCON x N, row-major) then b, and the DOP853 tables. */

#define NY (2 * N)
#define NSTAGES 12
#define NEXT 16
#define NDENSE 7
#define SAFETY 0.9
#define MIN_FACTOR 0.2
#define MAX_FACTOR 10.0

enum { OK = 0, STEP_TOO_SMALL = -1, SINGULAR = -2, NOT_FINITE = -3, PAST_END = -4, TOO_MANY_STEPS = -5 };

typedef struct {
    double t, t_old, t_bound, h_abs, h_prev, rtol, atol, max_steps;
    double y[NY], y_old[NY], f[NY];
    double K[NEXT][NY];
    double F[NDENSE][NY];
    int dense_ready, has_step;
    long nfev, nsteps, nrejected;
} state_t;

int mechsys_state_bytes(void) { return (int)sizeof(state_t); }
int mechsys_size(void) { return N; }
int mechsys_parameters(void) { return NPAR; }

/* Solve A x = b in place (A row-major n x n) by LU with partial pivoting; SINGULAR for a zero pivot. */
static int solve(double *A, double *b, int n) {
    for (int k = 0; k < n; k++) {
        int piv = k;
        double best = fabs(A[k * n + k]);
        for (int i = k + 1; i < n; i++)
            if (fabs(A[i * n + k]) > best) { best = fabs(A[i * n + k]); piv = i; }
        if (!(best > 0.0)) return SINGULAR;
        if (piv != k) {
            for (int j = 0; j < n; j++) { double s = A[k * n + j]; A[k * n + j] = A[piv * n + j]; A[piv * n + j] = s; }
            double s = b[k]; b[k] = b[piv]; b[piv] = s;
        }
        for (int i = k + 1; i < n; i++) {
            double l = A[i * n + k] / A[k * n + k];
            if (l == 0.0) continue;
            for (int j = k + 1; j < n; j++) A[i * n + j] -= l * A[k * n + j];
            b[i] -= l * b[k];
        }
    }
    for (int i = n - 1; i >= 0; i--) {
        double s = b[i];
        for (int j = i + 1; j < n; j++) s -= A[i * n + j] * b[j];
        b[i] = s / A[i * n + i];
    }
    return OK;
}

/* q'' from M q'' = f, assembled from the staged terms exactly as numeric/kane.py's CompiledEquations does. */
static int accelerations(double t, const double *y, const double *p, double *a) {
    double out[NOUT];
    double M[N * N], IJ[3 * N];
#if NCON > 0
    double rows[NCON * N + NCON], K[(N + NCON) * (N + NCON)], x[N + NCON];
#endif
    const double *q = y, *u = y + N;
    pieces(t, q, u, p, out);
    for (int i = 0; i < N; i++) a[i] = out[i];
    memset(M, 0, sizeof M);
    int k = N;
    for (int b = 0; b < NB; b++) {
        if (LAYOUT[2 * b]) {
            const double *Jv = out + k, m = out[k + 3 * N], *g = out + k + 3 * N + 1;
            for (int i = 0; i < N; i++) {
                for (int j = 0; j < N; j++)
                    M[i * N + j] += m * (Jv[i] * Jv[j] + Jv[N + i] * Jv[N + j] + Jv[2 * N + i] * Jv[2 * N + j]);
                a[i] += Jv[i] * g[0] + Jv[N + i] * g[1] + Jv[2 * N + i] * g[2];
            }
            k += 3 * N + 4;
        }
        if (LAYOUT[2 * b + 1]) {
            const double *Jw = out + k, *I = out + k + 3 * N, *al = I + 9, *w = I + 12;
            for (int r = 0; r < 3; r++)
                for (int j = 0; j < N; j++)
                    IJ[r * N + j] = I[3 * r] * Jw[j] + I[3 * r + 1] * Jw[N + j] + I[3 * r + 2] * Jw[2 * N + j];
            double Iw[3], h[3];
            for (int r = 0; r < 3; r++) Iw[r] = I[3 * r] * w[0] + I[3 * r + 1] * w[1] + I[3 * r + 2] * w[2];
            for (int r = 0; r < 3; r++) h[r] = I[3 * r] * al[0] + I[3 * r + 1] * al[1] + I[3 * r + 2] * al[2];
            h[0] += w[1] * Iw[2] - w[2] * Iw[1];
            h[1] += w[2] * Iw[0] - w[0] * Iw[2];
            h[2] += w[0] * Iw[1] - w[1] * Iw[0];
            for (int i = 0; i < N; i++) {
                for (int j = 0; j < N; j++)
                    M[i * N + j] += Jw[i] * IJ[j] + Jw[N + i] * IJ[N + j] + Jw[2 * N + i] * IJ[2 * N + j];
                a[i] -= Jw[i] * h[0] + Jw[N + i] * h[1] + Jw[2 * N + i] * h[2];
            }
            k += 3 * N + 15;
        }
    }
#if NCON > 0
    /* closed loops, rolling, drives: [[M, A^T], [A, 0]] [q''; -lambda] = [f; b] */
    constraint_rows(t, q, u, p, rows);
    const int S = N + NCON;
    memset(K, 0, sizeof K);
    for (int i = 0; i < N; i++) {
        for (int j = 0; j < N; j++) K[i * S + j] = M[i * N + j];
        x[i] = a[i];
    }
    for (int r = 0; r < NCON; r++) {
        for (int j = 0; j < N; j++) { K[(N + r) * S + j] = rows[r * N + j]; K[j * S + N + r] = rows[r * N + j]; }
        x[N + r] = rows[NCON * N + r];
    }
    int status = solve(K, x, S);
    for (int i = 0; i < N; i++) a[i] = x[i];
    return status;
#else
    return solve(M, a, N);
#endif
}

static int rhs(state_t *s, double t, const double *y, const double *p, double *dy) {
    s->nfev++;
    for (int i = 0; i < N; i++) dy[i] = y[N + i];
    int status = accelerations(t, y, p, dy + N);
    if (status != OK) return status;
    for (int i = 0; i < NY; i++)
        if (!isfinite(dy[i])) return NOT_FINITE;
    return OK;
}

/* q'' at one state (inverse checks and the energy columns use the Python path; this exports the same map). */
int mechsys_accelerations(double t, const double *y, const double *p, double *a) { return accelerations(t, y, p, a); }

static double rms(const double *x, const double *scale, int n) {
    double s = 0.0;
    for (int i = 0; i < n; i++) { double v = x[i] / scale[i]; s += v * v; }
    return sqrt(s / n);
}

/* scipy.integrate._ivp.common.select_initial_step with order 7 and no maximum step. */
static int initial_step(state_t *s, const double *p, double *h_out) {
    double scale[NY], y1[NY], f1[NY], diff[NY];
    double interval = fabs(s->t_bound - s->t);
    if (interval == 0.0) { *h_out = 0.0; return OK; }
    for (int i = 0; i < NY; i++) scale[i] = s->atol + fabs(s->y[i]) * s->rtol;
    double d0 = rms(s->y, scale, NY), d1 = rms(s->f, scale, NY), h0;
    h0 = (d0 < 1e-5 || d1 < 1e-5) ? 1e-6 : 0.01 * d0 / d1;
    if (h0 > interval) h0 = interval;
    for (int i = 0; i < NY; i++) y1[i] = s->y[i] + h0 * s->f[i];
    int status = rhs(s, s->t + h0, y1, p, f1);
    if (status != OK) return status;
    for (int i = 0; i < NY; i++) diff[i] = f1[i] - s->f[i];
    double d2 = rms(diff, scale, NY) / h0, h1;
    if (d1 <= 1e-15 && d2 <= 1e-15) h1 = fmax(1e-6, h0 * 1e-3);
    else h1 = pow(0.01 / fmax(d1, d2), 1.0 / 8.0);
    *h_out = fmin(fmin(100 * h0, h1), interval);
    return OK;
}

/* h0 > 0 continues with a known step size (closed loops restart at every output point after projection);
 * otherwise the initial step is selected as scipy does. */
int mechsys_start(state_t *s, double t0, double t_bound, const double *y0, const double *p, double rtol,
                  double atol, double max_steps, double h0) {
    memset(s, 0, sizeof *s);
    s->max_steps = max_steps;
    s->t = s->t_old = t0;
    s->t_bound = t_bound;
    s->rtol = rtol;
    s->atol = atol;
    memcpy(s->y, y0, sizeof s->y);
    int status = rhs(s, t0, s->y, p, s->f);
    if (status != OK) return status;
    if (h0 > 0.0) {
        s->h_abs = h0;
        return OK;
    }
    return initial_step(s, p, &s->h_abs);
}

/* One accepted step (scipy's RungeKutta._step_impl with DOP853's error norm). */
static int step(state_t *s, const double *p) {
    double t = s->t, y_new[NY], f_new[NY], scale[NY], tmp[NY];
    double min_step = 10 * fabs(nextafter(t, INFINITY) - t);
    double h_abs = s->h_abs < min_step ? min_step : s->h_abs, h = 0.0, t_new = t;
    int accepted = 0, rejected = 0;
    while (!accepted) {
        if (h_abs < min_step) return STEP_TOO_SMALL;
        if ((double)(s->nsteps + s->nrejected) >= s->max_steps) return TOO_MANY_STEPS;
        h = h_abs;
        t_new = t + h;
        if (t_new > s->t_bound) t_new = s->t_bound;
        h = t_new - t;
        h_abs = fabs(h);
        memcpy(s->K[0], s->f, sizeof s->f);
        for (int st = 1; st < NSTAGES; st++) {
            for (int i = 0; i < NY; i++) {
                double acc = 0.0;
                for (int j = 0; j < st; j++) acc += s->K[j][i] * A[st][j];
                tmp[i] = s->y[i] + acc * h;
            }
            int status = rhs(s, t + C[st] * h, tmp, p, s->K[st]);
            if (status != OK) return status;
        }
        for (int i = 0; i < NY; i++) {
            double acc = 0.0;
            for (int j = 0; j < NSTAGES; j++) acc += s->K[j][i] * B[j];
            y_new[i] = s->y[i] + h * acc;
        }
        int status = rhs(s, t + h, y_new, p, f_new);
        if (status != OK) return status;
        memcpy(s->K[NSTAGES], f_new, sizeof f_new);
        double e5 = 0.0, e3 = 0.0;
        for (int i = 0; i < NY; i++) {
            scale[i] = s->atol + fmax(fabs(s->y[i]), fabs(y_new[i])) * s->rtol;
            double a5 = 0.0, a3 = 0.0;
            for (int j = 0; j <= NSTAGES; j++) { a5 += s->K[j][i] * E5[j]; a3 += s->K[j][i] * E3[j]; }
            a5 /= scale[i];
            a3 /= scale[i];
            e5 += a5 * a5;
            e3 += a3 * a3;
        }
        double err;
        if (e5 == 0.0 && e3 == 0.0) err = 0.0;
        else err = fabs(h) * e5 / sqrt((e5 + 0.01 * e3) * NY);
        if (!isfinite(err)) return NOT_FINITE;
        if (err < 1) {
            double factor = err == 0.0 ? MAX_FACTOR : fmin(MAX_FACTOR, SAFETY * pow(err, -1.0 / 8.0));
            if (rejected) factor = fmin(1.0, factor);
            h_abs *= factor;
            accepted = 1;
        } else {
            h_abs *= fmax(MIN_FACTOR, SAFETY * pow(err, -1.0 / 8.0));
            rejected = 1;
            s->nrejected++;
        }
    }
    s->h_prev = h;
    memcpy(s->y_old, s->y, sizeof s->y);
    s->t_old = t;
    s->t = t_new;
    memcpy(s->y, y_new, sizeof y_new);
    memcpy(s->f, f_new, sizeof f_new);
    s->h_abs = h_abs;
    s->dense_ready = 0;
    s->has_step = 1;
    s->nsteps++;
    return OK;
}

/* The 7 interpolation coefficient rows of the last step (3 extra stages), as scipy's DOP853._dense_output_impl. */
static int dense(state_t *s, const double *p) {
    double h = s->h_prev, tmp[NY];
    for (int st = NSTAGES + 1; st < NEXT; st++) {
        for (int i = 0; i < NY; i++) {
            double acc = 0.0;
            for (int j = 0; j < st; j++) acc += s->K[j][i] * A[st][j];
            tmp[i] = s->y_old[i] + acc * h;
        }
        int status = rhs(s, s->t_old + C[st] * h, tmp, p, s->K[st]);
        if (status != OK) return status;
    }
    for (int i = 0; i < NY; i++) {
        double delta = s->y[i] - s->y_old[i], f_old = s->K[0][i];
        s->F[0][i] = delta;
        s->F[1][i] = h * f_old - delta;
        s->F[2][i] = 2 * delta - h * (s->f[i] + f_old);
        for (int r = 0; r < 4; r++) {
            double acc = 0.0;
            for (int j = 0; j < NEXT; j++) acc += D[r][j] * s->K[j][i];
            s->F[3 + r][i] = h * acc;
        }
    }
    s->dense_ready = 1;
    return OK;
}

static void interpolate(const state_t *s, double t, double *out) {
    double x = (t - s->t_old) / s->h_prev;
    for (int i = 0; i < NY; i++) {
        double v = 0.0;
        for (int k = NDENSE - 1, m = 0; k >= 0; k--, m++) {
            v += s->F[k][i];
            v *= (m % 2 == 0) ? x : 1.0 - x;
        }
        out[i] = v + s->y_old[i];
    }
}

/* Advance until every requested output time (ascending, within [t, t_bound]) is written to y_out (row-major,
 * n_out x NY). Returns OK or a failure status; *done counts the outputs written. */
int mechsys_advance(state_t *s, const double *p, int n_out, const double *t_out, double *y_out, int *done) {
    int k = 0;
    *done = 0;
    while (k < n_out) {
        double tk = t_out[k];
        if (tk > s->t_bound) return PAST_END;
        if (!s->has_step && tk == s->t) {  /* the initial state itself */
            memcpy(y_out + (long)k * NY, s->y, sizeof s->y);
            *done = ++k;
            continue;
        }
        if (s->has_step && tk == s->t) {  /* the step ends on the output time: no interpolation needed */
            memcpy(y_out + (long)k * NY, s->y, sizeof s->y);
            *done = ++k;
            continue;
        }
        if (s->has_step && tk >= s->t_old && tk <= s->t) {
            if (!s->dense_ready) {
                int status = dense(s, p);
                if (status != OK) return status;
            }
            interpolate(s, tk, y_out + (long)k * NY);
            *done = ++k;
            continue;
        }
        if (s->t >= s->t_bound) return PAST_END;
        int status = step(s, p);
        if (status != OK) return status;
    }
    return OK;
}

void mechsys_counters(const state_t *s, double *out) {
    out[0] = (double)s->nfev;
    out[1] = (double)s->nsteps;
    out[2] = (double)s->nrejected;
    out[3] = s->t;
    out[4] = s->h_abs;
}
