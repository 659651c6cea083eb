/* FMI 2.0 interface (Co-Simulation and Model Exchange) of a generated network FMU.
 *
 * The network is linear time-invariant; its input is piecewise constant: the
 * H-bridge voltage +-V_DC switches at the PRBS clock instants j / f_clk, and
 * the FMU inputs are held constant over a communication step (co-simulation)
 * or given continuously (model exchange).
 *
 * Co-simulation: doStep advances the state exactly with the zero-order-hold
 * discretisation x+ = Phi(h) x + Gamma(h) u, Phi and Gamma taken from
 * expm([[A, B], [0, 0]] h) and cached per step length h. A switching instant
 * inside a step splits it there.
 * Model exchange: x' = A x + B u; switching instants are time events
 * (fmi2EventInfo.nextEventTime) at which the FMU reports
 * valuesOfContinuousStatesChanged, so that integrators restart there.
 *
 * Inputs and parameters must be finite and inside their declared range;
 * tunable parameters (element values, vdc) re-assemble the model when set.
 */
#include <float.h>
#include <math.h>
#include <stdarg.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "prc_fmi2.h"
#include "prc_expm.h"
#include "prc_linalg.h"
#include "prc_model.h"
#include "prc_network.h"

#define PRC_CACHE 8
#define MSG_LEN 512

typedef enum { ST_INSTANTIATED, ST_INIT, ST_RUN, ST_TERMINATED, ST_ERROR } prc_state;

typedef struct {
    double h;      /* step length, s (0 = empty slot) */
    double *Phi;   /* nx x nx */
    double *Gam;   /* nx x nu */
} prc_disc;

typedef struct {
    const prc_model *m;
    fmi2CallbackFunctions cb;
    char *name;
    fmi2Type type;
    int logging;
    prc_state state;
    double *r;         /* Real variables by vr (states included) */
    int *iv;           /* Integer variables by vr */
    int dirty;         /* parameters changed since the last build */
    double time;
    double start_time, stop_time;  /* experiment (stop_defined: stop_time set) */
    int stop_defined;
    double t_committed;            /* model exchange: time may not go back before this */
    prc_net net;
    double *u, *dx, *scratch, *aug, *augexp, *work;
    double *kx, *ku;               /* directional derivative seeds */
    int *ipiv;
    prc_disc cache[PRC_CACHE];
    int cache_next;
    /* PRBS generator */
    unsigned long long reg, mask, taps;
    int order;
    long long bit;     /* index of the bit active now */
} prc_inst;

/* ------------------------------------------------------------------ helpers */

static void logmsg(prc_inst *c, fmi2Status status, const char *category, const char *fmt, ...) {
    char buf[MSG_LEN];
    va_list ap;
    if (!c->cb.logger) return;
    if (status == fmi2OK && !c->logging) return;
    va_start(ap, fmt);
    vsnprintf(buf, sizeof buf, fmt, ap);
    va_end(ap);
    c->cb.logger(c->cb.componentEnvironment, c->name, status, category, "%s", buf);
}

static fmi2Status fail(prc_inst *c, const char *fn, const char *fmt, ...) {
    char buf[MSG_LEN];
    va_list ap;
    if (!c) return fmi2Error;
    va_start(ap, fmt);
    vsnprintf(buf, sizeof buf, fmt, ap);
    va_end(ap);
    logmsg(c, fmi2Error, "logStatusError", "%s: %s", fn, buf);
    return fmi2Error;
}

static void *alloc(prc_inst *c, size_t n, size_t size) {
    return c->cb.allocateMemory(n ? n : 1, size);
}

static int nx_of(const prc_model *m) { return m->n_q1 + m->n_l; }
static int nu_of(const prc_model *m) { return m->n_ui + m->n_uv; }

static int has_bridge(const prc_model *m) { return m->bridge_input >= 0; }

static double fclk(prc_inst *c) { return c->r[c->m->vr_fclk]; }

static double next_switch(prc_inst *c) { return (double)(c->bit + 1) / fclk(c); }

static int current_bit(prc_inst *c) { return (int)((c->reg >> (c->order - 1)) & 1ULL); }

static void advance_bit(prc_inst *c) {
    unsigned long long fb = c->reg & c->taps;
    int parity = 0;
    while (fb) {
        parity ^= 1;
        fb &= fb - 1;
    }
    c->reg = ((c->reg << 1) | (unsigned long long)parity) & c->mask;
    c->bit++;
}

static double bridge_level(prc_inst *c) {
    double vdc = c->r[c->m->vr_vdc];
    return current_bit(c) ? vdc : -vdc;
}

/* u = [current inputs, voltage inputs] at the present time */
static void load_inputs(prc_inst *c) {
    const prc_model *m = c->m;
    int j;
    for (j = 0; j < nu_of(m); j++)
        c->u[j] = j == m->bridge_input ? bridge_level(c) : c->r[m->input_vr[j]];
}

static void reset_prbs(prc_inst *c) {
    const prc_model *m = c->m;
    if (!has_bridge(m)) return;
    c->order = c->iv[m->ivr_order];
    c->mask = c->order >= 64 ? ~0ULL : ((1ULL << c->order) - 1ULL);
    c->taps = m->prbs_taps[c->order];
    c->reg = c->iv[m->ivr_seed] == 0 ? c->mask : (unsigned long long)(unsigned int)c->iv[m->ivr_seed];
    c->bit = 0;
}

static int check_source(prc_inst *c, char *msg, size_t len) {
    const prc_model *m = c->m;
    int order, seed;
    double f, v;
    if (!has_bridge(m)) return 0;
    order = c->iv[m->ivr_order];
    seed = c->iv[m->ivr_seed];
    f = c->r[m->vr_fclk];
    v = c->r[m->vr_vdc];
    if (order < 2 || order > 32) {
        snprintf(msg, len, "parameter 'prbs_order' must be between 2 and 32 (got %d)", order);
        return -1;
    }
    if (seed < 0 || (order < 31 && seed >= (1 << order))) {
        snprintf(msg, len, "parameter 'prbs_seed' must be 0 (all ones) or in 1..2^%d-1 (got %d)", order, seed);
        return -1;
    }
    if (!isfinite(f) || !(f > 0.0)) {
        snprintf(msg, len, "parameter 'fclk' must be positive (got %g Hz)", f);
        return -1;
    }
    if (!isfinite(v) || !(v > 0.0)) {
        snprintf(msg, len, "parameter 'vdc' must be positive (got %g V)", v);
        return -1;
    }
    if (c->stop_defined && (c->stop_time - c->start_time) * f > m->max_switches) {
        snprintf(msg, len,
                 "parameter 'fclk' = %g Hz gives %.3g switching instants from %g s to %g s, more than the "
                 "limit of %.3g", f, (c->stop_time - c->start_time) * f, c->start_time, c->stop_time,
                 m->max_switches);
        return -1;
    }
    return 0;
}

/* Every Real and Integer variable with a declared range inside it. */
static int check_ranges(prc_inst *c, char *msg, size_t len) {
    const prc_model *m = c->m;
    int v;
    for (v = 0; v < m->n_real; v++) {
        double x = c->r[v];
        if (m->real_settable[v] == PRC_SET_NEVER) continue;
        if (!isfinite(x)) {
            snprintf(msg, len, "variable '%s' is not finite (got %g)", m->real_names[v], x);
            return -1;
        }
        if (x < m->real_min[v] || x > m->real_max[v]) {
            snprintf(msg, len, "parameter '%s' = %g is outside its range [%g, %g]", m->real_names[v], x,
                     m->real_min[v], m->real_max[v]);
            return -1;
        }
    }
    for (v = 0; v < m->n_int; v++)
        if (c->iv[v] < m->int_min[v] || c->iv[v] > m->int_max[v]) {
            snprintf(msg, len, "parameter '%s' = %d is outside its range [%d, %d]", m->int_names[v], c->iv[v],
                     m->int_min[v], m->int_max[v]);
            return -1;
        }
    return 0;
}

/* Evaluate ties, check values and rebuild the continuous model; 0 or -1 with the reason in msg. */
static int rebuild(prc_inst *c, char *msg, size_t len) {
    int i;
    c->m->compute(c->r);
    if (check_source(c, msg, len) || prc_network_build(c->m, c->r, &c->net, c->scratch, msg, len) ||
        check_ranges(c, msg, len))
        return -1;
    for (i = 0; i < PRC_CACHE; i++) c->cache[i].h = 0.0;
    c->dirty = 0;
    return 0;
}

/* Evaluate ties, check values and rebuild the continuous model when parameters changed. */
static fmi2Status ensure_built(prc_inst *c, const char *fn) {
    char msg[MSG_LEN];
    if (c->state == ST_ERROR) return fail(c, fn, "the instance is in an error state; call fmi2Reset");
    if (!c->dirty) return fmi2OK;
    if (rebuild(c, msg, sizeof msg)) {
        c->state = ST_ERROR;
        return fail(c, fn, "invalid parameters: %s", msg);
    }
    logmsg(c, fmi2OK, "logAll", "%s: model assembled (%d states)", fn, c->net.nx);
    return fmi2OK;
}

/* Phi(h), Gamma(h) from expm([[A h, B h], [0, 0]]), cached by h. */
static prc_disc *discretise(prc_inst *c, double h) {
    const int nx = c->net.nx, nu = c->net.nu, n = nx + nu;
    prc_disc *d;
    int i, j;
    for (i = 0; i < PRC_CACHE; i++)
        if (c->cache[i].h > 0.0 && fabs(c->cache[i].h - h) <= 1e-12 * h) return &c->cache[i];
    d = &c->cache[c->cache_next];
    c->cache_next = (c->cache_next + 1) % PRC_CACHE;
    memset(c->aug, 0, sizeof(double) * (size_t)n * n);
    for (i = 0; i < nx; i++) {
        for (j = 0; j < nx; j++) c->aug[(size_t)i * n + j] = c->net.A[(size_t)i * nx + j] * h;
        for (j = 0; j < nu; j++) c->aug[(size_t)i * n + nx + j] = c->net.B[(size_t)i * nu + j] * h;
    }
    if (prc_expm(n, c->aug, c->augexp, c->work, c->ipiv)) return NULL;
    for (i = 0; i < nx; i++) {
        for (j = 0; j < nx; j++) d->Phi[(size_t)i * nx + j] = c->augexp[(size_t)i * n + j];
        for (j = 0; j < nu; j++) d->Gam[(size_t)i * nu + j] = c->augexp[(size_t)i * n + nx + j];
    }
    d->h = h;
    return d;
}

static double *states(prc_inst *c) { return c->r + c->m->vr_state0; }

static int zoh_step(prc_inst *c, double h) {
    const int nx = c->net.nx, nu = c->net.nu;
    prc_disc *d = discretise(c, h);
    double *x = states(c);
    int i, j;
    if (!d) return -1;
    load_inputs(c);
    for (i = 0; i < nx; i++) {
        double s = 0.0;
        for (j = 0; j < nx; j++) s += d->Phi[(size_t)i * nx + j] * x[j];
        for (j = 0; j < nu; j++) s += d->Gam[(size_t)i * nu + j] * c->u[j];
        c->dx[i] = s;
    }
    memcpy(x, c->dx, sizeof(double) * (size_t)nx);
    return 0;
}

static void derivatives(prc_inst *c, double *out) {
    const int nx = c->net.nx, nu = c->net.nu;
    const double *x = states(c);
    int i, j;
    load_inputs(c);
    for (i = 0; i < nx; i++) {
        double s = 0.0;
        for (j = 0; j < nx; j++) s += c->net.A[(size_t)i * nx + j] * x[j];
        for (j = 0; j < nu; j++) s += c->net.B[(size_t)i * nu + j] * c->u[j];
        out[i] = s;
    }
}

static double output_value(prc_inst *c, const prc_output *o) {
    const int nx = c->net.nx, nu = c->net.nu;
    const double *x = states(c);
    double s = 0.0;
    int j;
    load_inputs(c);
    if (o->kind == PRC_OUT_STATE) return x[o->index];
    if (o->kind == PRC_OUT_INPUT) return c->u[o->index];
    for (j = 0; j < nx; j++) s += c->net.Cv[(size_t)o->index * nx + j] * x[j];
    for (j = 0; j < nu; j++) s += c->net.Dv[(size_t)o->index * nu + j] * c->u[j];
    return s;
}

static void restore_start(prc_inst *c) {
    memcpy(c->r, c->m->real_start, sizeof(double) * (size_t)c->m->n_real);
    if (c->m->n_int) memcpy(c->iv, c->m->int_start, sizeof(int) * (size_t)c->m->n_int);
    c->dirty = 1;
    c->time = 0.0;
    c->start_time = 0.0;
    c->stop_time = 0.0;
    c->stop_defined = 0;
    c->t_committed = 0.0;
    c->state = ST_INSTANTIATED;
}

static int is_state(const prc_model *m, int v) { return v >= m->vr_state0 && v < m->vr_state0 + nx_of(m); }

static int is_input(const prc_model *m, int v) {
    int j;
    for (j = 0; j < nu_of(m); j++)
        if (m->input_vr[j] == v) return 1;
    return 0;
}

/* Time events: advance the PRBS over every switching instant up to t (tolerance tol). */
static int catch_up(prc_inst *c, double t, double tol) {
    int changed = 0;
    if (!has_bridge(c->m)) return 0;
    while (next_switch(c) <= t + tol) {
        advance_bit(c);
        changed = 1;
    }
    return changed;
}

/* How close to a switching instant a time counts as at it. A co-simulation master that advances its
 * clock by adding the step h (t / h additions, each off by up to half an ulp of t) reaches a
 * communication point up to about DBL_EPSILON * t * t / h away from the exact multiple of h; a
 * switching instant that a step ends on must still switch there, so that the bridge voltage read at
 * that point is the level of the next step. At least 1e-9 of the step (or PRBS bit), at most a
 * quarter of it. Model exchange (h = 0) reaches the reported event times exactly. */
static double switch_tol(prc_inst *c, double h, double t) {
    double tclk = 1.0 / fclk(c);
    double base = h > 0.0 && h < tclk ? h : tclk;
    double tol = 1e-9 * base;
    double drift = h > 0.0 ? DBL_EPSILON * fabs(t) * (fabs(t) / h) : 0.0;
    if (drift > tol) tol = drift;
    return tol < 0.25 * base ? tol : 0.25 * base;
}

/* ------------------------------------------------------------------ common functions */

const char *PRC2(fmi2GetTypesPlatform)(void) { return fmi2TypesPlatform; }
const char *PRC2(fmi2GetVersion)(void) { return fmi2Version; }

fmi2Status PRC2(fmi2SetDebugLogging)(fmi2Component comp, fmi2Boolean loggingOn, size_t nCategories,
                               const fmi2String categories[]) {
    prc_inst *c = (prc_inst *)comp;
    (void)nCategories;
    (void)categories;
    if (!c) return fmi2Error;
    c->logging = loggingOn ? 1 : 0;
    return fmi2OK;
}

fmi2Component PRC2(fmi2Instantiate)(fmi2String instanceName, fmi2Type fmuType, fmi2String fmuGUID,
                              fmi2String fmuResourceLocation, const fmi2CallbackFunctions *functions,
                              fmi2Boolean visible, fmi2Boolean loggingOn) {
    const prc_model *m = &PRC_MODEL;
    prc_inst *c;
    int nx = nx_of(m), nu = nu_of(m), n = nx + nu, i;
    (void)fmuResourceLocation;
    (void)visible;
    if (!functions || !functions->allocateMemory || !functions->freeMemory) return NULL;
    c = (prc_inst *)functions->allocateMemory(1, sizeof(prc_inst));
    if (!c) return NULL;
    c->m = m;
    c->cb = *functions;
    c->type = fmuType;
    c->logging = loggingOn ? 1 : 0;
    c->name = (char *)alloc(c, strlen(instanceName ? instanceName : "") + 1, 1);
    strcpy(c->name, instanceName ? instanceName : "");
    if (!fmuGUID || strcmp(fmuGUID, m->guid) != 0) {
        logmsg(c, fmi2Error, "logStatusError", "fmi2Instantiate: GUID '%s' does not match the FMU ('%s')",
               fmuGUID ? fmuGUID : "(null)", m->guid);
        functions->freeMemory(c->name);
        functions->freeMemory(c);
        return NULL;
    }
    c->r = (double *)alloc(c, (size_t)m->n_real, sizeof(double));
    c->iv = (int *)alloc(c, (size_t)m->n_int, sizeof(int));
    c->net.N = m->n_nodes;
    c->net.nx = nx;
    c->net.nu = nu;
    c->net.A = (double *)alloc(c, (size_t)nx * nx, sizeof(double));
    c->net.B = (double *)alloc(c, (size_t)nx * nu, sizeof(double));
    c->net.Cv = (double *)alloc(c, (size_t)m->n_nodes * nx, sizeof(double));
    c->net.Dv = (double *)alloc(c, (size_t)m->n_nodes * nu, sizeof(double));
    c->u = (double *)alloc(c, (size_t)nu, sizeof(double));
    c->dx = (double *)alloc(c, (size_t)nx, sizeof(double));
    c->scratch = (double *)alloc(c, prc_network_scratch(m), sizeof(double));
    c->aug = (double *)alloc(c, (size_t)n * n, sizeof(double));
    c->augexp = (double *)alloc(c, (size_t)n * n, sizeof(double));
    c->work = (double *)alloc(c, PRC_EXPM_WORK(n), sizeof(double));
    c->ipiv = (int *)alloc(c, (size_t)n, sizeof(int));
    c->kx = (double *)alloc(c, (size_t)nx, sizeof(double));
    c->ku = (double *)alloc(c, (size_t)nu, sizeof(double));
    for (i = 0; i < PRC_CACHE; i++) {
        c->cache[i].Phi = (double *)alloc(c, (size_t)nx * nx, sizeof(double));
        c->cache[i].Gam = (double *)alloc(c, (size_t)nx * nu, sizeof(double));
    }
    restore_start(c);
    return c;
}

void PRC2(fmi2FreeInstance)(fmi2Component comp) {
    prc_inst *c = (prc_inst *)comp;
    fmi2CallbackFreeMemory f;
    int i;
    if (!c) return;
    f = c->cb.freeMemory;
    for (i = 0; i < PRC_CACHE; i++) {
        f(c->cache[i].Phi);
        f(c->cache[i].Gam);
    }
    f(c->r); f(c->iv); f(c->net.A); f(c->net.B); f(c->net.Cv); f(c->net.Dv);
    f(c->u); f(c->dx); f(c->kx); f(c->ku); f(c->scratch); f(c->aug); f(c->augexp); f(c->work); f(c->ipiv);
    f(c->name);
    f(c);
}

fmi2Status PRC2(fmi2SetupExperiment)(fmi2Component comp, fmi2Boolean toleranceDefined, fmi2Real tolerance,
                               fmi2Real startTime, fmi2Boolean stopTimeDefined, fmi2Real stopTime) {
    prc_inst *c = (prc_inst *)comp;
    (void)toleranceDefined; (void)tolerance;
    if (!c) return fmi2Error;
    if (c->state != ST_INSTANTIATED) return fail(c, "fmi2SetupExperiment", "only allowed after instantiation");
    if (!isfinite(startTime)) return fail(c, "fmi2SetupExperiment", "start time is not finite (got %g s)", startTime);
    if (stopTimeDefined && !(stopTime >= startTime))
        return fail(c, "fmi2SetupExperiment", "stop time %g s is before the start time %g s", stopTime, startTime);
    c->time = startTime;
    c->start_time = startTime;
    c->t_committed = startTime;
    c->stop_defined = stopTimeDefined ? 1 : 0;
    c->stop_time = stopTimeDefined ? stopTime : 0.0;
    return fmi2OK;
}

fmi2Status PRC2(fmi2EnterInitializationMode)(fmi2Component comp) {
    prc_inst *c = (prc_inst *)comp;
    if (!c || c->state != ST_INSTANTIATED) return fmi2Error;
    c->state = ST_INIT;
    return fmi2OK;
}

fmi2Status PRC2(fmi2ExitInitializationMode)(fmi2Component comp) {
    prc_inst *c = (prc_inst *)comp;
    fmi2Status s;
    if (!c) return fmi2Error;
    if (c->state != ST_INIT) return fail(c, "fmi2ExitInitializationMode", "not in initialization mode");
    s = ensure_built(c, "fmi2ExitInitializationMode");
    if (s != fmi2OK) return s;
    reset_prbs(c);
    if (has_bridge(c->m)) catch_up(c, c->time, switch_tol(c, 0.0, c->time));
    c->t_committed = c->time;
    c->state = ST_RUN;
    return fmi2OK;
}

fmi2Status PRC2(fmi2Terminate)(fmi2Component comp) {
    prc_inst *c = (prc_inst *)comp;
    if (!c) return fmi2Error;
    c->state = ST_TERMINATED;
    return fmi2OK;
}

fmi2Status PRC2(fmi2Reset)(fmi2Component comp) {
    prc_inst *c = (prc_inst *)comp;
    if (!c) return fmi2Error;
    restore_start(c);
    return fmi2OK;
}

static int is_output(const prc_model *m, int vr, const prc_output **o) {
    int k;
    for (k = 0; k < m->n_out; k++)
        if (m->outputs[k].vr == vr) {
            *o = &m->outputs[k];
            return 1;
        }
    return 0;
}

fmi2Status PRC2(fmi2GetReal)(fmi2Component comp, const fmi2ValueReference vr[], size_t nvr, fmi2Real value[]) {
    prc_inst *c = (prc_inst *)comp;
    const prc_model *m;
    size_t i;
    int built = 0, nx;
    if (!c) return fmi2Error;
    m = c->m;
    nx = nx_of(m);
    for (i = 0; i < nvr; i++) {
        int v = (int)vr[i];
        const prc_output *o;
        if (v < 0 || v >= m->n_real) return fail(c, "fmi2GetReal", "unknown value reference %d", v);
        if (c->state == ST_INSTANTIATED) {
            value[i] = c->r[v];
            continue;
        }
        if (!built) {
            if (ensure_built(c, "fmi2GetReal") != fmi2OK) return fmi2Error;
            built = 1;
        }
        if (is_output(m, v, &o)) {
            value[i] = output_value(c, o);
        } else if (v >= m->vr_deriv0 && v < m->vr_deriv0 + nx) {
            derivatives(c, c->dx);
            value[i] = c->dx[v - m->vr_deriv0];
        } else {
            value[i] = c->r[v];
        }
    }
    return fmi2OK;
}

fmi2Status PRC2(fmi2GetInteger)(fmi2Component comp, const fmi2ValueReference vr[], size_t nvr, fmi2Integer value[]) {
    prc_inst *c = (prc_inst *)comp;
    size_t i;
    if (!c) return fmi2Error;
    for (i = 0; i < nvr; i++) {
        if ((int)vr[i] >= c->m->n_int) return fail(c, "fmi2GetInteger", "unknown value reference %u", vr[i]);
        value[i] = c->iv[vr[i]];
    }
    return fmi2OK;
}

fmi2Status PRC2(fmi2GetBoolean)(fmi2Component comp, const fmi2ValueReference vr[], size_t nvr, fmi2Boolean value[]) {
    (void)value;
    if (nvr == 0) return fmi2OK;
    return fail((prc_inst *)comp, "fmi2GetBoolean", "the FMU has no Boolean variables (vr %u)", vr[0]);
}

fmi2Status PRC2(fmi2GetString)(fmi2Component comp, const fmi2ValueReference vr[], size_t nvr, fmi2String value[]) {
    (void)value;
    if (nvr == 0) return fmi2OK;
    return fail((prc_inst *)comp, "fmi2GetString", "the FMU has no String variables (vr %u)", vr[0]);
}

static fmi2Status check_settable(prc_inst *c, const char *fn, unsigned char how, const char *name) {
    if (how == PRC_SET_ALWAYS && c->state != ST_TERMINATED && c->state != ST_ERROR) return fmi2OK;
    if (how == PRC_SET_INIT && (c->state == ST_INSTANTIATED || c->state == ST_INIT)) return fmi2OK;
    if (how == PRC_SET_NEVER) return fail(c, fn, "variable '%s' cannot be set", name);
    return fail(c, fn, "variable '%s' can only be set before the end of initialization", name);
}

fmi2Status PRC2(fmi2SetReal)(fmi2Component comp, const fmi2ValueReference vr[], size_t nvr, const fmi2Real value[]) {
    prc_inst *c = (prc_inst *)comp;
    const prc_model *m;
    size_t i;
    if (!c) return fmi2Error;
    m = c->m;
    for (i = 0; i < nvr; i++) {
        int v = (int)vr[i];
        double old;
        if (v < 0 || v >= m->n_real) return fail(c, "fmi2SetReal", "unknown value reference %d", v);
        if (check_settable(c, "fmi2SetReal", m->real_settable[v], m->real_names[v]) != fmi2OK) return fmi2Error;
        if (!isfinite(value[i]))
            return fail(c, "fmi2SetReal", "value of '%s' is not finite (got %g)", m->real_names[v], value[i]);
        if (v == m->vr_vdc && !(value[i] > 0.0))
            return fail(c, "fmi2SetReal", "parameter 'vdc' must be positive (got %g V)", value[i]);
        old = c->r[v];
        c->r[v] = value[i];
        if (is_state(m, v) || is_input(m, v)) continue;
        c->dirty = 1;
        if (c->state == ST_RUN) {  /* tunable parameter: re-assemble now, keep the old value if refused */
            char msg[MSG_LEN];
            if (rebuild(c, msg, sizeof msg)) {
                char dummy[MSG_LEN];
                c->r[v] = old;
                if (rebuild(c, dummy, sizeof dummy)) c->state = ST_ERROR;
                return fail(c, "fmi2SetReal", "invalid parameters: %s", msg);
            }
        }
    }
    return fmi2OK;
}

fmi2Status PRC2(fmi2SetInteger)(fmi2Component comp, const fmi2ValueReference vr[], size_t nvr, const fmi2Integer value[]) {
    prc_inst *c = (prc_inst *)comp;
    size_t i;
    if (!c) return fmi2Error;
    for (i = 0; i < nvr; i++) {
        int v = (int)vr[i];
        if (v < 0 || v >= c->m->n_int) return fail(c, "fmi2SetInteger", "unknown value reference %d", v);
        if (check_settable(c, "fmi2SetInteger", c->m->int_settable[v], c->m->int_names[v]) != fmi2OK)
            return fmi2Error;

        c->iv[v] = value[i];
        c->dirty = 1;
    }
    return fmi2OK;
}

fmi2Status PRC2(fmi2SetBoolean)(fmi2Component comp, const fmi2ValueReference vr[], size_t nvr, const fmi2Boolean value[]) {
    (void)value;
    if (nvr == 0) return fmi2OK;
    return fail((prc_inst *)comp, "fmi2SetBoolean", "the FMU has no Boolean variables (vr %u)", vr[0]);
}

fmi2Status PRC2(fmi2SetString)(fmi2Component comp, const fmi2ValueReference vr[], size_t nvr, const fmi2String value[]) {
    (void)value;
    if (nvr == 0) return fmi2OK;
    return fail((prc_inst *)comp, "fmi2SetString", "the FMU has no String variables (vr %u)", vr[0]);
}

/* A saved FMU state: every variable, the time, the life-cycle state and the PRBS generator. */
typedef struct {
    unsigned int magic;
    int n_real, n_int;
    prc_state state;
    double time, start_time, stop_time, t_committed;
    int stop_defined, order;
    unsigned long long reg, mask, taps;
    long long bit;
} prc_saved_head;

#define PRC_STATE_MAGIC 0x50524353u

static size_t saved_size(const prc_model *m) {
    return sizeof(prc_saved_head) + sizeof(double) * (size_t)m->n_real + sizeof(int) * (size_t)m->n_int;
}

static void save_to(prc_inst *c, unsigned char *buf) {
    prc_saved_head h;
    memset(&h, 0, sizeof h);
    h.magic = PRC_STATE_MAGIC;
    h.n_real = c->m->n_real;
    h.n_int = c->m->n_int;
    h.state = c->state;
    h.time = c->time;
    h.start_time = c->start_time;
    h.stop_time = c->stop_time;
    h.t_committed = c->t_committed;
    h.stop_defined = c->stop_defined;
    h.order = c->order;
    h.reg = c->reg;
    h.mask = c->mask;
    h.taps = c->taps;
    h.bit = c->bit;
    memcpy(buf, &h, sizeof h);
    memcpy(buf + sizeof h, c->r, sizeof(double) * (size_t)c->m->n_real);
    memcpy(buf + sizeof h + sizeof(double) * (size_t)c->m->n_real, c->iv, sizeof(int) * (size_t)c->m->n_int);
}

/* Restore a saved state; the model is re-assembled only if a parameter differs. */
static fmi2Status restore_from(prc_inst *c, const unsigned char *buf, const char *fn) {
    const prc_model *m = c->m;
    prc_saved_head h;
    const double *r;
    const int *iv;
    int v, changed = 0;
    memcpy(&h, buf, sizeof h);
    if (h.magic != PRC_STATE_MAGIC || h.n_real != m->n_real || h.n_int != m->n_int)
        return fail(c, fn, "the FMU state does not belong to this model");
    r = (const double *)(buf + sizeof h);
    iv = (const int *)(buf + sizeof h + sizeof(double) * (size_t)m->n_real);
    for (v = 0; v < m->n_real && !changed; v++)
        if (!is_state(m, v) && !is_input(m, v) && m->real_settable[v] != PRC_SET_NEVER && r[v] != c->r[v])
            changed = 1;
    for (v = 0; v < m->n_int && !changed; v++)
        if (iv[v] != c->iv[v]) changed = 1;
    memcpy(c->r, r, sizeof(double) * (size_t)m->n_real);
    memcpy(c->iv, iv, sizeof(int) * (size_t)m->n_int);
    c->state = h.state;
    c->time = h.time;
    c->start_time = h.start_time;
    c->stop_time = h.stop_time;
    c->t_committed = h.t_committed;
    c->stop_defined = h.stop_defined;
    c->order = h.order;
    c->reg = h.reg;
    c->mask = h.mask;
    c->taps = h.taps;
    c->bit = h.bit;
    if (changed) c->dirty = 1;
    return fmi2OK;
}

fmi2Status PRC2(fmi2GetFMUstate)(fmi2Component comp, fmi2FMUstate *FMUstate) {
    prc_inst *c = (prc_inst *)comp;
    unsigned char *buf;
    if (!c || !FMUstate) return fmi2Error;
    buf = (unsigned char *)(*FMUstate ? *FMUstate : alloc(c, saved_size(c->m), 1));
    if (!buf) return fail(c, "fmi2GetFMUstate", "out of memory");
    save_to(c, buf);
    *FMUstate = buf;
    return fmi2OK;
}

fmi2Status PRC2(fmi2SetFMUstate)(fmi2Component comp, fmi2FMUstate FMUstate) {
    prc_inst *c = (prc_inst *)comp;
    if (!c) return fmi2Error;
    if (!FMUstate) return fail(c, "fmi2SetFMUstate", "no FMU state given");
    return restore_from(c, (const unsigned char *)FMUstate, "fmi2SetFMUstate");
}

fmi2Status PRC2(fmi2FreeFMUstate)(fmi2Component comp, fmi2FMUstate *FMUstate) {
    prc_inst *c = (prc_inst *)comp;
    if (!c || !FMUstate) return fmi2Error;
    if (*FMUstate) c->cb.freeMemory(*FMUstate);
    *FMUstate = NULL;
    return fmi2OK;
}

fmi2Status PRC2(fmi2SerializedFMUstateSize)(fmi2Component comp, fmi2FMUstate FMUstate, size_t *size) {
    prc_inst *c = (prc_inst *)comp;
    (void)FMUstate;
    if (!c || !size) return fmi2Error;
    *size = saved_size(c->m);
    return fmi2OK;
}

fmi2Status PRC2(fmi2SerializeFMUstate)(fmi2Component comp, fmi2FMUstate FMUstate, fmi2Byte serializedState[], size_t size) {
    prc_inst *c = (prc_inst *)comp;
    if (!c) return fmi2Error;
    if (!FMUstate || size < saved_size(c->m))
        return fail(c, "fmi2SerializeFMUstate", "buffer of %lu bytes is too small", (unsigned long)size);
    memcpy(serializedState, FMUstate, saved_size(c->m));
    return fmi2OK;
}

fmi2Status PRC2(fmi2DeSerializeFMUstate)(fmi2Component comp, const fmi2Byte serializedState[], size_t size,
                                   fmi2FMUstate *FMUstate) {
    prc_inst *c = (prc_inst *)comp;
    prc_saved_head h;
    unsigned char *buf;
    if (!c || !FMUstate) return fmi2Error;
    if (size != saved_size(c->m)) return fail(c, "fmi2DeSerializeFMUstate", "wrong size %lu", (unsigned long)size);
    memcpy(&h, serializedState, sizeof h);
    if (h.magic != PRC_STATE_MAGIC || h.n_real != c->m->n_real || h.n_int != c->m->n_int)
        return fail(c, "fmi2DeSerializeFMUstate", "the bytes are no FMU state of this model");
    buf = (unsigned char *)(*FMUstate ? *FMUstate : alloc(c, size, 1));
    if (!buf) return fail(c, "fmi2DeSerializeFMUstate", "out of memory");
    memcpy(buf, serializedState, size);
    *FMUstate = buf;
    return fmi2OK;
}

/* The model is linear: d(derivatives) = A dx + B du, d(node outputs) = Cv dx + Dv du. */
fmi2Status PRC2(fmi2GetDirectionalDerivative)(fmi2Component comp, const fmi2ValueReference vUnknown_ref[], size_t nUnknown,
                                        const fmi2ValueReference vKnown_ref[], size_t nKnown,
                                        const fmi2Real dvKnown[], fmi2Real dvUnknown[]) {
    prc_inst *c = (prc_inst *)comp;
    const prc_model *m;
    size_t i;
    int j, nx, nu;
    if (!c) return fmi2Error;
    if (c->state == ST_INSTANTIATED)
        return fail(c, "fmi2GetDirectionalDerivative", "not before initialization mode");
    if (ensure_built(c, "fmi2GetDirectionalDerivative") != fmi2OK) return fmi2Error;
    m = c->m;
    nx = c->net.nx;
    nu = c->net.nu;
    memset(c->kx, 0, sizeof(double) * (size_t)nx);
    memset(c->ku, 0, sizeof(double) * (size_t)nu);
    for (i = 0; i < nKnown; i++) {
        int v = (int)vKnown_ref[i], found = 0;
        if (v >= 0 && is_state(m, v)) {
            c->kx[v - m->vr_state0] += dvKnown[i];
            found = 1;
        }
        for (j = 0; j < nu; j++)
            if (m->input_vr[j] == v) {
                c->ku[j] += dvKnown[i];
                found = 1;
            }
        if (!found)
            return fail(c, "fmi2GetDirectionalDerivative", "known vr %d is neither a state nor an input", v);
    }
    for (i = 0; i < nUnknown; i++) {
        int v = (int)vUnknown_ref[i];
        const prc_output *o;
        const double *ra, *rb;
        double s = 0.0;
        if (v >= m->vr_deriv0 && v < m->vr_deriv0 + nx) {
            ra = c->net.A + (size_t)(v - m->vr_deriv0) * nx;
            rb = c->net.B + (size_t)(v - m->vr_deriv0) * nu;
        } else if (is_output(m, v, &o)) {
            if (o->kind == PRC_OUT_STATE) {
                dvUnknown[i] = c->kx[o->index];
                continue;
            }
            if (o->kind == PRC_OUT_INPUT) {
                dvUnknown[i] = c->ku[o->index];
                continue;
            }
            ra = c->net.Cv + (size_t)o->index * nx;
            rb = c->net.Dv + (size_t)o->index * nu;
        } else {
            return fail(c, "fmi2GetDirectionalDerivative", "unknown vr %d is neither a derivative nor an output", v);
        }
        for (j = 0; j < nx; j++) s += ra[j] * c->kx[j];
        for (j = 0; j < nu; j++) s += rb[j] * c->ku[j];
        dvUnknown[i] = s;
    }
    return fmi2OK;
}

/* ------------------------------------------------------------------ model exchange */

fmi2Status PRC2(fmi2EnterEventMode)(fmi2Component comp) {
    prc_inst *c = (prc_inst *)comp;
    if (!c) return fmi2Error;
    c->t_committed = c->time;
    return fmi2OK;
}

fmi2Status PRC2(fmi2NewDiscreteStates)(fmi2Component comp, fmi2EventInfo *info) {
    prc_inst *c = (prc_inst *)comp;
    if (!c) return fmi2Error;
    if (ensure_built(c, "fmi2NewDiscreteStates") != fmi2OK) return fmi2Error;
    info->newDiscreteStatesNeeded = fmi2False;
    info->terminateSimulation = fmi2False;
    info->nominalsOfContinuousStatesChanged = fmi2False;
    info->valuesOfContinuousStatesChanged = fmi2False;
    info->nextEventTimeDefined = fmi2False;
    info->nextEventTime = 0.0;
    if (has_bridge(c->m)) {
        /* the bridge voltage steps: the derivatives jump, so integrators must restart here */
        int before = current_bit(c);
        if (catch_up(c, c->time, switch_tol(c, 0.0, c->time)) && current_bit(c) != before)
            info->valuesOfContinuousStatesChanged = fmi2True;
        info->nextEventTimeDefined = fmi2True;
        info->nextEventTime = next_switch(c);
    }
    return fmi2OK;
}

fmi2Status PRC2(fmi2EnterContinuousTimeMode)(fmi2Component comp) {
    return comp ? fmi2OK : fmi2Error;
}

fmi2Status PRC2(fmi2CompletedIntegratorStep)(fmi2Component comp, fmi2Boolean noSetFMUStatePriorToCurrentPoint,
                                       fmi2Boolean *enterEventMode, fmi2Boolean *terminateSimulation) {
    prc_inst *c = (prc_inst *)comp;
    (void)noSetFMUStatePriorToCurrentPoint;
    if (!c) return fmi2Error;
    c->t_committed = c->time;
    *enterEventMode = fmi2False;
    *terminateSimulation = fmi2False;
    return fmi2OK;
}

fmi2Status PRC2(fmi2SetTime)(fmi2Component comp, fmi2Real time) {
    prc_inst *c = (prc_inst *)comp;
    if (!c) return fmi2Error;
    if (!isfinite(time)) return fail(c, "fmi2SetTime", "time is not finite (got %g s)", time);
    if (c->state == ST_RUN && time < c->t_committed - 1e-12 * (fabs(c->t_committed) + 1e-300))
        return fail(c, "fmi2SetTime", "time %.17g s is before the last completed step or event at %.17g s", time,
                    c->t_committed);
    c->time = time;
    return fmi2OK;
}

fmi2Status PRC2(fmi2SetContinuousStates)(fmi2Component comp, const fmi2Real x[], size_t nx) {
    prc_inst *c = (prc_inst *)comp;
    size_t i;
    if (!c || (int)nx != nx_of(c->m)) return fmi2Error;
    for (i = 0; i < nx; i++)
        if (!isfinite(x[i]))
            return fail(c, "fmi2SetContinuousStates", "state '%s' is not finite (got %g)",
                        c->m->real_names[c->m->vr_state0 + (int)i], x[i]);
    memcpy(states(c), x, sizeof(double) * nx);
    return fmi2OK;
}

fmi2Status PRC2(fmi2GetDerivatives)(fmi2Component comp, fmi2Real derivs[], size_t nx) {
    prc_inst *c = (prc_inst *)comp;
    if (!c || (int)nx != nx_of(c->m)) return fmi2Error;
    if (ensure_built(c, "fmi2GetDerivatives") != fmi2OK) return fmi2Error;
    derivatives(c, derivs);
    return fmi2OK;
}

fmi2Status PRC2(fmi2GetEventIndicators)(fmi2Component comp, fmi2Real eventIndicators[], size_t ni) {
    (void)eventIndicators;
    return comp && ni == 0 ? fmi2OK : fmi2Error;
}

fmi2Status PRC2(fmi2GetContinuousStates)(fmi2Component comp, fmi2Real x[], size_t nx) {
    prc_inst *c = (prc_inst *)comp;
    if (!c || (int)nx != nx_of(c->m)) return fmi2Error;
    memcpy(x, states(c), sizeof(double) * nx);
    return fmi2OK;
}

fmi2Status PRC2(fmi2GetNominalsOfContinuousStates)(fmi2Component comp, fmi2Real x_nominal[], size_t nx) {
    prc_inst *c = (prc_inst *)comp;
    size_t i;
    if (!c || (int)nx != nx_of(c->m)) return fmi2Error;
    for (i = 0; i < nx; i++) x_nominal[i] = c->m->state_nominal[i];
    return fmi2OK;
}

/* ------------------------------------------------------------------ co-simulation */

fmi2Status PRC2(fmi2SetRealInputDerivatives)(fmi2Component comp, const fmi2ValueReference vr[], size_t nvr,
                                       const fmi2Integer order[], const fmi2Real value[]) {
    (void)vr; (void)nvr; (void)order; (void)value;
    return fail((prc_inst *)comp, "fmi2SetRealInputDerivatives", "inputs are held constant (zero-order hold)");
}

fmi2Status PRC2(fmi2GetRealOutputDerivatives)(fmi2Component comp, const fmi2ValueReference vr[], size_t nvr,
                                        const fmi2Integer order[], fmi2Real value[]) {
    (void)vr; (void)nvr; (void)order; (void)value;
    return fail((prc_inst *)comp, "fmi2GetRealOutputDerivatives", "not supported");
}

fmi2Status PRC2(fmi2DoStep)(fmi2Component comp, fmi2Real t0, fmi2Real h, fmi2Boolean noSetFMUStatePriorToCurrentPoint) {
    prc_inst *c = (prc_inst *)comp;
    double t, t_end, tol;
    int first = 1;
    (void)noSetFMUStatePriorToCurrentPoint;
    if (!c) return fmi2Error;
    if (c->state != ST_RUN) return fail(c, "fmi2DoStep", "not in step mode (initialize first)");
    if (ensure_built(c, "fmi2DoStep") != fmi2OK) return fmi2Error;
    if (!(h > 0.0)) return fail(c, "fmi2DoStep", "communication step size must be positive (got %g s)", h);
    if (has_bridge(c->m) && h * fclk(c) > c->m->max_switches)
        return fail(c, "fmi2DoStep", "a step of %g s holds %.3g switching instants, more than the limit of %.3g", h,
                    h * fclk(c), c->m->max_switches);
    t = t0;
    t_end = t0 + h;
    tol = has_bridge(c->m) ? switch_tol(c, h, t_end) : 0.0;
    if (has_bridge(c->m)) catch_up(c, t, tol);
    for (;;) {
        double seg_end = t_end, dt;
        int split = 0;
        if (has_bridge(c->m)) {
            double ts = next_switch(c);
            if (ts < t_end - tol) {
                seg_end = ts;
                split = 1;
            }
        }
        dt = (first && !split) ? h : seg_end - t;
        if (dt > 0.0 && zoh_step(c, dt))
            return fail(c, "fmi2DoStep", "matrix exponential failed for step %g s", dt);
        t = seg_end;
        first = 0;
        if (!split) break;
        advance_bit(c);
    }
    if (has_bridge(c->m)) catch_up(c, t_end, tol);
    c->time = t_end;
    return fmi2OK;
}

fmi2Status PRC2(fmi2CancelStep)(fmi2Component comp) {
    return fail((prc_inst *)comp, "fmi2CancelStep", "doStep is never asynchronous");
}

fmi2Status PRC2(fmi2GetStatus)(fmi2Component comp, const fmi2StatusKind s, fmi2Status *value) {
    (void)s; (void)value;
    return comp ? fmi2Discard : fmi2Error;
}

fmi2Status PRC2(fmi2GetRealStatus)(fmi2Component comp, const fmi2StatusKind s, fmi2Real *value) {
    prc_inst *c = (prc_inst *)comp;
    if (!c) return fmi2Error;
    if (s == fmi2LastSuccessfulTime) {
        *value = c->time;
        return fmi2OK;
    }
    return fmi2Discard;
}

fmi2Status PRC2(fmi2GetIntegerStatus)(fmi2Component comp, const fmi2StatusKind s, fmi2Integer *value) {
    (void)s; (void)value;
    return comp ? fmi2Discard : fmi2Error;
}

fmi2Status PRC2(fmi2GetBooleanStatus)(fmi2Component comp, const fmi2StatusKind s, fmi2Boolean *value) {
    if (!comp) return fmi2Error;
    if (s == fmi2Terminated) {
        *value = fmi2False;
        return fmi2OK;
    }
    return fmi2Discard;
}

fmi2Status PRC2(fmi2GetStringStatus)(fmi2Component comp, const fmi2StatusKind s, fmi2String *value) {
    (void)s; (void)value;
    return comp ? fmi2Discard : fmi2Error;
}

#ifdef PRC_FMI3
double prc2_time(fmi2Component comp) { return comp ? ((prc_inst *)comp)->time : 0.0; }
#endif
