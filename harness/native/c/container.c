/* FMI 2.0 co-simulation glue shared by every scenario exported with `ipcosim export` (see
 * container.h): a closed loop of native components run as one FMU.
 *
 * Hand-written and scenario-independent: the generated table (container_table.c) says which
 * components there are, their step order and multiples, the connections and the container's
 * variables. The stepping is that of the ipcosim master's Gauss-Seidel algorithm
 * (harness/master/algorithm.py and execution.py):
 *   - initialization: every component's parameters are set, it enters initialization mode, its
 *     outputs are read; sweeps in step order (transfer, set inputs, read outputs) until no input
 *     changes; then, in step order, each component gets its inputs, leaves initialization mode
 *     and its outputs are read;
 *   - tick n advances from t_n = (start_ns + n step_ns) / 1e9 to t_(n+1); in step order a
 *     component with multiple m steps when (n + 1) % m == 0, from t_(floor(n/m) m), with step
 *     (m step_ns) / 1e9, its inputs set just before and its outputs read just after.
 * The container's communication step must be a whole number of ticks; each fmi2DoStep runs
 * that many ticks.
 */
#include <math.h>
#include <stdarg.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "container.h"
#include "fmi2Functions.h"

#define TIME_TOLERANCE 1e-6 /* of a tick: how far the host's time may be from the container's */
#define MULTIPLE_TOLERANCE 1e-9
#define EXACT_NS 9007199254740992.0 /* 2^53: nanosecond counts beyond it are not exact doubles */

typedef enum { ST_INSTANTIATED, ST_INIT, ST_STEP, ST_TERMINATED, ST_ERROR } Phase;

typedef struct {
    const ContainerInfo *m;
    double *v;
    fmi2Component *comp;  /* one instance per component */
    double **out;         /* each component's outputs as last read */
    double **in;          /* each component's inputs as last set */
    fmi2CallbackFunctions functions;
    char *name;
    Phase phase;
    double start;
    int stop_defined;
    double stop;
    long long start_ns;   /* start time in nanoseconds, when it is a whole number of them */
    int exact;
    long long tick;       /* ticks done since the start */
} Container;

static void report(Container *c, fmi2Status status, const char *category, const char *fmt, ...) {
    char msg[512];
    va_list ap;
    if (c == NULL || c->functions.logger == NULL) return;
    va_start(ap, fmt);
    vsnprintf(msg, sizeof msg, fmt, ap);
    va_end(ap);
    c->functions.logger(c->functions.componentEnvironment, c->name, status, category, "%s", msg);
}

/* t_n, as the master's TimeBase computes it. */
static double tick_time(const Container *c, long long n) {
    if (c->exact && (double)c->start_ns + (double)n * (double)c->m->step_ns < EXACT_NS)
        return (double)(c->start_ns + n * c->m->step_ns) / 1e9;
    return c->start + (double)n * c->m->step;
}

static double span(const Container *c, int multiple) {
    if (c->exact) return (double)((long long)multiple * c->m->step_ns) / 1e9;
    return (double)multiple * c->m->step;
}

static const ModelVariable *lookup(const Container *c, fmi2ValueReference vr) {
    if (vr >= (fmi2ValueReference)c->m->nby_vr || c->m->by_vr[vr] < 0) return NULL;
    return &c->m->vars[c->m->by_vr[vr]];
}

static fmi2Status failed(Container *c, int k, const char *function, fmi2Status s, double t) {
    report(c, fmi2Error, "logStatusError", "%s: component %s: %s returned status %d at t = %g s",
           c->m->identifier, c->m->components[k].name, function, (int)s, t);
    c->phase = ST_ERROR;
    return fmi2Error;
}

const char *fmi2GetTypesPlatform(void) { return fmi2TypesPlatform; }
const char *fmi2GetVersion(void) { return fmi2Version; }

fmi2Status fmi2SetDebugLogging(fmi2Component comp, fmi2Boolean on, size_t n, const fmi2String cats[]) {
    (void)on;
    (void)n;
    (void)cats;
    return comp != NULL ? fmi2OK : fmi2Error;
}

static void free_container(Container *c) {
    int k;
    if (c == NULL) return;
    for (k = 0; k < c->m->ncomponents; k++) {
        if (c->comp != NULL && c->comp[k] != NULL) c->m->components[k].fmi->free_instance(c->comp[k]);
        if (c->out != NULL) free(c->out[k]);
        if (c->in != NULL) free(c->in[k]);
    }
    free(c->comp);
    free(c->out);
    free(c->in);
    free(c->v);
    free(c->name);
    free(c);
}

static int allocate(Container *c, const char *name) {
    int k, n = c->m->ncomponents;
    c->v = (double *)calloc((size_t)c->m->nv, sizeof(double));
    c->comp = (fmi2Component *)calloc((size_t)n, sizeof(fmi2Component));
    c->out = (double **)calloc((size_t)n, sizeof(double *));
    c->in = (double **)calloc((size_t)n, sizeof(double *));
    c->name = (char *)calloc(strlen(name) + 1, 1);
    if (c->v == NULL || c->comp == NULL || c->out == NULL || c->in == NULL || c->name == NULL) return 0;
    for (k = 0; k < n; k++) {
        c->out[k] = (double *)calloc((size_t)c->m->components[k].n_out + 1, sizeof(double));
        c->in[k] = (double *)calloc((size_t)c->m->components[k].n_in + 1, sizeof(double));
        if (c->out[k] == NULL || c->in[k] == NULL) return 0;
    }
    strcpy(c->name, name);
    memcpy(c->v, c->m->start, (size_t)c->m->nv * sizeof(double));
    return 1;
}

static int instantiate_components(Container *c, fmi2String location) {
    int k;
    for (k = 0; k < c->m->ncomponents; k++) {
        const ContainerComponent *cc = &c->m->components[k];
        c->comp[k] = cc->fmi->instantiate(cc->name, fmi2CoSimulation, cc->guid, location, &c->functions, fmi2False,
                                          fmi2False);
        if (c->comp[k] == NULL) {
            report(c, fmi2Error, "logStatusError", "%s: component %s could not be instantiated",
                   c->m->identifier, cc->name);
            return 0;
        }
    }
    return 1;
}

fmi2Component fmi2Instantiate(fmi2String name, fmi2Type type, fmi2String guid, fmi2String location,
                              const fmi2CallbackFunctions *functions, fmi2Boolean visible, fmi2Boolean logging) {
    Container *c;
    fmi2CallbackLogger logger = functions != NULL ? functions->logger : NULL;
    fmi2ComponentEnvironment env = functions != NULL ? functions->componentEnvironment : NULL;
    (void)visible;
    (void)logging;
    if (type != fmi2CoSimulation || guid == NULL || strcmp(guid, container_info.guid) != 0) {
        if (logger != NULL)
            logger(env, name != NULL ? name : "?", fmi2Error, "logStatusError", "%s: %s", container_info.identifier,
                   type != fmi2CoSimulation ? "only co-simulation is supported" : "GUID does not match the model");
        return NULL;
    }
    c = (Container *)calloc(1, sizeof(Container));
    if (c == NULL) return NULL;
    c->m = &container_info;
    if (functions != NULL) c->functions = *functions;
    if (!allocate(c, name != NULL ? name : "") || !instantiate_components(c, location)) {
        free_container(c);
        return NULL;
    }
    c->phase = ST_INSTANTIATED;
    return c;
}

void fmi2FreeInstance(fmi2Component comp) { free_container((Container *)comp); }

fmi2Status fmi2SetupExperiment(fmi2Component comp, fmi2Boolean tol_defined, fmi2Real tol, fmi2Real start,
                               fmi2Boolean stop_defined, fmi2Real stop) {
    Container *c = (Container *)comp;
    (void)tol_defined;
    (void)tol;
    if (c == NULL || c->phase != ST_INSTANTIATED) return fmi2Error;
    c->start = start;
    c->stop_defined = stop_defined ? 1 : 0;
    c->stop = stop;
    return fmi2OK;
}

fmi2Status fmi2EnterInitializationMode(fmi2Component comp) {
    Container *c = (Container *)comp;
    if (c == NULL || c->phase != ST_INSTANTIATED) return fmi2Error;
    c->phase = ST_INIT;
    return fmi2OK;
}

/* The value a component input takes: `loop` selects the stepping loop's form of the
 * transformation (skipped when it is the identity), else the initialization's. */
static double source_value(const Container *c, const InputSource *s, int loop) {
    double x;
    if (s->kind == SOURCE_INPUT) {
        x = c->v[s->index];
    } else {
        x = c->out[s->component][s->index];
        if (!loop) x = s->factor * x + s->offset;
        else {
            if (s->factor != 1.0) x = s->factor * x;
            if (s->offset != 0.0) x = x + s->offset;
        }
    }
    if (s->add_slot >= 0) x = x + c->v[s->add_slot];
    return x;
}

/* Transfer into component k's inputs; returns how many changed. */
static int transfer(Container *c, int k, int loop) {
    const ContainerComponent *cc = &c->m->components[k];
    int i, changed = 0;
    for (i = 0; i < cc->n_in; i++) {
        double x = source_value(c, &cc->in_sources[i], loop);
        if (!(x == c->in[k][i] || (isnan(x) && isnan(c->in[k][i])))) changed++;
        c->in[k][i] = x;
    }
    return changed;
}

static fmi2Status set_inputs(Container *c, int k, double t) {
    const ContainerComponent *cc = &c->m->components[k];
    fmi2Status s;
    if (cc->n_in == 0) return fmi2OK;
    s = cc->fmi->set_real(c->comp[k], cc->in_vrs, (size_t)cc->n_in, c->in[k]);
    return s > fmi2Warning ? failed(c, k, "fmi2SetReal", s, t) : fmi2OK;
}

static fmi2Status get_outputs(Container *c, int k, double t) {
    const ContainerComponent *cc = &c->m->components[k];
    fmi2Status s;
    if (cc->n_out == 0) return fmi2OK;
    s = cc->fmi->get_real(c->comp[k], cc->out_vrs, (size_t)cc->n_out, c->out[k]);
    return s > fmi2Warning ? failed(c, k, "fmi2GetReal", s, t) : fmi2OK;
}

static void publish(Container *c) {
    int i;
    for (i = 0; i < c->m->noutputs; i++) {
        const OutputLink *o = &c->m->outputs[i];
        c->v[o->slot] = c->out[o->component][o->index];
    }
}

static fmi2Status set_parameter(Container *c, const ParameterLink *p) {
    const ComponentFunctions *f = c->m->components[p->component].fmi;
    double x = c->v[p->slot];
    if (p->type == VAR_INTEGER) {
        fmi2Integer i = (fmi2Integer)x;
        return f->set_integer(c->comp[p->component], &p->vr, 1, &i);
    }
    if (p->type == VAR_BOOLEAN) {
        fmi2Boolean b = x != 0.0 ? fmi2True : fmi2False;
        return f->set_boolean(c->comp[p->component], &p->vr, 1, &b);
    }
    return f->set_real(c->comp[p->component], &p->vr, 1, &x);
}

/* Set up every component, set its parameters and enter its initialization mode. */
static fmi2Status prepare_components(Container *c) {
    int k, i;
    for (k = 0; k < c->m->ncomponents; k++) {
        fmi2Status s = c->m->components[k].fmi->setup_experiment(c->comp[k], fmi2False, 0.0, c->start,
                                                                   c->stop_defined ? fmi2True : fmi2False, c->stop);
        if (s > fmi2Warning) return failed(c, k, "fmi2SetupExperiment", s, c->start);
    }
    for (i = 0; i < c->m->nparameters; i++) {
        fmi2Status s = set_parameter(c, &c->m->parameters[i]);
        if (s > fmi2Warning) return failed(c, c->m->parameters[i].component, "fmi2Set (parameter)", s, c->start);
    }
    for (k = 0; k < c->m->ncomponents; k++) {
        fmi2Status s = c->m->components[k].fmi->enter_initialization_mode(c->comp[k]);
        if (s > fmi2Warning) return failed(c, k, "fmi2EnterInitializationMode", s, c->start);
        if (get_outputs(c, k, c->start) != fmi2OK) return fmi2Error;
    }
    return fmi2OK;
}

static fmi2Status fixed_point(Container *c) {
    int it, j;
    for (it = 1; it <= c->m->max_init_iterations; it++) {
        int changed = 0;
        for (j = 0; j < c->m->ncomponents; j++) {
            int k = c->m->order[j];
            changed += transfer(c, k, 0);
            if (set_inputs(c, k, c->start) != fmi2OK || get_outputs(c, k, c->start) != fmi2OK) return fmi2Error;
        }
        if (changed == 0) return fmi2OK;
    }
    report(c, fmi2Error, "logStatusError", "%s: initialization did not reach a fixed point in %d iterations",
           c->m->identifier, c->m->max_init_iterations);
    c->phase = ST_ERROR;
    return fmi2Error;
}

fmi2Status fmi2ExitInitializationMode(fmi2Component comp) {
    Container *c = (Container *)comp;
    int j;
    double ns;
    if (c == NULL || c->phase != ST_INIT) return fmi2Error;
    ns = c->start * 1e9;
    c->start_ns = (long long)llround(ns);
    c->exact = fabs((double)c->start_ns - ns) <= 1e-6 * fmax(1.0, fabs(ns));
    c->tick = 0;
    if (prepare_components(c) != fmi2OK || fixed_point(c) != fmi2OK) return fmi2Error;
    for (j = 0; j < c->m->ncomponents; j++) {
        int k = c->m->order[j];
        fmi2Status s;
        transfer(c, k, 0);
        if (set_inputs(c, k, c->start) != fmi2OK) return fmi2Error;
        s = c->m->components[k].fmi->exit_initialization_mode(c->comp[k]);
        if (s > fmi2Warning) return failed(c, k, "fmi2ExitInitializationMode", s, c->start);
        if (get_outputs(c, k, c->start) != fmi2OK) return fmi2Error;
    }
    publish(c);
    c->phase = ST_STEP;
    return fmi2OK;
}

/* One tick of the Gauss-Seidel loop (tick n = c->tick). */
static fmi2Status tick(Container *c) {
    long long n = c->tick;
    double t = tick_time(c, n);
    int j;
    for (j = 0; j < c->m->ncomponents; j++) {
        int k = c->m->order[j];
        const ContainerComponent *cc = &c->m->components[k];
        int m = cc->multiple;
        double t_start;
        fmi2Status s;
        if (m != 1 && (n + 1) % m != 0) continue;
        t_start = m == 1 ? t : tick_time(c, (n / m) * m);
        transfer(c, k, 1);
        if (set_inputs(c, k, t) != fmi2OK) return fmi2Error;
        s = cc->fmi->do_step(c->comp[k], t_start, span(c, m), fmi2True);
        if (s > fmi2Warning) return failed(c, k, "fmi2DoStep", s, t_start);
        if (get_outputs(c, k, t) != fmi2OK) return fmi2Error;
    }
    c->tick = n + 1;
    return fmi2OK;
}

fmi2Status fmi2DoStep(fmi2Component comp, fmi2Real t, fmi2Real h, fmi2Boolean no_prior) {
    Container *c = (Container *)comp;
    double ticks, expected;
    long long k, count;
    (void)no_prior;
    if (c == NULL || c->phase != ST_STEP) return fmi2Error;
    ticks = h / c->m->step;
    count = (long long)llround(ticks);
    if (!isfinite(h) || count < 1 || fabs((double)count * c->m->step - h) > MULTIPLE_TOLERANCE * h) {
        report(c, fmi2Error, "logStatusError", "%s: communication step h = %g s is not a whole multiple of the "
               "scenario's step %g s (the loop runs on that step; use a multiple of it)", c->m->identifier, h,
               c->m->step);
        return fmi2Error;
    }
    expected = tick_time(c, c->tick);
    if (fabs(t - expected) > TIME_TOLERANCE * c->m->step) {
        report(c, fmi2Error, "logStatusError", "%s: fmi2DoStep from t = %.17g s, but the loop is at t = %.17g s",
               c->m->identifier, t, expected);
        return fmi2Error;
    }
    for (k = 0; k < count; k++)
        if (tick(c) != fmi2OK) return fmi2Error;
    publish(c);
    return fmi2OK;
}

fmi2Status fmi2Terminate(fmi2Component comp) {
    Container *c = (Container *)comp;
    int k;
    if (c == NULL) return fmi2Error;
    if (c->phase == ST_STEP)
        for (k = 0; k < c->m->ncomponents; k++) c->m->components[k].fmi->terminate(c->comp[k]);
    c->phase = ST_TERMINATED;
    return fmi2OK;
}

fmi2Status fmi2Reset(fmi2Component comp) {
    Container *c = (Container *)comp;
    int k;
    if (c == NULL) return fmi2Error;
    for (k = 0; k < c->m->ncomponents; k++) {
        if (c->m->components[k].fmi->reset(c->comp[k]) > fmi2Warning) return failed(c, k, "fmi2Reset", fmi2Error, 0.0);
        memset(c->out[k], 0, (size_t)c->m->components[k].n_out * sizeof(double));
        memset(c->in[k], 0, (size_t)c->m->components[k].n_in * sizeof(double));
    }
    memcpy(c->v, c->m->start, (size_t)c->m->nv * sizeof(double));
    c->start = 0.0;
    c->stop_defined = 0;
    c->tick = 0;
    c->phase = ST_INSTANTIATED;
    return fmi2OK;
}

#define FMI2_SHARED_INSTANCE Container
#include "fmi2shared.h"
