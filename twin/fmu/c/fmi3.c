/* Thermal twin ROM: FMI 3.0 Co-Simulation API (thermal-twin; machine-independent, shipped with the package).
 *
 * Same model and step as the FMI 2.0 source: reduced modal coordinates z, exact
 * zero-order hold for any communication step, inputs checked when they are set.
 * In the FMU this file is sources/thermal_twin_rom.c; it includes model.c (the shared model core)
 * and the generated model_data.h.
 * Build: cc -shared -fPIC -O2 -I. thermal_twin_rom.c -o <modelIdentifier>.so -lm
 */
#include <math.h>
#include <stdarg.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "fmi3Functions.h"
#include "model_data.h"

typedef struct {
    fmi3InstanceEnvironment env;
    fmi3LogMessageCallback log_message;
} Callbacks;

#include "model.c"

static void emit(const Instance *inst, int is_error, const char *category, const char *message) {
    if (inst->cb.log_message) inst->cb.log_message(inst->cb.env, is_error ? fmi3Error : fmi3OK, category, message);
}

static void *alloc_instance(const Instance *inst) { (void)inst; return malloc(sizeof(Instance)); }

const char *fmi3GetVersion(void) { return fmi3Version; }

fmi3Status fmi3SetDebugLogging(fmi3Instance instance, fmi3Boolean loggingOn, size_t nCategories,
                               const fmi3String categories[]) {
    Instance *inst = (Instance *)instance;
    (void)nCategories; (void)categories;
    if (!inst) return fmi3Error;
    inst->logging_on = loggingOn;
    return fmi3OK;
}

fmi3Instance fmi3InstantiateModelExchange(fmi3String instanceName, fmi3String instantiationToken,
                                          fmi3String resourcePath, fmi3Boolean visible, fmi3Boolean loggingOn,
                                          fmi3InstanceEnvironment instanceEnvironment,
                                          fmi3LogMessageCallback logMessage) {
    (void)instanceName; (void)instantiationToken; (void)resourcePath; (void)visible; (void)loggingOn;
    if (logMessage) logMessage(instanceEnvironment, fmi3Error, "logStatusError", "this FMU supports Co-Simulation only");
    return NULL;
}

fmi3Instance fmi3InstantiateCoSimulation(fmi3String instanceName, fmi3String instantiationToken,
                                         fmi3String resourcePath, fmi3Boolean visible, fmi3Boolean loggingOn,
                                         fmi3Boolean eventModeUsed, fmi3Boolean earlyReturnAllowed,
                                         const fmi3ValueReference requiredIntermediateVariables[],
                                         size_t nRequiredIntermediateVariables,
                                         fmi3InstanceEnvironment instanceEnvironment,
                                         fmi3LogMessageCallback logMessage,
                                         fmi3IntermediateUpdateCallback intermediateUpdate) {
    Instance *inst;
    (void)resourcePath; (void)visible; (void)earlyReturnAllowed; (void)requiredIntermediateVariables;
    (void)nRequiredIntermediateVariables; (void)intermediateUpdate;
    if (!instantiationToken || strcmp(instantiationToken, MODEL_GUID) != 0) {
        if (logMessage) logMessage(instanceEnvironment, fmi3Error, "logStatusError",
                                   "fmi3InstantiateCoSimulation: the instantiation token does not match");
        return NULL;
    }
    if (eventModeUsed) {
        if (logMessage) logMessage(instanceEnvironment, fmi3Error, "logStatusError",
                                   "fmi3InstantiateCoSimulation: this FMU has no event mode");
        return NULL;
    }
    inst = (Instance *)calloc(1, sizeof(Instance));
    if (!inst) return NULL;
    snprintf(inst->instance_name, sizeof inst->instance_name, "%s", instanceName ? instanceName : "");
    inst->cb.env = instanceEnvironment;
    inst->cb.log_message = logMessage;
    inst->logging_on = loggingOn;
    set_defaults(inst);
    return inst;
}

fmi3Instance fmi3InstantiateScheduledExecution(fmi3String instanceName, fmi3String instantiationToken,
                                               fmi3String resourcePath, fmi3Boolean visible, fmi3Boolean loggingOn,
                                               fmi3InstanceEnvironment instanceEnvironment,
                                               fmi3LogMessageCallback logMessage, fmi3ClockUpdateCallback clockUpdate,
                                               fmi3LockPreemptionCallback lockPreemption,
                                               fmi3UnlockPreemptionCallback unlockPreemption) {
    (void)instanceName; (void)instantiationToken; (void)resourcePath; (void)visible; (void)loggingOn;
    (void)clockUpdate; (void)lockPreemption; (void)unlockPreemption;
    if (logMessage) logMessage(instanceEnvironment, fmi3Error, "logStatusError", "this FMU supports Co-Simulation only");
    return NULL;
}

void fmi3FreeInstance(fmi3Instance instance) { free(instance); }

fmi3Status fmi3EnterInitializationMode(fmi3Instance instance, fmi3Boolean toleranceDefined, fmi3Float64 tolerance,
                                       fmi3Float64 startTime, fmi3Boolean stopTimeDefined, fmi3Float64 stopTime) {
    Instance *inst = (Instance *)instance;
    (void)toleranceDefined; (void)tolerance; (void)stopTimeDefined; (void)stopTime;
    if (!inst) return fmi3Error;
    inst->time = startTime;
    inst->phase = ST_INIT;
    return fmi3OK;
}

fmi3Status fmi3ExitInitializationMode(fmi3Instance instance) {
    Instance *inst = (Instance *)instance;
    if (!inst) return fmi3Error;
    exit_initialization(inst);
    return fmi3OK;
}

fmi3Status fmi3EnterStepMode(fmi3Instance instance) { return instance ? fmi3OK : fmi3Error; }

fmi3Status fmi3Terminate(fmi3Instance instance) {
    Instance *inst = (Instance *)instance;
    if (!inst) return fmi3Error;
    inst->phase = ST_TERMINATED;
    return fmi3OK;
}

fmi3Status fmi3Reset(fmi3Instance instance) {
    Instance *inst = (Instance *)instance;
    if (!inst) return fmi3Error;
    set_defaults(inst);
    return fmi3OK;
}

fmi3Status fmi3GetFloat64(fmi3Instance instance, const fmi3ValueReference valueReferences[], size_t nValueReferences,
                          fmi3Float64 values[], size_t nValues) {
    Instance *inst = (Instance *)instance;
    size_t k;
    if (!inst || nValues < nValueReferences) return fmi3Error;
    for (k = 0; k < nValueReferences; k++) {
        if (valueReferences[k] == VR_TIME) values[k] = inst->time;
        else if (!get_real(inst, valueReferences[k], &values[k], "fmi3GetFloat64", "Float64")) return fmi3Error;
    }
    return fmi3OK;
}

fmi3Status fmi3SetFloat64(fmi3Instance instance, const fmi3ValueReference valueReferences[], size_t nValueReferences,
                          const fmi3Float64 values[], size_t nValues) {
    Instance *inst = (Instance *)instance;
    size_t k;
    if (!inst || nValues < nValueReferences) return fmi3Error;
    for (k = 0; k < nValueReferences; k++)
        if (!set_real(inst, valueReferences[k], values[k], "fmi3SetFloat64", "Float64")) return fmi3Error;
    return fmi3OK;
}

fmi3Status fmi3GetBoolean(fmi3Instance instance, const fmi3ValueReference valueReferences[], size_t nValueReferences,
                          fmi3Boolean values[], size_t nValues) {
    Instance *inst = (Instance *)instance;
    size_t k;
    if (!inst || nValues < nValueReferences) return fmi3Error;
    for (k = 0; k < nValueReferences; k++) {
        if (valueReferences[k] != VR_STEADY_START) return fmi3Error;
        values[k] = inst->steady_start ? fmi3True : fmi3False;
    }
    return fmi3OK;
}

fmi3Status fmi3SetBoolean(fmi3Instance instance, const fmi3ValueReference valueReferences[], size_t nValueReferences,
                          const fmi3Boolean values[], size_t nValues) {
    Instance *inst = (Instance *)instance;
    size_t k;
    if (!inst || nValues < nValueReferences) return fmi3Error;
    for (k = 0; k < nValueReferences; k++) {
        if (valueReferences[k] != VR_STEADY_START || !parameters_settable(inst)) {
            log_error(inst, "fmi3SetBoolean: value reference %u cannot be set now", (unsigned)valueReferences[k]);
            return fmi3Error;
        }
        inst->steady_start = values[k] ? 1 : 0;
        inst->y_valid = 0;
    }
    return fmi3OK;
}

fmi3Status fmi3GetFMUState(fmi3Instance instance, fmi3FMUState *FMUState) {
    if (!instance || !FMUState) return fmi3Error;
    *FMUState = store_state((Instance *)instance, *FMUState, NULL);
    return *FMUState ? fmi3OK : fmi3Error;
}

fmi3Status fmi3SetFMUState(fmi3Instance instance, fmi3FMUState FMUState) {
    if (!instance || !FMUState) return fmi3Error;
    memcpy(instance, FMUState, sizeof(Instance));
    return fmi3OK;
}

fmi3Status fmi3FreeFMUState(fmi3Instance instance, fmi3FMUState *FMUState) {
    if (!instance || !FMUState) return fmi3Error;
    free(*FMUState);
    *FMUState = NULL;
    return fmi3OK;
}

fmi3Status fmi3SerializedFMUStateSize(fmi3Instance instance, fmi3FMUState FMUState, size_t *size) {
    (void)FMUState;
    if (!instance || !size) return fmi3Error;
    *size = sizeof(Instance);
    return fmi3OK;
}

fmi3Status fmi3SerializeFMUState(fmi3Instance instance, fmi3FMUState FMUState, fmi3Byte serializedState[],
                                 size_t size) {
    if (!instance || !FMUState || size < sizeof(Instance)) return fmi3Error;
    memcpy(serializedState, FMUState, sizeof(Instance));
    return fmi3OK;
}

fmi3Status fmi3DeserializeFMUState(fmi3Instance instance, const fmi3Byte serializedState[], size_t size,
                                   fmi3FMUState *FMUState) {
    if (!instance || !FMUState || size != sizeof(Instance)) return fmi3Error;
    *FMUState = store_state((Instance *)instance, *FMUState, serializedState);
    return *FMUState ? fmi3OK : fmi3Error;
}

fmi3Status fmi3DoStep(fmi3Instance instance, fmi3Float64 currentCommunicationPoint,
                      fmi3Float64 communicationStepSize, fmi3Boolean noSetFMUStatePriorToCurrentPoint,
                      fmi3Boolean *eventHandlingNeeded, fmi3Boolean *terminateSimulation, fmi3Boolean *earlyReturn,
                      fmi3Float64 *lastSuccessfulTime) {
    Instance *inst = (Instance *)instance;
    int ok;
    (void)noSetFMUStatePriorToCurrentPoint;
    if (!inst) return fmi3Error;
    if (eventHandlingNeeded) *eventHandlingNeeded = fmi3False;
    if (terminateSimulation) *terminateSimulation = fmi3False;
    if (earlyReturn) *earlyReturn = fmi3False;
    ok = do_step(inst, "fmi3DoStep", currentCommunicationPoint, communicationStepSize);
    if (lastSuccessfulTime) *lastSuccessfulTime = inst->time;
    return ok ? fmi3OK : fmi3Error;
}

#include "fmi3_unsupported.c"
