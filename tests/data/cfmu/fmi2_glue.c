/* FMI 2.0 co-simulation glue for the test models: one instance = one Model; every FMI 2.0
 * function is exported (those the tests do not need return fmi2Error). Compile with
 * -DMODEL_FILE=\"stair.c\" and the FMI 2.0 headers on the include path. */
#include <stdlib.h>
#include <string.h>
#include <stdio.h>
#include "fmi2Functions.h"
#include MODEL_FILE
#ifndef HAS_ME
#define HAS_ME 0 /* 1: model exchange too (fmi2_me.h) */
#endif
#ifndef HAS_CS
#define HAS_CS 1 /* 0: model exchange only */
#endif

typedef struct {
    Model m;
    fmi2CallbackFunctions cb;
    char name[128];
    int failed;
} Instance;

static void logf2(Instance *c, fmi2Status status, const char *msg) {
    if (c->cb.logger) c->cb.logger(c->cb.componentEnvironment, c->name, status, "log", "%s", msg);
}

const char *fmi2GetTypesPlatform(void) { return fmi2TypesPlatform; }
const char *fmi2GetVersion(void) { return fmi2Version; }
fmi2Status fmi2SetDebugLogging(fmi2Component c, fmi2Boolean on, size_t n, const fmi2String cat[]) { return fmi2OK; }

fmi2Component fmi2Instantiate(fmi2String name, fmi2Type type, fmi2String guid, fmi2String res,
                              const fmi2CallbackFunctions *cb, fmi2Boolean visible, fmi2Boolean logging) {
    Instance *c;
    if (!((type == fmi2CoSimulation && HAS_CS) || (type == fmi2ModelExchange && HAS_ME))) return NULL;
    c = (Instance *)calloc(1, sizeof(Instance));
    c->cb = *cb;
    strncpy(c->name, name ? name : "", sizeof(c->name) - 1);
    model_reset(&c->m);
    model_calculate(&c->m);
    return c;
}

void fmi2FreeInstance(fmi2Component c) { free(c); }

fmi2Status fmi2SetupExperiment(fmi2Component c, fmi2Boolean tolDef, fmi2Real tol, fmi2Real start,
                               fmi2Boolean stopDef, fmi2Real stop) {
    ((Instance *)c)->m.time = start;
    return fmi2OK;
}
fmi2Status fmi2EnterInitializationMode(fmi2Component c) { return fmi2OK; }
fmi2Status fmi2ExitInitializationMode(fmi2Component c) { model_calculate(&((Instance *)c)->m); return fmi2OK; }
fmi2Status fmi2Terminate(fmi2Component c) { return fmi2OK; }
fmi2Status fmi2Reset(fmi2Component c) { model_reset(&((Instance *)c)->m); return fmi2OK; }

#define CHECK_VR(max) for (i = 0; i < n; i++) if (vr[i] >= (max)) { logf2(inst, fmi2Error, "bad value reference"); return fmi2Error; }

fmi2Status fmi2GetReal(fmi2Component c, const fmi2ValueReference vr[], size_t n, fmi2Real v[]) {
    Instance *inst = (Instance *)c; size_t i; CHECK_VR(NR)
    for (i = 0; i < n; i++) v[i] = inst->m.r[vr[i]];
    return fmi2OK;
}
fmi2Status fmi2GetInteger(fmi2Component c, const fmi2ValueReference vr[], size_t n, fmi2Integer v[]) {
    Instance *inst = (Instance *)c; size_t i; CHECK_VR(NI)
    for (i = 0; i < n; i++) v[i] = (fmi2Integer)inst->m.i[vr[i]];
    return fmi2OK;
}
fmi2Status fmi2GetBoolean(fmi2Component c, const fmi2ValueReference vr[], size_t n, fmi2Boolean v[]) {
    Instance *inst = (Instance *)c; size_t i; CHECK_VR(NB)
    for (i = 0; i < n; i++) v[i] = inst->m.b[vr[i]] ? fmi2True : fmi2False;
    return fmi2OK;
}
fmi2Status fmi2GetString(fmi2Component c, const fmi2ValueReference vr[], size_t n, fmi2String v[]) {
    Instance *inst = (Instance *)c; size_t i; CHECK_VR(NS)
    for (i = 0; i < n; i++) v[i] = inst->m.s[vr[i]];
    return fmi2OK;
}
fmi2Status fmi2SetReal(fmi2Component c, const fmi2ValueReference vr[], size_t n, const fmi2Real v[]) {
    Instance *inst = (Instance *)c; size_t i; CHECK_VR(NR)
    for (i = 0; i < n; i++) inst->m.r[vr[i]] = v[i];
    model_calculate(&inst->m);
    return fmi2OK;
}
fmi2Status fmi2SetInteger(fmi2Component c, const fmi2ValueReference vr[], size_t n, const fmi2Integer v[]) {
    Instance *inst = (Instance *)c; size_t i; CHECK_VR(NI)
    for (i = 0; i < n; i++) inst->m.i[vr[i]] = v[i];
    model_calculate(&inst->m);
    return fmi2OK;
}
fmi2Status fmi2SetBoolean(fmi2Component c, const fmi2ValueReference vr[], size_t n, const fmi2Boolean v[]) {
    Instance *inst = (Instance *)c; size_t i; CHECK_VR(NB)
    for (i = 0; i < n; i++) inst->m.b[vr[i]] = v[i] ? 1 : 0;
    model_calculate(&inst->m);
    return fmi2OK;
}
fmi2Status fmi2SetString(fmi2Component c, const fmi2ValueReference vr[], size_t n, const fmi2String v[]) {
    Instance *inst = (Instance *)c; size_t i; CHECK_VR(NS)
    for (i = 0; i < n; i++) {
        strncpy(inst->m.s[vr[i]], v[i] ? v[i] : "", MAX_STRING - 1);
        inst->m.s[vr[i]][MAX_STRING - 1] = 0;
    }
    model_calculate(&inst->m);
    return fmi2OK;
}

fmi2Status fmi2DoStep(fmi2Component c, fmi2Real t, fmi2Real h, fmi2Boolean noSetPrior) {
    Instance *inst = (Instance *)c;
#if !HAS_CS
    return fmi2Error;
#else
    if (inst->m.terminated) { logf2(inst, fmi2Error, "doStep after the simulation ended"); return fmi2Error; }
    if (model_step(&inst->m, t, h)) return fmi2Discard;
    inst->m.time = t + h;
    inst->m.last_time = t + h;
    model_calculate(&inst->m);
    return fmi2OK;
#endif
}
fmi2Status fmi2CancelStep(fmi2Component c) { return fmi2Error; }
fmi2Status fmi2GetStatus(fmi2Component c, const fmi2StatusKind s, fmi2Status *v) { return fmi2Discard; }
fmi2Status fmi2GetRealStatus(fmi2Component c, const fmi2StatusKind s, fmi2Real *v) {
    if (s != fmi2LastSuccessfulTime) return fmi2Discard;
    *v = ((Instance *)c)->m.last_time;
    return fmi2OK;
}
fmi2Status fmi2GetIntegerStatus(fmi2Component c, const fmi2StatusKind s, fmi2Integer *v) { return fmi2Discard; }
fmi2Status fmi2GetBooleanStatus(fmi2Component c, const fmi2StatusKind s, fmi2Boolean *v) {
    if (s != fmi2Terminated) return fmi2Discard;
    *v = ((Instance *)c)->m.terminated ? fmi2True : fmi2False;
    return fmi2OK;
}
fmi2Status fmi2GetStringStatus(fmi2Component c, const fmi2StatusKind s, fmi2String *v) { return fmi2Discard; }

/* not used by these co-simulation models */
fmi2Status fmi2GetFMUstate(fmi2Component c, fmi2FMUstate *s) { return fmi2Error; }
fmi2Status fmi2SetFMUstate(fmi2Component c, fmi2FMUstate s) { return fmi2Error; }
fmi2Status fmi2FreeFMUstate(fmi2Component c, fmi2FMUstate *s) { return fmi2Error; }
fmi2Status fmi2SerializedFMUstateSize(fmi2Component c, fmi2FMUstate s, size_t *n) { return fmi2Error; }
fmi2Status fmi2SerializeFMUstate(fmi2Component c, fmi2FMUstate s, fmi2Byte b[], size_t n) { return fmi2Error; }
fmi2Status fmi2DeSerializeFMUstate(fmi2Component c, const fmi2Byte b[], size_t n, fmi2FMUstate *s) { return fmi2Error; }
fmi2Status fmi2GetDirectionalDerivative(fmi2Component c, const fmi2ValueReference u[], size_t nu,
                                        const fmi2ValueReference z[], size_t nz, const fmi2Real dv[], fmi2Real dz[]) {
    return fmi2Error;
}
fmi2Status fmi2SetRealInputDerivatives(fmi2Component c, const fmi2ValueReference vr[], size_t n,
                                       const fmi2Integer order[], const fmi2Real v[]) { return fmi2Error; }
fmi2Status fmi2GetRealOutputDerivatives(fmi2Component c, const fmi2ValueReference vr[], size_t n,
                                        const fmi2Integer order[], fmi2Real v[]) { return fmi2Error; }
#if HAS_ME
#include "fmi2_me.h"
#else
/* model exchange functions: exported so that loaders resolving every symbol succeed */
fmi2Status fmi2EnterEventMode(fmi2Component c) { return fmi2Error; }
fmi2Status fmi2NewDiscreteStates(fmi2Component c, fmi2EventInfo *e) { return fmi2Error; }
fmi2Status fmi2EnterContinuousTimeMode(fmi2Component c) { return fmi2Error; }
fmi2Status fmi2CompletedIntegratorStep(fmi2Component c, fmi2Boolean n, fmi2Boolean *e, fmi2Boolean *t) { return fmi2Error; }
fmi2Status fmi2SetTime(fmi2Component c, fmi2Real t) { return fmi2Error; }
fmi2Status fmi2SetContinuousStates(fmi2Component c, const fmi2Real x[], size_t n) { return fmi2Error; }
fmi2Status fmi2GetDerivatives(fmi2Component c, fmi2Real d[], size_t n) { return fmi2Error; }
fmi2Status fmi2GetEventIndicators(fmi2Component c, fmi2Real e[], size_t n) { return fmi2Error; }
fmi2Status fmi2GetContinuousStates(fmi2Component c, fmi2Real x[], size_t n) { return fmi2Error; }
fmi2Status fmi2GetNominalsOfContinuousStates(fmi2Component c, fmi2Real x[], size_t n) { return fmi2Error; }
#endif
