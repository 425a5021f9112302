/* BouncingBall: height h and velocity v under gravity g, bouncing with restitution e; events
 * located inside doStep by sub-steps of at most 1 ms with the exact impact time of the
 * ballistic arc (the motion between impacts is integrated exactly).
 * r: 0 h, 1 v, 2 g, 3 e | i: 0 bounces | b: 0 falling */
#include <math.h>
#define NR 4
#define NI 1
#define NB 1
#define NS 0
#include "model.h"

static void model_reset(Model *m) {
    m->r[0] = 1.0; m->r[1] = 0.0; m->r[2] = 9.81; m->r[3] = 0.7;
    m->i[0] = 0; m->b[0] = 1;
}
static void model_calculate(Model *m) { m->b[0] = m->r[1] < 0.0; }
static int model_step(Model *m, double t, double h) {
    double left = h, g = m->r[2], e = m->r[3];
    while (left > 0.0) {
        double dt = left < 1e-3 ? left : 1e-3;
        double x = m->r[0], v = m->r[1];
        double xn = x + v * dt - 0.5 * g * dt * dt;
        if (xn < 0.0 && v * v > 1e-12) {
            /* impact time: x + v s - g s^2 / 2 = 0 */
            double s = (v + sqrt(v * v + 2.0 * g * x)) / g;
            if (s > dt) s = dt;
            v = -e * (v - g * s);
            x = 0.0;
            m->i[0] += 1;
            dt = s;
            if (fabs(v) < 1e-3) v = 0.0;
        } else if (xn < 0.0) {
            x = 0.0; v = 0.0;
        } else {
            x = xn; v = v - g * dt;
        }
        m->r[0] = x; m->r[1] = v;
        left -= dt;
        if (dt <= 0.0) break;
    }
    return 0;
}
