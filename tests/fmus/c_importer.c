/* A minimal FMI 2.0 co-simulation importer in C, as a tool without Python (Simulink, AMESim)
   loads an FMU: load the FMU's binary by its path (dlopen; LoadLibraryA on Windows, so the
   same source builds with MinGW-w64 into c_importer.exe for Wine), instantiate, set one
   input, step with 1 ms, print one output on stdout. A failing call prints its fmi2Status
   on stderr after the FMU's logged messages and exits non-zero.
   usage: c_importer BINARY GUID RESOURCE_URI INPUT_VR INPUT_VALUE OUTPUT_VR STEPS */
#include <stdio.h>
#include <stdlib.h>
#include "fmi2FunctionTypes.h"

#ifdef _WIN32
#include <windows.h>
typedef HMODULE Library;
static Library open_library(const char *path) { return LoadLibraryA(path); }
static void *symbol(Library lib, const char *name) { return (void *)GetProcAddress(lib, name); }
static void report_open_error(void) { fprintf(stderr, "LoadLibraryA: error %lu\n", GetLastError()); }
#else
#include <dlfcn.h>
typedef void *Library;
static Library open_library(const char *path) { return dlopen(path, RTLD_NOW | RTLD_LOCAL); }
static void *symbol(Library lib, const char *name) { return dlsym(lib, name); }
static void report_open_error(void) { fprintf(stderr, "dlopen: %s\n", dlerror()); }
#endif

static void logger(fmi2ComponentEnvironment env, fmi2String name, fmi2Status status,
                   fmi2String category, fmi2String message, ...) {
    (void)env; (void)name; (void)category;
    fprintf(stderr, "fmu log (status %d): %s\n", status, message);
}

/* Exit 3 naming the call and its status if `call` returned worse than fmi2Warning. */
#define CHECK(call, what) do { fmi2Status s_ = (call); if (s_ > fmi2Warning) { \
    fprintf(stderr, "%s failed: status %d\n", what, (int)s_); return 3; } } while (0)

#define LOAD(T, f) T *f = (T *)symbol(lib, #f); if (!f) { fprintf(stderr, "no %s\n", #f); return 2; }

int main(int argc, char **argv) {
    if (argc != 8) { fprintf(stderr, "usage: see the source\n"); return 2; }
    Library lib = open_library(argv[1]);
    if (!lib) { report_open_error(); return 2; }
    LOAD(fmi2InstantiateTYPE, fmi2Instantiate)
    LOAD(fmi2SetupExperimentTYPE, fmi2SetupExperiment)
    LOAD(fmi2EnterInitializationModeTYPE, fmi2EnterInitializationMode)
    LOAD(fmi2ExitInitializationModeTYPE, fmi2ExitInitializationMode)
    LOAD(fmi2SetRealTYPE, fmi2SetReal)
    LOAD(fmi2GetRealTYPE, fmi2GetReal)
    LOAD(fmi2DoStepTYPE, fmi2DoStep)
    LOAD(fmi2TerminateTYPE, fmi2Terminate)
    LOAD(fmi2FreeInstanceTYPE, fmi2FreeInstance)
    fmi2CallbackFunctions callbacks = {logger, calloc, free, NULL, NULL};
    fmi2Component c = fmi2Instantiate("c_importer", fmi2CoSimulation, argv[2], argv[3],
                                      &callbacks, fmi2False, fmi2False);
    if (!c) { fprintf(stderr, "fmi2Instantiate failed\n"); return 3; }
    fmi2ValueReference in = (fmi2ValueReference)atoi(argv[4]);
    fmi2ValueReference out = (fmi2ValueReference)atoi(argv[6]);
    fmi2Real value = atof(argv[5]), result = 0.0;
    int steps = atoi(argv[7]);
    char what[64];
    CHECK(fmi2SetupExperiment(c, fmi2False, 0.0, 0.0, fmi2False, 0.0), "fmi2SetupExperiment");
    CHECK(fmi2EnterInitializationMode(c), "fmi2EnterInitializationMode");
    CHECK(fmi2SetReal(c, &in, 1, &value), "fmi2SetReal");
    CHECK(fmi2ExitInitializationMode(c), "fmi2ExitInitializationMode");
    for (int k = 0; k < steps; k++) {
        snprintf(what, sizeof what, "fmi2DoStep at step %d", k);
        CHECK(fmi2DoStep(c, k * 1e-3, 1e-3, fmi2True), what);
    }
    CHECK(fmi2GetReal(c, &out, 1, &result), "fmi2GetReal");
    printf("%.9g\n", result);
    CHECK(fmi2Terminate(c), "fmi2Terminate");
    fmi2FreeInstance(c);
    return 0;
}
