/* FMI 3.0 clocked co-simulation glue of a native sampled law (hasEventMode = true).
 *
 * The law is the model partition of one input clock, `sample_clock`, of constant interval (the
 * law's sample period, clock.h: CLOCK_VR, CLOCK_INTERVAL, CLOCK_SHIFT, the clocked inputs and
 * outputs). FMI 3.0 section 2.2.8 and the co-simulation state machine (4.2) say what each call does:
 *   fmi3InstantiateCoSimulation  eventModeUsed must be fmi3True (the law acts only on its clock)
 *   fmi3ExitInitializationMode   checks the parameters, enters Event Mode; no sample yet
 *   fmi3SetClock                 activates the clock at its tick t_i = t_start + shift + i*interval
 *   fmi3SetFloat64 / GetFloat64  clocked inputs and outputs only while the clock is active (and in
 *                                initialization); the outputs are the partition evaluated from the
 *                                inputs set and the clocked states of the last activation
 *   fmi3UpdateDiscreteStates     commits the clocked states (the sample), deactivates the clock
 *   fmi3EnterStepMode / DoStep   the output is held; a step may not pass over a tick
 *   fmi3EnterEventMode           back to Event Mode at a tick
 * The law's first activation is its first sample (what the unclocked variant computes on leaving
 * initialization), every later one a sample (what it computes at the end of a step on a tick), so
 * the two variants compute the same numbers at the same instants.
 *
 * Built on the FMI 3.0 adapter (fmi3adapter.h) over the FMI 2.0 glue (fmi2glue.c), both compiled
 * here: the adapter's versions of the functions this file defines take the prefix unclocked_. */
#include "fmi2Functions.h"
#undef fmi2FullName
#define IPCOSIM_PASTE(a, b) a##b
#define fmi2FullName(name) IPCOSIM_PASTE(ipcosim_fmi2_, name)
#include "fmi2glue.c"
#define IPCOSIM_TIME_VR ((fmi3ValueReference)model_info.nby_vr)
#include "fmi3Functions.h"

#undef fmi3InstantiateCoSimulation
#define fmi3InstantiateCoSimulation unclocked_fmi3InstantiateCoSimulation
#undef fmi3ExitInitializationMode
#define fmi3ExitInitializationMode unclocked_fmi3ExitInitializationMode
#undef fmi3Reset
#define fmi3Reset unclocked_fmi3Reset
#undef fmi3GetFloat64
#define fmi3GetFloat64 unclocked_fmi3GetFloat64
#undef fmi3SetFloat64
#define fmi3SetFloat64 unclocked_fmi3SetFloat64
#undef fmi3DoStep
#define fmi3DoStep unclocked_fmi3DoStep
#undef fmi3EnterEventMode
#define fmi3EnterEventMode unclocked_fmi3EnterEventMode
#undef fmi3EnterStepMode
#define fmi3EnterStepMode unclocked_fmi3EnterStepMode
#undef fmi3UpdateDiscreteStates
#define fmi3UpdateDiscreteStates unclocked_fmi3UpdateDiscreteStates
#undef fmi3GetClock
#define fmi3GetClock unclocked_fmi3GetClock
#undef fmi3SetClock
#define fmi3SetClock unclocked_fmi3SetClock
#undef fmi3GetIntervalDecimal
#define fmi3GetIntervalDecimal unclocked_fmi3GetIntervalDecimal
#undef fmi3GetShiftDecimal
#define fmi3GetShiftDecimal unclocked_fmi3GetShiftDecimal
#include "fmi3adapter.h"
#undef fmi3InstantiateCoSimulation
#define fmi3InstantiateCoSimulation fmi3FullName(fmi3InstantiateCoSimulation)
#undef fmi3ExitInitializationMode
#define fmi3ExitInitializationMode fmi3FullName(fmi3ExitInitializationMode)
#undef fmi3Reset
#define fmi3Reset fmi3FullName(fmi3Reset)
#undef fmi3GetFloat64
#define fmi3GetFloat64 fmi3FullName(fmi3GetFloat64)
#undef fmi3SetFloat64
#define fmi3SetFloat64 fmi3FullName(fmi3SetFloat64)
#undef fmi3DoStep
#define fmi3DoStep fmi3FullName(fmi3DoStep)
#undef fmi3EnterEventMode
#define fmi3EnterEventMode fmi3FullName(fmi3EnterEventMode)
#undef fmi3EnterStepMode
#define fmi3EnterStepMode fmi3FullName(fmi3EnterStepMode)
#undef fmi3UpdateDiscreteStates
#define fmi3UpdateDiscreteStates fmi3FullName(fmi3UpdateDiscreteStates)
#undef fmi3GetClock
#define fmi3GetClock fmi3FullName(fmi3GetClock)
#undef fmi3SetClock
#define fmi3SetClock fmi3FullName(fmi3SetClock)
#undef fmi3GetIntervalDecimal
#define fmi3GetIntervalDecimal fmi3FullName(fmi3GetIntervalDecimal)
#undef fmi3GetShiftDecimal
#define fmi3GetShiftDecimal fmi3FullName(fmi3GetShiftDecimal)

#include "clock.h"

/* the clock's tick i lies within this fraction of the interval of t_start + shift + i*interval */
#define CLOCK_TOLERANCE 1e-6

typedef struct {
    Fmi3Adapter a;  /* first: the adapter's functions take a Clocked instance as theirs */
    int event;      /* Event Mode (else Step Mode, once initialized) */
    int active;     /* the clock is active in this super-dense time instant */
    int evaluated;  /* the partition is evaluated (into the inner instance's scratch) from the inputs set */
    long ticks;     /* activations committed so far */
    double start;   /* t_start */
} Clocked;

#define CLOCKED(instance) ((Clocked *)(instance))
#define INSTANCE(instance) ((Instance *)CLOCKED(instance)->a.inner)

static void clocked_log(Clocked *k, fmi3Status status, const char *fmt, ...) {
    char text[512];
    va_list ap;
    if (k->a.log == NULL) return;
    va_start(ap, fmt);
    vsnprintf(text, sizeof text, fmt, ap);
    va_end(ap);
    k->a.log(k->a.env, status, status == fmi3Error ? "logStatusError" : "logStatusDiscard", text);
}

static int in_list(const fmi3ValueReference *list, size_t n, fmi3ValueReference vr) {
    size_t i;
    for (i = 0; i < n; i++)
        if (list[i] == vr) return 1;
    return 0;
}

static double tick_time(const Clocked *k, long i) { return k->start + CLOCK_SHIFT + (double)i * CLOCK_INTERVAL; }

static int initialized(const Clocked *k) { return INSTANCE(k)->phase == ST_STEP; }

fmi3Instance fmi3InstantiateCoSimulation(fmi3String instanceName, fmi3String instantiationToken,
                                         fmi3String resourcePath, fmi3Boolean visible, fmi3Boolean loggingOn,
                                         fmi3Boolean eventModeUsed, fmi3Boolean earlyReturnAllowed,
                                         const fmi3ValueReference requiredIntermediateVariables[],
                                         size_t nRequiredIntermediateVariables,
                                         fmi3InstanceEnvironment instanceEnvironment,
                                         fmi3LogMessageCallback logMessage,
                                         fmi3IntermediateUpdateCallback intermediateUpdate) {
    Clocked *k;
    (void)earlyReturnAllowed;
    (void)requiredIntermediateVariables;
    (void)nRequiredIntermediateVariables;
    (void)intermediateUpdate;
    if (!eventModeUsed) {
        if (logMessage != NULL)
            logMessage(instanceEnvironment, fmi3Error, "logStatusError",
                       "eventModeUsed = fmi3False: this law acts only when its input clock sample_clock ticks "
                       "(Event Mode); instantiate it with eventModeUsed = fmi3True, or take the unclocked variant");
        return NULL;
    }
    k = (Clocked *)calloc(1, sizeof(Clocked));
    if (k == NULL) return NULL;
    k->a.env = instanceEnvironment;
    k->a.log = logMessage;
    k->a.callbacks.logger = adapter_log;
    k->a.callbacks.allocateMemory = adapter_calloc;
    k->a.callbacks.freeMemory = adapter_free;
    k->a.callbacks.componentEnvironment = &k->a;
    k->a.inner = fmi2Instantiate(instanceName, fmi2CoSimulation, instantiationToken, resourcePath, &k->a.callbacks,
                                 visible ? fmi2True : fmi2False, loggingOn ? fmi2True : fmi2False);
    if (k->a.inner == NULL) {
        free(k);
        return NULL;
    }
    return k;
}

/* Leave initialization for Event Mode (eventModeUsed): the parameters checked as the unclocked
 * variant checks them, sample_period equal to the clock's interval; the first sample is the
 * clock's first activation, not this call. */
fmi3Status fmi3ExitInitializationMode(fmi3Instance instance) {
    Clocked *k = CLOCKED(instance);
    Instance *c;
    double period;
    if (k == NULL) return fmi3Error;
    c = INSTANCE(k);
    if (c->phase != ST_INIT) return fmi3Error;
    if (!parameters_valid(c)) {
        c->phase = ST_ERROR;
        return fmi3Error;
    }
    period = c->m->period_index >= 0 ? c->v[c->m->period_index] : CLOCK_INTERVAL; /* a source has none */
    if (period != CLOCK_INTERVAL) {
        clocked_log(k, fmi3Error, "%s: parameter sample_period = %g s differs from the interval of its constant "
                    "clock sample_clock, %g s (take the unclocked variant for another sample period)",
                    c->m->identifier, period, CLOCK_INTERVAL);
        c->phase = ST_ERROR;
        return fmi3Error;
    }
    c->phase = ST_STEP;
    k->start = c->t0;
    k->event = 1;
    k->active = k->evaluated = 0;
    k->ticks = 0;
    return fmi3OK;
}

fmi3Status fmi3Reset(fmi3Instance instance) {
    Clocked *k = CLOCKED(instance);
    if (k == NULL) return fmi3Error;
    k->event = k->active = k->evaluated = 0;
    k->ticks = 0;
    return unclocked_fmi3Reset(instance);
}

/* The partition at the active tick: the law's step on a copy of the committed values (inputs as set). */
static fmi3Status evaluate(Clocked *k) {
    Instance *c = INSTANCE(k);
    int i;
    if (k->evaluated) return fmi3OK;
    memcpy(c->scratch, c->v, (size_t)c->m->nv * sizeof(double));
    c->m->step(c->scratch, tick_time(k, k->ticks), 0.0);
    for (i = 0; i < c->m->nchecked; i++) {
        if (!isfinite(c->scratch[c->m->checked[i]])) {
            clocked_log(k, fmi3Error, "%s: the sample at t = %g s is not finite", c->m->identifier,
                        tick_time(k, k->ticks));
            return fmi3Error;
        }
    }
    k->evaluated = 1;
    return fmi3OK;
}

/* A clocked variable may be reached in initialization, or while its clock is active. */
static fmi3Status clocked_access(Clocked *k, fmi3ValueReference vr, const char *what) {
    const ModelVariable *var = lookup(INSTANCE(k), vr);
    if (!initialized(k) || (k->event && k->active)) return fmi3OK;
    clocked_log(k, fmi3Error, "%s: %s %s is clocked by sample_clock: it can be %s only in Event Mode while the "
                "clock is active (FMI 3.0, 2.2.8)", INSTANCE(k)->m->identifier, what,
                var != NULL ? var->name : "?", what[0] == 'i' ? "set" : "read");
    return fmi3Error;
}

fmi3Status fmi3GetFloat64(fmi3Instance instance, const fmi3ValueReference vr[], size_t nvr, fmi3Float64 values[],
                          size_t nValues) {
    Clocked *k = CLOCKED(instance);
    size_t i;
    if (k == NULL || nValues != nvr || (nvr > 0 && (vr == NULL || values == NULL))) return fmi3Error;
    for (i = 0; i < nvr; i++) {
        Instance *c = INSTANCE(k);
        if (vr[i] == IPCOSIM_TIME_VR) {
            values[i] = k->a.time;
        } else if (in_list(clocked_outputs, N_CLOCKED_OUTPUTS, vr[i])) {
            const ModelVariable *var = lookup(c, vr[i]);
            if (clocked_access(k, vr[i], "output") != fmi3OK) return fmi3Error;
            if (initialized(k) && evaluate(k) != fmi3OK) return fmi3Error;
            values[i] = (initialized(k) ? c->scratch : c->v)[var->index];
        } else {
            fmi2Status s = fmi2GetReal(c, &vr[i], 1, &values[i]);
            if (s > fmi2Warning) return (fmi3Status)s;
        }
    }
    return fmi3OK;
}

fmi3Status fmi3SetFloat64(fmi3Instance instance, const fmi3ValueReference vr[], size_t nvr,
                          const fmi3Float64 values[], size_t nValues) {
    Clocked *k = CLOCKED(instance);
    size_t i;
    if (k == NULL || nValues != nvr || (nvr > 0 && (vr == NULL || values == NULL))) return fmi3Error;
    for (i = 0; i < nvr; i++) {
        fmi2Status s;
        if (in_list(clocked_inputs, N_CLOCKED_INPUTS, vr[i])) {
            if (clocked_access(k, vr[i], "input") != fmi3OK) return fmi3Error;
            k->evaluated = 0;
        }
        s = fmi2SetReal(INSTANCE(k), &vr[i], 1, &values[i]);
        if (s > fmi2Warning) return (fmi3Status)s;
    }
    return fmi3OK;
}

fmi3Status fmi3SetClock(fmi3Instance instance, const fmi3ValueReference vr[], size_t nvr, const fmi3Clock values[]) {
    Clocked *k = CLOCKED(instance);
    size_t i;
    if (k == NULL || (nvr > 0 && (vr == NULL || values == NULL))) return fmi3Error;
    for (i = 0; i < nvr; i++) {
        double due = tick_time(k, k->ticks);
        if (vr[i] != CLOCK_VR) {
            clocked_log(k, fmi3Error, "%s: value reference %u is not a clock", INSTANCE(k)->m->identifier,
                        (unsigned)vr[i]);
            return fmi3Error;
        }
        if (!initialized(k) || !k->event) {
            clocked_log(k, fmi3Error, "%s: fmi3SetClock is allowed in Event Mode only", INSTANCE(k)->m->identifier);
            return fmi3Error;
        }
        if (!values[i]) {
            clocked_log(k, fmi3Error, "%s: sample_clock cannot be deactivated (canBeDeactivated = false)",
                        INSTANCE(k)->m->identifier);
            return fmi3Error;
        }
        if (fabs(k->a.time - due) > CLOCK_TOLERANCE * CLOCK_INTERVAL) {
            clocked_log(k, fmi3Error, "%s: sample_clock set at t = %.17g s; its tick %ld is at t = %.17g s",
                        INSTANCE(k)->m->identifier, k->a.time, k->ticks, due);
            return fmi3Error;
        }
        if (!k->active) k->evaluated = 0;
        k->active = 1;
    }
    return fmi3OK;
}

fmi3Status fmi3GetClock(fmi3Instance instance, const fmi3ValueReference vr[], size_t nvr, fmi3Clock values[]) {
    Clocked *k = CLOCKED(instance);
    size_t i;
    if (k == NULL || (nvr > 0 && (vr == NULL || values == NULL))) return fmi3Error;
    for (i = 0; i < nvr; i++) {
        if (vr[i] != CLOCK_VR) return fmi3Error;
        values[i] = k->active ? fmi3ClockActive : fmi3ClockInactive;
    }
    return fmi3OK;
}

/* The super-dense instant converged: commit the sample if the clock is active, deactivate it. */
fmi3Status fmi3UpdateDiscreteStates(fmi3Instance instance, fmi3Boolean *discreteStatesNeedUpdate,
                                    fmi3Boolean *terminateSimulation, fmi3Boolean *nominalsOfContinuousStatesChanged,
                                    fmi3Boolean *valuesOfContinuousStatesChanged, fmi3Boolean *nextEventTimeDefined,
                                    fmi3Float64 *nextEventTime) {
    Clocked *k = CLOCKED(instance);
    Instance *c;
    if (k == NULL || !initialized(k) || !k->event) return fmi3Error;
    c = INSTANCE(k);
    if (k->active) {
        if (evaluate(k) != fmi3OK) return fmi3Error;
        memcpy(c->v, c->scratch, (size_t)c->m->nv * sizeof(double));
        k->ticks++;
        k->active = k->evaluated = 0;
    }
    if (discreteStatesNeedUpdate != NULL) *discreteStatesNeedUpdate = fmi3False;
    if (terminateSimulation != NULL) *terminateSimulation = fmi3False;
    if (nominalsOfContinuousStatesChanged != NULL) *nominalsOfContinuousStatesChanged = fmi3False;
    if (valuesOfContinuousStatesChanged != NULL) *valuesOfContinuousStatesChanged = fmi3False;
    if (nextEventTimeDefined != NULL) *nextEventTimeDefined = fmi3False; /* the clock is the importer's */
    if (nextEventTime != NULL) *nextEventTime = 0.0;
    return fmi3OK;
}

fmi3Status fmi3EnterStepMode(fmi3Instance instance) {
    Clocked *k = CLOCKED(instance);
    if (k == NULL || !initialized(k) || !k->event) return fmi3Error;
    if (k->active) {
        clocked_log(k, fmi3Error, "%s: sample_clock is still active: call fmi3UpdateDiscreteStates before "
                    "fmi3EnterStepMode", INSTANCE(k)->m->identifier);
        return fmi3Error;
    }
    k->event = 0;
    return fmi3OK;
}

fmi3Status fmi3EnterEventMode(fmi3Instance instance) {
    Clocked *k = CLOCKED(instance);
    if (k == NULL || !initialized(k) || k->event) return fmi3Error;
    k->event = 1;
    return fmi3OK;
}

/* Step Mode: the output is held; the step ends on the next tick at the latest. */
fmi3Status fmi3DoStep(fmi3Instance instance, fmi3Float64 currentCommunicationPoint,
                      fmi3Float64 communicationStepSize, fmi3Boolean noSetFMUStatePriorToCurrentPoint,
                      fmi3Boolean *eventHandlingNeeded, fmi3Boolean *terminateSimulation, fmi3Boolean *earlyReturn,
                      fmi3Float64 *lastSuccessfulTime) {
    Clocked *k = CLOCKED(instance);
    double end = currentCommunicationPoint + communicationStepSize, due;
    (void)noSetFMUStatePriorToCurrentPoint;
    if (k == NULL || !initialized(k) || k->event) return fmi3Error;
    due = tick_time(k, k->ticks);
    if (!(communicationStepSize > 0.0) || end > due + CLOCK_TOLERANCE * CLOCK_INTERVAL) {
        clocked_log(k, fmi3Error, "%s: the step from t = %.17g s to %.17g s passes over tick %ld of sample_clock "
                    "(t = %.17g s): end the step there and set the clock in Event Mode",
                    INSTANCE(k)->m->identifier, currentCommunicationPoint, end, k->ticks, due);
        return fmi3Error;
    }
    k->a.time = end;
    if (eventHandlingNeeded != NULL) *eventHandlingNeeded = fmi3False;
    if (terminateSimulation != NULL) *terminateSimulation = fmi3False;
    if (earlyReturn != NULL) *earlyReturn = fmi3False;
    if (lastSuccessfulTime != NULL) *lastSuccessfulTime = end;
    return fmi3OK;
}

fmi3Status fmi3GetIntervalDecimal(fmi3Instance instance, const fmi3ValueReference vr[], size_t nvr,
                                  fmi3Float64 intervals[], fmi3IntervalQualifier qualifiers[]) {
    size_t i;
    if (instance == NULL) return fmi3Error;
    for (i = 0; i < nvr; i++) {
        if (vr[i] != CLOCK_VR) return fmi3Error;
        intervals[i] = CLOCK_INTERVAL;
        qualifiers[i] = fmi3IntervalUnchanged; /* a constant clock (2.2.8, qualifier table) */
    }
    return fmi3OK;
}

fmi3Status fmi3GetShiftDecimal(fmi3Instance instance, const fmi3ValueReference vr[], size_t nvr,
                               fmi3Float64 shifts[]) {
    size_t i;
    if (instance == NULL) return fmi3Error;
    for (i = 0; i < nvr; i++) {
        if (vr[i] != CLOCK_VR) return fmi3Error;
        shifts[i] = CLOCK_SHIFT;
    }
    return fmi3OK;
}
