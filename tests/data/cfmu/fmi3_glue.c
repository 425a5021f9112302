/* FMI 3.0 co-simulation glue for the test models (see model.h). Value references are unique
 * across types in FMI 3.0: Float64/Float32 0-99 -> r[vr], integers 100-199 -> i[vr - 100],
 * Boolean 200-299 -> b[vr - 200], String 300-399 -> s[vr - 300]. No event mode, no early
 * return; a model that ends the simulation completes its step with terminateSimulation = true.
 * The FMI 3.0 functions the tests do not use are generated as stubs returning fmi3Error
 * (stubs.c, written by tests/cfmu.py from fmi3FunctionTypes.h). */
#include <stdlib.h>
#include <string.h>
#include "fmi3Functions.h"
#include MODEL_FILE
#ifndef HAS_ME
#define HAS_ME 0 /* 1: model exchange too (fmi3_me.h) */
#endif
#ifndef HAS_CS
#define HAS_CS 1 /* 0: model exchange only */
#endif

typedef struct {
    Model m;
    fmi3InstanceEnvironment env;
    fmi3LogMessageCallback log;
    char name[128];
} Instance;

static fmi3Status bad_vr(Instance *c) {
    if (c->log) c->log(c->env, fmi3Error, "log", "bad value reference");
    return fmi3Error;
}

const char *fmi3GetVersion(void) { return fmi3Version; }
fmi3Status fmi3SetDebugLogging(fmi3Instance c, fmi3Boolean on, size_t n, const fmi3String cat[]) { return fmi3OK; }

fmi3Instance fmi3InstantiateCoSimulation(fmi3String name, fmi3String token, fmi3String res, fmi3Boolean visible,
                                         fmi3Boolean logging, fmi3Boolean eventMode, fmi3Boolean earlyReturn,
                                         const fmi3ValueReference req[], size_t nreq, fmi3InstanceEnvironment env,
                                         fmi3LogMessageCallback log, fmi3IntermediateUpdateCallback upd) {
    Instance *c = (Instance *)calloc(1, sizeof(Instance));
    c->env = env;
    c->log = log;
    strncpy(c->name, name ? name : "", sizeof(c->name) - 1);
    model_reset(&c->m);
    model_calculate(&c->m);
    return c;
}
void fmi3FreeInstance(fmi3Instance c) { free(c); }
fmi3Status fmi3EnterInitializationMode(fmi3Instance c, fmi3Boolean tolDef, fmi3Float64 tol, fmi3Float64 start,
                                       fmi3Boolean stopDef, fmi3Float64 stop) {
    ((Instance *)c)->m.time = start;
    return fmi3OK;
}
fmi3Status fmi3ExitInitializationMode(fmi3Instance c) { model_calculate(&((Instance *)c)->m); return fmi3OK; }
fmi3Status fmi3Terminate(fmi3Instance c) { return fmi3OK; }
fmi3Status fmi3Reset(fmi3Instance c) { model_reset(&((Instance *)c)->m); return fmi3OK; }

#define GETTER(NAME, T, ARR, BASE, MAX)                                                              \
    fmi3Status fmi3Get##NAME(fmi3Instance c, const fmi3ValueReference vr[], size_t n, T v[], size_t nv) { \
        Instance *inst = (Instance *)c; size_t k;                                                    \
        for (k = 0; k < n; k++) {                                                                    \
            if (vr[k] < BASE || vr[k] >= BASE + MAX) return bad_vr(inst);                            \
            v[k] = (T)inst->m.ARR[vr[k] - BASE];                                                     \
        }                                                                                            \
        return fmi3OK;                                                                               \
    }                                                                                                \
    fmi3Status fmi3Set##NAME(fmi3Instance c, const fmi3ValueReference vr[], size_t n, const T v[], size_t nv) { \
        Instance *inst = (Instance *)c; size_t k;                                                    \
        for (k = 0; k < n; k++) {                                                                    \
            if (vr[k] < BASE || vr[k] >= BASE + MAX) return bad_vr(inst);                            \
            inst->m.ARR[vr[k] - BASE] = v[k];                                                        \
        }                                                                                            \
        model_calculate(&inst->m);                                                                   \
        return fmi3OK;                                                                               \
    }

GETTER(Float64, fmi3Float64, r, 0, NR)
GETTER(Float32, fmi3Float32, r, 0, NR)
GETTER(Int8, fmi3Int8, i, 100, NI)
GETTER(UInt8, fmi3UInt8, i, 100, NI)
GETTER(Int16, fmi3Int16, i, 100, NI)
GETTER(UInt16, fmi3UInt16, i, 100, NI)
GETTER(Int32, fmi3Int32, i, 100, NI)
GETTER(UInt32, fmi3UInt32, i, 100, NI)
GETTER(Int64, fmi3Int64, i, 100, NI)
GETTER(UInt64, fmi3UInt64, i, 100, NI)
GETTER(Boolean, fmi3Boolean, b, 200, NB)

fmi3Status fmi3GetString(fmi3Instance c, const fmi3ValueReference vr[], size_t n, fmi3String v[], size_t nv) {
    Instance *inst = (Instance *)c; size_t k;
    for (k = 0; k < n; k++) {
        if (vr[k] < 300 || vr[k] >= 300 + NS) return bad_vr(inst);
        v[k] = inst->m.s[vr[k] - 300];
    }
    return fmi3OK;
}
fmi3Status fmi3SetString(fmi3Instance c, const fmi3ValueReference vr[], size_t n, const fmi3String v[], size_t nv) {
    Instance *inst = (Instance *)c; size_t k;
    for (k = 0; k < n; k++) {
        if (vr[k] < 300 || vr[k] >= 300 + NS) return bad_vr(inst);
        strncpy(inst->m.s[vr[k] - 300], v[k] ? v[k] : "", MAX_STRING - 1);
        inst->m.s[vr[k] - 300][MAX_STRING - 1] = 0;
    }
    model_calculate(&inst->m);
    return fmi3OK;
}

fmi3Status fmi3DoStep(fmi3Instance c, fmi3Float64 t, fmi3Float64 h, fmi3Boolean noSetPrior, fmi3Boolean *event,
                      fmi3Boolean *terminate, fmi3Boolean *early, fmi3Float64 *last) {
    Instance *inst = (Instance *)c;
    *event = fmi3False;
    *early = fmi3False;
    *terminate = fmi3False;
#if !HAS_CS
    return fmi3Error;
#else
    if (inst->m.terminated) return fmi3Error;
    if (model_step(&inst->m, t, h)) {
        *terminate = inst->m.terminated ? fmi3True : fmi3False;
        *last = t;
        return inst->m.terminated ? fmi3OK : fmi3Discard;
    }
    inst->m.time = t + h;
    *last = t + h;
    model_calculate(&inst->m);
    return fmi3OK;
#endif
}
#if HAS_ME
#include "fmi3_me.h"
#endif
