/* A minimal FMI 3.0 co-simulation importer in C, the FMI 3.0 twin of c_importer.c: load the
   FMU's binary by its path (dlopen; LoadLibraryA on Windows, so the same source builds with
   MinGW-w64 into c_importer3.exe for Wine), instantiate, set one Float64 input, step with
   1 ms, print one Float64 output on stdout. A failing call prints its fmi3Status on stderr
   after the FMU's logged messages and exits non-zero.
   usage: c_importer3 BINARY INSTANTIATION_TOKEN RESOURCE_PATH INPUT_VR INPUT_VALUE OUTPUT_VR
          STEPS   (RESOURCE_PATH: the FMU's resources folder, with a trailing separator) */
#include <stdio.h>
#include <stdlib.h>
#include "fmi3FunctionTypes.h"

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

static void logger(fmi3InstanceEnvironment env, fmi3Status status, fmi3String category,
                   fmi3String message) {
    (void)env; (void)category;
    fprintf(stderr, "fmu log (status %d): %s\n", status, message);
}

/* Exit 3 naming the call and its status if `call` returned worse than fmi3Warning. */
#define CHECK(call, what) do { fmi3Status s_ = (call); if (s_ > fmi3Warning) { \
    fprintf(stderr, "%s failed: status %d\n", what, (int)s_); return 3; } } while (0)

#define LOAD(T, f) T *f = (T *)symbol(lib, #f); if (!f) { fprintf(stderr, "no %s\n", #f); return 2; }

int main(int argc, char **argv) {
    if (argc != 8) { fprintf(stderr, "usage: see the source\n"); return 2; }
    Library lib = open_library(argv[1]);
    if (!lib) { report_open_error(); return 2; }
    LOAD(fmi3InstantiateCoSimulationTYPE, fmi3InstantiateCoSimulation)
    LOAD(fmi3EnterInitializationModeTYPE, fmi3EnterInitializationMode)
    LOAD(fmi3ExitInitializationModeTYPE, fmi3ExitInitializationMode)
    LOAD(fmi3SetFloat64TYPE, fmi3SetFloat64)
    LOAD(fmi3GetFloat64TYPE, fmi3GetFloat64)
    LOAD(fmi3DoStepTYPE, fmi3DoStep)
    LOAD(fmi3TerminateTYPE, fmi3Terminate)
    LOAD(fmi3FreeInstanceTYPE, fmi3FreeInstance)
    fmi3Instance c = fmi3InstantiateCoSimulation("c_importer3", argv[2], argv[3], fmi3False,
                                                 fmi3False, fmi3False, fmi3False, NULL, 0,
                                                 NULL, logger, NULL);
    if (!c) { fprintf(stderr, "fmi3InstantiateCoSimulation failed\n"); return 3; }
    fmi3ValueReference in = (fmi3ValueReference)atoi(argv[4]);
    fmi3ValueReference out = (fmi3ValueReference)atoi(argv[6]);
    fmi3Float64 value = atof(argv[5]), result = 0.0, last_time = 0.0;
    fmi3Boolean event = fmi3False, terminate = fmi3False, early = fmi3False;
    int steps = atoi(argv[7]);
    char what[64];
    CHECK(fmi3EnterInitializationMode(c, fmi3False, 0.0, 0.0, fmi3False, 0.0),
          "fmi3EnterInitializationMode");
    CHECK(fmi3SetFloat64(c, &in, 1, &value, 1), "fmi3SetFloat64");
    CHECK(fmi3ExitInitializationMode(c), "fmi3ExitInitializationMode");
    for (int k = 0; k < steps; k++) {
        snprintf(what, sizeof what, "fmi3DoStep at step %d", k);
        CHECK(fmi3DoStep(c, k * 1e-3, 1e-3, fmi3True, &event, &terminate, &early, &last_time),
              what);
        if (terminate) { fprintf(stderr, "the FMU asked to terminate at step %d\n", k); return 3; }
    }
    CHECK(fmi3GetFloat64(c, &out, 1, &result, 1), "fmi3GetFloat64");
    printf("%.9g\n", result);
    CHECK(fmi3Terminate(c), "fmi3Terminate");
    fmi3FreeInstance(c);
    return 0;
}
