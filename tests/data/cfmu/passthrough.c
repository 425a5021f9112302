/* PassThrough: every type in, every type out, through one parameter of that type each:
 * real_out = gain * real_in, int_out = int_in + offset, bool_out = bool_in xor invert,
 * string_out = prefix + string_in (direct feedthrough).
 * r: 0 real_in, 1 real_out, 2 gain | i: 0 int_in, 1 int_out, 2 offset
 * b: 0 bool_in, 1 bool_out, 2 invert | s: 0 string_in, 1 string_out, 2 prefix */
#include <string.h>
#include <stdio.h>
#define NR 3
#define NI 3
#define NB 3
#define NS 3
#include "model.h"

static void model_reset(Model *m) {
    m->r[0] = 0.0; m->r[2] = 1.0;
    m->i[0] = 0; m->i[2] = 0;
    m->b[0] = 0; m->b[2] = 0;
    strcpy(m->s[0], ""); strcpy(m->s[2], "");
}
static void model_calculate(Model *m) {
    m->r[1] = m->r[2] * m->r[0];
    m->i[1] = m->i[0] + m->i[2];
    m->b[1] = m->b[0] != m->b[2];
    snprintf(m->s[1], MAX_STRING, "%s%s", m->s[2], m->s[0]);
}
static int model_step(Model *m, double t, double h) { return 0; }
