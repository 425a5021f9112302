/* A small FMI 2.0 / 3.0 co-simulation host for the platform tests: runs a closed loop of FMUs' shared
 * libraries (or one FMU) from a plan file and prints every output after every tick, bit for bit.
 * The same source compiles for Linux (dlopen) and, with mingw-w64, for Windows (LoadLibrary;
 * run under wine), so the linux64 and win64 binaries of an FMU run in the same loop.
 *
 * usage: loop_host PLAN
 * PLAN, one command a line (integers in decimal; every Real X as the 16 hex digits of its IEEE bits,
 * so that no strtod of either C library rounds it; paths without spaces):
 *   fmu LIBRARY GUID MULTIPLE     an FMI 2.0 FMU (index 0, 1, ... in order); steps every MULTIPLE ticks
 *   fmu3 LIBRARY TOKEN MULTIPLE   the same for an FMI 3.0 FMU (instantiation token)
 *   set I VR TYPE VALUE           before initialization: parameter VR of FMU I (TYPE r, i or b)
 *   link I VR J VR2 FACTOR OFFSET before each step of FMU I: its Real input VR = FACTOR * out + OFFSET,
 *                                 out the Real output VR2 of FMU J (as read after J's last step)
 *   out I VR                      a Real output printed after each tick (also read after each step)
 *   order I ...                   the Gauss-Seidel step order
 *   run H TICKS                   the base step [s] and the number of ticks
 * Output: one line per tick (and one after initialization), each printed value as 16 hex digits
 * (the IEEE bits, so no printf rounding differs between the C libraries). Exit status non-zero on
 * any FMI error, naming the call.
 */
#include <stdarg.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "fmi2FunctionTypes.h"
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

#define MAX_FMUS 8
#define MAX_ITEMS 256

typedef struct {
    fmi2InstantiateTYPE *instantiate;
    fmi2SetupExperimentTYPE *setup;
    fmi2EnterInitializationModeTYPE *enter_init;
    fmi2ExitInitializationModeTYPE *exit_init;
    fmi2SetRealTYPE *set_real;
    fmi2SetIntegerTYPE *set_integer;
    fmi2SetBooleanTYPE *set_boolean;
    fmi2GetRealTYPE *get_real;
    fmi2DoStepTYPE *do_step;
    fmi2TerminateTYPE *terminate;
    fmi2FreeInstanceTYPE *free_instance;
    fmi2Component c;
    fmi3InstantiateCoSimulationTYPE *instantiate3;
    fmi3EnterInitializationModeTYPE *enter_init3;
    fmi3ExitInitializationModeTYPE *exit_init3;
    fmi3SetFloat64TYPE *set_float64;
    fmi3SetInt32TYPE *set_int32;
    fmi3SetBooleanTYPE *set_boolean3;
    fmi3GetFloat64TYPE *get_float64;
    fmi3DoStepTYPE *do_step3;
    fmi3TerminateTYPE *terminate3;
    fmi3FreeInstanceTYPE *free_instance3;
    int fmi3;
    int multiple;
} Fmu;

typedef struct { int fmu; unsigned vr; char type; double value; } Set;
typedef struct { int fmu; unsigned vr; int src; unsigned src_vr; double factor, offset; } Link;
typedef struct { int fmu; unsigned vr; double value; } Out;

static Fmu fmus[MAX_FMUS];
static Set sets[MAX_ITEMS];
static Link links[MAX_ITEMS];
static Out outs[MAX_ITEMS];
static int order[MAX_FMUS];
static int nfmus, nsets, nlinks, nouts, norder;

#include "host_logger.h"

static int fail(const char *what, int i) {
    fprintf(stderr, "loop_host: %s failed (FMU %d)\n", what, i);
    return 1;
}

/* memcpy: ISO C has no cast from the object pointer the loaders return to a function pointer. */
#define LOAD(field, name)                                                               \
    p = symbol(lib, #name);                                                              \
    memcpy(&f->field, &p, sizeof p);                                                     \
    if (p == NULL) {                                                                     \
        fprintf(stderr, "loop_host: %s has no %s\n", path, #name);                     \
        return 1;                                                                        \
    }

static fmi2CallbackFunctions callbacks = {logger, calloc, free, NULL, NULL};

static void log3(fmi3InstanceEnvironment env, fmi3Status status, fmi3String category, fmi3String message) {
    (void)env;
    fprintf(stderr, "[%d %s] %s\n", (int)status, category, message);
}

static int load(const char *path, const char *guid, int multiple, int fmi3) {
    Fmu *f = &fmus[nfmus];
    Library lib = open_library(path);
    void *p;
    if (lib == NULL) {
        fprintf(stderr, "loop_host: cannot load %s\n", path);
        return 1;
    }
    f->fmi3 = fmi3;
    f->multiple = multiple;
    if (fmi3) {
        LOAD(instantiate3, fmi3InstantiateCoSimulation)
        LOAD(enter_init3, fmi3EnterInitializationMode)
        LOAD(exit_init3, fmi3ExitInitializationMode)
        LOAD(set_float64, fmi3SetFloat64)
        LOAD(set_int32, fmi3SetInt32)
        LOAD(set_boolean3, fmi3SetBoolean)
        LOAD(get_float64, fmi3GetFloat64)
        LOAD(do_step3, fmi3DoStep)
        LOAD(terminate3, fmi3Terminate)
        LOAD(free_instance3, fmi3FreeInstance)
        f->c = f->instantiate3("host", guid, "", fmi3False, fmi3False, fmi3False, fmi3False, NULL, 0, NULL, log3, NULL);
        if (f->c == NULL) return fail("fmi3InstantiateCoSimulation", nfmus);
        nfmus++;
        return 0;
    }
    LOAD(instantiate, fmi2Instantiate)
    LOAD(setup, fmi2SetupExperiment)
    LOAD(enter_init, fmi2EnterInitializationMode)
    LOAD(exit_init, fmi2ExitInitializationMode)
    LOAD(set_real, fmi2SetReal)
    LOAD(set_integer, fmi2SetInteger)
    LOAD(set_boolean, fmi2SetBoolean)
    LOAD(get_real, fmi2GetReal)
    LOAD(do_step, fmi2DoStep)
    LOAD(terminate, fmi2Terminate)
    LOAD(free_instance, fmi2FreeInstance)
    f->c = f->instantiate("host", fmi2CoSimulation, guid, "", &callbacks, fmi2False, fmi2False);
    if (f->c == NULL) return fail("fmi2Instantiate", nfmus);
    nfmus++;
    return 0;
}

/* The FMI calls of either version: 0 on success. */
static int set_real(Fmu *f, unsigned vr, double x) {
    return f->fmi3 ? f->set_float64(f->c, &vr, 1, &x, 1) != fmi3OK : f->set_real(f->c, &vr, 1, &x) != fmi2OK;
}

static int get_real(Fmu *f, unsigned vr, double *x) {
    return f->fmi3 ? f->get_float64(f->c, &vr, 1, x, 1) != fmi3OK : f->get_real(f->c, &vr, 1, x) != fmi2OK;
}

static int enter_init(Fmu *f) {
    if (f->fmi3) return f->enter_init3(f->c, fmi3False, 0.0, 0.0, fmi3False, 0.0) != fmi3OK;
    return f->setup(f->c, fmi2False, 0.0, 0.0, fmi2False, 0.0) != fmi2OK || f->enter_init(f->c) != fmi2OK;
}

static int exit_init(Fmu *f) { return f->fmi3 ? f->exit_init3(f->c) != fmi3OK : f->exit_init(f->c) != fmi2OK; }

static int do_step(Fmu *f, double t, double h) {
    fmi3Boolean event = fmi3False, stop = fmi3False, early = fmi3False;
    fmi3Float64 last = t;
    if (f->fmi3) return f->do_step3(f->c, t, h, fmi3True, &event, &stop, &early, &last) != fmi3OK || stop || early;
    return f->do_step(f->c, t, h, fmi2True) != fmi2OK;
}

static void finish(Fmu *f) {
    if (f->fmi3) {
        f->terminate3(f->c);
        f->free_instance3(f->c);
    } else {
        f->terminate(f->c);
        f->free_instance(f->c);
    }
}

static int set_parameter(const Set *s) {
    Fmu *f = &fmus[s->fmu];
    if (s->type == 'i') {
        fmi2Integer i = (fmi2Integer)s->value;
        fmi3Int32 i3 = (fmi3Int32)s->value;
        return f->fmi3 ? f->set_int32(f->c, &s->vr, 1, &i3, 1) != fmi3OK : f->set_integer(f->c, &s->vr, 1, &i) != fmi2OK;
    }
    if (s->type == 'b') {
        fmi2Boolean b = s->value != 0.0 ? fmi2True : fmi2False;
        fmi3Boolean b3 = s->value != 0.0;
        return f->fmi3 ? f->set_boolean3(f->c, &s->vr, 1, &b3, 1) != fmi3OK : f->set_boolean(f->c, &s->vr, 1, &b) != fmi2OK;
    }
    return set_real(f, s->vr, s->value);
}

/* Read FMU k's outputs of the plan (those of `out` lines, and those links read). */
static int read_outputs(int k) {
    int i;
    for (i = 0; i < nouts; i++)
        if (outs[i].fmu == k && get_real(&fmus[k], outs[i].vr, &outs[i].value)) return fail("get (Real)", k);
    return 0;
}

static double output_value(int k, unsigned vr) {
    int i;
    for (i = 0; i < nouts; i++)
        if (outs[i].fmu == k && outs[i].vr == vr) return outs[i].value;
    fprintf(stderr, "loop_host: output %u of FMU %d is linked but not an `out` of the plan\n", vr, k);
    exit(2);
}

static int write_inputs(int k) {
    int i;
    for (i = 0; i < nlinks; i++) {
        if (links[i].fmu == k) {
            double x = links[i].factor * output_value(links[i].src, links[i].src_vr) + links[i].offset;
            if (set_real(&fmus[k], links[i].vr, x)) return fail("set (Real input)", k);
        }
    }
    return 0;
}

static void print_row(void) {
    int i;
    for (i = 0; i < nouts; i++) {
        unsigned char b[8];
        int j;
        memcpy(b, &outs[i].value, 8);
        for (j = 7; j >= 0; j--) printf("%02x", b[j]);
        putchar(i + 1 < nouts ? ' ' : '\n');
    }
}

static int initialize(void) {
    int i, j;
    for (i = 0; i < nsets; i++)
        if (set_parameter(&sets[i])) return fail("set (parameter)", sets[i].fmu);
    for (i = 0; i < nfmus; i++) {
        if (enter_init(&fmus[i])) return fail("setup / enter initialization mode", i);
        if (read_outputs(i)) return 1;
    }
    for (j = 0; j < norder; j++) {
        int k = order[j];
        if (write_inputs(k)) return 1;
        if (exit_init(&fmus[k])) return fail("exit initialization mode", k);
        if (read_outputs(k)) return 1;
    }
    return 0;
}

static int run(double h, long ticks) {
    long n;
    int j;
    if (initialize()) return 1;
    print_row();
    for (n = 0; n < ticks; n++) {
        for (j = 0; j < norder; j++) {
            int k = order[j], m = fmus[k].multiple;
            if ((n + 1) % m != 0) continue;
            if (write_inputs(k)) return 1;
            if (do_step(&fmus[k], (double)((n / m) * m) * h, (double)m * h)) return fail("do step", k);
            if (read_outputs(k)) return 1;
        }
        print_row();
    }
    for (j = 0; j < nfmus; j++) finish(&fmus[j]);
    return 0;
}

/* A Real of the plan: 16 hex digits, the IEEE bits, most significant first. */
static int read_real(FILE *plan, double *x) {
    char hex[17];
    unsigned char b[8];
    int i;
    if (fscanf(plan, "%16s", hex) != 1 || strlen(hex) != 16) return 0;
    for (i = 0; i < 8; i++) {
        unsigned v;
        if (sscanf(hex + 2 * i, "%2x", &v) != 1) return 0;
        b[7 - i] = (unsigned char)v;
    }
    memcpy(x, b, 8);
    return 1;
}

static int parse(FILE *plan) {
    char cmd[32], a[4096], b[512];
    double h = 0.0;
    long ticks = 0;
    while (fscanf(plan, "%31s", cmd) == 1) {
        if (strcmp(cmd, "fmu") == 0 || strcmp(cmd, "fmu3") == 0) {
            int m;
            if (nfmus >= MAX_FMUS || fscanf(plan, "%4095s %511s %d", a, b, &m) != 3 || load(a, b, m, cmd[3] == '3'))
                return 1;
        } else if (strcmp(cmd, "set") == 0 && nsets < MAX_ITEMS) {
            Set *s = &sets[nsets++];
            if (fscanf(plan, "%d %u %c", &s->fmu, &s->vr, &s->type) != 3 || !read_real(plan, &s->value)) return 1;
        } else if (strcmp(cmd, "link") == 0 && nlinks < MAX_ITEMS) {
            Link *l = &links[nlinks++];
            if (fscanf(plan, "%d %u %d %u", &l->fmu, &l->vr, &l->src, &l->src_vr) != 4 ||
                !read_real(plan, &l->factor) || !read_real(plan, &l->offset))
                return 1;
        } else if (strcmp(cmd, "out") == 0 && nouts < MAX_ITEMS) {
            Out *o = &outs[nouts++];
            if (fscanf(plan, "%d %u", &o->fmu, &o->vr) != 2) return 1;
        } else if (strcmp(cmd, "order") == 0) {
            for (norder = 0; norder < nfmus; norder++)
                if (fscanf(plan, "%d", &order[norder]) != 1) return 1;
        } else if (strcmp(cmd, "run") == 0) {
            if (!read_real(plan, &h) || fscanf(plan, "%ld", &ticks) != 1) return 1;
            return run(h, ticks);
        } else {
            fprintf(stderr, "loop_host: unknown or excess plan command %s\n", cmd);
            return 2;
        }
    }
    fprintf(stderr, "loop_host: the plan has no `run` line\n");
    return 2;
}

int main(int argc, char **argv) {
    FILE *plan;
    int status;
    if (argc != 2) {
        fprintf(stderr, "usage: loop_host PLAN\n");
        return 2;
    }
    plan = fopen(argv[1], "r");
    if (plan == NULL) {
        fprintf(stderr, "loop_host: cannot open %s\n", argv[1]);
        return 2;
    }
    status = parse(plan);
    fclose(plan);
    return status;
}
