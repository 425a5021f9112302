/* Counter: a multi-rate test component. Integer `steps` counts its steps, Real `reached` is the
 * time it reached, `integral` integrates its input u (held over each step: u * h).
 * r: 0 u, 1 reached, 2 integral | i: 0 steps */
#define NR 3
#define NI 1
#define NB 0
#define NS 0
#include "model.h"

static void model_reset(Model *m) { m->r[0] = 0.0; m->r[1] = 0.0; m->r[2] = 0.0; m->i[0] = 0; }
static void model_calculate(Model *m) { m->r[1] = m->time; }
static int model_step(Model *m, double t, double h) {
    m->r[2] += m->r[0] * h;
    m->i[0] += 1;
    m->time = t + h;
    return 0;
}
