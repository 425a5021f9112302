/* Source3 (FMI 3.0): Float64 `y` = amplitude from step_time on (0 before), Int32 `count` the
 * steps taken, Boolean `on` = (y != 0), String `label` = "on"/"off".
 * r: 0 y, 1 amplitude, 2 step_time | i: 0 count | b: 0 on | s: 0 label */
#include <string.h>
#define NR 3
#define NI 1
#define NB 1
#define NS 1
#include "model.h"

static void model_reset(Model *m) { m->r[1] = 1.0; m->r[2] = 0.5; m->i[0] = 0; }
static void model_calculate(Model *m) {
    m->r[0] = m->time >= m->r[2] - 1e-12 ? m->r[1] : 0.0;
    m->b[0] = m->r[0] != 0.0;
    strcpy(m->s[0], m->b[0] ? "on" : "off");
}
static int model_step(Model *m, double t, double h) { m->i[0] += 1; return 0; }
