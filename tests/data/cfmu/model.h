/* The interface between a test model and the FMI glue (fmi2_glue.c, fmi3_glue.c).
 *
 * A model keeps its values in per-type arrays indexed by value reference (FMI 2.0) or by value
 * reference minus the type's base (FMI 3.0, see fmi3_glue.c): r[] Real/Float64 (and Float32),
 * i[] Integer/Int*, b[] Boolean, s[] String. It provides its start values, its outputs as
 * functions of inputs and state, and one communication step. */
#ifndef TEST_MODEL_H
#define TEST_MODEL_H

#define MAX_STRING 256

typedef struct {
    double r[NR + 1];
    long long i[NI + 1];
    int b[NB + 1];
    char s[NS + 1][MAX_STRING];
    double time;
    int terminated;      /* the model ended the simulation */
    double last_time;    /* last successful time */
} Model;

/* Start values. */
static void model_reset(Model *m);
/* Outputs from inputs and state (called after every set and step). */
static void model_calculate(Model *m);
/* Advance from t to t + h: 0 done, 1 ended the simulation (set m->terminated, m->last_time). */
static int model_step(Model *m, double t, double h);

#endif
