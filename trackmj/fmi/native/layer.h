/* What trackmj's two FMI layers (fmi2.c, fmi3.c) share: the modes of the calling sequence,
   the doStep checks and the saved and serialised FMU state. None of it depends on an FMI
   version's types: a refusal comes back as a message, which each layer logs with its own
   status and callback. Included by one layer per binary, so its functions are static. */

#ifndef TRACKMJ_LAYER_H
#define TRACKMJ_LAYER_H

#include <limits.h>
#include <math.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "engine.h"

#ifdef __GNUC__
#define PRINTF_LIKE(f, a) __attribute__((format(printf, f, a)))
#else
#define PRINTF_LIKE(f, a)
#endif

/* Tolerances of doStep's checks: the communication point may differ from the FMU's time by
   TIME_ABS_S + TIME_REL * |t| (an importer's sum of step sizes rounds), the step size from a
   whole number of coupling steps by STEP_REL * h. */
#define TIME_ABS_S 1e-9
#define TIME_REL 1e-12
#define STEP_REL 1e-9

/* Modes of the calling sequence, as bits so that a call names the set it is allowed in
   (FMI 2: "step complete", FMI 3: "step mode"). */
typedef enum {
    MODE_INSTANTIATED = 1,
    MODE_INITIALIZATION = 2,
    MODE_STEP = 4,
    MODE_TERMINATED = 8,
    MODE_FAILED = 16
} Mode;

#define MODES_ANY (MODE_INSTANTIATED | MODE_INITIALIZATION | MODE_STEP | MODE_TERMINATED \
                   | MODE_FAILED)
#define MODES_GET (MODE_INITIALIZATION | MODE_STEP | MODE_TERMINATED | MODE_FAILED)
#define MODES_SET (MODE_INSTANTIATED | MODE_INITIALIZATION | MODE_STEP)
#define MODES_SAVE (MODE_INSTANTIATED | MODE_INITIALIZATION | MODE_STEP | MODE_TERMINATED)

/* A saved FMU state: the mode and the engine's bytes. */
typedef struct {
    Mode mode;
    size_t size;
    unsigned char bytes[];
} State;

/* Serialised state: magic[8], uint32 mode, uint32 zero, uint64 engine size, then the
   engine's bytes. */
#define STATE_HEADER_SIZE 24

/* Room for a refusal's message [chars]. */
#define REFUSAL_SIZE 256

/* Coupling steps of a doStep from the communication point `point` [s] by `h` [s], the FMU
   being at `t` [s] with the stop time `stop_s` [s] set by `stop_source` if `stop_defined`:
   at least 1, or 0 with the refusal in why[REFUSAL_SIZE]. */
static long step_count(double point, double h, double t, int stop_defined, double stop_s,
                       const char *stop_source, char *why)
{
    double steps = floor(h / ENGINE_STEP_S + 0.5);
    if (!(fabs(point - t) <= TIME_ABS_S + TIME_REL * fabs(t))) {
        snprintf(why, REFUSAL_SIZE, "doStep at t = %.12g s but the FMU is at %.12g s",
                 point, t);
        return 0;
    }
    if (!(h > 0.0) || steps < 1.0 || fabs(steps * ENGINE_STEP_S - h) > STEP_REL * h) {
        snprintf(why, REFUSAL_SIZE, "doStep with h = %.12g s: the step size must be a "
                 "positive whole multiple of %g s (within %g relative)", h, ENGINE_STEP_S,
                 STEP_REL);
        return 0;
    }
    if (steps > (double)LONG_MAX) {
        snprintf(why, REFUSAL_SIZE, "doStep with h = %.12g s: at most %.12g s in one step",
                 h, (double)LONG_MAX * ENGINE_STEP_S);
        return 0;
    }
    if (stop_defined && t + h > stop_s + TIME_ABS_S + TIME_REL * fabs(stop_s)) {
        snprintf(why, REFUSAL_SIZE, "doStep from t = %.12g s by h = %.12g s goes past the "
                 "stop time %.12g s (%s)", t, h, stop_s, stop_source);
        return 0;
    }
    return (long)steps;
}

/* A state of `size` engine bytes in *slot: the one there if it has that size, else a new
   one (the old freed); NULL if out of memory, *slot then NULL. */
static State *state_buffer(void **slot, size_t size)
{
    State *state = (State *)*slot;
    if (state && state->size == size)
        return state;
    free(state);
    *slot = NULL;
    state = (State *)malloc(sizeof(State) + size);
    if (state)
        state->size = size;
    return state;
}

/* The serialised `state` into out[STATE_HEADER_SIZE + state->size]. */
static void state_serialize(const State *state, const char magic[8], unsigned char *out)
{
    uint32_t mode = (uint32_t)state->mode, zero = 0;
    uint64_t engine_size = (uint64_t)state->size;
    memcpy(out, magic, 8);
    memcpy(out + 8, &mode, 4);
    memcpy(out + 12, &zero, 4);
    memcpy(out + 16, &engine_size, 8);
    memcpy(out + STATE_HEADER_SIZE, state->bytes, state->size);
}

/* The mode of serialised bytes[size] written by this FMU (its `magic`, `expected` engine
   bytes, one mode a state can be saved in), or 0 with the refusal in why[REFUSAL_SIZE];
   `version` names the FMI version in the message. */
static Mode state_mode(const unsigned char *bytes, size_t size, const char magic[8],
                       size_t expected, int version, char *why)
{
    uint32_t mode;
    uint64_t engine_size;
    if (size < STATE_HEADER_SIZE || memcmp(bytes, magic, 8) != 0) {
        snprintf(why, REFUSAL_SIZE, "%lu bytes without the header of a serialised FMI %d "
                 "state of this FMU", (unsigned long)size, version);
        return (Mode)0;
    }
    memcpy(&mode, bytes + 8, 4);
    memcpy(&engine_size, bytes + 16, 8);
    if (engine_size != (uint64_t)expected || size != STATE_HEADER_SIZE + expected
        || !(mode & MODES_SAVE) || (mode & (mode - 1)) != 0) {
        snprintf(why, REFUSAL_SIZE, "%lu bytes holding %lu state bytes in mode %lu; this "
                 "FMU's state takes %lu + %d bytes", (unsigned long)size,
                 (unsigned long)engine_size, (unsigned long)mode, (unsigned long)expected,
                 STATE_HEADER_SIZE);
        return (Mode)0;
    }
    return (Mode)mode;
}

#endif
