/* trackmj's native track FMU: the FMI 3.0 interface (co-simulation only) over the engine
   (engine.h). Model identifier TrackmjTrack, functions without prefix.

   How to build (the export does this, with trackmj_variables.h generated from
   trackmj/fmi/native/variables.py beside the sources):
     gcc -O2 -fPIC -shared -ffp-contract=off -std=c99 -I<include> -I<mujoco include> \
         fmi3.c engine.c -o TrackmjTrack.so -L<dir> -lmujoco
   and for Windows the same with x86_64-w64-mingw32-gcc, -o TrackmjTrack.dll and mujoco.dll
   to link against. fmi3Functions.h declares every function FMI3_Export:
   __declspec(dllexport) on Windows, default visibility with gcc elsewhere.

   Every function fmi3Functions.h declares is defined here. Calling sequence (FMI 3.0,
   section 4.2): InstantiateCoSimulation -> EnterInitializationMode ->
   ExitInitializationMode -> step mode (DoStep ...) -> Terminate; Reset goes back to
   instantiated from any mode. No event mode, no clocks, no intermediate update, no early
   return. A step or an initialisation the engine refuses puts the instance in the failed
   mode, where only Get*, Terminate, SetFMUState, Reset and FreeInstance are accepted. Every
   refused or unsupported call returns fmi3Error with a message through logMessage (category
   logStatusError, always logged); no call aborts the host. Instances share no data: any
   number may run in one process, each in its own thread. Time is in seconds since the
   settled initial state (the time variable, value reference 0). */

#include <stdarg.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "fmi3Functions.h"
#include "engine.h"
#include "layer.h"
#include "trackmj_variables.h"

typedef struct {
    Engine *engine;
    Mode mode;
    fmi3LogMessageCallback log;      /* may be NULL: nothing is logged */
    fmi3InstanceEnvironment environment;
    int log_warnings;                /* category logStatusWarning on */
    int log_events;                  /* category logEvents on (errors are always logged) */
    int stop_time_defined;
    double stop_time_s;              /* [s], from fmi3EnterInitializationMode */
} Instance;

/* Serialised state: the header of layer.h, then the engine's bytes. */
static const char STATE_MAGIC[8] = "TMJFMI3";

static const char *mode_name(Mode mode)
{
    switch (mode) {
    case MODE_INSTANTIATED: return "instantiated";
    case MODE_INITIALIZATION: return "initialization mode";
    case MODE_STEP: return "step mode";
    case MODE_TERMINATED: return "terminated";
    default: return "failed (a step or the initialisation failed: Reset, SetFMUState or "
                    "FreeInstance)";
    }
}

/* Logs one message through the callback unless its category is off. */
static void log_to(fmi3LogMessageCallback log, fmi3InstanceEnvironment environment,
                   fmi3Status status, const char *category, const char *format, va_list args)
{
    char text[1024];
    vsnprintf(text, sizeof text, format, args);
    log(environment, status, category, text);
}

static void log_message(const Instance *inst, fmi3Status status, const char *category,
                        const char *format, ...) PRINTF_LIKE(4, 5);
static void log_message(const Instance *inst, fmi3Status status, const char *category,
                        const char *format, ...)
{
    va_list args;
    if (!inst->log || (status == fmi3OK && !inst->log_events)
        || (status == fmi3Warning && !inst->log_warnings))
        return;
    va_start(args, format);
    log_to(inst->log, inst->environment, status, category, format, args);
    va_end(args);
}

#define LOG_ERROR(inst, ...) log_message(inst, fmi3Error, "logStatusError", __VA_ARGS__)
#define LOG_EVENT(inst, ...) log_message(inst, fmi3OK, "logEvents", __VA_ARGS__)

/* An error before there is an instance: straight to the callback. */
static void log_early(fmi3LogMessageCallback log, fmi3InstanceEnvironment environment,
                      const char *format, ...) PRINTF_LIKE(3, 4);
static void log_early(fmi3LogMessageCallback log, fmi3InstanceEnvironment environment,
                      const char *format, ...)
{
    va_list args;
    if (!log)
        return;
    va_start(args, format);
    log_to(log, environment, fmi3Error, "logStatusError", format, args);
    va_end(args);
}

static fmi3Status from_engine(EngineStatus status)
{
    switch (status) {
    case ENGINE_OK: return fmi3OK;
    case ENGINE_WARNING: return fmi3Warning;
    default: return fmi3Error;
    }
}

/* The engine's log callback: its level is the status of the message. */
static void engine_log(void *environment, EngineStatus level, const char *category,
                       const char *message)
{
    const char *fallback = level == ENGINE_ERROR ? "logStatusError"
                           : level == ENGINE_WARNING ? "logStatusWarning" : "logEvents";
    log_message((const Instance *)environment, from_engine(level),
                category ? category : fallback, "%s", message);
}

/* The instance if the call is allowed in its mode, else NULL (logged). */
static Instance *enter(fmi3Instance instance, int modes, const char *function)
{
    Instance *inst = (Instance *)instance;
    if (!inst)
        return NULL;
    if (!(inst->mode & modes)) {
        LOG_ERROR(inst, "%s: not allowed in mode %s", function, mode_name(inst->mode));
        return NULL;
    }
    return inst;
}

static fmi3Status not_provided(fmi3Instance instance, const char *function, const char *why)
{
    if (instance)
        LOG_ERROR((Instance *)instance, "%s: not provided (%s)", function, why);
    return fmi3Error;
}

/* Calls with values of a type the FMU has no variables of: fine for no value reference. */
static fmi3Status no_variables(fmi3Instance instance, int modes, const char *function,
                               const char *type, const fmi3ValueReference vr[], size_t nvr)
{
    Instance *inst = enter(instance, modes, function);
    if (!inst)
        return fmi3Error;
    if (nvr == 0)
        return fmi3OK;
    LOG_ERROR(inst, "%s: value reference %u: this FMU has no %s variables", function,
              vr ? (unsigned)vr[0] : 0u, type);
    return fmi3Error;
}

/* Arrays present and one value per reference (every variable is a scalar). */
static int bad_arrays(Instance *inst, const char *function, size_t nvr, const void *vr,
                      const void *values, size_t nValues)
{
    if (nvr > 0 && (!vr || !values)) {
        LOG_ERROR(inst, "%s: NULL value reference or value array", function);
        return 1;
    }
    if (nValues != nvr) {
        LOG_ERROR(inst, "%s: %lu values for %lu value references (the variables are "
                  "scalars)", function, (unsigned long)nValues, (unsigned long)nvr);
        return 1;
    }
    return 0;
}

static void free_instance(Instance *inst)
{
    if (inst->engine)
        engine_free(inst->engine);
    free(inst);
}

/* ---- common functions ------------------------------------------------------------------ */

const char *fmi3GetVersion(void)
{
    return fmi3Version;
}

fmi3Status fmi3SetDebugLogging(fmi3Instance instance, fmi3Boolean loggingOn,
                               size_t nCategories, const fmi3String categories[])
{
    Instance *inst = enter(instance, MODES_ANY, "fmi3SetDebugLogging");
    size_t i;
    if (!inst)
        return fmi3Error;
    if (nCategories == 0) {
        inst->log_warnings = inst->log_events = loggingOn;
        return fmi3OK;
    }
    if (!categories) {
        LOG_ERROR(inst, "fmi3SetDebugLogging: NULL categories");
        return fmi3Error;
    }
    for (i = 0; i < nCategories; i++) {
        const char *name = categories[i] ? categories[i] : "(NULL)";
        if (strcmp(name, "logEvents") == 0) {
            inst->log_events = loggingOn;
        } else if (strcmp(name, "logStatusWarning") == 0) {
            inst->log_warnings = loggingOn;
        } else if (strcmp(name, "logStatusError") != 0) {  /* errors: always logged */
            LOG_ERROR(inst, "fmi3SetDebugLogging: unknown log category \"%s\" (known: "
                      "logStatusError, logStatusWarning, logEvents)", name);
            return fmi3Error;
        }
    }
    return fmi3OK;
}

fmi3Instance fmi3InstantiateModelExchange(fmi3String instanceName,
                                          fmi3String instantiationToken,
                                          fmi3String resourcePath, fmi3Boolean visible,
                                          fmi3Boolean loggingOn,
                                          fmi3InstanceEnvironment instanceEnvironment,
                                          fmi3LogMessageCallback logMessage)
{
    (void)instanceName; (void)instantiationToken; (void)resourcePath; (void)visible;
    (void)loggingOn;
    log_early(logMessage, instanceEnvironment, "fmi3InstantiateModelExchange: this FMU "
              "provides co-simulation only");
    return NULL;
}

fmi3Instance fmi3InstantiateCoSimulation(fmi3String instanceName,
                                         fmi3String instantiationToken,
                                         fmi3String resourcePath, fmi3Boolean visible,
                                         fmi3Boolean loggingOn, fmi3Boolean eventModeUsed,
                                         fmi3Boolean earlyReturnAllowed,
                                         const fmi3ValueReference requiredIntermediateVariables[],
                                         size_t nRequiredIntermediateVariables,
                                         fmi3InstanceEnvironment instanceEnvironment,
                                         fmi3LogMessageCallback logMessage,
                                         fmi3IntermediateUpdateCallback intermediateUpdate)
{
    const char *f = "fmi3InstantiateCoSimulation";
    char *directory;
    size_t len;
    Instance *inst;
    (void)instanceName;          /* FMI 3's logMessage takes no instance name */
    (void)visible;
    (void)earlyReturnAllowed;    /* the FMU never returns early */
    (void)requiredIntermediateVariables;
    (void)intermediateUpdate;    /* providesIntermediateUpdate = false */
    if (eventModeUsed) {
        log_early(logMessage, instanceEnvironment, "%s: event mode not provided "
                  "(hasEventMode = false)", f);
        return NULL;
    }
    if (nRequiredIntermediateVariables > 0) {
        log_early(logMessage, instanceEnvironment, "%s: intermediate variables not provided "
                  "(providesIntermediateUpdate = false)", f);
        return NULL;
    }
    if (!instantiationToken || strcmp(instantiationToken, TRACKMJ_INSTANTIATION_TOKEN) != 0) {
        log_early(logMessage, instanceEnvironment, "%s: instantiationToken %s is not this "
                  "binary's %s (a modelDescription of another export)", f,
                  instantiationToken ? instantiationToken : "(NULL)",
                  TRACKMJ_INSTANTIATION_TOKEN);
        return NULL;
    }
    if (!resourcePath || resourcePath[0] == '\0') {
        log_early(logMessage, instanceEnvironment, "%s: no resource path given", f);
        return NULL;
    }
    inst = (Instance *)calloc(1, sizeof *inst);
    directory = (char *)malloc(strlen(resourcePath) + 1);
    if (!inst || !directory) {
        log_early(logMessage, instanceEnvironment, "%s: out of memory", f);
        free(inst);
        free(directory);
        return NULL;
    }
    strcpy(directory, resourcePath);
    len = strlen(directory);                 /* the path ends with a separator: dropped */
    while (len > 1 && (directory[len - 1] == '/' || directory[len - 1] == '\\')
           && !(len == 3 && directory[1] == ':'))
        directory[--len] = '\0';
    inst->log = logMessage;
    inst->environment = instanceEnvironment;
    inst->log_warnings = 1;
    inst->log_events = loggingOn;
    inst->engine = engine_new(directory, engine_log, inst);
    if (!inst->engine) {
        LOG_ERROR(inst, "%s: the track could not be loaded from %s", f, directory);
        free(directory);
        free_instance(inst);
        return NULL;
    }
    LOG_EVENT(inst, "instantiated from %s", directory);
    free(directory);
    inst->mode = MODE_INSTANTIATED;
    return inst;
}

fmi3Instance fmi3InstantiateScheduledExecution(fmi3String instanceName,
                                               fmi3String instantiationToken,
                                               fmi3String resourcePath, fmi3Boolean visible,
                                               fmi3Boolean loggingOn,
                                               fmi3InstanceEnvironment instanceEnvironment,
                                               fmi3LogMessageCallback logMessage,
                                               fmi3ClockUpdateCallback clockUpdate,
                                               fmi3LockPreemptionCallback lockPreemption,
                                               fmi3UnlockPreemptionCallback unlockPreemption)
{
    (void)instanceName; (void)instantiationToken; (void)resourcePath; (void)visible;
    (void)loggingOn; (void)clockUpdate; (void)lockPreemption; (void)unlockPreemption;
    log_early(logMessage, instanceEnvironment, "fmi3InstantiateScheduledExecution: this FMU "
              "provides co-simulation only");
    return NULL;
}

void fmi3FreeInstance(fmi3Instance instance)
{
    if (instance)
        free_instance((Instance *)instance);
}

fmi3Status fmi3EnterInitializationMode(fmi3Instance instance, fmi3Boolean toleranceDefined,
                                       fmi3Float64 tolerance, fmi3Float64 startTime,
                                       fmi3Boolean stopTimeDefined, fmi3Float64 stopTime)
{
    Instance *inst = enter(instance, MODE_INSTANTIATED, "fmi3EnterInitializationMode");
    (void)toleranceDefined;   /* fixed steps: no tolerance to control */
    (void)tolerance;
    if (!inst)
        return fmi3Error;
    if (startTime != 0.0) {
        LOG_ERROR(inst, "fmi3EnterInitializationMode: startTime = %.12g s: this FMU starts "
                  "at 0 s (the settled initial state)", startTime);
        return fmi3Error;
    }
    if (stopTimeDefined && !(stopTime >= 0.0)) {
        LOG_ERROR(inst, "fmi3EnterInitializationMode: stopTime = %.12g s before startTime "
                  "= 0 s", stopTime);
        return fmi3Error;
    }
    inst->stop_time_defined = stopTimeDefined;
    inst->stop_time_s = stopTime;
    inst->mode = MODE_INITIALIZATION;
    return fmi3OK;
}

fmi3Status fmi3ExitInitializationMode(fmi3Instance instance)
{
    Instance *inst = enter(instance, MODE_INITIALIZATION, "fmi3ExitInitializationMode");
    fmi3Status status;
    if (!inst)
        return fmi3Error;
    status = from_engine(engine_initialize(inst->engine));
    inst->mode = status == fmi3Error ? MODE_FAILED : MODE_STEP;
    if (status != fmi3Error)
        LOG_EVENT(inst, "initialised");
    return status;
}

fmi3Status fmi3EnterEventMode(fmi3Instance instance)
{
    return not_provided(instance, "fmi3EnterEventMode", "hasEventMode = false");
}

fmi3Status fmi3Terminate(fmi3Instance instance)
{
    Instance *inst = enter(instance, MODE_STEP | MODE_FAILED, "fmi3Terminate");
    if (!inst)
        return fmi3Error;
    inst->mode = MODE_TERMINATED;
    return fmi3OK;
}

fmi3Status fmi3Reset(fmi3Instance instance)
{
    Instance *inst = enter(instance, MODES_ANY, "fmi3Reset");
    fmi3Status status;
    if (!inst)
        return fmi3Error;
    status = from_engine(engine_reset(inst->engine));
    inst->mode = status == fmi3Error ? MODE_FAILED : MODE_INSTANTIATED;
    inst->stop_time_defined = 0;
    if (status != fmi3Error)
        LOG_EVENT(inst, "reset to the settled initial state");
    return status;
}

/* ---- values ------------------------------------------------------------------------------ */

fmi3Status fmi3GetFloat64(fmi3Instance instance, const fmi3ValueReference valueReferences[],
                          size_t nValueReferences, fmi3Float64 values[], size_t nValues)
{
    const char *f = "fmi3GetFloat64";
    Instance *inst = enter(instance, MODES_GET, f);
    fmi3Status status = fmi3OK, s;
    size_t i;
    if (!inst || bad_arrays(inst, f, nValueReferences, valueReferences, values, nValues))
        return fmi3Error;
    for (i = 0; i < nValueReferences; i++) {
        if (valueReferences[i] == VR_time) {
            values[i] = engine_time(inst->engine);
            continue;
        }
        s = from_engine(engine_get_real(inst->engine, valueReferences[i], &values[i]));
        if (s == fmi3Error)
            return fmi3Error;
        if (s > status)
            status = s;
    }
    return status;
}

fmi3Status fmi3GetBoolean(fmi3Instance instance, const fmi3ValueReference valueReferences[],
                          size_t nValueReferences, fmi3Boolean values[], size_t nValues)
{
    const char *f = "fmi3GetBoolean";
    Instance *inst = enter(instance, MODES_GET, f);
    fmi3Status status = fmi3OK, s;
    size_t i;
    int v;
    if (!inst || bad_arrays(inst, f, nValueReferences, valueReferences, values, nValues))
        return fmi3Error;
    for (i = 0; i < nValueReferences; i++) {
        s = from_engine(engine_get_boolean(inst->engine, valueReferences[i], &v));
        if (s == fmi3Error)
            return fmi3Error;
        values[i] = v != 0;
        if (s > status)
            status = s;
    }
    return status;
}

fmi3Status fmi3SetFloat64(fmi3Instance instance, const fmi3ValueReference valueReferences[],
                          size_t nValueReferences, const fmi3Float64 values[], size_t nValues)
{
    const char *f = "fmi3SetFloat64";
    Instance *inst = enter(instance, MODES_SET, f);
    fmi3Status status = fmi3OK, s;
    size_t i;
    if (!inst || bad_arrays(inst, f, nValueReferences, valueReferences, values, nValues))
        return fmi3Error;
    for (i = 0; i < nValueReferences; i++) {
        if (valueReferences[i] == VR_time) {
            LOG_ERROR(inst, "%s: the time (value reference 0) is the independent variable: "
                      "it advances by fmi3DoStep only", f);
            return fmi3Error;
        }
        s = from_engine(engine_set_real(inst->engine, valueReferences[i], values[i]));
        if (s == fmi3Error)
            return fmi3Error;
        if (s > status)
            status = s;
    }
    return status;
}

fmi3Status fmi3SetBoolean(fmi3Instance instance, const fmi3ValueReference valueReferences[],
                          size_t nValueReferences, const fmi3Boolean values[], size_t nValues)
{
    (void)values; (void)nValues;   /* the Booleans are outputs */
    return no_variables(instance, MODES_SET, "fmi3SetBoolean", "settable Boolean",
                        valueReferences, nValueReferences);
}

/* Getters and setters of the types the FMU has no variables of. */
#define NO_GETTER(NAME, TYPE, TYPENAME)                                                     \
    fmi3Status NAME(fmi3Instance instance, const fmi3ValueReference valueReferences[],   \
                    size_t nValueReferences, TYPE values[], size_t nValues)              \
    {                                                                                    \
        (void)values; (void)nValues;                                                     \
        return no_variables(instance, MODES_GET, #NAME, TYPENAME, valueReferences,       \
                            nValueReferences);                                           \
    }
#define NO_SETTER(NAME, TYPE, TYPENAME)                                                     \
    fmi3Status NAME(fmi3Instance instance, const fmi3ValueReference valueReferences[],   \
                    size_t nValueReferences, const TYPE values[], size_t nValues)         \
    {                                                                                    \
        (void)values; (void)nValues;                                                     \
        return no_variables(instance, MODES_SET, #NAME, TYPENAME, valueReferences,       \
                            nValueReferences);                                           \
    }

NO_GETTER(fmi3GetFloat32, fmi3Float32, "Float32")
NO_GETTER(fmi3GetInt8, fmi3Int8, "Int8")
NO_GETTER(fmi3GetUInt8, fmi3UInt8, "UInt8")
NO_GETTER(fmi3GetInt16, fmi3Int16, "Int16")
NO_GETTER(fmi3GetUInt16, fmi3UInt16, "UInt16")
NO_GETTER(fmi3GetInt32, fmi3Int32, "Int32")
NO_GETTER(fmi3GetUInt32, fmi3UInt32, "UInt32")
NO_GETTER(fmi3GetInt64, fmi3Int64, "Int64")
NO_GETTER(fmi3GetUInt64, fmi3UInt64, "UInt64")
NO_GETTER(fmi3GetString, fmi3String, "String")
NO_SETTER(fmi3SetFloat32, fmi3Float32, "Float32")
NO_SETTER(fmi3SetInt8, fmi3Int8, "Int8")
NO_SETTER(fmi3SetUInt8, fmi3UInt8, "UInt8")
NO_SETTER(fmi3SetInt16, fmi3Int16, "Int16")
NO_SETTER(fmi3SetUInt16, fmi3UInt16, "UInt16")
NO_SETTER(fmi3SetInt32, fmi3Int32, "Int32")
NO_SETTER(fmi3SetUInt32, fmi3UInt32, "UInt32")
NO_SETTER(fmi3SetInt64, fmi3Int64, "Int64")
NO_SETTER(fmi3SetUInt64, fmi3UInt64, "UInt64")
NO_SETTER(fmi3SetString, fmi3String, "String")

fmi3Status fmi3GetBinary(fmi3Instance instance, const fmi3ValueReference valueReferences[],
                         size_t nValueReferences, size_t valueSizes[], fmi3Binary values[],
                         size_t nValues)
{
    (void)valueSizes; (void)values; (void)nValues;
    return no_variables(instance, MODES_GET, "fmi3GetBinary", "Binary", valueReferences,
                        nValueReferences);
}

fmi3Status fmi3SetBinary(fmi3Instance instance, const fmi3ValueReference valueReferences[],
                         size_t nValueReferences, const size_t valueSizes[],
                         const fmi3Binary values[], size_t nValues)
{
    (void)valueSizes; (void)values; (void)nValues;
    return no_variables(instance, MODES_SET, "fmi3SetBinary", "Binary", valueReferences,
                        nValueReferences);
}

fmi3Status fmi3GetClock(fmi3Instance instance, const fmi3ValueReference valueReferences[],
                        size_t nValueReferences, fmi3Clock values[])
{
    (void)values;
    return no_variables(instance, MODES_ANY, "fmi3GetClock", "Clock", valueReferences,
                        nValueReferences);
}

fmi3Status fmi3SetClock(fmi3Instance instance, const fmi3ValueReference valueReferences[],
                        size_t nValueReferences, const fmi3Clock values[])
{
    (void)values;
    return no_variables(instance, MODES_ANY, "fmi3SetClock", "Clock", valueReferences,
                        nValueReferences);
}

fmi3Status fmi3GetNumberOfVariableDependencies(fmi3Instance instance,
                                               fmi3ValueReference valueReference,
                                               size_t *nDependencies)
{
    (void)valueReference; (void)nDependencies;
    return not_provided(instance, "fmi3GetNumberOfVariableDependencies",
                        "providesPerElementDependencies = false; the modelDescription lists "
                        "the dependencies");
}

fmi3Status fmi3GetVariableDependencies(fmi3Instance instance, fmi3ValueReference dependent,
                                       size_t elementIndicesOfDependent[],
                                       fmi3ValueReference independents[],
                                       size_t elementIndicesOfIndependents[],
                                       fmi3DependencyKind dependencyKinds[],
                                       size_t nDependencies)
{
    (void)dependent; (void)elementIndicesOfDependent; (void)independents;
    (void)elementIndicesOfIndependents; (void)dependencyKinds; (void)nDependencies;
    return not_provided(instance, "fmi3GetVariableDependencies",
                        "providesPerElementDependencies = false; the modelDescription lists "
                        "the dependencies");
}

/* ---- FMU state ----------------------------------------------------------------------- */

/* The state in *slot to write `size` engine bytes into: *slot itself if it is a state of
   that size (a non-NULL *slot is one of ours to overwrite), else a new one (*slot freed and
   cleared). NULL if out of memory (logged). */
static State *state_in(Instance *inst, void **slot, size_t size, const char *function)
{
    State *state = state_buffer(slot, size);
    if (!state)
        LOG_ERROR(inst, "%s: out of memory (%lu bytes)", function, (unsigned long)size);
    return state;
}

fmi3Status fmi3GetFMUState(fmi3Instance instance, fmi3FMUState *FMUState)
{
    Instance *inst = enter(instance, MODES_SAVE, "fmi3GetFMUState");
    State *state;
    if (!inst)
        return fmi3Error;
    if (!FMUState) {
        LOG_ERROR(inst, "fmi3GetFMUState: NULL FMUState pointer");
        return fmi3Error;
    }
    state = state_in(inst, FMUState, engine_state_size(inst->engine), "fmi3GetFMUState");
    if (!state)
        return fmi3Error;
    if (engine_save(inst->engine, state->bytes) == ENGINE_ERROR) {
        free(state);
        *FMUState = NULL;
        return fmi3Error;
    }
    state->mode = inst->mode;
    *FMUState = state;
    return fmi3OK;
}

fmi3Status fmi3SetFMUState(fmi3Instance instance, fmi3FMUState FMUState)
{
    Instance *inst = enter(instance, MODES_ANY, "fmi3SetFMUState");
    const State *state = (const State *)FMUState;
    if (!inst)
        return fmi3Error;
    if (!state) {
        LOG_ERROR(inst, "fmi3SetFMUState: NULL FMUState");
        return fmi3Error;
    }
    if (engine_restore(inst->engine, state->bytes, state->size) == ENGINE_ERROR) {
        inst->mode = MODE_FAILED;
        return fmi3Error;
    }
    inst->mode = state->mode;
    LOG_EVENT(inst, "state restored: t = %.12g s, mode %s", engine_time(inst->engine),
              mode_name(inst->mode));
    return fmi3OK;
}

fmi3Status fmi3FreeFMUState(fmi3Instance instance, fmi3FMUState *FMUState)
{
    (void)instance;
    if (FMUState) {
        free(*FMUState);
        *FMUState = NULL;
    }
    return fmi3OK;
}

fmi3Status fmi3SerializedFMUStateSize(fmi3Instance instance, fmi3FMUState FMUState,
                                      size_t *size)
{
    Instance *inst = enter(instance, MODES_ANY, "fmi3SerializedFMUStateSize");
    if (!inst)
        return fmi3Error;
    if (!FMUState || !size) {
        LOG_ERROR(inst, "fmi3SerializedFMUStateSize: NULL FMUState or size");
        return fmi3Error;
    }
    *size = STATE_HEADER_SIZE + ((const State *)FMUState)->size;
    return fmi3OK;
}

fmi3Status fmi3SerializeFMUState(fmi3Instance instance, fmi3FMUState FMUState,
                                 fmi3Byte serializedState[], size_t size)
{
    Instance *inst = enter(instance, MODES_ANY, "fmi3SerializeFMUState");
    const State *state = (const State *)FMUState;
    if (!inst)
        return fmi3Error;
    if (!state || !serializedState) {
        LOG_ERROR(inst, "fmi3SerializeFMUState: NULL FMUState or buffer");
        return fmi3Error;
    }
    if (size != STATE_HEADER_SIZE + state->size) {
        LOG_ERROR(inst, "fmi3SerializeFMUState: buffer of %lu bytes, the state takes %lu "
                  "(fmi3SerializedFMUStateSize)", (unsigned long)size,
                  (unsigned long)(STATE_HEADER_SIZE + state->size));
        return fmi3Error;
    }
    state_serialize(state, STATE_MAGIC, (unsigned char *)serializedState);
    return fmi3OK;
}

fmi3Status fmi3DeserializeFMUState(fmi3Instance instance, const fmi3Byte serializedState[],
                                   size_t size, fmi3FMUState *FMUState)
{
    Instance *inst = enter(instance, MODES_ANY, "fmi3DeserializeFMUState");
    size_t expected;
    Mode mode;
    State *state;
    char why[REFUSAL_SIZE];
    if (!inst)
        return fmi3Error;
    if (!serializedState || !FMUState) {
        LOG_ERROR(inst, "fmi3DeserializeFMUState: NULL bytes or FMUState pointer");
        return fmi3Error;
    }
    expected = engine_state_size(inst->engine);
    mode = state_mode((const unsigned char *)serializedState, size, STATE_MAGIC, expected, 3,
                      why);
    if (!mode) {
        LOG_ERROR(inst, "fmi3DeserializeFMUState: %s", why);
        return fmi3Error;
    }
    state = state_in(inst, FMUState, expected, "fmi3DeserializeFMUState");
    if (!state)
        return fmi3Error;
    state->mode = mode;
    memcpy(state->bytes, serializedState + STATE_HEADER_SIZE, expected);
    *FMUState = state;
    return fmi3OK;
}

/* ---- derivatives, configuration, clocks, discrete states: not provided ------------------ */

fmi3Status fmi3GetDirectionalDerivative(fmi3Instance instance,
                                        const fmi3ValueReference unknowns[], size_t nUnknowns,
                                        const fmi3ValueReference knowns[], size_t nKnowns,
                                        const fmi3Float64 seed[], size_t nSeed,
                                        fmi3Float64 sensitivity[], size_t nSensitivity)
{
    (void)unknowns; (void)nUnknowns; (void)knowns; (void)nKnowns; (void)seed; (void)nSeed;
    (void)sensitivity; (void)nSensitivity;
    return not_provided(instance, "fmi3GetDirectionalDerivative",
                        "providesDirectionalDerivatives = false");
}

fmi3Status fmi3GetAdjointDerivative(fmi3Instance instance,
                                    const fmi3ValueReference unknowns[], size_t nUnknowns,
                                    const fmi3ValueReference knowns[], size_t nKnowns,
                                    const fmi3Float64 seed[], size_t nSeed,
                                    fmi3Float64 sensitivity[], size_t nSensitivity)
{
    (void)unknowns; (void)nUnknowns; (void)knowns; (void)nKnowns; (void)seed; (void)nSeed;
    (void)sensitivity; (void)nSensitivity;
    return not_provided(instance, "fmi3GetAdjointDerivative",
                        "providesAdjointDerivatives = false");
}

fmi3Status fmi3EnterConfigurationMode(fmi3Instance instance)
{
    return not_provided(instance, "fmi3EnterConfigurationMode", "no structural parameters");
}

fmi3Status fmi3ExitConfigurationMode(fmi3Instance instance)
{
    return not_provided(instance, "fmi3ExitConfigurationMode", "no structural parameters");
}

fmi3Status fmi3GetIntervalDecimal(fmi3Instance instance,
                                  const fmi3ValueReference valueReferences[],
                                  size_t nValueReferences, fmi3Float64 intervals[],
                                  fmi3IntervalQualifier qualifiers[])
{
    (void)valueReferences; (void)nValueReferences; (void)intervals; (void)qualifiers;
    return not_provided(instance, "fmi3GetIntervalDecimal", "no clocks");
}

fmi3Status fmi3GetIntervalFraction(fmi3Instance instance,
                                   const fmi3ValueReference valueReferences[],
                                   size_t nValueReferences, fmi3UInt64 counters[],
                                   fmi3UInt64 resolutions[],
                                   fmi3IntervalQualifier qualifiers[])
{
    (void)valueReferences; (void)nValueReferences; (void)counters; (void)resolutions;
    (void)qualifiers;
    return not_provided(instance, "fmi3GetIntervalFraction", "no clocks");
}

fmi3Status fmi3GetShiftDecimal(fmi3Instance instance,
                               const fmi3ValueReference valueReferences[],
                               size_t nValueReferences, fmi3Float64 shifts[])
{
    (void)valueReferences; (void)nValueReferences; (void)shifts;
    return not_provided(instance, "fmi3GetShiftDecimal", "no clocks");
}

fmi3Status fmi3GetShiftFraction(fmi3Instance instance,
                                const fmi3ValueReference valueReferences[],
                                size_t nValueReferences, fmi3UInt64 counters[],
                                fmi3UInt64 resolutions[])
{
    (void)valueReferences; (void)nValueReferences; (void)counters; (void)resolutions;
    return not_provided(instance, "fmi3GetShiftFraction", "no clocks");
}

fmi3Status fmi3SetIntervalDecimal(fmi3Instance instance,
                                  const fmi3ValueReference valueReferences[],
                                  size_t nValueReferences, const fmi3Float64 intervals[])
{
    (void)valueReferences; (void)nValueReferences; (void)intervals;
    return not_provided(instance, "fmi3SetIntervalDecimal", "no clocks");
}

fmi3Status fmi3SetIntervalFraction(fmi3Instance instance,
                                   const fmi3ValueReference valueReferences[],
                                   size_t nValueReferences, const fmi3UInt64 counters[],
                                   const fmi3UInt64 resolutions[])
{
    (void)valueReferences; (void)nValueReferences; (void)counters; (void)resolutions;
    return not_provided(instance, "fmi3SetIntervalFraction", "no clocks");
}

fmi3Status fmi3SetShiftDecimal(fmi3Instance instance,
                               const fmi3ValueReference valueReferences[],
                               size_t nValueReferences, const fmi3Float64 shifts[])
{
    (void)valueReferences; (void)nValueReferences; (void)shifts;
    return not_provided(instance, "fmi3SetShiftDecimal", "no clocks");
}

fmi3Status fmi3SetShiftFraction(fmi3Instance instance,
                                const fmi3ValueReference valueReferences[],
                                size_t nValueReferences, const fmi3UInt64 counters[],
                                const fmi3UInt64 resolutions[])
{
    (void)valueReferences; (void)nValueReferences; (void)counters; (void)resolutions;
    return not_provided(instance, "fmi3SetShiftFraction", "no clocks");
}

fmi3Status fmi3EvaluateDiscreteStates(fmi3Instance instance)
{
    return not_provided(instance, "fmi3EvaluateDiscreteStates",
                        "providesEvaluateDiscreteStates = false");
}

fmi3Status fmi3UpdateDiscreteStates(fmi3Instance instance,
                                    fmi3Boolean *discreteStatesNeedUpdate,
                                    fmi3Boolean *terminateSimulation,
                                    fmi3Boolean *nominalsOfContinuousStatesChanged,
                                    fmi3Boolean *valuesOfContinuousStatesChanged,
                                    fmi3Boolean *nextEventTimeDefined,
                                    fmi3Float64 *nextEventTime)
{
    (void)discreteStatesNeedUpdate; (void)terminateSimulation;
    (void)nominalsOfContinuousStatesChanged; (void)valuesOfContinuousStatesChanged;
    (void)nextEventTimeDefined; (void)nextEventTime;
    return not_provided(instance, "fmi3UpdateDiscreteStates", "hasEventMode = false");
}

/* ---- model exchange: not provided --------------------------------------------------- */

#define ME_ONLY "model exchange: this FMU provides co-simulation only"

fmi3Status fmi3EnterContinuousTimeMode(fmi3Instance instance)
{
    return not_provided(instance, "fmi3EnterContinuousTimeMode", ME_ONLY);
}

fmi3Status fmi3CompletedIntegratorStep(fmi3Instance instance,
                                       fmi3Boolean noSetFMUStatePriorToCurrentPoint,
                                       fmi3Boolean *enterEventMode,
                                       fmi3Boolean *terminateSimulation)
{
    (void)noSetFMUStatePriorToCurrentPoint; (void)enterEventMode; (void)terminateSimulation;
    return not_provided(instance, "fmi3CompletedIntegratorStep", ME_ONLY);
}

fmi3Status fmi3SetTime(fmi3Instance instance, fmi3Float64 time)
{
    (void)time;
    return not_provided(instance, "fmi3SetTime", ME_ONLY);
}

fmi3Status fmi3SetContinuousStates(fmi3Instance instance,
                                   const fmi3Float64 continuousStates[],
                                   size_t nContinuousStates)
{
    (void)continuousStates; (void)nContinuousStates;
    return not_provided(instance, "fmi3SetContinuousStates", ME_ONLY);
}

fmi3Status fmi3GetContinuousStateDerivatives(fmi3Instance instance, fmi3Float64 derivatives[],
                                             size_t nContinuousStates)
{
    (void)derivatives; (void)nContinuousStates;
    return not_provided(instance, "fmi3GetContinuousStateDerivatives", ME_ONLY);
}

fmi3Status fmi3GetEventIndicators(fmi3Instance instance, fmi3Float64 eventIndicators[],
                                  size_t nEventIndicators)
{
    (void)eventIndicators; (void)nEventIndicators;
    return not_provided(instance, "fmi3GetEventIndicators", ME_ONLY);
}

fmi3Status fmi3GetContinuousStates(fmi3Instance instance, fmi3Float64 continuousStates[],
                                   size_t nContinuousStates)
{
    (void)continuousStates; (void)nContinuousStates;
    return not_provided(instance, "fmi3GetContinuousStates", ME_ONLY);
}

fmi3Status fmi3GetNominalsOfContinuousStates(fmi3Instance instance, fmi3Float64 nominals[],
                                             size_t nContinuousStates)
{
    (void)nominals; (void)nContinuousStates;
    return not_provided(instance, "fmi3GetNominalsOfContinuousStates", ME_ONLY);
}

fmi3Status fmi3GetNumberOfEventIndicators(fmi3Instance instance, size_t *nEventIndicators)
{
    (void)nEventIndicators;
    return not_provided(instance, "fmi3GetNumberOfEventIndicators", ME_ONLY);
}

fmi3Status fmi3GetNumberOfContinuousStates(fmi3Instance instance, size_t *nContinuousStates)
{
    (void)nContinuousStates;
    return not_provided(instance, "fmi3GetNumberOfContinuousStates", ME_ONLY);
}

/* ---- co-simulation -------------------------------------------------------------------- */

fmi3Status fmi3EnterStepMode(fmi3Instance instance)
{
    return not_provided(instance, "fmi3EnterStepMode", "hasEventMode = false: "
                        "fmi3ExitInitializationMode enters step mode");
}

fmi3Status fmi3GetOutputDerivatives(fmi3Instance instance,
                                    const fmi3ValueReference valueReferences[],
                                    size_t nValueReferences, const fmi3Int32 orders[],
                                    fmi3Float64 values[], size_t nValues)
{
    (void)valueReferences; (void)nValueReferences; (void)orders; (void)values; (void)nValues;
    return not_provided(instance, "fmi3GetOutputDerivatives", "maxOutputDerivativeOrder = 0");
}

fmi3Status fmi3DoStep(fmi3Instance instance, fmi3Float64 currentCommunicationPoint,
                      fmi3Float64 communicationStepSize,
                      fmi3Boolean noSetFMUStatePriorToCurrentPoint,
                      fmi3Boolean *eventHandlingNeeded, fmi3Boolean *terminateSimulation,
                      fmi3Boolean *earlyReturn, fmi3Float64 *lastSuccessfulTime)
{
    Instance *inst = enter(instance, MODE_STEP, "fmi3DoStep");
    long steps;
    fmi3Status status;
    char why[REFUSAL_SIZE];
    (void)noSetFMUStatePriorToCurrentPoint;   /* states are kept by the importer's copies */
    if (!inst)
        return fmi3Error;
    if (!eventHandlingNeeded || !terminateSimulation || !earlyReturn || !lastSuccessfulTime) {
        LOG_ERROR(inst, "fmi3DoStep: NULL output argument");
        return fmi3Error;
    }
    *eventHandlingNeeded = false;
    *terminateSimulation = false;
    *earlyReturn = false;
    *lastSuccessfulTime = engine_time(inst->engine);
    steps = step_count(currentCommunicationPoint, communicationStepSize, *lastSuccessfulTime,
                       inst->stop_time_defined, inst->stop_time_s,
                       "fmi3EnterInitializationMode", why);
    if (!steps) {
        LOG_ERROR(inst, "%s", why);
        return fmi3Error;
    }
    status = from_engine(engine_step(inst->engine, steps));
    if (status == fmi3Error)
        inst->mode = MODE_FAILED;
    *lastSuccessfulTime = engine_time(inst->engine);
    return status;
}

/* ---- scheduled execution: not provided ------------------------------------------------ */

fmi3Status fmi3ActivateModelPartition(fmi3Instance instance, fmi3ValueReference clockReference,
                                      fmi3Float64 activationTime)
{
    (void)clockReference; (void)activationTime;
    return not_provided(instance, "fmi3ActivateModelPartition",
                        "scheduled execution: this FMU provides co-simulation only");
}
