/* A minimal FMI 2.0 Co-Simulation master with no Python in the process (tests/test_fmu.py).
 *
 * Usage: fmi2_c_host <binaries/linux64/x.so> <guid> <resource URI> <vr input> <value> <vr output> <steps> <h>
 * Instantiates the FMU, initialises it with the defaults, sets one Real input, makes <steps> steps of
 * <h> s and prints the output after each step as %.17g, one per line.  Exit status 1 on any non-OK call.
 */
#include <dlfcn.h>
#include <stdarg.h>
#include <stdio.h>
#include <stdlib.h>

#include "fmi2Functions.h"

static void logger(fmi2ComponentEnvironment env, fmi2String name, fmi2Status status, fmi2String category,
                   fmi2String message, ...) {
    (void)env; (void)name; (void)status;
    fprintf(stderr, "[%s] %s\n", category, message);
}

#define LOAD(f) f##TYPE *f = (f##TYPE *)dlsym(lib, #f); if (!f) { fprintf(stderr, "no %s\n", #f); return 1; }
#define CHECK(call) if ((call) != fmi2OK) { fprintf(stderr, "%s failed\n", #call); return 1; }

int main(int argc, char **argv) {
    void *lib;
    fmi2CallbackFunctions cb = {logger, calloc, free, NULL, NULL};
    fmi2Component c;
    fmi2ValueReference in_vr, out_vr;
    fmi2Real in_value, y, h, t = 0.0;
    long k, steps;
    if (argc != 9) { fprintf(stderr, "usage: see the source\n"); return 2; }
    lib = dlopen(argv[1], RTLD_NOW | RTLD_LOCAL);
    if (!lib) { fprintf(stderr, "%s\n", dlerror()); return 1; }
    {
        LOAD(fmi2Instantiate) LOAD(fmi2SetupExperiment) LOAD(fmi2EnterInitializationMode)
        LOAD(fmi2ExitInitializationMode) LOAD(fmi2SetReal) LOAD(fmi2GetReal) LOAD(fmi2DoStep)
        LOAD(fmi2Terminate) LOAD(fmi2FreeInstance)
        in_vr = (fmi2ValueReference)strtoul(argv[4], NULL, 10);
        in_value = strtod(argv[5], NULL);
        out_vr = (fmi2ValueReference)strtoul(argv[6], NULL, 10);
        steps = strtol(argv[7], NULL, 10);
        h = strtod(argv[8], NULL);
        c = fmi2Instantiate("host", fmi2CoSimulation, argv[2], argv[3], &cb, fmi2False, fmi2False);
        if (!c) { fprintf(stderr, "fmi2Instantiate failed\n"); return 1; }
        CHECK(fmi2SetupExperiment(c, fmi2False, 0.0, 0.0, fmi2False, 0.0))
        CHECK(fmi2EnterInitializationMode(c))
        CHECK(fmi2ExitInitializationMode(c))
        CHECK(fmi2SetReal(c, &in_vr, 1, &in_value))
        for (k = 0; k < steps; k++) {
            CHECK(fmi2DoStep(c, t, h, fmi2True))
            t += h;
            CHECK(fmi2GetReal(c, &out_vr, 1, &y))
            printf("%.17g\n", y);
        }
        CHECK(fmi2Terminate(c))
        fmi2FreeInstance(c);
    }
    dlclose(lib);
    return 0;
}
