/* FMI 3.0 co-simulation glue of an exported loop: the FMI 2.0 container (container.c) compiled
 * here under the prefix ipcosim_fmi2_ (not exported), with the FMI 3.0 functions of
 * fmi3adapter.h over it. The components keep their own prefixes (<component>_unit.c). */
#include "fmi2Functions.h"
#undef fmi2FullName
#define IPCOSIM_PASTE(a, b) a##b
#define fmi2FullName(name) IPCOSIM_PASTE(ipcosim_fmi2_, name)
#include "container.c"
/* time: one past the largest value reference of the FMI 2.0 variant (harness/native/fmi3.py) */
#define IPCOSIM_TIME_VR ((fmi3ValueReference)container_info.nby_vr)
#include "fmi3adapter.h"
