/* Interface between the shared container glue (container.c) and one generated scenario table
 * (container_table.c): a closed loop of native components compiled into one FMI 2.0 FMU.
 *
 * Each component is a native model (its generated model.c with the shared fmi2glue.c) compiled
 * in its own translation unit with FMI2_FUNCTION_PREFIX set to a prefix of its own, so its FMI
 * functions are reached only through the table's function pointers. The container's own
 * variables (inputs, outputs, parameters) are doubles in the instance's array v[0 .. nv-1], as
 * in model.h; Integer and Boolean parameters are stored as doubles too.
 */
#ifndef IPCOSIM_NATIVE_CONTAINER_H
#define IPCOSIM_NATIVE_CONTAINER_H

#include "fmi2FunctionTypes.h"
#include "model.h"

/* The FMI functions of one component (prefixed in their translation unit). */
typedef struct {
    fmi2InstantiateTYPE *instantiate;
    fmi2FreeInstanceTYPE *free_instance;
    fmi2SetupExperimentTYPE *setup_experiment;
    fmi2EnterInitializationModeTYPE *enter_initialization_mode;
    fmi2ExitInitializationModeTYPE *exit_initialization_mode;
    fmi2TerminateTYPE *terminate;
    fmi2ResetTYPE *reset;
    fmi2GetRealTYPE *get_real;
    fmi2SetRealTYPE *set_real;
    fmi2SetIntegerTYPE *set_integer;
    fmi2SetBooleanTYPE *set_boolean;
    fmi2DoStepTYPE *do_step;
} ComponentFunctions;

/* Where a component input takes its value from before each step of its component. */
#define SOURCE_OUTPUT 0 /* an output of another component: factor * out + offset */
#define SOURCE_INPUT 1  /* an input of the container (an input no connection feeds) */

typedef struct {
    int kind;          /* SOURCE_OUTPUT or SOURCE_INPUT */
    int component;     /* SOURCE_OUTPUT: the source component */
    int index;         /* SOURCE_OUTPUT: position in its outputs; SOURCE_INPUT: slot in v */
    double factor;     /* SOURCE_OUTPUT: the connection's linear transformation */
    double offset;
    int add_slot;      /* slot in v added to the value (the container's reference input), or -1 */
} InputSource;

typedef struct {
    const char *name;                 /* instance name in the scenario */
    const char *guid;                 /* the component model's GUID */
    const ComponentFunctions *fmi;
    int multiple;                     /* steps once every `multiple` ticks, with step multiple * h */
    int n_out;                        /* Real outputs read after each of its steps */
    const fmi2ValueReference *out_vrs;
    int n_in;                         /* Real inputs set before each of its steps */
    const fmi2ValueReference *in_vrs;
    const InputSource *in_sources;
} ContainerComponent;

/* A component parameter the container exposes as <component>.<name>. */
typedef struct {
    int slot;          /* slot in v */
    int component;
    fmi2ValueReference vr;
    int type;          /* VAR_REAL, VAR_INTEGER, VAR_BOOLEAN */
} ParameterLink;

/* A container output: a component's output copied after every tick. */
typedef struct {
    int slot;
    int component;
    int index;         /* position in the component's outputs */
} OutputLink;

typedef struct {
    const char *identifier;
    const char *guid;
    const ModelVariable *vars;        /* the container's variables (model.h's table row) */
    int nvars;
    const int *by_vr;                 /* value reference -> position in vars, or -1 */
    int nby_vr;
    int nv;
    const double *start;              /* nv start values */
    const ContainerComponent *components;
    int ncomponents;
    const int *order;                 /* Gauss-Seidel step order (component positions) */
    const ParameterLink *parameters;
    int nparameters;
    const OutputLink *outputs;
    int noutputs;
    long long step_ns;                /* the scenario's base step in nanoseconds (> 0) */
    double step;                      /* the same in seconds */
    int max_init_iterations;          /* bound on the initialization fixed point */
} ContainerInfo;

extern const ContainerInfo container_info;

#endif
