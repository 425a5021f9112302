/* FMI 2.0 co-simulation glue shared by every native ipcosim model (see model.h).
 *
 * Hand-written and model-independent: instance life cycle, get/set by value reference, the
 * three stepping policies (plant, sampled law, time source) and error reporting. A failed
 * step is reported through the logger and returns fmi2Discard with the state kept at t.
 * A plant also offers model exchange (fmi2me.h, included at the end).
 */
#include <math.h>
#include <stdarg.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "fmi2Functions.h"
#include "model.h"

#define TICK_TOLERANCE 1e-6
#define STEP_TOLERANCE 1e-9

/* ST_EVENT, ST_CONTINUOUS: model exchange's Event Mode and Continuous-Time Mode (fmi2me.h) */
typedef enum { ST_INSTANTIATED, ST_INIT, ST_STEP, ST_TERMINATED, ST_ERROR, ST_EVENT, ST_CONTINUOUS } Phase;

typedef struct {
    const ModelInfo *m;
    double *v;
    double *scratch;
    fmi2CallbackLogger logger;
    fmi2ComponentEnvironment env;
    char *name;
    int logging;
    Phase phase;
    double t0;
    int exchange;   /* instantiated for model exchange */
    double time;    /* model exchange: the time the host set */
    int fresh;      /* model exchange: derivatives, event indicators and outputs are those of v */
    int iterations; /* model exchange: passes of the event iteration at this event */
} Instance;

static void report(Instance *c, fmi2Status status, const char *category, const char *fmt, ...) {
    char msg[512];
    va_list ap;
    if (c == NULL || c->logger == NULL) return;
    va_start(ap, fmt);
    vsnprintf(msg, sizeof msg, fmt, ap);
    va_end(ap);
    c->logger(c->env, c->name, status, category, "%s", msg);
}

static const ModelVariable *lookup(const Instance *c, fmi2ValueReference vr) {
    if (vr >= (fmi2ValueReference)c->m->nby_vr || c->m->by_vr[vr] < 0) return NULL;
    return &c->m->vars[c->m->by_vr[vr]];
}

const char *fmi2GetTypesPlatform(void) { return fmi2TypesPlatform; }
const char *fmi2GetVersion(void) { return fmi2Version; }

fmi2Status fmi2SetDebugLogging(fmi2Component comp, fmi2Boolean on, size_t n, const fmi2String cats[]) {
    Instance *c = (Instance *)comp;
    (void)n;
    (void)cats;
    if (c == NULL) return fmi2Error;
    c->logging = on ? 1 : 0;
    return fmi2OK;
}

static void reset_values(Instance *c) {
    memcpy(c->v, c->m->start, (size_t)c->m->nv * sizeof(double));
    c->phase = ST_INSTANTIATED;
    c->t0 = 0.0;
    c->time = 0.0;
    c->fresh = 0;
}

static fmi2Status exchange_start(Instance *c); /* fmi2me.h */
static void refresh(Instance *c, const fmi2ValueReference vr[], size_t n);

fmi2Component fmi2Instantiate(fmi2String name, fmi2Type type, fmi2String guid, fmi2String location,
                              const fmi2CallbackFunctions *functions, fmi2Boolean visible, fmi2Boolean logging) {
    Instance *c;
    fmi2CallbackLogger logger = functions != NULL ? functions->logger : NULL;
    fmi2ComponentEnvironment env = functions != NULL ? functions->componentEnvironment : NULL;
    (void)location;
    (void)visible;
    int exchange = type == fmi2ModelExchange && model_info.exchange != NULL;
    if ((type != fmi2CoSimulation && !exchange) || guid == NULL || strcmp(guid, model_info.guid) != 0) {
        if (logger != NULL)
            logger(env, name != NULL ? name : "?", fmi2Error, "logStatusError",
                   "%s: %s", model_info.identifier,
                   type != fmi2CoSimulation && !exchange ? "only co-simulation is supported"
                                                         : "GUID does not match the model");
        return NULL;
    }
    c = (Instance *)calloc(1, sizeof(Instance));
    if (c == NULL) return NULL;
    c->m = &model_info;
    c->v = (double *)calloc((size_t)model_info.nv, sizeof(double));
    c->scratch = (double *)calloc((size_t)model_info.nv, sizeof(double));
    c->name = (char *)calloc(strlen(name != NULL ? name : "") + 1, 1);
    if (c->v == NULL || c->scratch == NULL || c->name == NULL) {
        free(c->v);
        free(c->scratch);
        free(c->name);
        free(c);
        return NULL;
    }
    strcpy(c->name, name != NULL ? name : "");
    c->logger = logger;
    c->env = env;
    c->logging = logging ? 1 : 0;
    c->exchange = exchange;
    reset_values(c);
    return c;
}

void fmi2FreeInstance(fmi2Component comp) {
    Instance *c = (Instance *)comp;
    if (c == NULL) return;
    free(c->v);
    free(c->scratch);
    free(c->name);
    free(c);
}

fmi2Status fmi2SetupExperiment(fmi2Component comp, fmi2Boolean tol_defined, fmi2Real tol, fmi2Real start,
                               fmi2Boolean stop_defined, fmi2Real stop) {
    Instance *c = (Instance *)comp;
    (void)tol_defined;
    (void)tol;
    (void)stop_defined;
    (void)stop;
    if (c == NULL || c->phase != ST_INSTANTIATED) return fmi2Error;
    c->t0 = start;
    return fmi2OK;
}

fmi2Status fmi2EnterInitializationMode(fmi2Component comp) {
    Instance *c = (Instance *)comp;
    if (c == NULL || c->phase != ST_INSTANTIATED) return fmi2Error;
    c->phase = ST_INIT;
    return fmi2OK;
}

static int parameters_valid(Instance *c) {
    int i;
    static const char *const need[] = {"be a finite number", "be > 0", "be >= 0",
                                       "be 0 in the native flavour (no measurement noise or taps: use the python flavour)"};
    for (i = 0; i < c->m->nchecks; i++) {
        const ParameterCheck *k = &c->m->checks[i];
        double x = c->v[k->index];
        int ok = isfinite(x) && (k->kind != CHECK_POSITIVE || x > 0.0) && (k->kind != CHECK_NONNEGATIVE || x >= 0.0) &&
                 (k->kind != CHECK_ZERO || x == 0.0);
        if (!ok) {
            report(c, fmi2Error, "logStatusError", "%s: parameter %s = %g must %s", c->m->identifier, k->name, x,
                   need[k->kind]);
            return 0;
        }
    }
    return 1;
}

fmi2Status fmi2ExitInitializationMode(fmi2Component comp) {
    Instance *c = (Instance *)comp;
    if (c == NULL || c->phase != ST_INIT) return fmi2Error;
    if (!parameters_valid(c)) {
        c->phase = ST_ERROR;
        return fmi2Error;
    }
    if (c->m->period_index >= 0) {
        double p = c->v[c->m->period_index];
        if (!(p > 0.0) || !isfinite(p)) {
            report(c, fmi2Error, "logStatusError", "%s: parameter %s = %g s must be > 0", c->m->identifier,
                   c->m->kind == MODEL_KIND_PLANT ? "integrator_step" : "sample_period", p);
            c->phase = ST_ERROR;
            return fmi2Error;
        }
    }
    if (c->exchange) return exchange_start(c);
    c->m->initialize(c->v, c->t0);
    c->phase = ST_STEP;
    return fmi2OK;
}

fmi2Status fmi2Terminate(fmi2Component comp) {
    Instance *c = (Instance *)comp;
    if (c == NULL) return fmi2Error;
    c->phase = ST_TERMINATED;
    return fmi2OK;
}

fmi2Status fmi2Reset(fmi2Component comp) {
    Instance *c = (Instance *)comp;
    if (c == NULL) return fmi2Error;
    reset_values(c);
    return fmi2OK;
}

/* Run the model's step on a scratch copy; commit only if every checked slot is finite. */
static fmi2Status guarded_step(Instance *c, double t, double h) {
    int i;
    memcpy(c->scratch, c->v, (size_t)c->m->nv * sizeof(double));
    c->m->step(c->scratch, t, h);
    for (i = 0; i < c->m->nchecked; i++) {
        if (!isfinite(c->scratch[c->m->checked[i]])) {
            report(c, fmi2Discard, "logStatusDiscard", "%s: state became non-finite in the step from t = %g s "
                   "(h = %g s); state kept at t", c->m->identifier, t, h);
            return fmi2Discard;
        }
    }
    memcpy(c->v, c->scratch, (size_t)c->m->nv * sizeof(double));
    return fmi2OK;
}

static fmi2Status sampled_step(Instance *c, double t, double h) {
    double T = c->v[c->m->period_index];
    double ticks, k, tick = c->v[c->m->tick_index];
    if (h > T * (1.0 + TICK_TOLERANCE)) {
        report(c, fmi2Discard, "logStatusDiscard", "%s: communication step h = %g s is longer than sample_period = "
               "%g s: the controller would miss sample instants (use a master step that divides sample_period)",
               c->m->identifier, h, T);
        return fmi2Discard;
    }
    ticks = (t + h - c->t0) / T;
    k = floor(ticks + 0.5);
    if (fabs(ticks - k) <= TICK_TOLERANCE && k > tick) {
        fmi2Status s;
        if (k != tick + 1.0) {
            report(c, fmi2Discard, "logStatusDiscard", "%s: sample instant %.0f (t = %g s) was skipped by the step "
                   "from t = %g s", c->m->identifier, tick + 1.0, c->t0 + (tick + 1.0) * T, t);
            return fmi2Discard;
        }
        s = guarded_step(c, t, h);
        if (s == fmi2OK) c->v[c->m->tick_index] = k;
        return s;
    }
    return fmi2OK;
}

fmi2Status fmi2DoStep(fmi2Component comp, fmi2Real t, fmi2Real h, fmi2Boolean no_prior) {
    Instance *c = (Instance *)comp;
    (void)no_prior;
    if (c == NULL || c->phase != ST_STEP) return fmi2Error;
    if (!(h > 0.0) || !isfinite(h)) {
        report(c, fmi2Error, "logStatusError", "%s: step size h = %g s must be positive", c->m->identifier, h);
        return fmi2Error;
    }
    if (c->m->kind == MODEL_KIND_SAMPLED) return sampled_step(c, t, h);
    if (c->m->kind == MODEL_KIND_PLANT) {
        double step = c->v[c->m->period_index];
        if (fabs(h - step) > STEP_TOLERANCE * step) {
            report(c, fmi2Discard, "logStatusDiscard", "%s: communication step h = %g s differs from parameter "
                   "integrator_step = %g s (the integrator's coefficients are computed for that step)",
                   c->m->identifier, h, step);
            return fmi2Discard;
        }
    }
    return guarded_step(c, t, h);
}

#define FMI2_SHARED_INSTANCE Instance
#define FMI2_SHARED_BEFORE_GET(c, vr, n) refresh(c, vr, n)
#define FMI2_SHARED_AFTER_SET(c) ((c)->fresh = 0)
#include "fmi2shared.h"
#include "fmi2me.h"
