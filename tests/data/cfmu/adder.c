/* Adder: y = k1 * u1 + k2 * u2 (direct feedthrough), with a calculated parameter k_sum = k1 + k2
 * that the model computes on initialization (SSP's kind="calculatedParameter"), and a local variable
 * twice_y = 2 y (SSP 2.0's kind="local").
 * r: 0 u1, 1 u2, 2 y, 3 k1, 4 k2, 5 k_sum, 6 twice_y */
#define NR 7
#define NI 0
#define NB 0
#define NS 0
#include "model.h"

static void model_reset(Model *m) {
    m->r[0] = 1.0; m->r[1] = 1.0;
    m->r[3] = 1.0; m->r[4] = 1.0;
}
static void model_calculate(Model *m) {
    m->r[2] = m->r[3] * m->r[0] + m->r[4] * m->r[1];
    m->r[5] = m->r[3] + m->r[4];
    m->r[6] = 2.0 * m->r[2];
}
static int model_step(Model *m, double t, double h) { return 0; }
