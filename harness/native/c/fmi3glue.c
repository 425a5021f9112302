/* FMI 3.0 co-simulation glue of a native ipcosim model: the FMI 2.0 glue (fmi2glue.c) compiled
 * here under the prefix ipcosim_fmi2_ (not exported), with the FMI 3.0 functions of
 * fmi3adapter.h over it. Sources of an FMI 3.0 native FMU: model.c and this file. */
#include "fmi2Functions.h"
#undef fmi2FullName
#define IPCOSIM_PASTE(a, b) a##b
#define fmi2FullName(name) IPCOSIM_PASTE(ipcosim_fmi2_, name)
#include "fmi2glue.c"
/* time: one past the largest value reference of the FMI 2.0 variant (harness/native/fmi3.py) */
#define IPCOSIM_TIME_VR ((fmi3ValueReference)model_info.nby_vr)
/* model exchange where the model has it (a plant): fmi3me.h */
#define IPCOSIM_EXCHANGE (model_info.exchange)
#include "fmi3adapter.h"
