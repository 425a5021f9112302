/* An FMI 3.0 co-simulation importer of a clocked controller, written from the standard's text
 * (2.2.8 Clocks, 2.3 common states, 4.2 co-simulation state machine), with no Python anywhere.
 *
 * usage: clocked_host STOP STEP SETPOINT CONTROLLER PLANT CONNECTIONS
 *   each FMU: LIBRARY:MODEL_IDENTIFIER:TOKEN:IN_VRS:OUT_VRS[:CLOCK_VR]  (VRS comma-separated; a CLOCK_VR
 *             makes it clocked: instantiated with eventModeUsed, run in Event Mode at its ticks)
 *   CONNECTIONS: the source of each controller input, comma-separated: sK (setpoint output K) or pK
 *                (plant output K); the plant's input 0 is the controller's output 0.
 * Runs the loop (setpoint, plant, controller: the controller samples the plant's new outputs, the
 * plant integrates with the voltage held) and prints the plant's outputs and the controller's
 * output at STOP (%.17g), then the number of Event Modes the controller went through.
 * For a clocked controller, its clock's interval and shift are asked with fmi3GetIntervalDecimal and
 * fmi3GetShiftDecimal in Initialization Mode; tick i is at t_start + shift + i * interval (2.2.8),
 * which must be a communication point (the host checks it in integers of steps). At each tick:
 * fmi3EnterEventMode (not after fmi3ExitInitializationMode, which enters Event Mode itself),
 * fmi3SetClock, fmi3SetFloat64 of the clocked inputs, fmi3GetFloat64 of the clocked outputs while the
 * clock is active, fmi3UpdateDiscreteStates until discreteStatesNeedUpdate is false, fmi3EnterStepMode.
 * Exits non-zero on any FMI error. */
#include <dlfcn.h>
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "fmi3Functions.h"

#define MAXV 16

typedef struct {
    void *lib;
    fmi3Instance c;
    unsigned in[MAXV], out[MAXV];
    int nin, nout;
    double in_v[MAXV], out_v[MAXV];
    int clocked;
    fmi3ValueReference clock;
    long long first, every; /* ticks at steps first + i * every */
    long long events;
} Fmu;

static void logger(fmi3InstanceEnvironment env, fmi3Status status, fmi3String category, fmi3String message) {
    (void)env;
    fprintf(stderr, "[%d] %s: %s\n", (int)status, category != NULL ? category : "", message != NULL ? message : "");
}

static void *sym(Fmu *f, const char *name) {
    void *p = dlsym(f->lib, name);
    if (p == NULL) {
        fprintf(stderr, "missing %s\n", name);
        exit(2);
    }
    return p;
}

#define CALL(f, T, name, ...)                                                      \
    do {                                                                           \
        fmi3Status s_ = ((T *)(size_t)sym(f, #name))((f)->c, __VA_ARGS__);         \
        if (s_ > fmi3Warning) {                                                    \
            fprintf(stderr, "%s failed (%d) at line %d\n", #name, (int)s_, __LINE__); \
            exit(1);                                                               \
        }                                                                          \
    } while (0)
#define CALL0(f, T, name)                                                          \
    do {                                                                           \
        fmi3Status s_ = ((T *)(size_t)sym(f, #name))((f)->c);                      \
        if (s_ > fmi3Warning) {                                                    \
            fprintf(stderr, "%s failed (%d)\n", #name, (int)s_);                   \
            exit(1);                                                               \
        }                                                                          \
    } while (0)

static int vrs(char *text, unsigned *out) {
    int n = 0;
    char *tok;
    for (tok = strtok(text, ","); tok != NULL && n < MAXV; tok = strtok(NULL, ",")) out[n++] = (unsigned)atoi(tok);
    return n;
}

static void load(Fmu *f, char *spec, double stop) {
    char *parts[6] = {0};
    int i = 0;
    char *p = spec;
    fmi3InstantiateCoSimulationTYPE *inst;
    parts[i++] = p;
    while ((p = strchr(p, ':')) != NULL && i < 6) {
        *p++ = '\0';
        parts[i++] = p;
    }
    memset(f, 0, sizeof *f);
    f->lib = dlopen(parts[0], RTLD_NOW | RTLD_LOCAL);
    if (f->lib == NULL) {
        fprintf(stderr, "%s\n", dlerror());
        exit(2);
    }
    f->nin = parts[3] && *parts[3] ? vrs(parts[3], f->in) : 0;
    f->nout = parts[4] && *parts[4] ? vrs(parts[4], f->out) : 0;
    f->clocked = parts[5] != NULL && *parts[5];
    if (f->clocked) f->clock = (fmi3ValueReference)atoi(parts[5]);
    inst = (fmi3InstantiateCoSimulationTYPE *)(size_t)sym(f, "fmi3InstantiateCoSimulation");
    f->c = inst(parts[1], parts[2], NULL, fmi3False, fmi3True, f->clocked ? fmi3True : fmi3False, fmi3False, NULL, 0,
                NULL, logger, NULL);
    if (f->c == NULL) {
        fprintf(stderr, "fmi3InstantiateCoSimulation failed: %s\n", parts[1]);
        exit(1);
    }
    CALL(f, fmi3EnterInitializationModeTYPE, fmi3EnterInitializationMode, fmi3False, 0.0, 0.0, fmi3True, stop);
}

static void get_outputs(Fmu *f) {
    if (f->nout) CALL(f, fmi3GetFloat64TYPE, fmi3GetFloat64, f->out, (size_t)f->nout, f->out_v, (size_t)f->nout);
}

static void set_inputs(Fmu *f) {
    if (f->nin) CALL(f, fmi3SetFloat64TYPE, fmi3SetFloat64, f->in, (size_t)f->nin, f->in_v, (size_t)f->nin);
}

/* The clock's ticks in steps of h (Initialization Mode: the interval and shift of a constant clock). */
static void clock_ticks(Fmu *f, double h) {
    double interval, shift;
    fmi3IntervalQualifier q;
    CALL(f, fmi3GetIntervalDecimalTYPE, fmi3GetIntervalDecimal, &f->clock, 1, &interval, &q);
    CALL(f, fmi3GetShiftDecimalTYPE, fmi3GetShiftDecimal, &f->clock, 1, &shift);
    f->every = llround(interval / h);
    f->first = llround(shift / h);
    if (f->every < 1 || fabs((double)f->every * h - interval) > 1e-12 * interval ||
        fabs((double)f->first * h - shift) > 1e-12 * interval) {
        fprintf(stderr, "clock interval %g s / shift %g s is not a whole number of steps %g s\n", interval, shift, h);
        exit(1);
    }
}

/* One Event Mode at a tick of the clock (entered: already in Event Mode, after initialization). */
static void tick(Fmu *f, int entered) {
    fmi3Clock on = fmi3ClockActive;
    fmi3Boolean need = fmi3True, term = fmi3False, b1, b2, defined;
    double next;
    if (!entered) CALL0(f, fmi3EnterEventModeTYPE, fmi3EnterEventMode);
    CALL(f, fmi3SetClockTYPE, fmi3SetClock, &f->clock, 1, &on);
    set_inputs(f);
    get_outputs(f);
    while (need) {
        CALL(f, fmi3UpdateDiscreteStatesTYPE, fmi3UpdateDiscreteStates, &need, &term, &b1, &b2, &defined, &next);
        if (term) {
            fprintf(stderr, "the controller asked to terminate\n");
            exit(1);
        }
    }
    CALL0(f, fmi3EnterStepModeTYPE, fmi3EnterStepMode);
    f->events++;
}

static void connect(Fmu *s, Fmu *c, Fmu *p, char **conn) {
    int i;
    for (i = 0; i < c->nin; i++) c->in_v[i] = conn[i][0] == 's' ? s->out_v[atoi(conn[i] + 1)] : p->out_v[atoi(conn[i] + 1)];
}

static void do_step(Fmu *f, double t, double h) {
    fmi3Boolean event = fmi3False, term = fmi3False, early = fmi3False;
    double last;
    CALL(f, fmi3DoStepTYPE, fmi3DoStep, t, h, fmi3True, &event, &term, &early, &last);
    if (term) {
        fprintf(stderr, "an FMU asked to terminate\n");
        exit(1);
    }
}

int main(int argc, char **argv) {
    Fmu s, c, p;
    double stop, h;
    long long n, steps, h_ns;
    char *conn[MAXV];
    int i, nconn = 0;
    char *tok;
    if (argc != 7) {
        fprintf(stderr, "usage: clocked_host STOP STEP SETPOINT CONTROLLER PLANT CONNECTIONS\n");
        return 2;
    }
    stop = atof(argv[1]);
    h = atof(argv[2]);
    h_ns = llround(h * 1e9);
    steps = llround(stop / h);
    load(&s, argv[3], stop);
    load(&c, argv[4], stop);
    load(&p, argv[5], stop);
    for (tok = strtok(argv[6], ","); tok != NULL && nconn < MAXV; tok = strtok(NULL, ",")) conn[nconn++] = tok;
    if (nconn != c.nin) {
        fprintf(stderr, "%d connections for %d controller inputs\n", nconn, c.nin);
        return 2;
    }
    if (c.clocked) clock_ticks(&c, h);
    /* Initialization Mode: outputs, the controller's inputs, the plant's voltage; leave in step order */
    get_outputs(&s);
    get_outputs(&p);
    connect(&s, &c, &p, conn);
    set_inputs(&c);
    get_outputs(&c);
    p.in_v[0] = c.out_v[0];
    set_inputs(&p);
    CALL0(&s, fmi3ExitInitializationModeTYPE, fmi3ExitInitializationMode);
    get_outputs(&s);
    CALL0(&p, fmi3ExitInitializationModeTYPE, fmi3ExitInitializationMode);
    get_outputs(&p);
    connect(&s, &c, &p, conn);
    if (c.clocked) {
        CALL0(&c, fmi3ExitInitializationModeTYPE, fmi3ExitInitializationMode); /* now in Event Mode */
        if (c.first == 0) {
            tick(&c, 1);
        } else {
            fmi3Boolean need = fmi3True, term, b1, b2, defined;
            double next;
            while (need)
                CALL(&c, fmi3UpdateDiscreteStatesTYPE, fmi3UpdateDiscreteStates, &need, &term, &b1, &b2, &defined,
                     &next);
            CALL0(&c, fmi3EnterStepModeTYPE, fmi3EnterStepMode);
        }
    } else {
        set_inputs(&c);
        CALL0(&c, fmi3ExitInitializationModeTYPE, fmi3ExitInitializationMode);
        get_outputs(&c);
    }
    for (n = 0; n < steps; n++) {
        double t = (double)(n * h_ns) / 1e9;
        do_step(&s, t, h);
        get_outputs(&s);
        p.in_v[0] = c.out_v[0];
        set_inputs(&p);
        do_step(&p, t, h);
        get_outputs(&p);
        connect(&s, &c, &p, conn);
        if (c.clocked) {
            do_step(&c, t, h);
            if (n + 1 >= c.first && (n + 1 - c.first) % c.every == 0) tick(&c, 0);
        } else {
            set_inputs(&c);
            do_step(&c, t, h);
            get_outputs(&c);
        }
    }
    for (i = 0; i < p.nout; i++) printf("%.17g ", p.out_v[i]);
    printf("%.17g\n%lld\n", c.out_v[0], c.events);
    CALL0(&c, fmi3TerminateTYPE, fmi3Terminate);
    CALL0(&p, fmi3TerminateTYPE, fmi3Terminate);
    CALL0(&s, fmi3TerminateTYPE, fmi3Terminate);
    return 0;
}
