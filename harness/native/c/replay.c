/* The identification replay of one native plant (see harness/native/replay.py and model.h).
 *
 * Hand-written and model-independent: the value array starts at the model's start values, the
 * caller's values are written into their slots, the model is initialized at t = 0 and stepped once
 * per logged voltage, exactly as the FMI glue's plant policy steps it (fmi2glue.c), and the slots
 * named in `out` are copied after the start and after every step. Nothing is allocated but the
 * value array; one call is one simulation of the log.
 */
#include <math.h>
#include <stdlib.h>
#include <string.h>

#include "model.h"

int ipcosim_replay_size(void);
long ipcosim_replay(const int *slots, const double *values, int nset, int voltage_slot,
                    const double *voltages, long n, double h, const int *out, int nout, double *rows);

/* The length of the model's value array. */
int ipcosim_replay_size(void) { return model_info.nv; }

/* Returns 0, or k + 1 when a checked slot became non-finite in the step from k h (rows up to k written);
 * -1 when the value array cannot be allocated. */
long ipcosim_replay(const int *slots, const double *values, int nset, int voltage_slot,
                    const double *voltages, long n, double h, const int *out, int nout, double *rows) {
    double *v = malloc((size_t)model_info.nv * sizeof(double));
    long k;
    int i;
    if (v == NULL) return -1;
    memcpy(v, model_info.start, (size_t)model_info.nv * sizeof(double));
    for (i = 0; i < nset; i++) v[slots[i]] = values[i];
    model_info.initialize(v, 0.0);
    for (i = 0; i < nout; i++) rows[i] = v[out[i]];
    for (k = 0; k < n; k++) {
        v[voltage_slot] = voltages[k];
        model_info.step(v, (double)k * h, h);
        for (i = 0; i < model_info.nchecked; i++) {
            if (!isfinite(v[model_info.checked[i]])) {
                free(v);
                return k + 1;
            }
        }
        for (i = 0; i < nout; i++) rows[(k + 1) * nout + i] = v[out[i]];
    }
    free(v);
    return 0;
}
