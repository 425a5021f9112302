/* Staircase: an Integer counter that steps up by one at every time event t = n * period
 * (n = 0, 1, ...), announced as the next event time; no continuous state (model exchange only).
 * With limit > 0 it asks to end the simulation at the event where the counter reaches limit.
 * r: 0 period, 1 height (= 0.5 counter), 2 last_tick | i: 0 counter, 1 limit */
#define NR 3
#define NI 2
#define NB 0
#define NS 0
#define NX 0
#define NZ 0
#include "model.h"
#include "me_model.h"
static const int STATES[] = {0}, DERS[] = {0}, INDICATORS[] = {0};

static void model_reset(Model *m) { m->r[0] = 0.15; m->r[2] = 0.0; m->i[0] = 0; m->i[1] = 0; }
static void model_calculate(Model *m) { m->r[1] = 0.5 * (double)m->i[0]; }
static int model_event(Model *m, int *terminate, double *next_time) {
    double next = (double)m->i[0] * m->r[0];
    if (m->time >= next - 1e-12 * (1.0 + fabs(next))) {
        m->i[0] += 1;
        m->r[2] = m->time;
        next = (double)m->i[0] * m->r[0];
        *terminate = m->i[1] > 0 && m->i[0] >= m->i[1];
    }
    *next_time = next;
    return 0;
}
