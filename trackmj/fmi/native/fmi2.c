/* trackmj's native track FMU: the FMI 2.0 co-simulation interface over the engine
   (engine.h). Model identifier TrackmjTrack, functions without prefix.

   How to build (the export does this, with trackmj_variables.h generated from
   trackmj/fmi/native/variables.py beside the sources):
     gcc -O2 -fPIC -shared -ffp-contract=off -std=c99 -I<include> -I<mujoco include> \
         fmi2.c engine.c -o TrackmjTrack.so -L<dir> -lmujoco
   and for Windows the same with x86_64-w64-mingw32-gcc, -o TrackmjTrack.dll and mujoco.dll
   to link against. fmi2Functions.h declares every function FMI2_Export:
   __declspec(dllexport) on Windows, default visibility with gcc elsewhere.

   Calling sequence (FMI 2.0.4, section 4.2.4): Instantiate -> [SetupExperiment] ->
   EnterInitializationMode -> ExitInitializationMode -> DoStep ... -> Terminate; Reset goes
   back to instantiated from any mode. A step or an initialisation the engine refuses puts
   the instance in the failed mode, where only Get*, Terminate, SetFMUstate, Reset and
   FreeInstance are accepted. Every refused call returns fmi2Error with a message through
   the logger (category logStatusError, always logged); no call aborts the host. Instances
   share no data: any number may run in one process, each in its own thread. Time is in
   seconds since the settled initial state (the time variable, value reference 0). */

#include <ctype.h>
#include <stdarg.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "fmi2Functions.h"
#include "engine.h"
#include "layer.h"
#include "trackmj_variables.h"

#ifdef _WIN32
#define ON_WINDOWS 1
#else
#define ON_WINDOWS 0
#endif

typedef struct {
    Engine *engine;
    Mode mode;
    char *name;
    fmi2CallbackLogger logger;       /* may be NULL: nothing is logged */
    fmi2ComponentEnvironment environment;
    int log_warnings;                /* category logStatusWarning on */
    int log_events;                  /* category logEvents on (errors are always logged) */
    int stop_time_defined;
    double stop_time_s;              /* [s], from fmi2SetupExperiment */
} Instance;

/* Serialised state: the header of layer.h, then the engine's bytes. */
static const char STATE_MAGIC[8] = "TMJFMI2";

static const char *mode_name(Mode mode)
{
    switch (mode) {
    case MODE_INSTANTIATED: return "instantiated";
    case MODE_INITIALIZATION: return "initialization mode";
    case MODE_STEP: return "step complete";
    case MODE_TERMINATED: return "terminated";
    default: return "failed (a step or the initialisation failed: Reset, SetFMUstate or "
                    "FreeInstance)";
    }
}

/* Logs one message unless its category is off; the logger's message is a printf format, so
   '%' is doubled. */
static void log_message(const Instance *inst, fmi2Status status, const char *category,
                        const char *format, ...) PRINTF_LIKE(4, 5);
static void log_message(const Instance *inst, fmi2Status status, const char *category,
                        const char *format, ...)
{
    char text[1024], escaped[2048];
    size_t i, j = 0;
    va_list args;
    if (!inst->logger || (status == fmi2OK && !inst->log_events)
        || (status == fmi2Warning && !inst->log_warnings))
        return;
    va_start(args, format);
    vsnprintf(text, sizeof text, format, args);
    va_end(args);
    for (i = 0; text[i] != '\0' && j + 2 < sizeof escaped; i++) {
        if (text[i] == '%')
            escaped[j++] = '%';
        escaped[j++] = text[i];
    }
    escaped[j] = '\0';
    inst->logger(inst->environment, inst->name, status, category, escaped);
}

#define LOG_ERROR(inst, ...) log_message(inst, fmi2Error, "logStatusError", __VA_ARGS__)
#define LOG_EVENT(inst, ...) log_message(inst, fmi2OK, "logEvents", __VA_ARGS__)

static fmi2Status from_engine(EngineStatus status)
{
    switch (status) {
    case ENGINE_OK: return fmi2OK;
    case ENGINE_WARNING: return fmi2Warning;
    default: return fmi2Error;
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

/* The instance behind c if the call is allowed in its mode, else NULL (logged). */
static Instance *enter(fmi2Component c, int modes, const char *function)
{
    Instance *inst = (Instance *)c;
    if (!inst)
        return NULL;
    if (!(inst->mode & modes)) {
        LOG_ERROR(inst, "%s: not allowed in mode %s", function, mode_name(inst->mode));
        return NULL;
    }
    return inst;
}

static fmi2Status not_provided(fmi2Component c, const char *function, const char *why)
{
    if (c)
        LOG_ERROR((Instance *)c, "%s: not provided (%s)", function, why);
    return fmi2Error;
}

/* Calls with values of a type the FMU has no variables of: fine for no value reference. */
static fmi2Status no_variables(fmi2Component c, int modes, const char *function,
                               const char *type, const fmi2ValueReference vr[], size_t nvr)
{
    Instance *inst = enter(c, modes, function);
    if (!inst)
        return fmi2Error;
    if (nvr == 0)
        return fmi2OK;
    LOG_ERROR(inst, "%s: value reference %u: this FMU has no %s variables", function,
              vr ? vr[0] : 0u, type);
    return fmi2Error;
}

static int null_arrays(Instance *inst, const char *function, size_t nvr, const void *vr,
                       const void *value)
{
    if (nvr > 0 && (!vr || !value)) {
        LOG_ERROR(inst, "%s: NULL value reference or value array", function);
        return 1;
    }
    return 0;
}

static int hex_digit(char c)
{
    if (c >= '0' && c <= '9') return c - '0';
    if (c >= 'a' && c <= 'f') return c - 'a' + 10;
    if (c >= 'A' && c <= 'F') return c - 'A' + 10;
    return -1;
}

/* The directory a file URI names, malloc'd, without trailing separator: file:///dir,
   file:/dir, file://localhost/dir, percent escapes decoded; on Windows (windows != 0) also
   file:///C:/dir -> C:/dir, file://C:/dir and file://host/share -> //host/share. NULL with
   *why set if it names no local directory. */
static char *directory_of_uri(const char *uri, int windows, const char **why)
{
    const char *p, *host, *path;
    size_t host_len, len;
    char *out, *q;
    if (!uri) {
        *why = "no resource location given";
        return NULL;
    }
    if (strlen(uri) < 5 || tolower((unsigned char)uri[0]) != 'f'
        || tolower((unsigned char)uri[1]) != 'i' || tolower((unsigned char)uri[2]) != 'l'
        || tolower((unsigned char)uri[3]) != 'e' || uri[4] != ':') {
        *why = "not a file: URI";
        return NULL;
    }
    p = uri + 5;
    out = (char *)malloc(strlen(uri) + 3);
    if (!out) {
        *why = "out of memory";
        return NULL;
    }
    q = out;
    if (p[0] == '/' && p[1] == '/') {
        host = p + 2;
        path = strchr(host, '/');
        if (!path)
            path = host + strlen(host);
        host_len = (size_t)(path - host);
        if (host_len == 2 && windows && isalpha((unsigned char)host[0]) && host[1] == ':') {
            path = host;                                   /* file://C:/dir */
        } else if (host_len == 9 && strncmp(host, "localhost", 9) == 0) {
            /* local */
        } else if (host_len > 0) {
            if (!windows) {
                free(out);
                *why = "a file URI naming another host";
                return NULL;
            }
            *q++ = '/';                                    /* UNC: //host/share */
            *q++ = '/';
            memcpy(q, host, host_len);
            q += host_len;
        }
    } else {
        path = p;
    }
    if (q == out && path[0] != '/' && !(windows && isalpha((unsigned char)path[0])
                                        && path[1] == ':')) {
        free(out);
        *why = "not an absolute path";
        return NULL;
    }
    for (; *path; path++) {
        if (*path == '%') {
            int hi = hex_digit(path[1]), lo = hi < 0 ? -1 : hex_digit(path[2]);
            if (hi < 0 || lo < 0 || (hi == 0 && lo == 0)) {
                free(out);
                *why = "an invalid percent escape";
                return NULL;
            }
            *q++ = (char)(hi * 16 + lo);
            path += 2;
        } else {
            *q++ = *path;
        }
    }
    *q = '\0';
    if (windows && out[0] == '/' && isalpha((unsigned char)out[1]) && out[2] == ':')
        memmove(out, out + 1, strlen(out));                /* /C:/dir -> C:/dir */
    len = strlen(out);
    while (len > 1 && (out[len - 1] == '/' || (windows && out[len - 1] == '\\'))
           && !(windows && len == 3 && out[1] == ':'))
        out[--len] = '\0';
    return out;
}

static void free_instance(Instance *inst)
{
    if (inst->engine)
        engine_free(inst->engine);
    free(inst->name);
    free(inst);
}

/* ---- common functions ------------------------------------------------------------------ */

const char *fmi2GetTypesPlatform(void)
{
    return fmi2TypesPlatform;
}

const char *fmi2GetVersion(void)
{
    return fmi2Version;
}

fmi2Status fmi2SetDebugLogging(fmi2Component c, fmi2Boolean loggingOn, size_t nCategories,
                               const fmi2String categories[])
{
    Instance *inst = enter(c, MODES_ANY, "fmi2SetDebugLogging");
    size_t i;
    if (!inst)
        return fmi2Error;
    if (nCategories == 0) {
        inst->log_warnings = inst->log_events = loggingOn != fmi2False;
        return fmi2OK;
    }
    if (!categories) {
        LOG_ERROR(inst, "fmi2SetDebugLogging: NULL categories");
        return fmi2Error;
    }
    for (i = 0; i < nCategories; i++) {
        const char *name = categories[i] ? categories[i] : "(NULL)";
        if (strcmp(name, "logEvents") == 0) {
            inst->log_events = loggingOn != fmi2False;
        } else if (strcmp(name, "logStatusWarning") == 0) {
            inst->log_warnings = loggingOn != fmi2False;
        } else if (strcmp(name, "logStatusError") != 0) {  /* errors: always logged */
            LOG_ERROR(inst, "fmi2SetDebugLogging: unknown log category \"%s\" (known: "
                      "logStatusError, logStatusWarning, logEvents)", name);
            return fmi2Error;
        }
    }
    return fmi2OK;
}

fmi2Component fmi2Instantiate(fmi2String instanceName, fmi2Type fmuType, fmi2String fmuGUID,
                              fmi2String fmuResourceLocation,
                              const fmi2CallbackFunctions *functions, fmi2Boolean visible,
                              fmi2Boolean loggingOn)
{
    const char *name = instanceName ? instanceName : "";
    const char *why = NULL;
    char *directory;
    Instance *inst;
    (void)visible;
    if (!functions)
        return NULL;
    inst = (Instance *)calloc(1, sizeof *inst);
    if (inst)
        inst->name = (char *)malloc(strlen(name) + 1);
    if (!inst || !inst->name) {
        if (functions->logger)
            functions->logger(functions->componentEnvironment, name, fmi2Error,
                              "logStatusError", "fmi2Instantiate: out of memory");
        free(inst);
        return NULL;
    }
    strcpy(inst->name, name);
    inst->logger = functions->logger;
    inst->environment = functions->componentEnvironment;
    inst->log_warnings = 1;
    inst->log_events = loggingOn != fmi2False;
    if (fmuType != fmi2CoSimulation) {
        LOG_ERROR(inst, "fmi2Instantiate: this FMU provides co-simulation only");
        free_instance(inst);
        return NULL;
    }
    if (!fmuGUID || strcmp(fmuGUID, TRACKMJ_INSTANTIATION_TOKEN) != 0) {
        LOG_ERROR(inst, "fmi2Instantiate: GUID %s is not this binary's %s (a "
                  "modelDescription of another export)", fmuGUID ? fmuGUID : "(NULL)",
                  TRACKMJ_INSTANTIATION_TOKEN);
        free_instance(inst);
        return NULL;
    }
    directory = directory_of_uri(fmuResourceLocation, ON_WINDOWS, &why);
    if (!directory) {
        LOG_ERROR(inst, "fmi2Instantiate: resource location %s: %s",
                  fmuResourceLocation ? fmuResourceLocation : "(NULL)", why);
        free_instance(inst);
        return NULL;
    }
    inst->engine = engine_new(directory, engine_log, inst);
    if (!inst->engine) {
        LOG_ERROR(inst, "fmi2Instantiate: the track could not be loaded from %s", directory);
        free(directory);
        free_instance(inst);
        return NULL;
    }
    LOG_EVENT(inst, "instantiated from %s", directory);
    free(directory);
    inst->mode = MODE_INSTANTIATED;
    return inst;
}

void fmi2FreeInstance(fmi2Component c)
{
    if (c)
        free_instance((Instance *)c);
}

fmi2Status fmi2SetupExperiment(fmi2Component c, fmi2Boolean toleranceDefined,
                               fmi2Real tolerance, fmi2Real startTime,
                               fmi2Boolean stopTimeDefined, fmi2Real stopTime)
{
    Instance *inst = enter(c, MODE_INSTANTIATED, "fmi2SetupExperiment");
    (void)toleranceDefined;   /* fixed steps: no tolerance to control */
    (void)tolerance;
    if (!inst)
        return fmi2Error;
    if (startTime != 0.0) {
        LOG_ERROR(inst, "fmi2SetupExperiment: startTime = %.12g s: this FMU starts at 0 s "
                  "(the settled initial state)", startTime);
        return fmi2Error;
    }
    if (stopTimeDefined && !(stopTime >= 0.0)) {
        LOG_ERROR(inst, "fmi2SetupExperiment: stopTime = %.12g s before startTime = 0 s",
                  stopTime);
        return fmi2Error;
    }
    inst->stop_time_defined = stopTimeDefined != fmi2False;
    inst->stop_time_s = stopTime;
    return fmi2OK;
}

fmi2Status fmi2EnterInitializationMode(fmi2Component c)
{
    Instance *inst = enter(c, MODE_INSTANTIATED, "fmi2EnterInitializationMode");
    if (!inst)
        return fmi2Error;
    inst->mode = MODE_INITIALIZATION;
    return fmi2OK;
}

fmi2Status fmi2ExitInitializationMode(fmi2Component c)
{
    Instance *inst = enter(c, MODE_INITIALIZATION, "fmi2ExitInitializationMode");
    fmi2Status status;
    if (!inst)
        return fmi2Error;
    status = from_engine(engine_initialize(inst->engine));
    inst->mode = status == fmi2Error ? MODE_FAILED : MODE_STEP;
    if (status != fmi2Error)
        LOG_EVENT(inst, "initialised");
    return status;
}

fmi2Status fmi2Terminate(fmi2Component c)
{
    Instance *inst = enter(c, MODE_STEP | MODE_FAILED, "fmi2Terminate");
    if (!inst)
        return fmi2Error;
    inst->mode = MODE_TERMINATED;
    return fmi2OK;
}

fmi2Status fmi2Reset(fmi2Component c)
{
    Instance *inst = enter(c, MODES_ANY, "fmi2Reset");
    fmi2Status status;
    if (!inst)
        return fmi2Error;
    status = from_engine(engine_reset(inst->engine));
    inst->mode = status == fmi2Error ? MODE_FAILED : MODE_INSTANTIATED;
    inst->stop_time_defined = 0;
    if (status != fmi2Error)
        LOG_EVENT(inst, "reset to the settled initial state");
    return status;
}

/* ---- values ------------------------------------------------------------------------------ */

fmi2Status fmi2GetReal(fmi2Component c, const fmi2ValueReference vr[], size_t nvr,
                       fmi2Real value[])
{
    Instance *inst = enter(c, MODES_GET, "fmi2GetReal");
    fmi2Status status = fmi2OK, s;
    size_t i;
    if (!inst || null_arrays(inst, "fmi2GetReal", nvr, vr, value))
        return fmi2Error;
    for (i = 0; i < nvr; i++) {
        if (vr[i] == VR_time) {
            value[i] = engine_time(inst->engine);
            continue;
        }
        s = from_engine(engine_get_real(inst->engine, vr[i], &value[i]));
        if (s == fmi2Error)
            return fmi2Error;
        if (s > status)
            status = s;
    }
    return status;
}

fmi2Status fmi2GetInteger(fmi2Component c, const fmi2ValueReference vr[], size_t nvr,
                          fmi2Integer value[])
{
    (void)value;
    return no_variables(c, MODES_GET, "fmi2GetInteger", "Integer", vr, nvr);
}

fmi2Status fmi2GetBoolean(fmi2Component c, const fmi2ValueReference vr[], size_t nvr,
                          fmi2Boolean value[])
{
    Instance *inst = enter(c, MODES_GET, "fmi2GetBoolean");
    fmi2Status status = fmi2OK, s;
    size_t i;
    int v;
    if (!inst || null_arrays(inst, "fmi2GetBoolean", nvr, vr, value))
        return fmi2Error;
    for (i = 0; i < nvr; i++) {
        s = from_engine(engine_get_boolean(inst->engine, vr[i], &v));
        if (s == fmi2Error)
            return fmi2Error;
        value[i] = v ? fmi2True : fmi2False;
        if (s > status)
            status = s;
    }
    return status;
}

fmi2Status fmi2GetString(fmi2Component c, const fmi2ValueReference vr[], size_t nvr,
                         fmi2String value[])
{
    (void)value;
    return no_variables(c, MODES_GET, "fmi2GetString", "String", vr, nvr);
}

fmi2Status fmi2SetReal(fmi2Component c, const fmi2ValueReference vr[], size_t nvr,
                       const fmi2Real value[])
{
    Instance *inst = enter(c, MODES_SET, "fmi2SetReal");
    fmi2Status status = fmi2OK, s;
    size_t i;
    if (!inst || null_arrays(inst, "fmi2SetReal", nvr, vr, value))
        return fmi2Error;
    for (i = 0; i < nvr; i++) {
        if (vr[i] == VR_time) {
            LOG_ERROR(inst, "fmi2SetReal: the time (value reference 0) is the independent "
                      "variable: it advances by fmi2DoStep only");
            return fmi2Error;
        }
        s = from_engine(engine_set_real(inst->engine, vr[i], value[i]));
        if (s == fmi2Error)
            return fmi2Error;
        if (s > status)
            status = s;
    }
    return status;
}

fmi2Status fmi2SetInteger(fmi2Component c, const fmi2ValueReference vr[], size_t nvr,
                          const fmi2Integer value[])
{
    (void)value;
    return no_variables(c, MODES_SET, "fmi2SetInteger", "Integer", vr, nvr);
}

fmi2Status fmi2SetBoolean(fmi2Component c, const fmi2ValueReference vr[], size_t nvr,
                          const fmi2Boolean value[])
{
    (void)value;   /* the Booleans are outputs */
    return no_variables(c, MODES_SET, "fmi2SetBoolean", "settable Boolean", vr, nvr);
}

fmi2Status fmi2SetString(fmi2Component c, const fmi2ValueReference vr[], size_t nvr,
                         const fmi2String value[])
{
    (void)value;
    return no_variables(c, MODES_SET, "fmi2SetString", "String", vr, nvr);
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

fmi2Status fmi2GetFMUstate(fmi2Component c, fmi2FMUstate *FMUstate)
{
    Instance *inst = enter(c, MODES_SAVE, "fmi2GetFMUstate");
    State *state;
    if (!inst)
        return fmi2Error;
    if (!FMUstate) {
        LOG_ERROR(inst, "fmi2GetFMUstate: NULL FMUstate pointer");
        return fmi2Error;
    }
    state = state_in(inst, FMUstate, engine_state_size(inst->engine), "fmi2GetFMUstate");
    if (!state)
        return fmi2Error;
    if (engine_save(inst->engine, state->bytes) == ENGINE_ERROR) {
        free(state);
        *FMUstate = NULL;
        return fmi2Error;
    }
    state->mode = inst->mode;
    *FMUstate = state;
    return fmi2OK;
}

fmi2Status fmi2SetFMUstate(fmi2Component c, fmi2FMUstate FMUstate)
{
    Instance *inst = enter(c, MODES_ANY, "fmi2SetFMUstate");
    const State *state = (const State *)FMUstate;
    if (!inst)
        return fmi2Error;
    if (!state) {
        LOG_ERROR(inst, "fmi2SetFMUstate: NULL FMUstate");
        return fmi2Error;
    }
    if (engine_restore(inst->engine, state->bytes, state->size) == ENGINE_ERROR) {
        inst->mode = MODE_FAILED;
        return fmi2Error;
    }
    inst->mode = state->mode;
    LOG_EVENT(inst, "state restored: t = %.12g s, mode %s", engine_time(inst->engine),
              mode_name(inst->mode));
    return fmi2OK;
}

fmi2Status fmi2FreeFMUstate(fmi2Component c, fmi2FMUstate *FMUstate)
{
    (void)c;
    if (FMUstate) {
        free(*FMUstate);
        *FMUstate = NULL;
    }
    return fmi2OK;
}

fmi2Status fmi2SerializedFMUstateSize(fmi2Component c, fmi2FMUstate FMUstate, size_t *size)
{
    Instance *inst = enter(c, MODES_ANY, "fmi2SerializedFMUstateSize");
    if (!inst)
        return fmi2Error;
    if (!FMUstate || !size) {
        LOG_ERROR(inst, "fmi2SerializedFMUstateSize: NULL FMUstate or size");
        return fmi2Error;
    }
    *size = STATE_HEADER_SIZE + ((const State *)FMUstate)->size;
    return fmi2OK;
}

fmi2Status fmi2SerializeFMUstate(fmi2Component c, fmi2FMUstate FMUstate,
                                 fmi2Byte serializedState[], size_t size)
{
    Instance *inst = enter(c, MODES_ANY, "fmi2SerializeFMUstate");
    const State *state = (const State *)FMUstate;
    if (!inst)
        return fmi2Error;
    if (!state || !serializedState) {
        LOG_ERROR(inst, "fmi2SerializeFMUstate: NULL FMUstate or buffer");
        return fmi2Error;
    }
    if (size != STATE_HEADER_SIZE + state->size) {
        LOG_ERROR(inst, "fmi2SerializeFMUstate: buffer of %lu bytes, the state takes %lu "
                  "(fmi2SerializedFMUstateSize)", (unsigned long)size,
                  (unsigned long)(STATE_HEADER_SIZE + state->size));
        return fmi2Error;
    }
    state_serialize(state, STATE_MAGIC, (unsigned char *)serializedState);
    return fmi2OK;
}

fmi2Status fmi2DeSerializeFMUstate(fmi2Component c, const fmi2Byte serializedState[],
                                   size_t size, fmi2FMUstate *FMUstate)
{
    Instance *inst = enter(c, MODES_ANY, "fmi2DeSerializeFMUstate");
    size_t expected;
    Mode mode;
    State *state;
    char why[REFUSAL_SIZE];
    if (!inst)
        return fmi2Error;
    if (!serializedState || !FMUstate) {
        LOG_ERROR(inst, "fmi2DeSerializeFMUstate: NULL bytes or FMUstate pointer");
        return fmi2Error;
    }
    expected = engine_state_size(inst->engine);
    mode = state_mode((const unsigned char *)serializedState, size, STATE_MAGIC, expected, 2,
                      why);
    if (!mode) {
        LOG_ERROR(inst, "fmi2DeSerializeFMUstate: %s", why);
        return fmi2Error;
    }
    state = state_in(inst, FMUstate, expected, "fmi2DeSerializeFMUstate");
    if (!state)
        return fmi2Error;
    state->mode = mode;
    memcpy(state->bytes, serializedState + STATE_HEADER_SIZE, expected);
    *FMUstate = state;
    return fmi2OK;
}

fmi2Status fmi2GetDirectionalDerivative(fmi2Component c, const fmi2ValueReference vUnknown_ref[],
                                        size_t nUnknown, const fmi2ValueReference vKnown_ref[],
                                        size_t nKnown, const fmi2Real dvKnown[],
                                        fmi2Real dvUnknown[])
{
    (void)vUnknown_ref; (void)nUnknown; (void)vKnown_ref; (void)nKnown; (void)dvKnown;
    (void)dvUnknown;
    return not_provided(c, "fmi2GetDirectionalDerivative", "providesDirectionalDerivative = "
                        "false");
}

/* ---- co-simulation -------------------------------------------------------------------- */

fmi2Status fmi2SetRealInputDerivatives(fmi2Component c, const fmi2ValueReference vr[],
                                       size_t nvr, const fmi2Integer order[],
                                       const fmi2Real value[])
{
    (void)vr; (void)nvr; (void)order; (void)value;
    return not_provided(c, "fmi2SetRealInputDerivatives", "canInterpolateInputs = false: "
                        "inputs are held over each step");
}

fmi2Status fmi2GetRealOutputDerivatives(fmi2Component c, const fmi2ValueReference vr[],
                                        size_t nvr, const fmi2Integer order[],
                                        fmi2Real value[])
{
    (void)vr; (void)nvr; (void)order; (void)value;
    return not_provided(c, "fmi2GetRealOutputDerivatives", "maxOutputDerivativeOrder = 0");
}

fmi2Status fmi2DoStep(fmi2Component c, fmi2Real currentCommunicationPoint,
                      fmi2Real communicationStepSize,
                      fmi2Boolean noSetFMUStatePriorToCurrentPoint)
{
    Instance *inst = enter(c, MODE_STEP, "fmi2DoStep");
    long steps;
    fmi2Status status;
    char why[REFUSAL_SIZE];
    (void)noSetFMUStatePriorToCurrentPoint;   /* states are kept by the importer's copies */
    if (!inst)
        return fmi2Error;
    steps = step_count(currentCommunicationPoint, communicationStepSize,
                       engine_time(inst->engine), inst->stop_time_defined, inst->stop_time_s,
                       "fmi2SetupExperiment", why);
    if (!steps) {
        LOG_ERROR(inst, "%s", why);
        return fmi2Error;
    }
    status = from_engine(engine_step(inst->engine, steps));
    if (status == fmi2Error)
        inst->mode = MODE_FAILED;
    return status;
}

fmi2Status fmi2CancelStep(fmi2Component c)
{
    return not_provided(c, "fmi2CancelStep", "fmi2DoStep is synchronous: "
                        "canRunAsynchronuously = false");
}

fmi2Status fmi2GetStatus(fmi2Component c, const fmi2StatusKind s, fmi2Status *value)
{
    (void)s; (void)value;
    return not_provided(c, "fmi2GetStatus", "fmi2DoStep never returns fmi2Pending");
}

fmi2Status fmi2GetRealStatus(fmi2Component c, const fmi2StatusKind s, fmi2Real *value)
{
    Instance *inst = enter(c, MODES_GET, "fmi2GetRealStatus");
    if (!inst)
        return fmi2Error;
    if (s != fmi2LastSuccessfulTime || !value)
        return not_provided(c, "fmi2GetRealStatus", "only fmi2LastSuccessfulTime");
    *value = engine_time(inst->engine);
    return fmi2OK;
}

fmi2Status fmi2GetIntegerStatus(fmi2Component c, const fmi2StatusKind s, fmi2Integer *value)
{
    (void)s; (void)value;
    return not_provided(c, "fmi2GetIntegerStatus", "no integer status");
}

fmi2Status fmi2GetBooleanStatus(fmi2Component c, const fmi2StatusKind s, fmi2Boolean *value)
{
    Instance *inst = enter(c, MODES_GET, "fmi2GetBooleanStatus");
    if (!inst)
        return fmi2Error;
    if (s != fmi2Terminated || !value)
        return not_provided(c, "fmi2GetBooleanStatus", "only fmi2Terminated");
    *value = fmi2False;   /* the FMU never asks to end the simulation */
    return fmi2OK;
}

fmi2Status fmi2GetStringStatus(fmi2Component c, const fmi2StatusKind s, fmi2String *value)
{
    (void)s; (void)value;
    return not_provided(c, "fmi2GetStringStatus", "fmi2DoStep never returns fmi2Pending");
}
