/* FMI 2.0 Model Exchange interface of a mechsys model (template of `mechsys codegen --target fmu`).

   The equations are the C target's functions (<model>.c, <model>.h); "fmu_model.h", written for each model,
   names them (msfmu_accelerations, msfmu_outputs, ...) and lists the variables. Value references:

       0 .. NPAR-1                          parameters (file order; calculated ones are computed from the others)
       NPAR .. NPAR+NSTATE-1                continuous states x = [q; u] (coordinates, then their rates)
       NPAR+NSTATE .. NPAR+2 NSTATE-1       their derivatives der(x) = [u; q'']
       NPAR+2 NSTATE .. NPAR+2 NSTATE+NOUT-1  outputs (energies, the constraint residual, the file's outputs)

   With constraint rows (closed loops, nonholonomic models) the states are all coordinates and rates, and q''
   solves [[M, -A^T], [A, 0]] [q''; lam] = [f; b] (the constraints differentiated to acceleration level: an
   index-1 ODE, no Baumgarte terms). Integration drifts off the position and velocity constraints; after every
   completed integrator step whose residual exceeds MSFMU_DRIFT x (1 + max |x|) the FMU asks for an event, and in
   fmi2NewDiscreteStates it projects the state back (Gauss-Newton on the holonomic rows Phi(q, t) = 0 with
   minimum-norm steps, then the minimum-norm change of u that satisfies A u + a_t = 0), as `mechsys simulate`
   does between output times. The initial state is assembled the same way at fmi2ExitInitializationMode.
   The model has no event indicators. */
#include <float.h>
#include <math.h>
#include <stdarg.h>
#include <stddef.h>
#include <stdio.h>
#include <string.h>

#include "fmu_model.h"  /* first: the FMI headers' macros (fmi2True, ...) may be model names */
#include "fmi2Functions.h"

#define MSFMU_VR_STATE MSFMU_NPAR
#define MSFMU_VR_DERIVATIVE (MSFMU_NPAR + MSFMU_NSTATE)
#define MSFMU_VR_OUTPUT (MSFMU_NPAR + 2 * MSFMU_NSTATE)
#define MSFMU_NVR (MSFMU_VR_OUTPUT + MSFMU_NOUT)
#define MSFMU_SIZE(n) ((n) > 0 ? (n) : 1)

#define MSFMU_DRIFT 1e-12          /* a larger constraint residual after a step asks for a projection */
#define MSFMU_CONVERGED 1e-14      /* Gauss-Newton stops below this residual of Phi (relative, as mechsys) */
#define MSFMU_TOLERANCE 1e-6       /* a projected state must satisfy the constraints to this (relative) */
#define MSFMU_ITERATIONS 20
#define MSFMU_CONTRACTION 0.25    /* a carry step's Newton contracts at once (mechsys: CONTRACTION) */
#define MSFMU_CORRECTION 0.2      /* and corrects at most this of the tangent's move (mechsys: CORRECTION) */
#define MSFMU_ANGLE_STEP 0.25     /* and turns no angle by more [rad] (mechsys: ANGLE_STEP) */

enum {
    MSFMU_INSTANTIATED = 1, MSFMU_INITIALIZATION = 2, MSFMU_EVENT = 4, MSFMU_CONTINUOUS = 8,
    MSFMU_TERMINATED = 16, MSFMU_ERROR = 32
};
#define MSFMU_ANY (MSFMU_INSTANTIATED | MSFMU_INITIALIZATION | MSFMU_EVENT | MSFMU_CONTINUOUS | \
                   MSFMU_TERMINATED | MSFMU_ERROR)
#define MSFMU_SOLVED (MSFMU_INITIALIZATION | MSFMU_EVENT | MSFMU_CONTINUOUS | MSFMU_TERMINATED | MSFMU_ERROR)

typedef struct {
    fmi2CallbackFunctions functions;
    char *name;
    int mode;
    int logging;
    double time;
    msfmu_parameters p;              /* every parameter; calculated ones follow the others */
    double start[MSFMU_NSTATE];      /* start values of the states that have one */
    int set[MSFMU_NSTATE];           /* start values set by fmi2SetReal */
    int held[MSFMU_NSTATE];          /* those and the ones --set gave at export: the assembly holds them */
    double x[MSFMU_NSTATE];          /* the continuous states */
    int initial_ready;               /* before initialization ends: x derived from start and p */
    double a[MSFMU_NCOORD];          /* q'' at (time, x, p) when valid */
    double out[MSFMU_NOUT];          /* outputs at (time, x, p) when valid */
    int valid;
} msfmu_instance;

/* ----------------------------------------------------------------------------------------- logging */
static void msfmu_log(const msfmu_instance *c, fmi2Status status, const char *category, const char *format, ...) {
    char text[1024], escaped[2048];
    va_list args;
    size_t j = 0;
    if (c == NULL || c->functions.logger == NULL || (status == fmi2OK && !c->logging)) return;
    va_start(args, format);
    vsnprintf(text, sizeof text, format, args);
    va_end(args);
    for (size_t i = 0; text[i] != '\0' && j + 2 < sizeof escaped; i++) {  /* the logger reads a format */
        if (text[i] == '%') escaped[j++] = '%';
        escaped[j++] = text[i];
    }
    escaped[j] = '\0';
    c->functions.logger(c->functions.componentEnvironment, c->name, status, category, escaped);
}

static fmi2Status msfmu_error(const msfmu_instance *c, const char *format, const char *function) {
    msfmu_log(c, fmi2Error, "logStatusError", format, function);
    return fmi2Error;
}

/* fmi2OK if `function` may be called in the current mode, else fmi2Error with a message */
static fmi2Status msfmu_allowed(const msfmu_instance *c, const char *function, int modes) {
    if (c == NULL) return fmi2Error;
    if (c->mode & modes) return fmi2OK;
    return msfmu_error(c, "%s is not allowed in the current mode of the FMU (FMI 2.0 state machine)", function);
}

/* ----------------------------------------------------------------------------------------- variables */
static double *msfmu_parameter(msfmu_instance *c, size_t k) {
    return (double *)((char *)&c->p + msfmu_parameter_offset[k]);
}

static void msfmu_defaults(msfmu_instance *c) {
    c->p = msfmu_defaults_of_parameters();
    msfmu_calculate_parameters(&c->p);
    memcpy(c->start, msfmu_state_start, sizeof c->start);
    memset(c->set, 0, sizeof c->set);
    memcpy(c->held, msfmu_state_held, sizeof c->held);
    memcpy(c->x, msfmu_state_start, sizeof c->x);
    memset(c->a, 0, sizeof c->a);
    memset(c->out, 0, sizeof c->out);
    c->time = 0.0;
    c->initial_ready = 0;
    c->valid = 0;
}

/* ----------------------------------------------------------------------------------------- constraints */
#if MSFMU_NROWS > 0
static double msfmu_max_abs(const double *v, int n) {
    double m = 0.0;
    for (int i = 0; i < n; i++)
        if (!(fabs(v[i]) <= m)) m = fabs(v[i]);  /* a NaN propagates */
    return m;
}

/* Solve G y = r in place (G n x n row-major, r becomes y) by Gaussian elimination with partial pivoting.
   Returns 0, or -1 for a zero or non-finite pivot. */
static int msfmu_solve(int n, double *G, double *r) {
    for (int k = 0; k < n; k++) {
        int pivot = k;
        for (int i = k + 1; i < n; i++)
            if (fabs(G[i * n + k]) > fabs(G[pivot * n + k])) pivot = i;
        if (!(fabs(G[pivot * n + k]) > 0.0) || !isfinite(G[pivot * n + k])) return -1;
        if (pivot != k) {
            for (int j = 0; j < n; j++) {
                double s = G[k * n + j];
                G[k * n + j] = G[pivot * n + j];
                G[pivot * n + j] = s;
            }
            double s = r[k];
            r[k] = r[pivot];
            r[pivot] = s;
        }
        for (int i = k + 1; i < n; i++) {
            double factor = G[i * n + k] / G[k * n + k];
            for (int j = k; j < n; j++) G[i * n + j] -= factor * G[k * n + j];
            r[i] -= factor * r[k];
        }
    }
    for (int k = n - 1; k >= 0; k--) {
        double s = r[k];
        for (int j = k + 1; j < n; j++) s -= G[k * n + j] * r[j];
        r[k] = s / G[k * n + k];
    }
    return 0;
}

/* v -= B^T (B B^T)^-1 r for the rows of B (m x n, row-major): the minimum-norm change with B dv = -r */
static int msfmu_min_norm_step(int m, int n, const double *B, double *r, double *v) {
    double G[MSFMU_NROWS * MSFMU_NROWS];
    for (int i = 0; i < m; i++)
        for (int j = 0; j < m; j++) {
            double s = 0.0;
            for (int k = 0; k < n; k++) s += B[i * n + k] * B[j * n + k];
            G[i * m + j] = s;
        }
    if (msfmu_solve(m, G, r)) return -1;
    for (int k = 0; k < n; k++)
        for (int i = 0; i < m; i++) v[k] -= B[i * n + k] * r[i];
    return 0;
}

/* max |Phi(q, t)| over the holonomic rows and max |A u + a_t| over all rows */
static double msfmu_residual(const msfmu_instance *c) {
    const double *q = c->x, *u = c->x + MSFMU_NCOORD;
    double r[MSFMU_NROWS], worst;
    msfmu_constraint_velocity(c->time, q, u, &c->p, r);
    worst = msfmu_max_abs(r, MSFMU_NROWS);
#if MSFMU_NHOL > 0
    double phi[MSFMU_NHOL];
    msfmu_constraint_position(c->time, q, u, &c->p, phi);
    double hol = msfmu_max_abs(phi, MSFMU_NHOL);
    if (!(hol <= worst)) worst = hol;
#endif
    return worst;
}

/* The columns of the rows B (m x n) of the held entries set to zero: a minimum-norm step leaves them */
static void msfmu_hold(int m, int n, double *B, const int *held) {
    if (held == NULL) return;
    for (int i = 0; i < m; i++)
        for (int k = 0; k < n; k++)
            if (held[k]) B[i * n + k] = 0.0;
}

/* Gauss-Newton with minimum-norm steps on Phi(q, t) = 0, moving no coordinate ``held`` marks (NULL: any) */
static void msfmu_positions(msfmu_instance *c, const int *held) {
#if MSFMU_NHOL > 0
    double *q = c->x, *u = c->x + MSFMU_NCOORD;
    double A[MSFMU_NROWS * MSFMU_NCOORD];
    for (int iteration = 0; iteration < MSFMU_ITERATIONS; iteration++) {
        double phi[MSFMU_NHOL], H[MSFMU_NHOL * MSFMU_NCOORD];
        msfmu_constraint_position(c->time, q, u, &c->p, phi);
        if (!(msfmu_max_abs(phi, MSFMU_NHOL) >= MSFMU_CONVERGED * (1.0 + msfmu_max_abs(q, MSFMU_NCOORD)))) break;
        msfmu_constraint_matrix(c->time, q, u, &c->p, A);
        for (int i = 0; i < MSFMU_NHOL; i++)
            memcpy(H + i * MSFMU_NCOORD, A + msfmu_holonomic_row[i] * MSFMU_NCOORD, sizeof(double) * MSFMU_NCOORD);
        msfmu_hold(MSFMU_NHOL, MSFMU_NCOORD, H, held);
        if (msfmu_min_norm_step(MSFMU_NHOL, MSFMU_NCOORD, H, phi, q)) break;
    }
#else
    (void)c;
    (void)held;
#endif
    c->valid = 0;
}

/* the minimum-norm change of the rates ``held`` does not mark (NULL: all) with A u + a_t = 0; nonzero if A (its
   columns not held) is singular */
static int msfmu_rates(msfmu_instance *c, const int *held) {
    double *q = c->x, *u = c->x + MSFMU_NCOORD;
    double A[MSFMU_NROWS * MSFMU_NCOORD], r[MSFMU_NROWS];
    msfmu_constraint_matrix(c->time, q, u, &c->p, A);
    msfmu_constraint_velocity(c->time, q, u, &c->p, r);
    msfmu_hold(MSFMU_NROWS, MSFMU_NCOORD, A, held);
    int singular = msfmu_min_norm_step(MSFMU_NROWS, MSFMU_NCOORD, A, r, u);
    c->valid = 0;
    return singular;
}

#if MSFMU_NHOL > 0
/* Gauss-Newton on Phi(q, t) = offset moving no coordinate ``held`` marks (minimum-norm steps): 0 when it converges
   in 12 steps with its second step at most MSFMU_CONTRACTION of its first (mechsys simulate's _settle) */
static int msfmu_settle(msfmu_instance *c, const int *held, const double *offset) {
    double *q = c->x, *u = c->x + MSFMU_NCOORD;
    double A[MSFMU_NROWS * MSFMU_NCOORD], first = 0.0;
    for (int iteration = 0; iteration < 12; iteration++) {
        double phi[MSFMU_NHOL], H[MSFMU_NHOL * MSFMU_NCOORD], before[MSFMU_NCOORD];
        msfmu_constraint_position(c->time, q, u, &c->p, phi);
        for (int i = 0; i < MSFMU_NHOL; i++) phi[i] -= offset[i];
        double size = msfmu_max_abs(phi, MSFMU_NHOL);
        if (!(size == size) || !(msfmu_max_abs(q, MSFMU_NCOORD) <= DBL_MAX)) return -1;
        if (size < MSFMU_CONVERGED * (1.0 + msfmu_max_abs(q, MSFMU_NCOORD))) return 0;
        msfmu_constraint_matrix(c->time, q, u, &c->p, A);
        for (int i = 0; i < MSFMU_NHOL; i++)
            memcpy(H + i * MSFMU_NCOORD, A + msfmu_holonomic_row[i] * MSFMU_NCOORD, sizeof(double) * MSFMU_NCOORD);
        msfmu_hold(MSFMU_NHOL, MSFMU_NCOORD, H, held);
        memcpy(before, q, sizeof before);
        if (msfmu_min_norm_step(MSFMU_NHOL, MSFMU_NCOORD, H, phi, q)) return -1;
        double step = 0.0;
        for (int k = 0; k < MSFMU_NCOORD; k++)
            if (fabs(q[k] - before[k]) > step) step = fabs(q[k] - before[k]);
        if (iteration == 0) first = step;
        else if (iteration == 1 && step > MSFMU_CONTRACTION * first) return -1;
    }
    return -1;
}
#endif

/* The coordinates of x with the ``held`` ones of ``guess`` reached from ``origin`` along the homotopy
   Phi(q) = (1 - s) Phi(origin), the held ones going from origin's to guess's with s: tangent predictor, Newton
   corrector, a step kept where Newton contracts at once, corrects by at most MSFMU_CORRECTION of the tangent's
   move and turns no angle by more than MSFMU_ANGLE_STEP (mechsys simulate's carry); 0 on success, else x's
   coordinates are left undefined */
static int msfmu_carry(msfmu_instance *c, const double *origin, const double *guess, const int *held) {
#if MSFMU_NHOL > 0
    double *q = c->x, *u = c->x + MSFMU_NCOORD;
    double offset[MSFMU_NHOL], scaled[MSFMU_NHOL], previous[MSFMU_NCOORD], move[MSFMU_NCOORD];
    double A[MSFMU_NROWS * MSFMU_NCOORD], H[MSFMU_NHOL * MSFMU_NCOORD], r[MSFMU_NHOL], tangent[MSFMU_NCOORD];
    double trial[MSFMU_NCOORD];
    msfmu_constraint_position(c->time, origin, u, &c->p, offset);
    if (!(msfmu_max_abs(offset, MSFMU_NHOL) <= DBL_MAX)) return -1;
    memcpy(previous, origin, sizeof previous);
    for (int k = 0; k < MSFMU_NCOORD; k++) move[k] = held[k] ? guess[k] - origin[k] : 0.0;
    double s = 0.0, ds = 1.0;
    while (s < 1.0) {
        double step = ds < 1.0 - s ? ds : 1.0 - s;
        /* the tangent: J q' = -Phi(origin), the free part of minimum norm */
        msfmu_constraint_matrix(c->time, previous, u, &c->p, A);
        for (int i = 0; i < MSFMU_NHOL; i++) {
            memcpy(H + i * MSFMU_NCOORD, A + msfmu_holonomic_row[i] * MSFMU_NCOORD, sizeof(double) * MSFMU_NCOORD);
            double Am = 0.0;
            for (int k = 0; k < MSFMU_NCOORD; k++) Am += H[i * MSFMU_NCOORD + k] * move[k];
            r[i] = Am + offset[i];  /* min_norm_step subtracts B^T (B B^T)^-1 r from a zero start */
        }
        msfmu_hold(MSFMU_NHOL, MSFMU_NCOORD, H, held);
        memset(tangent, 0, sizeof tangent);
        int singular = msfmu_min_norm_step(MSFMU_NHOL, MSFMU_NCOORD, H, r, tangent);
        double size = msfmu_max_abs(previous, MSFMU_NCOORD), moved = 0.0, corrected = 0.0;
        for (int k = 0; k < MSFMU_NCOORD; k++) {
            if (held[k]) tangent[k] = move[k];
            trial[k] = previous[k] + tangent[k] * step;
            if (held[k]) trial[k] = s + step >= 1.0 ? guess[k] : origin[k] + (s + step) * move[k];
            q[k] = trial[k];
            if (fabs(trial[k] - previous[k]) > moved) moved = fabs(trial[k] - previous[k]);
        }
        for (int i = 0; i < MSFMU_NHOL; i++) scaled[i] = (1.0 - s - step) * offset[i];
        int failed = singular || msfmu_settle(c, held, scaled);
        if (!failed) {
            double turned = 0.0;
            for (int k = 0; k < MSFMU_NCOORD; k++) {
                if (fabs(q[k] - trial[k]) > corrected) corrected = fabs(q[k] - trial[k]);
                if (msfmu_coordinate_angle[k] && fabs(q[k] - previous[k]) > turned) turned = fabs(q[k] - previous[k]);
            }
            failed = corrected > MSFMU_CORRECTION * moved + 1e-14 * (1.0 + size) || turned > MSFMU_ANGLE_STEP;
        }
        if (failed) {
            ds /= 2;
            if (ds < 1e-6) return -1;
            continue;
        }
        memcpy(previous, q, sizeof previous);
        s += step;
        ds = 2 * ds < 1.0 ? 2 * ds : 1.0;
    }
    c->valid = 0;
    return 0;
#else
    (void)c;
    (void)origin;
    (void)guess;
    (void)held;
    return 0;
#endif
}

/* each angle (not held) within half a turn of its guess, where the constraints hold there as well (mechsys
   simulate's _unwound) */
static void msfmu_unwind(msfmu_instance *c, const double *guess, const int *held) {
#if MSFMU_NHOL > 0
    double *q = c->x, *u = c->x + MSFMU_NCOORD, phi[MSFMU_NHOL];
    double tolerance = 1e-12 * (1.0 + msfmu_max_abs(q, MSFMU_NCOORD));
    for (int k = 0; k < MSFMU_NCOORD; k++) {
        if (!msfmu_coordinate_angle[k] || (held != NULL && held[k])) continue;
        double turns = nearbyint((q[k] - guess[k]) / (2 * M_PI)), kept = q[k];
        if (turns == 0.0) continue;
        q[k] -= 2 * M_PI * turns;
        msfmu_constraint_position(c->time, q, u, &c->p, phi);
        if (!(msfmu_max_abs(phi, MSFMU_NHOL) <= tolerance)) q[k] = kept;
    }
    c->valid = 0;
#else
    (void)c;
    (void)guess;
    (void)held;
#endif
}

/* Move the state onto the constraints, as `mechsys simulate` does; fmi2Error (and a message saying `when`) if
   the result still violates them by more than MSFMU_TOLERANCE x (1 + max |x|). */
static fmi2Status msfmu_project(msfmu_instance *c, const char *when) {
    msfmu_positions(c, NULL);
    int singular = msfmu_rates(c, NULL);
    double residual = msfmu_residual(c);
    double tolerance = MSFMU_TOLERANCE * (1.0 + msfmu_max_abs(c->x, MSFMU_NSTATE));
    if (residual <= tolerance) return fmi2OK;
    msfmu_log(c, fmi2Error, "logStatusError", "%s: the constraint residual is %.3g at t = %.17g (tolerance %.3g); "
              "the projection onto the constraints did not converge (%s)", when, residual, c->time, tolerance,
              singular ? "the constraint Jacobian is rank deficient: a singular (dead-centre, locked) configuration "
                         "or redundant constraints"
                       : "no nearby state satisfies the constraints");
    return fmi2Error;
}

static double msfmu_drift_limit(const msfmu_instance *c) {
    return MSFMU_DRIFT * (1.0 + msfmu_max_abs(c->x, MSFMU_NSTATE));
}
#endif

/* ----------------------------------------------------------------------------------------- evaluation */
/* Before initialization ends, the states follow their start values and the parameters (a state without a start
   value is computed from the parameters), assembled onto the constraints if there are any. */
static fmi2Status msfmu_initial_state(msfmu_instance *c) {
    if (c->initial_ready) return fmi2OK;
    /* the start values set, the file's values (with --set's, before assembly) for the others: `mechsys simulate
       --set` starts from the same state (the defaults, already assembled, gave another start: a crank set to 0.6
       started at 0.476 here and at 0.396 there) */
    for (int i = 0; i < MSFMU_NSTATE; i++) c->x[i] = c->set[i] ? c->start[i] : msfmu_state_guess[i];
    msfmu_calculated_states(&c->p, c->x);
    c->valid = 0;
#if MSFMU_NROWS > 0
    /* as mechsys simulate's assemble_start: the coordinates set carried to their values (from the guesses, else
       along the projection's branch), the free angles within half a turn of their guesses; then the rates set held
       while the others satisfy the velocity rows; a value set that cannot be held is left where projection puts it */
    double raw[MSFMU_NSTATE], given[MSFMU_NSTATE], projected[MSFMU_NCOORD];
    int held_q = 0, held_u = 0, dropped = 0;
    memcpy(raw, c->x, sizeof raw);
    for (int i = 0; i < MSFMU_NSTATE; i++) {
        if (i < MSFMU_NCOORD) held_q |= c->held[i]; else held_u |= c->held[i];
        /* what the importer sees as given: its value, else the declared start (a calculated one: its value) */
        given[i] = c->set[i] || !msfmu_state_settable[i] ? raw[i] : msfmu_state_start[i];
    }
    msfmu_positions(c, NULL);
    memcpy(projected, c->x, sizeof projected);
    if (held_q && msfmu_carry(c, raw, raw, c->held) && msfmu_carry(c, projected, raw, c->held)) {
        memcpy(c->x, projected, sizeof projected);
        dropped = 1;
    }
    msfmu_unwind(c, raw, dropped ? NULL : c->held);
    memcpy(c->x + MSFMU_NCOORD, raw + MSFMU_NCOORD, sizeof(double) * MSFMU_NCOORD);
    if (held_u) {
        msfmu_rates(c, c->held + MSFMU_NCOORD);
        if (!(msfmu_residual(c) <= 1e-12 * (1.0 + msfmu_max_abs(c->x, MSFMU_NSTATE)))) {
            memcpy(c->x + MSFMU_NCOORD, raw + MSFMU_NCOORD, sizeof(double) * MSFMU_NCOORD);
            msfmu_rates(c, NULL);
            dropped = 1;
        }
    } else {
        msfmu_rates(c, NULL);
    }
    if (dropped)
        msfmu_log(c, fmi2Warning, "logStatusWarning", "start values set cannot be held on the constraints (no path "
                  "from the file's values reaches them, nor the projection's branch, or the rates set conflict): "
                  "moved");
    double residual = msfmu_residual(c), tolerance = MSFMU_TOLERANCE * (1.0 + msfmu_max_abs(c->x, MSFMU_NSTATE));
    if (!(residual <= tolerance)) {
        msfmu_log(c, fmi2Error, "logStatusError", "the initial state cannot be assembled onto the constraints: the "
                  "constraint residual is %.3g at t = %.17g (tolerance %.3g)", residual, c->time, tolerance);
        return fmi2Error;
    }
    for (int i = 0; i < MSFMU_NSTATE; i++)
        if (fabs(c->x[i] - given[i]) > 1e-9 * (1.0 + fabs(given[i])))
            msfmu_log(c, fmi2Warning, "logStatusWarning", "initial state assembled onto the constraints: %s = %.10g "
                      "(given %.10g)", msfmu_variable_name[MSFMU_VR_STATE + i], c->x[i], given[i]);
#endif
    c->initial_ready = 1;
    return fmi2OK;
}

/* q'' and the outputs at (time, x, p), once per change of them */
static fmi2Status msfmu_update(msfmu_instance *c) {
    const double *q = c->x, *u = c->x + MSFMU_NCOORD;
    if (c->mode & (MSFMU_INSTANTIATED | MSFMU_INITIALIZATION))
        if (msfmu_initial_state(c) != fmi2OK) return fmi2Error;
    if (c->valid) return fmi2OK;
    if (msfmu_accelerations(c->time, q, u, &c->p, c->a) != 0) {
        msfmu_log(c, fmi2Error, "logStatusError", "the system matrix (M, or [[M, -A^T], [A, 0]] with constraints) is "
                  "singular at t = %.17g: a coordinate without mass or inertia, or a singular configuration of the "
                  "constraints", c->time);
        return fmi2Error;
    }
    for (int i = 0; i < MSFMU_NCOORD; i++)
        if (!isfinite(c->a[i])) {
            msfmu_log(c, fmi2Error, "logStatusError", "the acceleration %s is not finite at t = %.17g (an overflow "
                      "or a domain error: check the parameters and the state)",
                      msfmu_variable_name[MSFMU_VR_DERIVATIVE + MSFMU_NCOORD + i], c->time);
            return fmi2Error;
        }
    msfmu_outputs(c->time, q, u, c->a, &c->p, c->out);
#if MSFMU_NROWS > 0
    c->out[MSFMU_RESIDUAL_OUTPUT] = msfmu_residual(c);
#endif
    c->valid = 1;
    return fmi2OK;
}

/* ----------------------------------------------------------------------------------------- common functions */
const char *fmi2GetTypesPlatform(void) { return fmi2TypesPlatform; }

const char *fmi2GetVersion(void) { return fmi2Version; }

fmi2Status fmi2SetDebugLogging(fmi2Component component, fmi2Boolean loggingOn, size_t nCategories,
                               const fmi2String categories[]) {
    msfmu_instance *c = (msfmu_instance *)component;
    (void)nCategories;
    (void)categories;
    if (msfmu_allowed(c, "fmi2SetDebugLogging", MSFMU_ANY) != fmi2OK) return fmi2Error;
    c->logging = loggingOn ? 1 : 0;
    return fmi2OK;
}

fmi2Component fmi2Instantiate(fmi2String instanceName, fmi2Type fmuType, fmi2String fmuGUID,
                              fmi2String fmuResourceLocation, const fmi2CallbackFunctions *functions,
                              fmi2Boolean visible, fmi2Boolean loggingOn) {
    msfmu_instance probe, *c;
    const char *name = instanceName != NULL ? instanceName : "";
    (void)fmuResourceLocation;
    (void)visible;
    if (functions == NULL || functions->allocateMemory == NULL || functions->freeMemory == NULL) return NULL;
    memset(&probe, 0, sizeof probe);
    probe.functions = *functions;
    probe.name = (char *)name;
    if (fmuType != fmi2ModelExchange) {
        msfmu_error(&probe, "%s: this FMU implements FMI 2.0 Model Exchange only (no Co-Simulation)",
                    "fmi2Instantiate");
        return NULL;
    }
    if (fmuGUID == NULL || strcmp(fmuGUID, MSFMU_GUID) != 0) {
        msfmu_error(&probe, "%s: the GUID does not match this FMU's modelDescription.xml", "fmi2Instantiate");
        return NULL;
    }
    c = (msfmu_instance *)functions->allocateMemory(1, sizeof(msfmu_instance));
    if (c == NULL) return NULL;
    c->functions = *functions;
    c->name = (char *)functions->allocateMemory(strlen(name) + 1, sizeof(char));
    if (c->name == NULL) {
        functions->freeMemory(c);
        return NULL;
    }
    memcpy(c->name, name, strlen(name) + 1);
    c->logging = loggingOn ? 1 : 0;
    c->mode = MSFMU_INSTANTIATED;
    msfmu_defaults(c);
    return c;
}

void fmi2FreeInstance(fmi2Component component) {
    msfmu_instance *c = (msfmu_instance *)component;
    if (c == NULL) return;
    c->functions.freeMemory(c->name);
    c->functions.freeMemory(c);
}

fmi2Status fmi2SetupExperiment(fmi2Component component, fmi2Boolean toleranceDefined, fmi2Real tolerance,
                               fmi2Real startTime, fmi2Boolean stopTimeDefined, fmi2Real stopTime) {
    msfmu_instance *c = (msfmu_instance *)component;
    (void)toleranceDefined;
    (void)tolerance;
    (void)stopTimeDefined;
    (void)stopTime;
    if (msfmu_allowed(c, "fmi2SetupExperiment", MSFMU_INSTANTIATED) != fmi2OK) return fmi2Error;
    c->time = startTime;
    c->initial_ready = 0;
    c->valid = 0;
    return fmi2OK;
}

fmi2Status fmi2EnterInitializationMode(fmi2Component component) {
    msfmu_instance *c = (msfmu_instance *)component;
    if (msfmu_allowed(c, "fmi2EnterInitializationMode", MSFMU_INSTANTIATED) != fmi2OK) return fmi2Error;
    c->mode = MSFMU_INITIALIZATION;
    return fmi2OK;
}

fmi2Status fmi2ExitInitializationMode(fmi2Component component) {
    msfmu_instance *c = (msfmu_instance *)component;
    if (msfmu_allowed(c, "fmi2ExitInitializationMode", MSFMU_INITIALIZATION) != fmi2OK) return fmi2Error;
    if (msfmu_update(c) != fmi2OK) {
        c->mode = MSFMU_ERROR;
        return fmi2Error;
    }
    c->mode = MSFMU_EVENT;
    return fmi2OK;
}

fmi2Status fmi2Terminate(fmi2Component component) {
    msfmu_instance *c = (msfmu_instance *)component;
    if (msfmu_allowed(c, "fmi2Terminate", MSFMU_EVENT | MSFMU_CONTINUOUS | MSFMU_ERROR) != fmi2OK) return fmi2Error;
    c->mode = MSFMU_TERMINATED;
    return fmi2OK;
}

fmi2Status fmi2Reset(fmi2Component component) {
    msfmu_instance *c = (msfmu_instance *)component;
    if (msfmu_allowed(c, "fmi2Reset", MSFMU_ANY) != fmi2OK) return fmi2Error;
    msfmu_defaults(c);
    c->mode = MSFMU_INSTANTIATED;
    return fmi2OK;
}

/* ----------------------------------------------------------------------------------------- get and set */
fmi2Status fmi2GetReal(fmi2Component component, const fmi2ValueReference vr[], size_t nvr, fmi2Real value[]) {
    msfmu_instance *c = (msfmu_instance *)component;
    if (msfmu_allowed(c, "fmi2GetReal", MSFMU_SOLVED) != fmi2OK) return fmi2Error;
    for (size_t i = 0; i < nvr; i++) {
        fmi2ValueReference r = vr[i];
        if (r >= MSFMU_NVR) {
            msfmu_log(c, fmi2Error, "logStatusError", "fmi2GetReal: unknown value reference %u", (unsigned)r);
            return fmi2Error;
        }
        if (r < MSFMU_VR_STATE) {
            value[i] = *msfmu_parameter(c, r);
            continue;
        }
        if (r < MSFMU_VR_DERIVATIVE) {  /* a state needs no accelerations */
            if ((c->mode & MSFMU_INITIALIZATION) && msfmu_initial_state(c) != fmi2OK) return fmi2Error;
            value[i] = c->x[r - MSFMU_VR_STATE];
            continue;
        }
        if (msfmu_update(c) != fmi2OK) return fmi2Error;
        if (r < MSFMU_VR_OUTPUT)
            value[i] = r - MSFMU_VR_DERIVATIVE < MSFMU_NCOORD ? c->x[MSFMU_NCOORD + (r - MSFMU_VR_DERIVATIVE)]
                                                               : c->a[r - MSFMU_VR_DERIVATIVE - MSFMU_NCOORD];
        else
            value[i] = c->out[r - MSFMU_VR_OUTPUT];
    }
    return fmi2OK;
}

static fmi2Status msfmu_set_parameter(msfmu_instance *c, fmi2ValueReference r, double value) {
    if (!msfmu_parameter_settable[r]) {
        msfmu_log(c, fmi2Error, "logStatusError", "fmi2SetReal: %s is a calculated parameter (the model file computes "
                  "it from other parameters); set those, or export with --set to give it a value",
                  msfmu_variable_name[r]);
        return fmi2Error;
    }
    if (msfmu_parameter_fixed[r][0] && value != msfmu_parameter_exported[r]) {
        msfmu_log(c, fmi2Error, "logStatusError", "fmi2SetReal: %s = %g: %s fixes the structure of this FMU (%s); "
                  "export again with mechsys codegen --set %s=%g", msfmu_variable_name[r], value,
                  msfmu_variable_name[r], msfmu_parameter_fixed[r], msfmu_variable_name[r], value);
        return fmi2Error;
    }
    if (!(c->mode & (MSFMU_INSTANTIATED | MSFMU_INITIALIZATION | MSFMU_EVENT))) {
        msfmu_log(c, fmi2Error, "logStatusError", "fmi2SetReal: the parameter %s can be set before initialization "
                  "ends and in event mode only", msfmu_variable_name[r]);
        return fmi2Error;
    }
    *msfmu_parameter(c, r) = value;
    msfmu_calculate_parameters(&c->p);
    if (c->mode & (MSFMU_INSTANTIATED | MSFMU_INITIALIZATION)) c->initial_ready = 0;
    c->valid = 0;
    return fmi2OK;
}

static fmi2Status msfmu_set_start(msfmu_instance *c, fmi2ValueReference r, double value) {
    size_t k = r - MSFMU_VR_STATE;
    if (!(c->mode & (MSFMU_INSTANTIATED | MSFMU_INITIALIZATION))) {
        msfmu_log(c, fmi2Error, "logStatusError", "fmi2SetReal: the state %s takes a start value before "
                  "initialization ends only; afterwards use fmi2SetContinuousStates", msfmu_variable_name[r]);
        return fmi2Error;
    }
    if (!msfmu_state_settable[k]) {
        msfmu_log(c, fmi2Error, "logStatusError", "fmi2SetReal: the initial value of %s is calculated from the "
                  "parameters (the model file gives an expression); export with --set to give it a number",
                  msfmu_variable_name[r]);
        return fmi2Error;
    }
    c->start[k] = value;
    c->set[k] = c->held[k] = 1;
    c->initial_ready = 0;
    c->valid = 0;
    return fmi2OK;
}

fmi2Status fmi2SetReal(fmi2Component component, const fmi2ValueReference vr[], size_t nvr, const fmi2Real value[]) {
    msfmu_instance *c = (msfmu_instance *)component;
    if (msfmu_allowed(c, "fmi2SetReal", MSFMU_INSTANTIATED | MSFMU_INITIALIZATION | MSFMU_EVENT) != fmi2OK)
        return fmi2Error;
    for (size_t i = 0; i < nvr; i++) {
        fmi2ValueReference r = vr[i];
        fmi2Status status;
        if (r >= MSFMU_NVR) {
            msfmu_log(c, fmi2Error, "logStatusError", "fmi2SetReal: unknown value reference %u", (unsigned)r);
            return fmi2Error;
        }
        if (!isfinite(value[i])) {
            msfmu_log(c, fmi2Error, "logStatusError", "fmi2SetReal: %s = %g is not a finite number",
                      msfmu_variable_name[r], value[i]);
            return fmi2Error;
        }
        if (r < MSFMU_VR_STATE)
            status = msfmu_set_parameter(c, r, value[i]);
        else if (r < MSFMU_VR_DERIVATIVE)
            status = msfmu_set_start(c, r, value[i]);
        else {
            msfmu_log(c, fmi2Error, "logStatusError", "fmi2SetReal: %s is computed by the model and cannot be set",
                      msfmu_variable_name[r]);
            status = fmi2Error;
        }
        if (status != fmi2OK) return status;
    }
    return fmi2OK;
}

/* The model has Real variables only: Integer, Boolean and String accesses must name no variable. */
static fmi2Status msfmu_no_variables(msfmu_instance *c, const char *function, size_t nvr) {
    if (msfmu_allowed(c, function, MSFMU_ANY) != fmi2OK) return fmi2Error;
    if (nvr == 0) return fmi2OK;
    return msfmu_error(c, "%s: the FMU has Real variables only", function);
}

fmi2Status fmi2GetInteger(fmi2Component c, const fmi2ValueReference vr[], size_t nvr, fmi2Integer value[]) {
    (void)vr;
    (void)value;
    return msfmu_no_variables((msfmu_instance *)c, "fmi2GetInteger", nvr);
}

fmi2Status fmi2GetBoolean(fmi2Component c, const fmi2ValueReference vr[], size_t nvr, fmi2Boolean value[]) {
    (void)vr;
    (void)value;
    return msfmu_no_variables((msfmu_instance *)c, "fmi2GetBoolean", nvr);
}

fmi2Status fmi2GetString(fmi2Component c, const fmi2ValueReference vr[], size_t nvr, fmi2String value[]) {
    (void)vr;
    (void)value;
    return msfmu_no_variables((msfmu_instance *)c, "fmi2GetString", nvr);
}

fmi2Status fmi2SetInteger(fmi2Component c, const fmi2ValueReference vr[], size_t nvr, const fmi2Integer value[]) {
    (void)vr;
    (void)value;
    return msfmu_no_variables((msfmu_instance *)c, "fmi2SetInteger", nvr);
}

fmi2Status fmi2SetBoolean(fmi2Component c, const fmi2ValueReference vr[], size_t nvr, const fmi2Boolean value[]) {
    (void)vr;
    (void)value;
    return msfmu_no_variables((msfmu_instance *)c, "fmi2SetBoolean", nvr);
}

fmi2Status fmi2SetString(fmi2Component c, const fmi2ValueReference vr[], size_t nvr, const fmi2String value[]) {
    (void)vr;
    (void)value;
    return msfmu_no_variables((msfmu_instance *)c, "fmi2SetString", nvr);
}

/* ----------------------------------------------------------------------------------------- not supported */
/* canGetAndSetFMUstate, canSerializeFMUstate and providesDirectionalDerivative are false in modelDescription.xml */
static fmi2Status msfmu_unsupported(fmi2Component c, const char *function) {
    return msfmu_error((msfmu_instance *)c, "%s is not supported by this FMU (see its modelDescription.xml)",
                       function);
}

fmi2Status fmi2GetFMUstate(fmi2Component c, fmi2FMUstate *FMUstate) {
    (void)FMUstate;
    return msfmu_unsupported(c, "fmi2GetFMUstate");
}

fmi2Status fmi2SetFMUstate(fmi2Component c, fmi2FMUstate FMUstate) {
    (void)FMUstate;
    return msfmu_unsupported(c, "fmi2SetFMUstate");
}

fmi2Status fmi2FreeFMUstate(fmi2Component c, fmi2FMUstate *FMUstate) {
    (void)FMUstate;
    return msfmu_unsupported(c, "fmi2FreeFMUstate");
}

fmi2Status fmi2SerializedFMUstateSize(fmi2Component c, fmi2FMUstate FMUstate, size_t *size) {
    (void)FMUstate;
    (void)size;
    return msfmu_unsupported(c, "fmi2SerializedFMUstateSize");
}

fmi2Status fmi2SerializeFMUstate(fmi2Component c, fmi2FMUstate FMUstate, fmi2Byte serializedState[], size_t size) {
    (void)FMUstate;
    (void)serializedState;
    (void)size;
    return msfmu_unsupported(c, "fmi2SerializeFMUstate");
}

fmi2Status fmi2DeSerializeFMUstate(fmi2Component c, const fmi2Byte serializedState[], size_t size,
                                   fmi2FMUstate *FMUstate) {
    (void)serializedState;
    (void)size;
    (void)FMUstate;
    return msfmu_unsupported(c, "fmi2DeSerializeFMUstate");
}

fmi2Status fmi2GetDirectionalDerivative(fmi2Component c, const fmi2ValueReference vUnknown_ref[], size_t nUnknown,
                                        const fmi2ValueReference vKnown_ref[], size_t nKnown,
                                        const fmi2Real dvKnown[], fmi2Real dvUnknown[]) {
    (void)vUnknown_ref;
    (void)nUnknown;
    (void)vKnown_ref;
    (void)nKnown;
    (void)dvKnown;
    (void)dvUnknown;
    return msfmu_unsupported(c, "fmi2GetDirectionalDerivative");
}

/* ----------------------------------------------------------------------------------------- model exchange */
fmi2Status fmi2EnterEventMode(fmi2Component component) {
    msfmu_instance *c = (msfmu_instance *)component;
    if (msfmu_allowed(c, "fmi2EnterEventMode", MSFMU_EVENT | MSFMU_CONTINUOUS) != fmi2OK) return fmi2Error;
    c->mode = MSFMU_EVENT;
    return fmi2OK;
}

fmi2Status fmi2NewDiscreteStates(fmi2Component component, fmi2EventInfo *eventInfo) {
    msfmu_instance *c = (msfmu_instance *)component;
    if (msfmu_allowed(c, "fmi2NewDiscreteStates", MSFMU_EVENT) != fmi2OK) return fmi2Error;
    eventInfo->newDiscreteStatesNeeded = fmi2False;
    eventInfo->terminateSimulation = fmi2False;
    eventInfo->nominalsOfContinuousStatesChanged = fmi2False;
    eventInfo->valuesOfContinuousStatesChanged = fmi2False;
    eventInfo->nextEventTimeDefined = fmi2False;
    eventInfo->nextEventTime = 0.0;
#if MSFMU_NROWS > 0
    if (!(msfmu_residual(c) <= msfmu_drift_limit(c))) {
        double before[MSFMU_NSTATE];
        memcpy(before, c->x, sizeof before);
        if (msfmu_project(c, "the motion left the constraint manifold") != fmi2OK) {
            c->mode = MSFMU_ERROR;
            return fmi2Error;
        }
        eventInfo->valuesOfContinuousStatesChanged = memcmp(before, c->x, sizeof before) != 0;
        msfmu_log(c, fmi2OK, "logEvents", "projected the state onto the constraints at t = %.17g", c->time);
    }
#endif
    return fmi2OK;
}

fmi2Status fmi2EnterContinuousTimeMode(fmi2Component component) {
    msfmu_instance *c = (msfmu_instance *)component;
    if (msfmu_allowed(c, "fmi2EnterContinuousTimeMode", MSFMU_EVENT) != fmi2OK) return fmi2Error;
    c->mode = MSFMU_CONTINUOUS;
    return fmi2OK;
}

fmi2Status fmi2CompletedIntegratorStep(fmi2Component component, fmi2Boolean noSetFMUStatePriorToCurrentPoint,
                                       fmi2Boolean *enterEventMode, fmi2Boolean *terminateSimulation) {
    msfmu_instance *c = (msfmu_instance *)component;
    (void)noSetFMUStatePriorToCurrentPoint;
    if (msfmu_allowed(c, "fmi2CompletedIntegratorStep", MSFMU_CONTINUOUS) != fmi2OK) return fmi2Error;
    *enterEventMode = fmi2False;
    *terminateSimulation = fmi2False;
#if MSFMU_NROWS > 0
    if (!(msfmu_residual(c) <= msfmu_drift_limit(c))) *enterEventMode = fmi2True;  /* project in event mode */
#endif
    return fmi2OK;
}

fmi2Status fmi2SetTime(fmi2Component component, fmi2Real time) {
    msfmu_instance *c = (msfmu_instance *)component;
    if (msfmu_allowed(c, "fmi2SetTime", MSFMU_EVENT | MSFMU_CONTINUOUS) != fmi2OK) return fmi2Error;
    c->time = time;
    c->valid = 0;
    return fmi2OK;
}

static fmi2Status msfmu_check_size(const msfmu_instance *c, const char *function, size_t n, size_t expected) {
    if (n == expected) return fmi2OK;
    msfmu_log(c, fmi2Error, "logStatusError", "%s: expected %u values, got %u", function, (unsigned)expected,
              (unsigned)n);
    return fmi2Error;
}

fmi2Status fmi2SetContinuousStates(fmi2Component component, const fmi2Real x[], size_t nx) {
    msfmu_instance *c = (msfmu_instance *)component;
    if (msfmu_allowed(c, "fmi2SetContinuousStates", MSFMU_EVENT | MSFMU_CONTINUOUS) != fmi2OK) return fmi2Error;
    if (msfmu_check_size(c, "fmi2SetContinuousStates", nx, MSFMU_NSTATE) != fmi2OK) return fmi2Error;
    memcpy(c->x, x, sizeof(double) * MSFMU_NSTATE);
    c->valid = 0;
    return fmi2OK;
}

fmi2Status fmi2GetDerivatives(fmi2Component component, fmi2Real derivatives[], size_t nx) {
    msfmu_instance *c = (msfmu_instance *)component;
    if (msfmu_allowed(c, "fmi2GetDerivatives", MSFMU_SOLVED) != fmi2OK) return fmi2Error;
    if (msfmu_check_size(c, "fmi2GetDerivatives", nx, MSFMU_NSTATE) != fmi2OK) return fmi2Error;
    if (msfmu_update(c) != fmi2OK) return fmi2Error;
    memcpy(derivatives, c->x + MSFMU_NCOORD, sizeof(double) * MSFMU_NCOORD);
    memcpy(derivatives + MSFMU_NCOORD, c->a, sizeof(double) * MSFMU_NCOORD);
    return fmi2OK;
}

fmi2Status fmi2GetEventIndicators(fmi2Component component, fmi2Real eventIndicators[], size_t ni) {
    msfmu_instance *c = (msfmu_instance *)component;
    (void)eventIndicators;
    if (msfmu_allowed(c, "fmi2GetEventIndicators", MSFMU_SOLVED) != fmi2OK) return fmi2Error;
    return msfmu_check_size(c, "fmi2GetEventIndicators", ni, 0);
}

fmi2Status fmi2GetContinuousStates(fmi2Component component, fmi2Real x[], size_t nx) {
    msfmu_instance *c = (msfmu_instance *)component;
    if (msfmu_allowed(c, "fmi2GetContinuousStates", MSFMU_SOLVED) != fmi2OK) return fmi2Error;
    if (msfmu_check_size(c, "fmi2GetContinuousStates", nx, MSFMU_NSTATE) != fmi2OK) return fmi2Error;
    if ((c->mode & MSFMU_INITIALIZATION) && msfmu_initial_state(c) != fmi2OK) return fmi2Error;
    memcpy(x, c->x, sizeof(double) * MSFMU_NSTATE);
    return fmi2OK;
}

fmi2Status fmi2GetNominalsOfContinuousStates(fmi2Component component, fmi2Real x_nominal[], size_t nx) {
    msfmu_instance *c = (msfmu_instance *)component;
    if (msfmu_allowed(c, "fmi2GetNominalsOfContinuousStates", MSFMU_ANY) != fmi2OK) return fmi2Error;
    if (msfmu_check_size(c, "fmi2GetNominalsOfContinuousStates", nx, MSFMU_NSTATE) != fmi2OK) return fmi2Error;
    for (size_t i = 0; i < nx; i++) x_nominal[i] = 1.0;
    return fmi2OK;
}

/* ----------------------------------------------------------------------------------------- co-simulation */
/* Declared by fmi2Functions.h; this FMU is Model Exchange only (fmi2Instantiate refuses fmi2CoSimulation). */
fmi2Status fmi2SetRealInputDerivatives(fmi2Component c, const fmi2ValueReference vr[], size_t nvr,
                                       const fmi2Integer order[], const fmi2Real value[]) {
    (void)vr;
    (void)nvr;
    (void)order;
    (void)value;
    return msfmu_unsupported(c, "fmi2SetRealInputDerivatives");
}

fmi2Status fmi2GetRealOutputDerivatives(fmi2Component c, const fmi2ValueReference vr[], size_t nvr,
                                        const fmi2Integer order[], fmi2Real value[]) {
    (void)vr;
    (void)nvr;
    (void)order;
    (void)value;
    return msfmu_unsupported(c, "fmi2GetRealOutputDerivatives");
}

fmi2Status fmi2DoStep(fmi2Component c, fmi2Real currentCommunicationPoint, fmi2Real communicationStepSize,
                      fmi2Boolean noSetFMUStatePriorToCurrentPoint) {
    (void)currentCommunicationPoint;
    (void)communicationStepSize;
    (void)noSetFMUStatePriorToCurrentPoint;
    return msfmu_unsupported(c, "fmi2DoStep");
}

fmi2Status fmi2CancelStep(fmi2Component c) { return msfmu_unsupported(c, "fmi2CancelStep"); }

fmi2Status fmi2GetStatus(fmi2Component c, const fmi2StatusKind s, fmi2Status *value) {
    (void)s;
    (void)value;
    return msfmu_unsupported(c, "fmi2GetStatus");
}

fmi2Status fmi2GetRealStatus(fmi2Component c, const fmi2StatusKind s, fmi2Real *value) {
    (void)s;
    (void)value;
    return msfmu_unsupported(c, "fmi2GetRealStatus");
}

fmi2Status fmi2GetIntegerStatus(fmi2Component c, const fmi2StatusKind s, fmi2Integer *value) {
    (void)s;
    (void)value;
    return msfmu_unsupported(c, "fmi2GetIntegerStatus");
}

fmi2Status fmi2GetBooleanStatus(fmi2Component c, const fmi2StatusKind s, fmi2Boolean *value) {
    (void)s;
    (void)value;
    return msfmu_unsupported(c, "fmi2GetBooleanStatus");
}

fmi2Status fmi2GetStringStatus(fmi2Component c, const fmi2StatusKind s, fmi2String *value) {
    (void)s;
    (void)value;
    return msfmu_unsupported(c, "fmi2GetStringStatus");
}
