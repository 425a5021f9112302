/* FMI 3.0 co-simulation interface over an FMI 2.0 one: shared by the native models (fmi3glue.c)
 * and the loop container (fmi3container.c). Include it once, at the end of a translation unit
 * that has compiled the FMI 2.0 implementation (fmi2glue.c or container.c) under a prefix of its
 * own (fmi2FullName redefined, so that its fmi2Xxx names reach it and are not exported).
 *
 * Every FMI 3.0 call is the FMI 2.0 call of the same meaning on the inner instance:
 *   fmi3InstantiateCoSimulation      -> fmi2Instantiate (instantiation token = GUID)
 *   fmi3EnterInitializationMode      -> fmi2SetupExperiment, fmi2EnterInitializationMode
 *   fmi3Get/SetFloat64, Int32, Boolean -> fmi2Get/SetReal, Integer, Boolean
 *   fmi3DoStep                       -> fmi2DoStep (no event mode, no early return)
 * so the stepping, the checks and the messages are those of the FMI 2.0 variant. The log
 * messages go to the FMI 3.0 callback. Model exchange (a plant's) is fmi3me.h over the FMI 2.0
 * model exchange (fmi2me.h), the same way. What the native FMUs do not have (clocks, FMU state,
 * directional derivatives, other variable types) answers fmi3Error, except a get or set of no
 * variables.
 *
 * FMI 3.0 asks for an independent variable, which FMI 2.0 does not have: the model description
 * declares `time` (Float64, value reference IPCOSIM_TIME_VR, one past the largest of the FMI 2.0
 * variant, defined by the including file) and the adapter answers it here, in every state where
 * fmi3GetFloat64 is allowed: the start time given to fmi3EnterInitializationMode (0 before it),
 * then the communication point each fmi3DoStep reached (section 2.3, "t := tStart" on leaving
 * initialization; 4.2.1, the FMU's time after a step). It cannot be set.
 * Instantiation flags (fmi3InstantiateCoSimulation, section 2.3.1): earlyReturnAllowed is
 * accepted (the step always reaches its end: mightReturnEarlyFromDoStep is false);
 * eventModeUsed = fmi3True is refused with a logged error, as the standard requires of an FMU
 * with hasEventMode = false. */
#include <stdarg.h>
#include <stdio.h>
#include <stdlib.h>

#include "fmi3Functions.h"

typedef struct {
    fmi2Component inner;
    fmi2CallbackFunctions callbacks;
    fmi3InstanceEnvironment env;
    fmi3LogMessageCallback log;
    fmi3Float64 time; /* the independent variable: start time, then the communication point reached */
} Fmi3Adapter;

#ifndef IPCOSIM_TIME_VR
#error "define IPCOSIM_TIME_VR (the value reference of time) before including fmi3adapter.h"
#endif

#define ADAPTER(instance) ((Fmi3Adapter *)(instance))
#define INNER(instance) (ADAPTER(instance)->inner)

static void adapter_log(fmi2ComponentEnvironment env, fmi2String name, fmi2Status status, fmi2String category,
                        fmi2String message, ...) {
    Fmi3Adapter *a = (Fmi3Adapter *)env;
    char text[1024];
    va_list ap;
    (void)name;
    if (a == NULL || a->log == NULL) return;
    va_start(ap, message);
    vsnprintf(text, sizeof text, message, ap);
    va_end(ap);
    a->log(a->env, status == fmi2Pending ? fmi3Error : (fmi3Status)status, category, text);
}

static void *adapter_calloc(size_t n, size_t size) { return calloc(n, size); }
static void adapter_free(void *p) { free(p); }

const char *fmi3GetVersion(void) { return fmi3Version; }

fmi3Status fmi3SetDebugLogging(fmi3Instance instance, fmi3Boolean loggingOn, size_t nCategories,
                               const fmi3String categories[]) {
    if (instance == NULL) return fmi3Error;
    return (fmi3Status)fmi2SetDebugLogging(INNER(instance), loggingOn ? fmi2True : fmi2False, nCategories,
                                           categories);
}

fmi3Instance fmi3InstantiateCoSimulation(fmi3String instanceName, fmi3String instantiationToken,
                                         fmi3String resourcePath, fmi3Boolean visible, fmi3Boolean loggingOn,
                                         fmi3Boolean eventModeUsed, fmi3Boolean earlyReturnAllowed,
                                         const fmi3ValueReference requiredIntermediateVariables[],
                                         size_t nRequiredIntermediateVariables,
                                         fmi3InstanceEnvironment instanceEnvironment,
                                         fmi3LogMessageCallback logMessage,
                                         fmi3IntermediateUpdateCallback intermediateUpdate) {
    Fmi3Adapter *a;
    (void)earlyReturnAllowed; /* accepted: no step returns early */
    (void)requiredIntermediateVariables;
    (void)nRequiredIntermediateVariables;
    (void)intermediateUpdate;
    if (eventModeUsed) { /* hasEventMode is false: the standard asks the FMU to raise an error */
        if (logMessage != NULL)
            logMessage(instanceEnvironment, fmi3Error, "logStatusError",
                       "eventModeUsed = fmi3True: this FMU has no Event Mode (hasEventMode = false); "
                       "instantiate it with eventModeUsed = fmi3False");
        return NULL;
    }
    a = (Fmi3Adapter *)calloc(1, sizeof(Fmi3Adapter));
    if (a == NULL) return NULL;
    a->env = instanceEnvironment;
    a->log = logMessage;
    a->callbacks.logger = adapter_log;
    a->callbacks.allocateMemory = adapter_calloc;
    a->callbacks.freeMemory = adapter_free;
    a->callbacks.componentEnvironment = a;
    a->inner = fmi2Instantiate(instanceName, fmi2CoSimulation, instantiationToken, resourcePath, &a->callbacks,
                               visible ? fmi2True : fmi2False, loggingOn ? fmi2True : fmi2False);
    if (a->inner == NULL) {
        free(a);
        return NULL;
    }
    return a;
}

void fmi3FreeInstance(fmi3Instance instance) {
    if (instance == NULL) return;
    fmi2FreeInstance(INNER(instance));
    free(instance);
}

fmi3Status fmi3EnterInitializationMode(fmi3Instance instance, fmi3Boolean toleranceDefined, fmi3Float64 tolerance,
                                       fmi3Float64 startTime, fmi3Boolean stopTimeDefined, fmi3Float64 stopTime) {
    fmi2Status s;
    if (instance == NULL) return fmi3Error;
    s = fmi2SetupExperiment(INNER(instance), toleranceDefined ? fmi2True : fmi2False, tolerance, startTime,
                            stopTimeDefined ? fmi2True : fmi2False, stopTime);
    if (s > fmi2Warning) return (fmi3Status)s;
    ADAPTER(instance)->time = startTime;
    return (fmi3Status)fmi2EnterInitializationMode(INNER(instance));
}

fmi3Status fmi3ExitInitializationMode(fmi3Instance instance) {
    return instance != NULL ? (fmi3Status)fmi2ExitInitializationMode(INNER(instance)) : fmi3Error;
}

fmi3Status fmi3Terminate(fmi3Instance instance) {
    return instance != NULL ? (fmi3Status)fmi2Terminate(INNER(instance)) : fmi3Error;
}

fmi3Status fmi3Reset(fmi3Instance instance) {
    if (instance == NULL) return fmi3Error;
    ADAPTER(instance)->time = 0.0;
    return (fmi3Status)fmi2Reset(INNER(instance));
}

static int asks_time(const fmi3ValueReference vr[], size_t nvr) {
    size_t i;
    for (i = 0; i < nvr; i++)
        if (vr[i] == IPCOSIM_TIME_VR) return 1;
    return 0;
}

fmi3Status fmi3GetFloat64(fmi3Instance instance, const fmi3ValueReference vr[], size_t nvr, fmi3Float64 values[],
                          size_t nValues) {
    size_t i;
    if (instance == NULL || nValues != nvr || (nvr > 0 && (vr == NULL || values == NULL))) return fmi3Error;
    if (!asks_time(vr, nvr)) return (fmi3Status)fmi2GetReal(INNER(instance), vr, nvr, values); /* one call */
    for (i = 0; i < nvr; i++) {
        fmi2Status s;
        if (vr[i] == IPCOSIM_TIME_VR) {
            values[i] = ADAPTER(instance)->time;
            continue;
        }
        s = fmi2GetReal(INNER(instance), &vr[i], 1, &values[i]);
        if (s > fmi2Warning) return (fmi3Status)s;
    }
    return fmi3OK;
}

fmi3Status fmi3SetFloat64(fmi3Instance instance, const fmi3ValueReference vr[], size_t nvr,
                          const fmi3Float64 values[], size_t nValues) {
    if (instance == NULL || nValues != nvr) return fmi3Error;
    return (fmi3Status)fmi2SetReal(INNER(instance), vr, nvr, values);
}

/* Int32 and Boolean one value at a time: fmi2Integer and fmi2Boolean are ints, fmi3Boolean a bool. */
fmi3Status fmi3GetInt32(fmi3Instance instance, const fmi3ValueReference vr[], size_t nvr, fmi3Int32 values[],
                        size_t nValues) {
    size_t i;
    if (instance == NULL || nValues != nvr) return fmi3Error;
    for (i = 0; i < nvr; i++) {
        fmi2Integer x = 0;
        fmi2Status s = fmi2GetInteger(INNER(instance), &vr[i], 1, &x);
        if (s != fmi2OK) return (fmi3Status)s;
        values[i] = (fmi3Int32)x;
    }
    return fmi3OK;
}

fmi3Status fmi3SetInt32(fmi3Instance instance, const fmi3ValueReference vr[], size_t nvr, const fmi3Int32 values[],
                        size_t nValues) {
    size_t i;
    if (instance == NULL || nValues != nvr) return fmi3Error;
    for (i = 0; i < nvr; i++) {
        fmi2Integer x = (fmi2Integer)values[i];
        fmi2Status s = fmi2SetInteger(INNER(instance), &vr[i], 1, &x);
        if (s != fmi2OK) return (fmi3Status)s;
    }
    return fmi3OK;
}

fmi3Status fmi3GetBoolean(fmi3Instance instance, const fmi3ValueReference vr[], size_t nvr, fmi3Boolean values[],
                          size_t nValues) {
    size_t i;
    if (instance == NULL || nValues != nvr) return fmi3Error;
    for (i = 0; i < nvr; i++) {
        fmi2Boolean x = fmi2False;
        fmi2Status s = fmi2GetBoolean(INNER(instance), &vr[i], 1, &x);
        if (s != fmi2OK) return (fmi3Status)s;
        values[i] = x ? fmi3True : fmi3False;
    }
    return fmi3OK;
}

fmi3Status fmi3SetBoolean(fmi3Instance instance, const fmi3ValueReference vr[], size_t nvr,
                          const fmi3Boolean values[], size_t nValues) {
    size_t i;
    if (instance == NULL || nValues != nvr) return fmi3Error;
    for (i = 0; i < nvr; i++) {
        fmi2Boolean x = values[i] ? fmi2True : fmi2False;
        fmi2Status s = fmi2SetBoolean(INNER(instance), &vr[i], 1, &x);
        if (s != fmi2OK) return (fmi3Status)s;
    }
    return fmi3OK;
}

fmi3Status fmi3DoStep(fmi3Instance instance, fmi3Float64 currentCommunicationPoint,
                      fmi3Float64 communicationStepSize, fmi3Boolean noSetFMUStatePriorToCurrentPoint,
                      fmi3Boolean *eventHandlingNeeded, fmi3Boolean *terminateSimulation, fmi3Boolean *earlyReturn,
                      fmi3Float64 *lastSuccessfulTime) {
    fmi2Status s;
    if (instance == NULL) return fmi3Error;
    s = fmi2DoStep(INNER(instance), currentCommunicationPoint, communicationStepSize,
                   noSetFMUStatePriorToCurrentPoint ? fmi2True : fmi2False);
    if (eventHandlingNeeded != NULL) *eventHandlingNeeded = fmi3False;
    if (terminateSimulation != NULL) *terminateSimulation = fmi3False;
    if (earlyReturn != NULL) *earlyReturn = fmi3False;
    /* a discarded step keeps the state at the communication point */
    if (s == fmi2OK || s == fmi2Warning) ADAPTER(instance)->time = currentCommunicationPoint + communicationStepSize;
    if (lastSuccessfulTime != NULL)
        *lastSuccessfulTime = s == fmi2OK ? currentCommunicationPoint + communicationStepSize
                                          : currentCommunicationPoint;
    return s == fmi2Pending ? fmi3Error : (fmi3Status)s;
}

/* ---- What the native FMUs do not have: the arguments are not used. ---- */
#if defined(__GNUC__)
#pragma GCC diagnostic ignored "-Wunused-parameter"
#endif

fmi3Instance fmi3InstantiateScheduledExecution(fmi3String instanceName, fmi3String instantiationToken,
                                               fmi3String resourcePath, fmi3Boolean visible, fmi3Boolean loggingOn,
                                               fmi3InstanceEnvironment instanceEnvironment,
                                               fmi3LogMessageCallback logMessage, fmi3ClockUpdateCallback clockUpdate,
                                               fmi3LockPreemptionCallback lockPreemption,
                                               fmi3UnlockPreemptionCallback unlockPreemption) {
    return NULL;
}

/* A get or set of a type no variable has: fine for no variables, else an error. */
#define NO_VALUES(name, T)                                                                                     \
    fmi3Status fmi3Get##name(fmi3Instance instance, const fmi3ValueReference vr[], size_t nvr, T values[],     \
                             size_t nValues) {                                                               \
        return instance != NULL && nvr == 0 ? fmi3OK : fmi3Error;                                           \
    }                                                                                                        \
    fmi3Status fmi3Set##name(fmi3Instance instance, const fmi3ValueReference vr[], size_t nvr, const T values[], \
                             size_t nValues) {                                                               \
        return instance != NULL && nvr == 0 ? fmi3OK : fmi3Error;                                           \
    }
NO_VALUES(Float32, fmi3Float32)
NO_VALUES(Int8, fmi3Int8)
NO_VALUES(UInt8, fmi3UInt8)
NO_VALUES(Int16, fmi3Int16)
NO_VALUES(UInt16, fmi3UInt16)
NO_VALUES(UInt32, fmi3UInt32)
NO_VALUES(Int64, fmi3Int64)
NO_VALUES(UInt64, fmi3UInt64)
NO_VALUES(String, fmi3String)

fmi3Status fmi3GetBinary(fmi3Instance instance, const fmi3ValueReference vr[], size_t nvr, size_t valueSizes[],
                         fmi3Binary values[], size_t nValues) {
    return instance != NULL && nvr == 0 ? fmi3OK : fmi3Error;
}
fmi3Status fmi3SetBinary(fmi3Instance instance, const fmi3ValueReference vr[], size_t nvr, const size_t valueSizes[],
                         const fmi3Binary values[], size_t nValues) {
    return instance != NULL && nvr == 0 ? fmi3OK : fmi3Error;
}
fmi3Status fmi3GetClock(fmi3Instance instance, const fmi3ValueReference vr[], size_t nvr, fmi3Clock values[]) {
    return instance != NULL && nvr == 0 ? fmi3OK : fmi3Error;
}
fmi3Status fmi3SetClock(fmi3Instance instance, const fmi3ValueReference vr[], size_t nvr, const fmi3Clock values[]) {
    return instance != NULL && nvr == 0 ? fmi3OK : fmi3Error;
}

fmi3Status fmi3GetNumberOfVariableDependencies(fmi3Instance instance, fmi3ValueReference valueReference,
                                               size_t *nDependencies) {
    return fmi3Error;
}
fmi3Status fmi3GetVariableDependencies(fmi3Instance instance, fmi3ValueReference dependent,
                                       size_t elementIndicesOfDependent[], fmi3ValueReference independents[],
                                       size_t elementIndicesOfIndependents[], fmi3DependencyKind dependencyKinds[],
                                       size_t nDependencies) {
    return fmi3Error;
}
fmi3Status fmi3GetFMUState(fmi3Instance instance, fmi3FMUState *FMUState) { return fmi3Error; }
fmi3Status fmi3SetFMUState(fmi3Instance instance, fmi3FMUState FMUState) { return fmi3Error; }
fmi3Status fmi3FreeFMUState(fmi3Instance instance, fmi3FMUState *FMUState) { return fmi3Error; }
fmi3Status fmi3SerializedFMUStateSize(fmi3Instance instance, fmi3FMUState FMUState, size_t *size) {
    return fmi3Error;
}
fmi3Status fmi3SerializeFMUState(fmi3Instance instance, fmi3FMUState FMUState, fmi3Byte serializedState[],
                                 size_t size) {
    return fmi3Error;
}
fmi3Status fmi3DeserializeFMUState(fmi3Instance instance, const fmi3Byte serializedState[], size_t size,
                                   fmi3FMUState *FMUState) {
    return fmi3Error;
}
fmi3Status fmi3GetDirectionalDerivative(fmi3Instance instance, const fmi3ValueReference unknowns[], size_t nUnknowns,
                                        const fmi3ValueReference knowns[], size_t nKnowns, const fmi3Float64 seed[],
                                        size_t nSeed, fmi3Float64 sensitivity[], size_t nSensitivity) {
    return fmi3Error;
}
fmi3Status fmi3GetAdjointDerivative(fmi3Instance instance, const fmi3ValueReference unknowns[], size_t nUnknowns,
                                    const fmi3ValueReference knowns[], size_t nKnowns, const fmi3Float64 seed[],
                                    size_t nSeed, fmi3Float64 sensitivity[], size_t nSensitivity) {
    return fmi3Error;
}
fmi3Status fmi3EnterConfigurationMode(fmi3Instance instance) { return fmi3Error; }
fmi3Status fmi3ExitConfigurationMode(fmi3Instance instance) { return fmi3Error; }
fmi3Status fmi3GetIntervalDecimal(fmi3Instance instance, const fmi3ValueReference vr[], size_t nvr,
                                  fmi3Float64 intervals[], fmi3IntervalQualifier qualifiers[]) {
    return fmi3Error;
}
fmi3Status fmi3GetIntervalFraction(fmi3Instance instance, const fmi3ValueReference vr[], size_t nvr,
                                   fmi3UInt64 counters[], fmi3UInt64 resolutions[],
                                   fmi3IntervalQualifier qualifiers[]) {
    return fmi3Error;
}
fmi3Status fmi3GetShiftDecimal(fmi3Instance instance, const fmi3ValueReference vr[], size_t nvr,
                               fmi3Float64 shifts[]) {
    return fmi3Error;
}
fmi3Status fmi3GetShiftFraction(fmi3Instance instance, const fmi3ValueReference vr[], size_t nvr,
                                fmi3UInt64 counters[], fmi3UInt64 resolutions[]) {
    return fmi3Error;
}
fmi3Status fmi3SetIntervalDecimal(fmi3Instance instance, const fmi3ValueReference vr[], size_t nvr,
                                  const fmi3Float64 intervals[]) {
    return fmi3Error;
}
fmi3Status fmi3SetIntervalFraction(fmi3Instance instance, const fmi3ValueReference vr[], size_t nvr,
                                   const fmi3UInt64 counters[], const fmi3UInt64 resolutions[]) {
    return fmi3Error;
}
fmi3Status fmi3SetShiftDecimal(fmi3Instance instance, const fmi3ValueReference vr[], size_t nvr,
                               const fmi3Float64 shifts[]) {
    return fmi3Error;
}
fmi3Status fmi3SetShiftFraction(fmi3Instance instance, const fmi3ValueReference vr[], size_t nvr,
                                const fmi3UInt64 counters[], const fmi3UInt64 resolutions[]) {
    return fmi3Error;
}
fmi3Status fmi3EvaluateDiscreteStates(fmi3Instance instance) { return fmi3Error; }
/* Model exchange: a native plant's (fmi3me.h, where the including file defines IPCOSIM_EXCHANGE), else none. */
#ifdef IPCOSIM_EXCHANGE
#include "fmi3me.h"
#else
fmi3Instance fmi3InstantiateModelExchange(fmi3String instanceName, fmi3String instantiationToken,
                                          fmi3String resourcePath, fmi3Boolean visible, fmi3Boolean loggingOn,
                                          fmi3InstanceEnvironment instanceEnvironment,
                                          fmi3LogMessageCallback logMessage) {
    return NULL;
}

fmi3Status fmi3EnterEventMode(fmi3Instance instance) { return fmi3Error; }
fmi3Status fmi3UpdateDiscreteStates(fmi3Instance instance, fmi3Boolean *discreteStatesNeedUpdate,
                                    fmi3Boolean *terminateSimulation, fmi3Boolean *nominalsOfContinuousStatesChanged,
                                    fmi3Boolean *valuesOfContinuousStatesChanged, fmi3Boolean *nextEventTimeDefined,
                                    fmi3Float64 *nextEventTime) {
    return fmi3Error;
}
fmi3Status fmi3EnterContinuousTimeMode(fmi3Instance instance) { return fmi3Error; }
fmi3Status fmi3CompletedIntegratorStep(fmi3Instance instance, fmi3Boolean noSetFMUStatePriorToCurrentPoint,
                                       fmi3Boolean *enterEventMode, fmi3Boolean *terminateSimulation) {
    return fmi3Error;
}
fmi3Status fmi3SetTime(fmi3Instance instance, fmi3Float64 time) { return fmi3Error; }
fmi3Status fmi3SetContinuousStates(fmi3Instance instance, const fmi3Float64 continuousStates[],
                                   size_t nContinuousStates) {
    return fmi3Error;
}
fmi3Status fmi3GetContinuousStateDerivatives(fmi3Instance instance, fmi3Float64 derivatives[],
                                             size_t nContinuousStates) {
    return fmi3Error;
}
fmi3Status fmi3GetEventIndicators(fmi3Instance instance, fmi3Float64 eventIndicators[], size_t nEventIndicators) {
    return fmi3Error;
}
fmi3Status fmi3GetContinuousStates(fmi3Instance instance, fmi3Float64 continuousStates[], size_t nContinuousStates) {
    return fmi3Error;
}
fmi3Status fmi3GetNominalsOfContinuousStates(fmi3Instance instance, fmi3Float64 nominals[],
                                             size_t nContinuousStates) {
    return fmi3Error;
}
fmi3Status fmi3GetNumberOfEventIndicators(fmi3Instance instance, size_t *nEventIndicators) { return fmi3Error; }
fmi3Status fmi3GetNumberOfContinuousStates(fmi3Instance instance, size_t *nContinuousStates) { return fmi3Error; }
#endif
fmi3Status fmi3EnterStepMode(fmi3Instance instance) { return fmi3Error; }
fmi3Status fmi3GetOutputDerivatives(fmi3Instance instance, const fmi3ValueReference vr[], size_t nvr,
                                    const fmi3Int32 orders[], fmi3Float64 values[], size_t nValues) {
    return fmi3Error;
}
fmi3Status fmi3ActivateModelPartition(fmi3Instance instance, fmi3ValueReference clockReference,
                                      fmi3Float64 activationTime) {
    return fmi3Error;
}
