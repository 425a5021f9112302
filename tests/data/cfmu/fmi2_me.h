/* FMI 2.0 model-exchange functions of the test glue (fmi2_glue.c with -DHAS_ME=1), over the
 * model's states, derivatives, event indicators and event update (me_model.h). */
fmi2Status fmi2EnterEventMode(fmi2Component c) { return fmi2OK; }
fmi2Status fmi2NewDiscreteStates(fmi2Component c, fmi2EventInfo *e) {
    Instance *inst = (Instance *)c;
    int terminate = 0;
    double next = INFINITY;
    int changed = model_event(&inst->m, &terminate, &next);
    model_calculate(&inst->m);
    e->newDiscreteStatesNeeded = fmi2False;
    e->terminateSimulation = terminate ? fmi2True : fmi2False;
    e->nominalsOfContinuousStatesChanged = fmi2False;
    e->valuesOfContinuousStatesChanged = changed ? fmi2True : fmi2False;
    e->nextEventTimeDefined = isfinite(next) ? fmi2True : fmi2False;
    e->nextEventTime = isfinite(next) ? next : 0.0;
    return fmi2OK;
}
fmi2Status fmi2EnterContinuousTimeMode(fmi2Component c) { return fmi2OK; }
fmi2Status fmi2CompletedIntegratorStep(fmi2Component c, fmi2Boolean n, fmi2Boolean *e, fmi2Boolean *t) {
    *e = fmi2False;
    *t = fmi2False;
    return fmi2OK;
}
fmi2Status fmi2SetTime(fmi2Component c, fmi2Real t) {
    ((Instance *)c)->m.time = t;
    model_calculate(&((Instance *)c)->m);
    return fmi2OK;
}
fmi2Status fmi2SetContinuousStates(fmi2Component c, const fmi2Real x[], size_t n) {
    Instance *inst = (Instance *)c; size_t k;
    if (n != NX) return fmi2Error;
    for (k = 0; k < n; k++) inst->m.r[STATES[k]] = x[k];
    model_calculate(&inst->m);
    return fmi2OK;
}
fmi2Status fmi2GetDerivatives(fmi2Component c, fmi2Real d[], size_t n) {
    Instance *inst = (Instance *)c; size_t k;
    if (n != NX) return fmi2Error;
    for (k = 0; k < n; k++) d[k] = inst->m.r[DERS[k]];
    return fmi2OK;
}
fmi2Status fmi2GetEventIndicators(fmi2Component c, fmi2Real z[], size_t n) {
    Instance *inst = (Instance *)c; size_t k;
    if (n != NZ) return fmi2Error;
    for (k = 0; k < n; k++) z[k] = inst->m.r[INDICATORS[k]];
    return fmi2OK;
}
fmi2Status fmi2GetContinuousStates(fmi2Component c, fmi2Real x[], size_t n) {
    Instance *inst = (Instance *)c; size_t k;
    if (n != NX) return fmi2Error;
    for (k = 0; k < n; k++) x[k] = inst->m.r[STATES[k]];
    return fmi2OK;
}
fmi2Status fmi2GetNominalsOfContinuousStates(fmi2Component c, fmi2Real x[], size_t n) {
    size_t k;
    for (k = 0; k < n; k++) x[k] = 1.0;
    return fmi2OK;
}
