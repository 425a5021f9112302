/*
 * A minimal FMI 2.0 co-simulation host: what any C/C++ tool does with an FMU, nothing more.
 *
 * It loads each FMU's binary with dlopen (RTLD_NOW | RTLD_LOCAL), calls
 * fmi2Instantiate ... fmi2FreeInstance, and closes the binary with dlclose. It knows nothing
 * of Python: the ipcosim FMUs need libpython in the process's global symbol scope, which the
 * user provides exactly as for any other tool (docs/other-tools.md):
 *
 *     LD_PRELOAD=<libpython the FMUs were built with>  PYTHONHOME=<its prefix>  fmi_host ...
 *
 * Usage:
 *     fmi_host [--keep] STOP STEP SETPOINT CONTROLLER PLANT [SETPOINT CONTROLLER PLANT ...]
 *
 * Each FMU argument is DIR:MODEL_IDENTIFIER:GUID:IN_VRS:OUT_VRS, with DIR the unzipped FMU
 * and IN_VRS / OUT_VRS comma-separated Real value references (either may be empty). Each
 * group of three is one closed loop, wired as
 *     controller inputs = setpoint outputs, then plant outputs (in that order)
 *     plant inputs      = controller outputs
 * and stepped from t = 0 to STOP with communication step STEP, tick n at t = n * STEP, in the
 * order setpoint, plant (with the voltage of the previous step held), controller.
 * After the run every instance is terminated and freed and every binary closed, unless
 * --keep is given: then the host exits with everything still loaded (as many tools do).
 * Prints "loop K: v1 v2 ..." (the plant's outputs at STOP, %.17g) per loop; exits 0, or 1
 * with one line naming the FMU and the call that failed.
 */
#include <dlfcn.h>
#include <stdarg.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "fmi2FunctionTypes.h"

#define MAX_VRS 16
#define MAX_FMUS 30

typedef struct {
    char dir[4096], id[256], guid[256];
    fmi2ValueReference in[MAX_VRS], out[MAX_VRS];
    size_t n_in, n_out;
    fmi2Real in_values[MAX_VRS], out_values[MAX_VRS];
    void *lib;
    fmi2Component c;
    fmi2InstantiateTYPE *instantiate;
    fmi2SetupExperimentTYPE *setup_experiment;
    fmi2EnterInitializationModeTYPE *enter_init;
    fmi2ExitInitializationModeTYPE *exit_init;
    fmi2SetRealTYPE *set_real;
    fmi2GetRealTYPE *get_real;
    fmi2DoStepTYPE *do_step;
    fmi2TerminateTYPE *terminate;
    fmi2FreeInstanceTYPE *free_instance;
} Fmu;

static void fail(const char *fmt, ...) {
    va_list ap;
    va_start(ap, fmt);
    fputs("fmi_host: ", stderr);
    vfprintf(stderr, fmt, ap);
    fputc('\n', stderr);
    va_end(ap);
    exit(1);
}

static void logger(fmi2ComponentEnvironment env, fmi2String name, fmi2Status status, fmi2String category,
                   fmi2String message, ...) {
    (void)env;
    fprintf(stderr, "[%s] status %d %s: %s\n", name, (int)status, category ? category : "", message);
}

static size_t parse_vrs(const char *text, fmi2ValueReference *vrs, const char *what) {
    size_t n = 0;
    char *end;
    while (*text) {
        if (n == MAX_VRS) fail("%s: more than %d value references", what, MAX_VRS);
        vrs[n++] = (fmi2ValueReference)strtoul(text, &end, 10);
        if (end == text || (*end && *end != ',')) fail("%s: bad value reference list '%s'", what, text);
        text = *end ? end + 1 : end;
    }
    return n;
}

static void parse_fmu(const char *arg, Fmu *f) {
    char buf[8192], *field[5], *p = buf;
    if (strlen(arg) >= sizeof buf) fail("FMU argument too long: %s", arg);
    strcpy(buf, arg);
    for (int k = 0; k < 5; k++) {
        field[k] = p;
        p = strchr(p, ':');
        if (k < 4 && !p) fail("FMU argument '%s': expected DIR:MODEL_IDENTIFIER:GUID:IN_VRS:OUT_VRS", arg);
        if (p) *p++ = '\0';
    }
    snprintf(f->dir, sizeof f->dir, "%s", field[0]);
    snprintf(f->id, sizeof f->id, "%s", field[1]);
    snprintf(f->guid, sizeof f->guid, "%s", field[2]);
    f->n_in = parse_vrs(field[3], f->in, arg);
    f->n_out = parse_vrs(field[4], f->out, arg);
}

static void *symbol(Fmu *f, const char *name) {
    void *s = dlsym(f->lib, name);
    if (!s) fail("%s: no symbol %s", f->id, name);
    return s;
}

static void load(Fmu *f, double stop) {
    char path[8400], uri[8400];
    snprintf(path, sizeof path, "%s/binaries/linux64/%s.so", f->dir, f->id);
    f->lib = dlopen(path, RTLD_NOW | RTLD_LOCAL);
    if (!f->lib) fail("%s: dlopen failed: %s", f->id, dlerror());
    f->instantiate = (fmi2InstantiateTYPE *)symbol(f, "fmi2Instantiate");
    f->setup_experiment = (fmi2SetupExperimentTYPE *)symbol(f, "fmi2SetupExperiment");
    f->enter_init = (fmi2EnterInitializationModeTYPE *)symbol(f, "fmi2EnterInitializationMode");
    f->exit_init = (fmi2ExitInitializationModeTYPE *)symbol(f, "fmi2ExitInitializationMode");
    f->set_real = (fmi2SetRealTYPE *)symbol(f, "fmi2SetReal");
    f->get_real = (fmi2GetRealTYPE *)symbol(f, "fmi2GetReal");
    f->do_step = (fmi2DoStepTYPE *)symbol(f, "fmi2DoStep");
    f->terminate = (fmi2TerminateTYPE *)symbol(f, "fmi2Terminate");
    f->free_instance = (fmi2FreeInstanceTYPE *)symbol(f, "fmi2FreeInstance");
    static fmi2CallbackFunctions callbacks = {logger, calloc, free, NULL, NULL};
    snprintf(uri, sizeof uri, "file://%s/resources", f->dir);
    f->c = f->instantiate(f->id, fmi2CoSimulation, f->guid, uri, &callbacks, fmi2False, fmi2True);
    if (!f->c) fail("%s: fmi2Instantiate failed", f->id);
    if (f->setup_experiment(f->c, fmi2False, 0.0, 0.0, fmi2True, stop) > fmi2Warning)
        fail("%s: fmi2SetupExperiment failed", f->id);
    if (f->enter_init(f->c) > fmi2Warning) fail("%s: fmi2EnterInitializationMode failed", f->id);
    if (f->exit_init(f->c) > fmi2Warning) fail("%s: fmi2ExitInitializationMode failed", f->id);
    if (f->n_out && f->get_real(f->c, f->out, f->n_out, f->out_values) > fmi2Warning)
        fail("%s: fmi2GetReal failed", f->id);
}

static void step(Fmu *f, double t, double h) {
    if (f->n_in && f->set_real(f->c, f->in, f->n_in, f->in_values) > fmi2Warning)
        fail("%s: fmi2SetReal failed at t = %g s", f->id, t);
    if (f->do_step(f->c, t, h, fmi2True) > fmi2Warning) fail("%s: fmi2DoStep failed at t = %g s", f->id, t);
    if (f->n_out && f->get_real(f->c, f->out, f->n_out, f->out_values) > fmi2Warning)
        fail("%s: fmi2GetReal failed at t = %g s", f->id, t);
}

static void run_loop(Fmu *sp, Fmu *ctrl, Fmu *plant, long ticks, double h) {
    if (ctrl->n_in != sp->n_out + plant->n_out || plant->n_in != ctrl->n_out)
        fail("%s/%s/%s: connector counts do not match", sp->id, ctrl->id, plant->id);
    for (long n = 0; n < ticks; n++) {
        double t = (double)n * h;
        step(sp, t, h);
        memcpy(plant->in_values, ctrl->out_values, ctrl->n_out * sizeof(fmi2Real));
        step(plant, t, h);
        memcpy(ctrl->in_values, sp->out_values, sp->n_out * sizeof(fmi2Real));
        memcpy(ctrl->in_values + sp->n_out, plant->out_values, plant->n_out * sizeof(fmi2Real));
        step(ctrl, t, h);
    }
}

int main(int argc, char **argv) {
    static Fmu fmus[MAX_FMUS];
    int a = 1, keep = 0;
    if (a < argc && strcmp(argv[a], "--keep") == 0) keep = 1, a++;
    int count = argc - a - 2;
    if (count < 3 || count % 3 || count > MAX_FMUS)
        fail("usage: fmi_host [--keep] STOP STEP SETPOINT CONTROLLER PLANT [SETPOINT CONTROLLER PLANT ...]");
    double stop = atof(argv[a]), h = atof(argv[a + 1]);
    if (!(stop > 0) || !(h > 0)) fail("STOP and STEP must be > 0 (got %s, %s)", argv[a], argv[a + 1]);
    long ticks = (long)(stop / h + 0.5);
    for (int k = 0; k < count; k++) parse_fmu(argv[a + 2 + k], &fmus[k]);
    for (int k = 0; k < count; k++) load(&fmus[k], stop);
    for (int k = 0; k < count; k += 3) {
        run_loop(&fmus[k], &fmus[k + 1], &fmus[k + 2], ticks, h);
        printf("loop %d:", k / 3);
        for (size_t j = 0; j < fmus[k + 2].n_out; j++) printf(" %.17g", fmus[k + 2].out_values[j]);
        printf("\n");
    }
    fflush(stdout);
    if (keep) return 0;
    for (int k = 0; k < count; k++) {
        if (fmus[k].terminate(fmus[k].c) > fmi2Warning) fail("%s: fmi2Terminate failed", fmus[k].id);
        fmus[k].free_instance(fmus[k].c);
    }
    for (int k = 0; k < count; k++) dlclose(fmus[k].lib);
    return 0;
}
