/* PassThrough3 (FMI 3.0): every FMI 3.0 type SSP can connect, copied from input to output.
 * r: 0 f64_in, 1 f64_out, 2 f32_in, 3 f32_out
 * i: 0 i32_in, 1 i32_out, 2 i16_in, 3 i16_out, 4 u8_in, 5 u8_out, 6 i64_in, 7 i64_out
 * b: 0 bool_in, 1 bool_out | s: 0 string_in, 1 string_out */
#include <string.h>
#define NR 4
#define NI 8
#define NB 2
#define NS 2
#include "model.h"

static void model_reset(Model *m) { memset(m, 0, sizeof(Model)); }
static void model_calculate(Model *m) {
    int k;
    for (k = 0; k < NR; k += 2) m->r[k + 1] = m->r[k];
    for (k = 0; k < NI; k += 2) m->i[k + 1] = m->i[k];
    m->b[1] = m->b[0];
    strcpy(m->s[1], m->s[0]);
}
static int model_step(Model *m, double t, double h) { return 0; }
