/* BouncingBallME: h' = v, v' = -g; the event indicator h locates each impact, where v becomes
 * -e v (model exchange only). Below 0.1 m/s after an impact the ball rests (h = v = 0).
 * r: 0 h, 1 v, 2 g, 3 e, 4 der(h), 5 der(v), 6 indicator, 7 last_bounce | i: 0 bounces | b: 0 resting */
#define NR 8
#define NI 1
#define NB 1
#define NS 0
#define NX 2
#define NZ 1
#include "model.h"
#include "me_model.h"
static const int STATES[] = {0, 1}, DERS[] = {4, 5}, INDICATORS[] = {6};

static void model_reset(Model *m) {
    m->r[0] = 1.0; m->r[1] = 0.0; m->r[2] = 9.81; m->r[3] = 0.7; m->r[7] = 0.0;
    m->i[0] = 0; m->b[0] = 0;
}
static void model_calculate(Model *m) {
    m->r[4] = m->b[0] ? 0.0 : m->r[1];
    m->r[5] = m->b[0] ? 0.0 : -m->r[2];
    m->r[6] = m->b[0] ? 1.0 : m->r[0];
}
static int model_event(Model *m, int *terminate, double *next_time) {
    *next_time = INFINITY;
    if (m->b[0] || m->r[0] > 0.0 || m->r[1] >= 0.0) return 0;
    m->r[0] = 0.0;
    m->r[1] = -m->r[3] * m->r[1];
    m->i[0] += 1;
    m->r[7] = m->time;
    if (m->r[1] < 0.1) { m->b[0] = 1; m->r[1] = 0.0; }
    return 1;
}
