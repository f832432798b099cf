/* trackmj's native track FMU: the engine (one track side in MuJoCo, stepped as
   trackmj.track.plant.TrackPlant steps it) behind the FMI 2.0 and 3.0 layers.

   The engine knows nothing of FMI: it loads the model and its configuration from the FMU's
   resources folder, takes values by value reference (trackmj_variables.h, generated at
   export from trackmj/fmi/native/variables.py), advances whole 1 ms coupling steps and
   reports every failure through its log callback as one line naming the quantity, the
   allowed range or the time. SI units throughout. */
#ifndef TRACKMJ_ENGINE_H
#define TRACKMJ_ENGINE_H

#include <stddef.h>

#ifdef __cplusplus
extern "C" {
#endif

typedef struct Engine Engine;

/* Results of the engine's calls, ordered as FMI's statuses. */
typedef enum {
    ENGINE_OK = 0,
    ENGINE_WARNING = 1,
    ENGINE_ERROR = 3      /* the call failed; the instance may be reset or freed */
} EngineStatus;

/* Log callback: level is an EngineStatus (OK for information), message one line. */
typedef void (*EngineLog)(void *environment, EngineStatus level, const char *category,
                          const char *message);

/* The coupling step [s]: every step is a whole number of these. */
#define ENGINE_STEP_S 1e-3

/* Loads resources/track.mjb and resources/track.cfg from resource_dir (a directory path,
   no trailing separator needed) and puts the track in its settled initial state. NULL on
   failure, after logging why. Never aborts the process (MuJoCo's errors are caught). */
Engine *engine_new(const char *resource_dir, EngineLog log, void *environment);
void engine_free(Engine *engine);

/* Back to the state engine_new left (parameters and inputs to their start values). */
EngineStatus engine_reset(Engine *engine);

/* Values by value reference. Setting checks finiteness and the declared range, and that the
   variable may be set now (parameters only before engine_initialize); getting checks the
   reference and the type. */
EngineStatus engine_set_real(Engine *engine, unsigned vr, double value);
EngineStatus engine_get_real(Engine *engine, unsigned vr, double *value);
EngineStatus engine_get_boolean(Engine *engine, unsigned vr, int *value);

/* End of initialisation: parameters take effect; outputs are valid from engine_new on. */
EngineStatus engine_initialize(Engine *engine);

/* Advance `steps` coupling steps (each ENGINE_STEP_S) with the inputs as set. A step that
   leaves physics (non-finite state, a MuJoCo warning, a pin torn off the track) returns
   ENGINE_ERROR with a message naming the time and the quantity; the instance may then be
   reset or freed. */
EngineStatus engine_step(Engine *engine, long steps);

/* Simulated time [s] since the initial state. */
double engine_time(const Engine *engine);

/* The whole state (MuJoCo's integration state, the ground's memory, the clock, the inputs,
   parameters and outputs), as bytes: engine_state_size bytes, engine_save writes them,
   engine_restore reads them (ENGINE_ERROR for bytes of another model or size). */
size_t engine_state_size(const Engine *engine);
EngineStatus engine_save(const Engine *engine, void *bytes);
EngineStatus engine_restore(Engine *engine, const void *bytes, size_t size);

#ifdef __cplusplus
}
#endif

#endif /* TRACKMJ_ENGINE_H */
