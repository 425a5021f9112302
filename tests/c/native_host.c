/* Minimal FMI 2.0 co-simulation host for the native-FMU tests: no Python anywhere.
 *
 * usage: native_host LIBRARY GUID STEP_SIZE STEPS [VR=VALUE ...] -- OUTPUT_VR
 * Loads LIBRARY with dlopen, sets the given Real inputs/parameters before initialization,
 * steps STEPS times and prints the Real OUTPUT_VR. Exits 3 if a Python library is mapped
 * into the process (read from /proc/self/maps), non-zero on any FMI error.
 */
#include <dlfcn.h>
#include <stdarg.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "fmi2Functions.h"

#include "host_logger.h"

static int python_mapped(void) {
    char line[4096];
    int found = 0;
    FILE *f = fopen("/proc/self/maps", "r");
    if (f == NULL) return -1;
    while (fgets(line, sizeof line, f) != NULL)
        if (strstr(line, "libpython") != NULL) found = 1;
    fclose(f);
    return found;
}

#define LOAD(T, name) T name = (T)(size_t)dlsym(lib, #name); if (name == NULL) { fprintf(stderr, "missing %s\n", #name); return 2; }

int main(int argc, char **argv) {
    void *lib;
    fmi2CallbackFunctions cb = {logger, calloc, free, NULL, NULL};
    fmi2Component c;
    double h, t = 0.0, y = 0.0;
    long steps, k;
    int i, out_arg = -1;
    fmi2ValueReference out_vr;
    if (argc < 7) { fprintf(stderr, "usage: native_host LIB GUID H STEPS [VR=VALUE ...] -- OUT_VR\n"); return 2; }
    lib = dlopen(argv[1], RTLD_NOW | RTLD_LOCAL);
    if (lib == NULL) { fprintf(stderr, "%s\n", dlerror()); return 2; }
    {
        LOAD(fmi2InstantiateTYPE *, fmi2Instantiate)
        LOAD(fmi2SetupExperimentTYPE *, fmi2SetupExperiment)
        LOAD(fmi2EnterInitializationModeTYPE *, fmi2EnterInitializationMode)
        LOAD(fmi2ExitInitializationModeTYPE *, fmi2ExitInitializationMode)
        LOAD(fmi2SetRealTYPE *, fmi2SetReal)
        LOAD(fmi2GetRealTYPE *, fmi2GetReal)
        LOAD(fmi2DoStepTYPE *, fmi2DoStep)
        LOAD(fmi2TerminateTYPE *, fmi2Terminate)
        LOAD(fmi2FreeInstanceTYPE *, fmi2FreeInstance)
        h = atof(argv[3]);
        steps = atol(argv[4]);
        c = fmi2Instantiate("host", fmi2CoSimulation, argv[2], "", &cb, fmi2False, fmi2False);
        if (c == NULL) return 4;
        for (i = 5; i < argc; i++) {
            if (strcmp(argv[i], "--") == 0) { out_arg = i + 1; break; }
            {
                fmi2ValueReference vr = (fmi2ValueReference)strtoul(argv[i], NULL, 10);
                const char *eq = strchr(argv[i], '=');
                fmi2Real v = eq != NULL ? atof(eq + 1) : 0.0;
                if (fmi2SetReal(c, &vr, 1, &v) != fmi2OK) return 5;
            }
        }
        if (out_arg < 0 || out_arg >= argc) return 2;
        out_vr = (fmi2ValueReference)strtoul(argv[out_arg], NULL, 10);
        if (fmi2SetupExperiment(c, fmi2False, 0.0, 0.0, fmi2False, 0.0) != fmi2OK) return 5;
        if (fmi2EnterInitializationMode(c) != fmi2OK || fmi2ExitInitializationMode(c) != fmi2OK) return 5;
        for (k = 0; k < steps; k++) {
            if (fmi2DoStep(c, t, h, fmi2True) != fmi2OK) return 6;
            t = (double)(k + 1) * h;
        }
        if (fmi2GetReal(c, &out_vr, 1, &y) != fmi2OK) return 5;
        fmi2Terminate(c);
        fmi2FreeInstance(c);
    }
    printf("%.17g\n", y);
    if (python_mapped() != 0) { fprintf(stderr, "a Python library is mapped into the host\n"); return 3; }
    dlclose(lib);
    return 0;
}
