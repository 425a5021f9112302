/* Decay: x' = -k x + u, one continuous state, offered as model exchange and as co-simulation
 * (whose step is the exact solution with u held: x(t+h) = u/k + (x - u/k) exp(-k h)).
 * r: 0 x, 1 k, 2 u, 3 der(x) */
#include <math.h>
#define NR 4
#define NI 0
#define NB 0
#define NS 0
#define NX 1
#define NZ 0
#include "model.h"
#include "me_model.h"
static const int STATES[] = {0}, DERS[] = {3}, INDICATORS[] = {0};

static void model_reset(Model *m) { m->r[0] = 1.0; m->r[1] = 1.0; m->r[2] = 0.0; }
static void model_calculate(Model *m) { m->r[3] = -m->r[1] * m->r[0] + m->r[2]; }
static int model_step(Model *m, double t, double h) {
    double k = m->r[1], u = m->r[2], x = m->r[0];
    m->r[0] = k != 0.0 ? u / k + (x - u / k) * exp(-k * h) : x + u * h;
    return 0;
}
static int model_event(Model *m, int *terminate, double *next_time) { *next_time = INFINITY; return 0; }
