/* FMI 3.0 model exchange of a native plant over its FMI 2.0 model exchange (fmi2me.h): included by
 * fmi3adapter.h where the including file defines IPCOSIM_EXCHANGE (the model's ModelExchangeInfo,
 * or NULL). Every call is the FMI 2.0 call of the same meaning on the inner instance:
 *   fmi3InstantiateModelExchange        -> fmi2Instantiate(fmi2ModelExchange)
 *   fmi3EnterEventMode                  -> fmi2EnterEventMode
 *   fmi3UpdateDiscreteStates            -> fmi2NewDiscreteStates (the same event information)
 *   fmi3EnterContinuousTimeMode, fmi3CompletedIntegratorStep, fmi3SetContinuousStates,
 *   fmi3GetContinuousStates, fmi3GetNominalsOfContinuousStates -> their FMI 2.0 namesakes
 *   fmi3GetContinuousStateDerivatives   -> fmi2GetDerivatives
 *   fmi3GetEventIndicators              -> fmi2GetEventIndicators
 *   fmi3SetTime                         -> fmi2SetTime; the independent variable `time` follows it
 * so the states, the events and the messages are those of the FMI 2.0 variant. */

fmi3Instance fmi3InstantiateModelExchange(fmi3String instanceName, fmi3String instantiationToken,
                                          fmi3String resourcePath, fmi3Boolean visible, fmi3Boolean loggingOn,
                                          fmi3InstanceEnvironment instanceEnvironment,
                                          fmi3LogMessageCallback logMessage) {
    Fmi3Adapter *a = (Fmi3Adapter *)calloc(1, sizeof(Fmi3Adapter));
    if (a == NULL) return NULL;
    a->env = instanceEnvironment;
    a->log = logMessage;
    a->callbacks.logger = adapter_log;
    a->callbacks.allocateMemory = adapter_calloc;
    a->callbacks.freeMemory = adapter_free;
    a->callbacks.componentEnvironment = a;
    a->inner = fmi2Instantiate(instanceName, fmi2ModelExchange, instantiationToken, resourcePath, &a->callbacks,
                               visible ? fmi2True : fmi2False, loggingOn ? fmi2True : fmi2False);
    if (a->inner == NULL) {
        free(a);
        return NULL;
    }
    return a;
}

fmi3Status fmi3EnterEventMode(fmi3Instance instance) {
    return instance != NULL ? (fmi3Status)fmi2EnterEventMode(INNER(instance)) : fmi3Error;
}

fmi3Status fmi3UpdateDiscreteStates(fmi3Instance instance, fmi3Boolean *discreteStatesNeedUpdate,
                                    fmi3Boolean *terminateSimulation, fmi3Boolean *nominalsOfContinuousStatesChanged,
                                    fmi3Boolean *valuesOfContinuousStatesChanged, fmi3Boolean *nextEventTimeDefined,
                                    fmi3Float64 *nextEventTime) {
    fmi2EventInfo info;
    fmi2Status s;
    if (instance == NULL) return fmi3Error;
    s = fmi2NewDiscreteStates(INNER(instance), &info);
    if (s != fmi2OK) return (fmi3Status)s;
    if (discreteStatesNeedUpdate != NULL) *discreteStatesNeedUpdate = info.newDiscreteStatesNeeded != fmi2False;
    if (terminateSimulation != NULL) *terminateSimulation = info.terminateSimulation != fmi2False;
    if (nominalsOfContinuousStatesChanged != NULL)
        *nominalsOfContinuousStatesChanged = info.nominalsOfContinuousStatesChanged != fmi2False;
    if (valuesOfContinuousStatesChanged != NULL)
        *valuesOfContinuousStatesChanged = info.valuesOfContinuousStatesChanged != fmi2False;
    if (nextEventTimeDefined != NULL) *nextEventTimeDefined = info.nextEventTimeDefined != fmi2False;
    if (nextEventTime != NULL) *nextEventTime = info.nextEventTime;
    return fmi3OK;
}

fmi3Status fmi3EnterContinuousTimeMode(fmi3Instance instance) {
    return instance != NULL ? (fmi3Status)fmi2EnterContinuousTimeMode(INNER(instance)) : fmi3Error;
}

fmi3Status fmi3CompletedIntegratorStep(fmi3Instance instance, fmi3Boolean noSetFMUStatePriorToCurrentPoint,
                                       fmi3Boolean *enterEventMode, fmi3Boolean *terminateSimulation) {
    fmi2Boolean enter = fmi2False, terminate = fmi2False;
    fmi2Status s;
    if (instance == NULL || enterEventMode == NULL || terminateSimulation == NULL) return fmi3Error;
    s = fmi2CompletedIntegratorStep(INNER(instance), noSetFMUStatePriorToCurrentPoint ? fmi2True : fmi2False, &enter,
                                    &terminate);
    *enterEventMode = enter != fmi2False;
    *terminateSimulation = terminate != fmi2False;
    return (fmi3Status)s;
}

fmi3Status fmi3SetTime(fmi3Instance instance, fmi3Float64 time) {
    fmi2Status s;
    if (instance == NULL) return fmi3Error;
    s = fmi2SetTime(INNER(instance), time);
    if (s == fmi2OK) ADAPTER(instance)->time = time;
    return (fmi3Status)s;
}

fmi3Status fmi3SetContinuousStates(fmi3Instance instance, const fmi3Float64 continuousStates[],
                                   size_t nContinuousStates) {
    if (instance == NULL) return fmi3Error;
    return (fmi3Status)fmi2SetContinuousStates(INNER(instance), continuousStates, nContinuousStates);
}

fmi3Status fmi3GetContinuousStateDerivatives(fmi3Instance instance, fmi3Float64 derivatives[],
                                             size_t nContinuousStates) {
    if (instance == NULL) return fmi3Error;
    return (fmi3Status)fmi2GetDerivatives(INNER(instance), derivatives, nContinuousStates);
}

fmi3Status fmi3GetEventIndicators(fmi3Instance instance, fmi3Float64 eventIndicators[], size_t nEventIndicators) {
    if (instance == NULL) return fmi3Error;
    return (fmi3Status)fmi2GetEventIndicators(INNER(instance), eventIndicators, nEventIndicators);
}

fmi3Status fmi3GetContinuousStates(fmi3Instance instance, fmi3Float64 continuousStates[], size_t nContinuousStates) {
    if (instance == NULL) return fmi3Error;
    return (fmi3Status)fmi2GetContinuousStates(INNER(instance), continuousStates, nContinuousStates);
}

fmi3Status fmi3GetNominalsOfContinuousStates(fmi3Instance instance, fmi3Float64 nominals[],
                                             size_t nContinuousStates) {
    if (instance == NULL) return fmi3Error;
    return (fmi3Status)fmi2GetNominalsOfContinuousStates(INNER(instance), nominals, nContinuousStates);
}

/* The numbers of the model (section 3.2.1: allowed in every state after instantiation). */
fmi3Status fmi3GetNumberOfEventIndicators(fmi3Instance instance, size_t *nEventIndicators) {
    if (instance == NULL || nEventIndicators == NULL || IPCOSIM_EXCHANGE == NULL) return fmi3Error;
    *nEventIndicators = (size_t)IPCOSIM_EXCHANGE->nz;
    return fmi3OK;
}

fmi3Status fmi3GetNumberOfContinuousStates(fmi3Instance instance, size_t *nContinuousStates) {
    if (instance == NULL || nContinuousStates == NULL || IPCOSIM_EXCHANGE == NULL) return fmi3Error;
    *nContinuousStates = (size_t)IPCOSIM_EXCHANGE->nx;
    return fmi3OK;
}
