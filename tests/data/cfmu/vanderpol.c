/* VanDerPol: x0' = x1, x1' = mu (1 - x0^2) x1 - x0 (model exchange only).
 * r: 0 x0, 1 x1, 2 mu, 3 der(x0), 4 der(x1) */
#define NR 5
#define NI 0
#define NB 0
#define NS 0
#define NX 2
#define NZ 0
#include "model.h"
#include "me_model.h"
static const int STATES[] = {0, 1}, DERS[] = {3, 4}, INDICATORS[] = {0};

static void model_reset(Model *m) { m->r[0] = 2.0; m->r[1] = 0.0; m->r[2] = 1.0; }
static void model_calculate(Model *m) {
    m->r[3] = m->r[1];
    m->r[4] = m->r[2] * (1.0 - m->r[0] * m->r[0]) * m->r[1] - m->r[0];
}
static int model_event(Model *m, int *terminate, double *next_time) { *next_time = INFINITY; return 0; }
