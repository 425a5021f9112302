/* What a model-exchange test model adds to model.h (see fmi2_me.h, fmi3_me.h): NX continuous
 * states r[STATES[k]] with derivatives r[DERS[k]], NZ event indicators r[INDICATORS[k]] (all
 * computed by model_calculate from the states, the inputs and m->time), and the event update. */
#ifndef TEST_ME_MODEL_H
#define TEST_ME_MODEL_H
#include <math.h>

/* Update the discrete states at an event (event mode, at m->time): 1 when the continuous states
 * changed; sets *terminate to end the simulation and *next_time to the next time event
 * (INFINITY: none). Called until it reports no further change is needed: it must be idempotent. */
static int model_event(Model *m, int *terminate, double *next_time);

#endif
