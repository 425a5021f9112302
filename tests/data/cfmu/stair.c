/* Stair: an Integer counter that counts the communication steps and ends the simulation itself
 * when it would pass `limit` (fmi2Discard from doStep, fmi2Terminated true; FMI 3.0:
 * terminateSimulation). With `end_simulation` false it only discards the step (fmi2Terminated
 * false). With `end_midstep` it ends halfway through that step, counting once more there (its
 * last successful time is then t + h/2, as the Reference-FMUs' Stair ends between two
 * communication points). Output `height` = 0.5 * counter.
 * r: 0 height | i: 0 counter, 1 limit | b: 0 end_simulation, 1 end_midstep */
#define NR 1
#define NI 2
#define NB 2
#define NS 0
#include "model.h"

static void model_reset(Model *m) { m->i[0] = 1; m->i[1] = 10; m->b[0] = 1; m->b[1] = 0; m->terminated = 0; }
static void model_calculate(Model *m) { m->r[0] = 0.5 * (double)m->i[0]; }
static int model_step(Model *m, double t, double h) {
    if (m->i[0] + 1 > m->i[1]) {
        m->terminated = m->b[0];
        m->last_time = t;
        if (m->b[1]) {
            m->i[0] += 1;
            m->r[0] = 0.5 * (double)m->i[0];
            m->last_time = t + 0.5 * h;
        }
        return 1;
    }
    m->i[0] += 1;
    return 0;
}
