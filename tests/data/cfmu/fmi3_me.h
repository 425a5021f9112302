/* FMI 3.0 model-exchange functions of the test glue (fmi3_glue.c with -DHAS_ME=1), over the
 * model's states, derivatives, event indicators and event update (me_model.h). */
fmi3Instance fmi3InstantiateModelExchange(fmi3String name, fmi3String token, fmi3String res, fmi3Boolean visible,
                                          fmi3Boolean logging, fmi3InstanceEnvironment env,
                                          fmi3LogMessageCallback log) {
    Instance *c = (Instance *)calloc(1, sizeof(Instance));
    c->env = env;
    c->log = log;
    strncpy(c->name, name ? name : "", sizeof(c->name) - 1);
    model_reset(&c->m);
    model_calculate(&c->m);
    return c;
}
fmi3Status fmi3EnterEventMode(fmi3Instance c) { return fmi3OK; }
fmi3Status fmi3UpdateDiscreteStates(fmi3Instance c, fmi3Boolean *again, fmi3Boolean *terminate,
                                    fmi3Boolean *nominals, fmi3Boolean *values, fmi3Boolean *defined,
                                    fmi3Float64 *next_time) {
    Instance *inst = (Instance *)c;
    int term = 0;
    double next = INFINITY;
    int changed = model_event(&inst->m, &term, &next);
    model_calculate(&inst->m);
    *again = fmi3False;
    *terminate = term ? fmi3True : fmi3False;
    *nominals = fmi3False;
    *values = changed ? fmi3True : fmi3False;
    *defined = isfinite(next) ? fmi3True : fmi3False;
    *next_time = isfinite(next) ? next : 0.0;
    return fmi3OK;
}
fmi3Status fmi3EnterContinuousTimeMode(fmi3Instance c) { return fmi3OK; }
fmi3Status fmi3CompletedIntegratorStep(fmi3Instance c, fmi3Boolean n, fmi3Boolean *e, fmi3Boolean *t) {
    *e = fmi3False;
    *t = fmi3False;
    return fmi3OK;
}
fmi3Status fmi3SetTime(fmi3Instance c, fmi3Float64 t) {
    ((Instance *)c)->m.time = t;
    model_calculate(&((Instance *)c)->m);
    return fmi3OK;
}
fmi3Status fmi3SetContinuousStates(fmi3Instance c, const fmi3Float64 x[], size_t n) {
    Instance *inst = (Instance *)c; size_t k;
    if (n != NX) return fmi3Error;
    for (k = 0; k < n; k++) inst->m.r[STATES[k]] = x[k];
    model_calculate(&inst->m);
    return fmi3OK;
}
fmi3Status fmi3GetContinuousStateDerivatives(fmi3Instance c, fmi3Float64 d[], size_t n) {
    Instance *inst = (Instance *)c; size_t k;
    if (n != NX) return fmi3Error;
    for (k = 0; k < n; k++) d[k] = inst->m.r[DERS[k]];
    return fmi3OK;
}
fmi3Status fmi3GetEventIndicators(fmi3Instance c, fmi3Float64 z[], size_t n) {
    Instance *inst = (Instance *)c; size_t k;
    if (n != NZ) return fmi3Error;
    for (k = 0; k < n; k++) z[k] = inst->m.r[INDICATORS[k]];
    return fmi3OK;
}
fmi3Status fmi3GetContinuousStates(fmi3Instance c, fmi3Float64 x[], size_t n) {
    Instance *inst = (Instance *)c; size_t k;
    if (n != NX) return fmi3Error;
    for (k = 0; k < n; k++) x[k] = inst->m.r[STATES[k]];
    return fmi3OK;
}
fmi3Status fmi3GetNominalsOfContinuousStates(fmi3Instance c, fmi3Float64 x[], size_t n) {
    size_t k;
    for (k = 0; k < n; k++) x[k] = 1.0;
    return fmi3OK;
}
fmi3Status fmi3GetNumberOfEventIndicators(fmi3Instance c, size_t *n) { *n = NZ; return fmi3OK; }
fmi3Status fmi3GetNumberOfContinuousStates(fmi3Instance c, size_t *n) { *n = NX; return fmi3OK; }
