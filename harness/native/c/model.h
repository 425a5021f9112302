/* Interface between the shared FMI 2.0 glue (fmi2glue.c) and one generated model (model.c).
 *
 * Every variable and every internal state of a model is one double in the instance's value
 * array v[0 .. MODEL_NV-1]; Integer and Boolean variables are stored as doubles too.
 * Call order kept by the glue:
 *   instantiate: v = model_start                  (start values, internal state at rest)
 *   exitInitializationMode: model_initialize(v, t0)
 *   doStep(t, h): model_step(v, t, h) on a copy, committed only if every checked value is finite
 */
#ifndef IPCOSIM_NATIVE_MODEL_H
#define IPCOSIM_NATIVE_MODEL_H

#include <stddef.h>

#define MODEL_KIND_PLANT 0   /* one integrator step of exactly integrator_step per fmi2DoStep */
#define MODEL_KIND_SAMPLED 1 /* a discrete law sampled at sample_period, output held in between */
#define MODEL_KIND_SOURCE 2  /* an output that is a function of time */

#define VAR_REAL 0
#define VAR_INTEGER 1
#define VAR_BOOLEAN 2

typedef struct {
    unsigned int vr;   /* value reference */
    int index;         /* slot in v */
    int type;          /* VAR_REAL, VAR_INTEGER, VAR_BOOLEAN */
    int settable;      /* 0: output or calculated; 1: parameter; 2: input */
    const char *name;
} ModelVariable;

#define CHECK_FINITE 0
#define CHECK_POSITIVE 1
#define CHECK_NONNEGATIVE 2
#define CHECK_ZERO 3        /* an option of the Python flavour the native one lacks: must stay 0 */

typedef struct {
    int index;         /* slot in v */
    int kind;          /* CHECK_FINITE, CHECK_POSITIVE, CHECK_NONNEGATIVE, CHECK_ZERO */
    const char *name;
} ParameterCheck;

/* Model exchange of a plant (harness/native/exchange.py; the glue: fmi2me.h). Between events the
 * host sets the time, the states and the inputs, and evaluate(v, time) writes the derivatives, the
 * event indicators and the outputs into their slots; at an event, update(v, time) is one pass of the
 * event iteration (states, discrete states, the next time event), repeated until no discrete state
 * and no state changes. */
typedef struct {
    int nx;                        /* continuous states */
    const int *states;             /* their slots */
    const int *derivatives;        /* the slots of their derivatives */
    int nz;                        /* event indicators */
    const int *indicators;         /* their slots */
    int ndiscrete;                 /* discrete states (the carts' modes, the taps) */
    const int *discrete;           /* their slots */
    int next_event;                /* slot of the next time event (-1.0 in it: none) */
    const ParameterCheck *off;     /* parameters that must be 0 in model exchange (what it does not model) */
    int noff;
    void (*evaluate)(double *v, double time);
    void (*update)(double *v, double time);
} ModelExchangeInfo;

typedef struct {
    const char *identifier;
    const char *guid;
    int kind;
    int nv;                        /* size of the value array */
    const double *start;           /* nv start values */
    const ModelVariable *vars;
    int nvars;
    const int *checked;            /* slots that must stay finite after a step */
    int nchecked;
    int period_index;              /* sample_period (sampled) or integrator_step (plant) slot, else -1 */
    int tick_index;                /* slot of the glue's sample counter (sampled models), else -1 */
    const ParameterCheck *checks;  /* parameter ranges checked on leaving initialization mode */
    int nchecks;
    const int *by_vr;              /* value reference -> position in vars, or -1 */
    int nby_vr;
    void (*initialize)(double *v, double t0);
    void (*step)(double *v, double t, double h);
    const ModelExchangeInfo *exchange; /* NULL: co-simulation only */
} ModelInfo;

extern const ModelInfo model_info;

#endif
