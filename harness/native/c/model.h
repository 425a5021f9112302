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
} ModelInfo;

extern const ModelInfo model_info;

#endif
