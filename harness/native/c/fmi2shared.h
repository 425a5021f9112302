/* FMI 2.0 functions written once for the single-model glue (fmi2glue.c) and the loop container
 * (container.c): get and set by value reference, and the functions the native FMUs do not support
 * or answer trivially. Each of the two files defines FMI2_SHARED_INSTANCE (its instance type, with
 * the members m (const ModelInfo *), v (the values) and phase (ST_INSTANTIATED, ST_INIT, ...)), its
 * lookup(c, vr) and report(c, ...), then includes this file once, at its end, so the functions take
 * that file's names (a component's prefix in a container). Function definitions, not declarations:
 * include it in exactly one place per file. */

static fmi2Status get_values(FMI2_SHARED_INSTANCE *c, const fmi2ValueReference vr[], size_t n, int type,
                             void *out) {
    size_t i;
    if (c == NULL || (n > 0 && (vr == NULL || out == NULL))) return fmi2Error;
#ifdef FMI2_SHARED_BEFORE_GET
    FMI2_SHARED_BEFORE_GET(c, vr, n); /* values computed on demand */
#endif
    for (i = 0; i < n; i++) {
        const ModelVariable *var = lookup(c, vr[i]);
        double x;
        if (var == NULL || var->type != type) {
            report(c, fmi2Error, "logStatusError", "%s: no variable of this type has value reference %u",
                   c->m->identifier, (unsigned)vr[i]);
            return fmi2Error;
        }
        x = c->v[var->index];
        if (type == VAR_REAL) ((fmi2Real *)out)[i] = x;
        else if (type == VAR_INTEGER) ((fmi2Integer *)out)[i] = (fmi2Integer)x;
        else ((fmi2Boolean *)out)[i] = x != 0.0 ? fmi2True : fmi2False;
    }
    return fmi2OK;
}

static fmi2Status set_values(FMI2_SHARED_INSTANCE *c, const fmi2ValueReference vr[], size_t n, int type,
                             const void *in) {
    size_t i;
    if (c == NULL || (n > 0 && (vr == NULL || in == NULL))) return fmi2Error;
    for (i = 0; i < n; i++) {
        const ModelVariable *var = lookup(c, vr[i]);
        double x;
        if (var == NULL || var->type != type || var->settable == 0) {
            report(c, fmi2Error, "logStatusError", "%s: value reference %u is not a settable variable of this type",
                   c->m->identifier, (unsigned)vr[i]);
            return fmi2Error;
        }
        if (var->settable == 1 && c->phase != ST_INSTANTIATED && c->phase != ST_INIT) {
            report(c, fmi2Error, "logStatusError", "%s: parameter %s is fixed after initialization",
                   c->m->identifier, var->name);
            return fmi2Error;
        }
        if (type == VAR_REAL) x = ((const fmi2Real *)in)[i];
        else if (type == VAR_INTEGER) x = (double)((const fmi2Integer *)in)[i];
        else x = ((const fmi2Boolean *)in)[i] ? 1.0 : 0.0;
        c->v[var->index] = x;
    }
#ifdef FMI2_SHARED_AFTER_SET
    FMI2_SHARED_AFTER_SET(c); /* what was computed from the values is out of date */
#endif
    return fmi2OK;
}

fmi2Status fmi2GetReal(fmi2Component c, const fmi2ValueReference vr[], size_t n, fmi2Real value[]) {
    return get_values((FMI2_SHARED_INSTANCE *)c, vr, n, VAR_REAL, value);
}
fmi2Status fmi2GetInteger(fmi2Component c, const fmi2ValueReference vr[], size_t n, fmi2Integer value[]) {
    return get_values((FMI2_SHARED_INSTANCE *)c, vr, n, VAR_INTEGER, value);
}
fmi2Status fmi2GetBoolean(fmi2Component c, const fmi2ValueReference vr[], size_t n, fmi2Boolean value[]) {
    return get_values((FMI2_SHARED_INSTANCE *)c, vr, n, VAR_BOOLEAN, value);
}
fmi2Status fmi2GetString(fmi2Component c, const fmi2ValueReference vr[], size_t n, fmi2String value[]) {
    (void)vr;
    (void)value;
    return (c != NULL && n == 0) ? fmi2OK : fmi2Error;
}
fmi2Status fmi2SetReal(fmi2Component c, const fmi2ValueReference vr[], size_t n, const fmi2Real value[]) {
    return set_values((FMI2_SHARED_INSTANCE *)c, vr, n, VAR_REAL, value);
}
fmi2Status fmi2SetInteger(fmi2Component c, const fmi2ValueReference vr[], size_t n, const fmi2Integer value[]) {
    return set_values((FMI2_SHARED_INSTANCE *)c, vr, n, VAR_INTEGER, value);
}
fmi2Status fmi2SetBoolean(fmi2Component c, const fmi2ValueReference vr[], size_t n, const fmi2Boolean value[]) {
    return set_values((FMI2_SHARED_INSTANCE *)c, vr, n, VAR_BOOLEAN, value);
}
fmi2Status fmi2SetString(fmi2Component c, const fmi2ValueReference vr[], size_t n, const fmi2String value[]) {
    (void)vr;
    (void)value;
    return (c != NULL && n == 0) ? fmi2OK : fmi2Error;
}

fmi2Status fmi2CancelStep(fmi2Component c) {
    (void)c;
    return fmi2Error;
}

fmi2Status fmi2GetStatus(fmi2Component c, const fmi2StatusKind s, fmi2Status *value) {
    (void)c;
    (void)s;
    (void)value;
    return fmi2Discard;
}
fmi2Status fmi2GetRealStatus(fmi2Component c, const fmi2StatusKind s, fmi2Real *value) {
    (void)s;
    (void)value;
    return c != NULL ? fmi2Discard : fmi2Error;
}
fmi2Status fmi2GetIntegerStatus(fmi2Component c, const fmi2StatusKind s, fmi2Integer *value) {
    (void)c;
    (void)s;
    (void)value;
    return fmi2Discard;
}
fmi2Status fmi2GetBooleanStatus(fmi2Component c, const fmi2StatusKind s, fmi2Boolean *value) {
    (void)c;
    (void)s;
    (void)value;
    return fmi2Discard;
}
fmi2Status fmi2GetStringStatus(fmi2Component c, const fmi2StatusKind s, fmi2String *value) {
    (void)c;
    (void)s;
    (void)value;
    return fmi2Discard;
}

/* Not supported (canGetAndSetFMUstate = false, no directional derivatives, no input derivatives). */
fmi2Status fmi2GetFMUstate(fmi2Component c, fmi2FMUstate *s) {
    (void)c;
    (void)s;
    return fmi2Error;
}
fmi2Status fmi2SetFMUstate(fmi2Component c, fmi2FMUstate s) {
    (void)c;
    (void)s;
    return fmi2Error;
}
fmi2Status fmi2FreeFMUstate(fmi2Component c, fmi2FMUstate *s) {
    (void)c;
    (void)s;
    return fmi2Error;
}
fmi2Status fmi2SerializedFMUstateSize(fmi2Component c, fmi2FMUstate s, size_t *n) {
    (void)c;
    (void)s;
    (void)n;
    return fmi2Error;
}
fmi2Status fmi2SerializeFMUstate(fmi2Component c, fmi2FMUstate s, fmi2Byte b[], size_t n) {
    (void)c;
    (void)s;
    (void)b;
    (void)n;
    return fmi2Error;
}
fmi2Status fmi2DeSerializeFMUstate(fmi2Component c, const fmi2Byte b[], size_t n, fmi2FMUstate *s) {
    (void)c;
    (void)b;
    (void)n;
    (void)s;
    return fmi2Error;
}
fmi2Status fmi2GetDirectionalDerivative(fmi2Component c, const fmi2ValueReference u[], size_t nu,
                                        const fmi2ValueReference z[], size_t nz, const fmi2Real du[],
                                        fmi2Real dz[]) {
    (void)c;
    (void)u;
    (void)nu;
    (void)z;
    (void)nz;
    (void)du;
    (void)dz;
    return fmi2Error;
}
fmi2Status fmi2SetRealInputDerivatives(fmi2Component c, const fmi2ValueReference vr[], size_t n,
                                       const fmi2Integer order[], const fmi2Real value[]) {
    (void)c;
    (void)vr;
    (void)n;
    (void)order;
    (void)value;
    return fmi2Error;
}
fmi2Status fmi2GetRealOutputDerivatives(fmi2Component c, const fmi2ValueReference vr[], size_t n,
                                        const fmi2Integer order[], fmi2Real value[]) {
    (void)c;
    (void)vr;
    (void)n;
    (void)order;
    (void)value;
    return fmi2Error;
}
