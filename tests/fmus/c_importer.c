/* A minimal FMI 2.0 co-simulation importer in C, as a tool without Python (Simulink, AMESim)
   loads an FMU: dlopen the FMU's binary, instantiate, set one input, step with 1 ms, read
   one output.
   usage: c_importer BINARY GUID RESOURCE_URI INPUT_VR INPUT_VALUE OUTPUT_VR STEPS */
#include <dlfcn.h>
#include <stdio.h>
#include <stdlib.h>
#include "fmi2Functions.h"

static void logger(fmi2ComponentEnvironment env, fmi2String name, fmi2Status status,
                   fmi2String category, fmi2String message, ...) {
    (void)env; (void)name; (void)category;
    fprintf(stderr, "fmu log (status %d): %s\n", status, message);
}

#define LOAD(T, f) T *f = (T *)dlsym(lib, #f); if (!f) { fprintf(stderr, "no %s\n", #f); return 2; }

int main(int argc, char **argv) {
    if (argc != 8) { fprintf(stderr, "usage: see the source\n"); return 2; }
    void *lib = dlopen(argv[1], RTLD_NOW | RTLD_LOCAL);
    if (!lib) { fprintf(stderr, "dlopen: %s\n", dlerror()); return 2; }
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
    if (fmi2SetupExperiment(c, fmi2False, 0.0, 0.0, fmi2False, 0.0) > fmi2Warning
        || fmi2EnterInitializationMode(c) > fmi2Warning
        || fmi2SetReal(c, &in, 1, &value) > fmi2Warning
        || fmi2ExitInitializationMode(c) > fmi2Warning) {
        fprintf(stderr, "initialisation failed\n");
        return 3;
    }
    for (int k = 0; k < steps; k++) {
        if (fmi2DoStep(c, k * 1e-3, 1e-3, fmi2True) > fmi2Warning) {
            fprintf(stderr, "fmi2DoStep failed at step %d\n", k);
            return 3;
        }
    }
    fmi2GetReal(c, &out, 1, &result);
    printf("%.9g\n", result);
    fmi2Terminate(c);
    fmi2FreeInstance(c);
    return 0;
}
