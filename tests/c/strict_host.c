/* An FMI 3.0 co-simulation importer that does what the standard allows and a strict host does:
 * reads every variable of the model description, one batched fmi3Get{Type} call per type, in
 * every state where the standard allows a get (Instantiated, Initialization Mode, Step Mode after
 * initialization and after every step, Terminated: FMI 3.0 section 2.3), and checks the
 * independent variable against the communication point. The same source compiles for Linux
 * (dlopen) and, with mingw-w64, for Windows (LoadLibrary; run under wine).
 *
 * usage: strict_host PLAN
 * PLAN, one command a line (paths without spaces; the variables as the model description lists them),
 * any number of FMUs one after the other:
 *   fmu LIBRARY TOKEN        the FMU's shared library and instantiation token
 *   var TYPE VR              a variable: TYPE Float64, Float32, Int8, UInt8, Int16, UInt16, Int32,
 *                            UInt32, Int64, UInt64, Boolean or String
 *   time VR                  the independent variable (a Float64, also listed with var)
 *   run START H STEPS        start time, communication step size [s], number of steps: runs the FMU
 *   set VR VALUE             a Float64 to set in Initialization Mode of the next `me` run
 *   me START H STEPS         runs the FMU through its model exchange instead (run_me below)
 * What it checks for each FMU, a failure ending that FMU's run with one line "error: ..." (then
 * the next FMU; exit status 1 at the end):
 *   - fmi3InstantiateCoSimulation with eventModeUsed = fmi3True returns NULL and logs an error
 *     (the FMU declares no Event Mode: section 2.3.1 "otherwise the FMU must raise an error");
 *   - instantiated with eventModeUsed = fmi3False, earlyReturnAllowed = fmi3True: every get returns
 *     fmi3OK in every state above;
 *   - time = START in Initialization Mode and after it; after each fmi3DoStep(t, h), time = t + h
 *     (section 4.2.1: the FMU computes up to currentCommunicationPoint + communicationStepSize),
 *     and the step neither returns early nor asks for event handling (neither was enabled);
 *   - after fmi3Terminate, time is still the last communication point.
 * Output per FMU: "fmu LIBRARY", one line per round of reads, "STATE TIME NVALUES" (TIME %.17g),
 * then "ok" or "error: ...". Exit status 0 when every FMU passed, 1 if one failed, 2 for a bad plan.
 */
#include <stdarg.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "fmi3FunctionTypes.h"

#ifdef _WIN32
#include <windows.h>
typedef HMODULE Library;
static Library open_library(const char *path) { return LoadLibraryA(path); }
static void *symbol(Library lib, const char *name) { return (void *)(size_t)GetProcAddress(lib, name); }
#else
#include <dlfcn.h>
typedef void *Library;
static Library open_library(const char *path) { return dlopen(path, RTLD_NOW | RTLD_LOCAL); }
static void *symbol(Library lib, const char *name) { return dlsym(lib, name); }
#endif

#define MAX_VARS 4096
#define NTYPES 12

static const char *const TYPE_NAMES[NTYPES] = {"Float64", "Float32", "Int8",   "UInt8",  "Int16",   "UInt16",
                                               "Int32",   "UInt32",  "Int64",  "UInt64", "Boolean", "String"};

/* Every getter has the signature (instance, vrs, nvr, values, nValues); the values buffer is
 * large enough for any type (8 bytes a value). */
typedef fmi3Status GetterType(fmi3Instance, const fmi3ValueReference[], size_t, void *, size_t);

static GetterType *getters[NTYPES];
static fmi3ValueReference vrs[NTYPES][MAX_VARS];
static size_t nvrs[NTYPES];
static fmi3ValueReference time_vr;
static int has_time;
static int errors_logged;

/* A bad plan or a missing function: the host stops. */
static void fatal(const char *fmt, ...) {
    va_list ap;
    va_start(ap, fmt);
    fputs("strict_host: ", stderr);
    vfprintf(stderr, fmt, ap);
    fputc('\n', stderr);
    va_end(ap);
    exit(2);
}

/* A check that failed: the FMU's run ends (its instance is left as it is). */
static int fail(const char *fmt, ...) {
    va_list ap;
    va_start(ap, fmt);
    fputs("error: ", stdout);
    vprintf(fmt, ap);
    fputc('\n', stdout);
    va_end(ap);
    return 1;
}

static void logger(fmi3InstanceEnvironment env, fmi3Status status, fmi3String category, fmi3String message) {
    (void)env;
    if (status >= fmi3Error) errors_logged++;
    fprintf(stderr, "[%d] %s: %s\n", (int)status, category ? category : "", message ? message : "");
}

static int type_index(const char *name) {
    int k;
    for (k = 0; k < NTYPES; k++)
        if (strcmp(TYPE_NAMES[k], name) == 0) return k;
    return -1;
}

/* memcpy: ISO C has no cast from the object pointer the loaders return to a function pointer. */
#define LOAD(dest, name)                                                  \
    do {                                                                  \
        void *p_ = symbol(lib, name);                                     \
        if (p_ == NULL) return fail("the FMU does not export %s", name);  \
        memcpy(&(dest), &p_, sizeof p_);                                  \
    } while (0)

/* Every variable, one call per type, printed as one line; 0, or 1 after a failed get (reported).
 * `t`: the value of time (0 without one). */
static int read_all(fmi3Instance c, const char *state, double *t) {
    static fmi3UInt64 values[MAX_VARS];
    size_t total = 0, i;
    int k;
    *t = 0.0;
    for (k = 0; k < NTYPES; k++) {
        fmi3Status s;
        if (nvrs[k] == 0) continue;
        s = getters[k](c, vrs[k], nvrs[k], values, nvrs[k]);
        if (s != fmi3OK)
            return fail("%s: fmi3Get%s of its %u variables returned status %d", state, TYPE_NAMES[k],
                        (unsigned)nvrs[k], (int)s);
        total += nvrs[k];
        if (k == 0 && has_time)
            for (i = 0; i < nvrs[0]; i++)
                if (vrs[0][i] == time_vr) memcpy(t, &values[i], sizeof *t);
    }
    printf("%s %.17g %u\n", state, *t, (unsigned)total);
    return 0;
}

/* Every variable read in `state`, and time the communication point `want`: 0, or 1 (reported). */
static int check_state(fmi3Instance c, const char *state, double want) {
    double t;
    if (read_all(c, state, &t)) return 1;
    if (has_time && t != want) return fail("%s: time = %.17g, expected the communication point %.17g", state, t, want);
    return 0;
}

/* Instantiate, initialize, step and terminate the FMU of `path`, reading every variable in each
 * state: 0 if every check passed, else 1 (the failure printed). */
static int run_fmu(const char *path, const char *token, double start, double h, long steps) {
    Library lib = open_library(path);
    fmi3InstantiateCoSimulationTYPE *instantiate;
    fmi3EnterInitializationModeTYPE *enter_init;
    fmi3ExitInitializationModeTYPE *exit_init;
    fmi3DoStepTYPE *do_step;
    fmi3TerminateTYPE *terminate;
    fmi3FreeInstanceTYPE *free_instance;
    fmi3Instance c;
    double t, ignored;
    long n;
    int k;
    printf("fmu %s\n", path);
    if (lib == NULL) return fail("cannot load %s", path);
    LOAD(instantiate, "fmi3InstantiateCoSimulation");
    LOAD(enter_init, "fmi3EnterInitializationMode");
    LOAD(exit_init, "fmi3ExitInitializationMode");
    LOAD(do_step, "fmi3DoStep");
    LOAD(terminate, "fmi3Terminate");
    LOAD(free_instance, "fmi3FreeInstance");
    for (k = 0; k < NTYPES; k++) {
        char name[64];
        snprintf(name, sizeof name, "fmi3Get%s", TYPE_NAMES[k]);
        LOAD(getters[k], name);
    }

    /* eventModeUsed = fmi3True on an FMU without Event Mode: an error, no instance */
    errors_logged = 0;
    c = instantiate("strict", token, NULL, fmi3False, fmi3True, fmi3True, fmi3True, NULL, 0, NULL, logger, NULL);
    if (c != NULL) return fail("fmi3InstantiateCoSimulation accepted eventModeUsed = fmi3True (hasEventMode is false)");
    if (errors_logged == 0) return fail("fmi3InstantiateCoSimulation refused eventModeUsed = fmi3True without an error");

    c = instantiate("strict", token, NULL, fmi3False, fmi3True, fmi3False, fmi3True, NULL, 0, NULL, logger, NULL);
    if (c == NULL) return fail("fmi3InstantiateCoSimulation (eventModeUsed false, earlyReturnAllowed true) returned NULL");
    if (read_all(c, "instantiated", &ignored)) return 1;
    if (enter_init(c, fmi3False, 0.0, start, fmi3True, start + (double)steps * h) != fmi3OK)
        return fail("fmi3EnterInitializationMode failed");
    if (check_state(c, "initialization", start)) return 1;
    if (exit_init(c) != fmi3OK) return fail("fmi3ExitInitializationMode failed");
    if (check_state(c, "initialized", start)) return 1;
    t = start;
    for (n = 1; n <= steps; n++) {
        fmi3Boolean event = fmi3True, terminate_now = fmi3True, early = fmi3True;
        fmi3Float64 last = -1.0;
        char state[64];
        fmi3Status s = do_step(c, t, h, fmi3True, &event, &terminate_now, &early, &last);
        if (s != fmi3OK) return fail("fmi3DoStep from t = %.17g returned status %d", t, (int)s);
        if (early || event || terminate_now)
            return fail("fmi3DoStep from t = %.17g: earlyReturn %d, eventHandlingNeeded %d, terminateSimulation %d",
                        t, (int)early, (int)event, (int)terminate_now);
        if (last != t + h)
            return fail("fmi3DoStep from t = %.17g: lastSuccessfulTime %.17g, expected %.17g", t, last, t + h);
        snprintf(state, sizeof state, "step%ld", n);
        if (check_state(c, state, t + h)) return 1;
        t = t + h;
    }
    if (terminate(c) != fmi3OK) return fail("fmi3Terminate failed");
    if (check_state(c, "terminated", t)) return 1;
    free_instance(c);
    printf("ok\n");
    return 0;
}

/* Model exchange (FMI 3.0 chapter 3): instantiated with fmi3InstantiateModelExchange, the `set` values
 * given in Initialization Mode, then STEPS explicit Euler steps of H as the simplest importer
 * integrates: states and derivatives got, the time and the new states set, fmi3CompletedIntegratorStep;
 * where an event indicator changed sign, Event Mode and the event iteration (fmi3UpdateDiscreteStates
 * until no update is needed, at most 64 passes). Every variable is read in Instantiated, Initialization
 * Mode, Event Mode after initialization ("event0"), Continuous-Time Mode after each step ("ctN"), Event
 * Mode at each event ("eventN") and Terminated; time is the time set (the start time until the first
 * fmi3SetTime); fmi3GetNumberOfContinuousStates and fmi3GetNumberOfEventIndicators answer. */
#define MAX_STATES 64
static fmi3ValueReference set_vrs[MAX_VARS];
static double set_values[MAX_VARS];
static size_t nsets;

typedef struct {
    fmi3UpdateDiscreteStatesTYPE *update;
    fmi3EnterContinuousTimeModeTYPE *enter_ct;
    fmi3EnterEventModeTYPE *enter_event;
    fmi3GetEventIndicatorsTYPE *indicators;
} EventCalls;

/* Event Mode at `t`, every variable read, the event iteration, back to Continuous-Time Mode. */
static int handle_event(fmi3Instance c, const EventCalls *e, const char *state, double t, int enter) {
    int pass;
    fmi3Boolean more = fmi3True, stop, nominals, values, defined;
    fmi3Float64 next;
    if (enter && e->enter_event(c) != fmi3OK) return fail("%s: fmi3EnterEventMode failed", state);
    if (check_state(c, state, t)) return 1;
    for (pass = 0; more; pass++) {
        if (pass == 64) return fail("%s: the event iteration did not settle in 64 passes", state);
        if (e->update(c, &more, &stop, &nominals, &values, &defined, &next) != fmi3OK)
            return fail("%s: fmi3UpdateDiscreteStates failed", state);
    }
    return e->enter_ct(c) != fmi3OK ? fail("%s: fmi3EnterContinuousTimeMode failed", state) : 0;
}

static int run_me(const char *path, const char *token, double start, double h, long steps) {
    Library lib = open_library(path);
    fmi3InstantiateModelExchangeTYPE *instantiate;
    fmi3EnterInitializationModeTYPE *enter_init;
    fmi3ExitInitializationModeTYPE *exit_init;
    fmi3SetFloat64TYPE *set_float64;
    fmi3SetTimeTYPE *set_time;
    fmi3GetContinuousStatesTYPE *get_x;
    fmi3SetContinuousStatesTYPE *set_x;
    fmi3GetContinuousStateDerivativesTYPE *get_dx;
    fmi3GetNumberOfContinuousStatesTYPE *number_of_states;
    fmi3GetNumberOfEventIndicatorsTYPE *number_of_indicators;
    fmi3CompletedIntegratorStepTYPE *completed;
    fmi3TerminateTYPE *terminate;
    fmi3FreeInstanceTYPE *free_instance;
    EventCalls e;
    fmi3Instance c;
    double x[MAX_STATES], dx[MAX_STATES], z[MAX_STATES], z0[MAX_STATES], t = start, ignored;
    size_t nx = MAX_STATES + 1, nz = MAX_STATES + 1, i;
    long n;
    int k;
    printf("fmu %s\n", path);
    if (lib == NULL) return fail("cannot load %s", path);
    LOAD(instantiate, "fmi3InstantiateModelExchange");
    LOAD(enter_init, "fmi3EnterInitializationMode");
    LOAD(exit_init, "fmi3ExitInitializationMode");
    LOAD(set_float64, "fmi3SetFloat64");
    LOAD(set_time, "fmi3SetTime");
    LOAD(get_x, "fmi3GetContinuousStates");
    LOAD(set_x, "fmi3SetContinuousStates");
    LOAD(get_dx, "fmi3GetContinuousStateDerivatives");
    LOAD(number_of_states, "fmi3GetNumberOfContinuousStates");
    LOAD(number_of_indicators, "fmi3GetNumberOfEventIndicators");
    LOAD(completed, "fmi3CompletedIntegratorStep");
    LOAD(terminate, "fmi3Terminate");
    LOAD(free_instance, "fmi3FreeInstance");
    LOAD(e.update, "fmi3UpdateDiscreteStates");
    LOAD(e.enter_ct, "fmi3EnterContinuousTimeMode");
    LOAD(e.enter_event, "fmi3EnterEventMode");
    LOAD(e.indicators, "fmi3GetEventIndicators");
    for (k = 0; k < NTYPES; k++) {
        char name[64];
        snprintf(name, sizeof name, "fmi3Get%s", TYPE_NAMES[k]);
        LOAD(getters[k], name);
    }
    c = instantiate("strict", token, NULL, fmi3False, fmi3True, NULL, logger);
    if (c == NULL) return fail("fmi3InstantiateModelExchange returned NULL");
    if (read_all(c, "instantiated", &ignored)) return 1;
    if (number_of_states(c, &nx) != fmi3OK || number_of_indicators(c, &nz) != fmi3OK || nx > MAX_STATES ||
        nz > MAX_STATES)
        return fail("fmi3GetNumberOfContinuousStates / EventIndicators failed (or above %d)", MAX_STATES);
    if (enter_init(c, fmi3False, 0.0, start, fmi3True, start + (double)steps * h) != fmi3OK)
        return fail("fmi3EnterInitializationMode failed");
    if (nsets > 0 && set_float64(c, set_vrs, nsets, set_values, nsets) != fmi3OK) return fail("fmi3SetFloat64 failed");
    if (check_state(c, "initialization", start)) return 1;
    if (exit_init(c) != fmi3OK) return fail("fmi3ExitInitializationMode failed");
    if (handle_event(c, &e, "event0", start, 0)) return 1;
    if (e.indicators(c, z0, nz) != fmi3OK) return fail("fmi3GetEventIndicators failed");
    for (n = 1; n <= steps; n++) {
        fmi3Boolean enter = fmi3True, stop = fmi3True;
        char state[64];
        if (get_x(c, x, nx) != fmi3OK || get_dx(c, dx, nx) != fmi3OK)
            return fail("t = %.17g: fmi3GetContinuousStates or fmi3GetContinuousStateDerivatives failed", t);
        for (i = 0; i < nx; i++) x[i] += h * dx[i];
        t = start + (double)n * h;
        if (set_time(c, t) != fmi3OK || set_x(c, x, nx) != fmi3OK)
            return fail("t = %.17g: fmi3SetTime or fmi3SetContinuousStates failed", t);
        if (completed(c, fmi3True, &enter, &stop) != fmi3OK || stop)
            return fail("t = %.17g: fmi3CompletedIntegratorStep failed or asked to stop", t);
        snprintf(state, sizeof state, "ct%ld", n);
        if (check_state(c, state, t)) return 1;
        if (e.indicators(c, z, nz) != fmi3OK) return fail("t = %.17g: fmi3GetEventIndicators failed", t);
        for (i = 0; i < nz && !enter; i++) enter = (z0[i] > 0.0) != (z[i] > 0.0);
        if (enter) {
            snprintf(state, sizeof state, "event%ld", n);
            if (handle_event(c, &e, state, t, 1) || e.indicators(c, z, nz) != fmi3OK) return 1;
        }
        memcpy(z0, z, nz * sizeof z[0]);
    }
    if (terminate(c) != fmi3OK) return fail("fmi3Terminate failed");
    if (check_state(c, "terminated", t)) return 1;
    free_instance(c);
    printf("ok\n");
    return 0;
}

int main(int argc, char **argv) {
    char line[8192], word[64], path[4096], token[1024];
    int failed = 0, k;
    FILE *plan;
    if (argc != 2) {
        fprintf(stderr, "usage: strict_host PLAN\n");
        return 2;
    }
    plan = fopen(argv[1], "r");
    if (plan == NULL) fatal("cannot read the plan %s", argv[1]);
    path[0] = token[0] = 0;
    while (fgets(line, sizeof line, plan) != NULL) {
        char type[64];
        unsigned vr;
        double start, h, value;
        long steps;
        if (sscanf(line, "%63s", word) != 1) continue;
        if (strcmp(word, "fmu") == 0) {
            if (sscanf(line, "fmu %4095s %1023s", path, token) != 2) fatal("bad plan line: %s", line);
            for (k = 0; k < NTYPES; k++) nvrs[k] = 0;
            has_time = 0;
            nsets = 0;
        } else if (strcmp(word, "var") == 0) {
            if (sscanf(line, "var %63s %u", type, &vr) != 2 || (k = type_index(type)) < 0 || nvrs[k] >= MAX_VARS)
                fatal("bad plan line: %s", line);
            vrs[k][nvrs[k]++] = vr;
        } else if (strcmp(word, "time") == 0) {
            if (sscanf(line, "time %u", &vr) != 1) fatal("bad plan line: %s", line);
            time_vr = vr;
            has_time = 1;
        } else if (strcmp(word, "run") == 0) {
            if (sscanf(line, "run %lf %lf %ld", &start, &h, &steps) != 3 || path[0] == 0)
                fatal("bad plan line: %s", line);
            failed |= run_fmu(path, token, start, h, steps);
            fflush(stdout);
        } else if (strcmp(word, "set") == 0) {
            if (sscanf(line, "set %u %lf", &vr, &value) != 2 || nsets >= MAX_VARS) fatal("bad plan line: %s", line);
            set_vrs[nsets] = vr;
            set_values[nsets++] = value;
        } else if (strcmp(word, "me") == 0) {
            if (sscanf(line, "me %lf %lf %ld", &start, &h, &steps) != 3 || path[0] == 0)
                fatal("bad plan line: %s", line);
            failed |= run_me(path, token, start, h, steps);
            fflush(stdout);
        } else {
            fatal("unknown plan command %s", word);
        }
    }
    fclose(plan);
    return failed;
}
