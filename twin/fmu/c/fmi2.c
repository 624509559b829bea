/* Thermal twin ROM: FMI 2.0 Co-Simulation API (thermal-twin; machine-independent, shipped with the package).
 *
 * State: reduced modal coordinates z (NZ), dz/dt = -LAMBDA .* z + BZ u,
 * outputs y = CZ z + DZ u + OFFSET, u = thermal inputs (zone ambients, gradient,
 * source powers) from the FMU inputs (spindle speed, feeds, ambients, gradient)
 * through the machine's power models P = c (n / n_ref)^b.
 * In the FMU this file is sources/thermal_twin_rom.c; it includes model.c (the shared model core)
 * and the generated model_data.h.
 * Build: cc -shared -fPIC -O2 -I. thermal_twin_rom.c -o <modelIdentifier>.so -lm
 */
#include <math.h>
#include <stdarg.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "fmi2Functions.h"
#include "model_data.h"

typedef fmi2CallbackFunctions Callbacks;

#include "model.c"

static void emit(const Instance *inst, int is_error, const char *category, const char *message) {
    char esc[2048];
    size_t i, j = 0;
    if (!inst->cb.logger) return;
    for (i = 0; message[i] && j + 2 < sizeof esc; i++) { /* the importer treats the message as a format */
        if (message[i] == '%') esc[j++] = '%';
        esc[j++] = message[i];
    }
    esc[j] = 0;
    inst->cb.logger(inst->cb.componentEnvironment, inst->instance_name, is_error ? fmi2Error : fmi2OK, category,
                    esc);
}

static void *alloc_instance(const Instance *inst) { return inst->cb.allocateMemory(1, sizeof(Instance)); }

/* ------------------------------------------------------------------ common functions */
const char *fmi2GetTypesPlatform(void) { return fmi2TypesPlatform; }
const char *fmi2GetVersion(void) { return fmi2Version; }

fmi2Status fmi2SetDebugLogging(fmi2Component c, fmi2Boolean loggingOn, size_t nCategories,
                               const fmi2String categories[]) {
    Instance *inst = (Instance *)c;
    (void)nCategories; (void)categories;
    if (!inst) return fmi2Error;
    inst->logging_on = loggingOn;
    return fmi2OK;
}

fmi2Component fmi2Instantiate(fmi2String instanceName, fmi2Type fmuType, fmi2String fmuGUID,
                              fmi2String fmuResourceLocation, const fmi2CallbackFunctions *functions,
                              fmi2Boolean visible, fmi2Boolean loggingOn) {
    Instance *inst;
    (void)fmuResourceLocation; (void)visible;
    if (!functions || !functions->allocateMemory || !functions->freeMemory) return NULL;
    inst = (Instance *)functions->allocateMemory(1, sizeof(Instance));
    if (!inst) return NULL;
    memset(inst, 0, sizeof(Instance));
    inst->cb = *functions;
    snprintf(inst->instance_name, sizeof inst->instance_name, "%s", instanceName ? instanceName : "");
    inst->logging_on = loggingOn;
    if (fmuType != fmi2CoSimulation) {
        log_error(inst, "fmi2Instantiate: this FMU supports Co-Simulation only");
        functions->freeMemory(inst);
        return NULL;
    }
    if (!fmuGUID || strcmp(fmuGUID, MODEL_GUID) != 0) {
        log_error(inst, "fmi2Instantiate: GUID %s does not match %s", fmuGUID ? fmuGUID : "(null)", MODEL_GUID);
        functions->freeMemory(inst);
        return NULL;
    }
    set_defaults(inst);
    return inst;
}

void fmi2FreeInstance(fmi2Component c) {
    Instance *inst = (Instance *)c;
    if (inst) inst->cb.freeMemory(inst);
}

fmi2Status fmi2SetupExperiment(fmi2Component c, fmi2Boolean toleranceDefined, fmi2Real tolerance,
                               fmi2Real startTime, fmi2Boolean stopTimeDefined, fmi2Real stopTime) {
    Instance *inst = (Instance *)c;
    (void)toleranceDefined; (void)tolerance; (void)stopTimeDefined; (void)stopTime;
    if (!inst) return fmi2Error;
    inst->time = startTime;
    return fmi2OK;
}

fmi2Status fmi2EnterInitializationMode(fmi2Component c) {
    Instance *inst = (Instance *)c;
    if (!inst) return fmi2Error;
    inst->phase = ST_INIT;
    return fmi2OK;
}

fmi2Status fmi2ExitInitializationMode(fmi2Component c) {
    Instance *inst = (Instance *)c;
    if (!inst) return fmi2Error;
    exit_initialization(inst);
    return fmi2OK;
}

fmi2Status fmi2Terminate(fmi2Component c) {
    Instance *inst = (Instance *)c;
    if (!inst) return fmi2Error;
    inst->phase = ST_TERMINATED;
    return fmi2OK;
}

fmi2Status fmi2Reset(fmi2Component c) {
    Instance *inst = (Instance *)c;
    if (!inst) return fmi2Error;
    set_defaults(inst);
    return fmi2OK;
}

/* ------------------------------------------------------------------ get / set */
fmi2Status fmi2GetReal(fmi2Component c, const fmi2ValueReference vr[], size_t nvr, fmi2Real value[]) {
    Instance *inst = (Instance *)c;
    size_t k;
    if (!inst || (nvr > 0 && (!vr || !value))) return fmi2Error;
    for (k = 0; k < nvr; k++)
        if (!get_real(inst, vr[k], &value[k], "fmi2GetReal", "Real")) return fmi2Error;
    return fmi2OK;
}

fmi2Status fmi2SetReal(fmi2Component c, const fmi2ValueReference vr[], size_t nvr, const fmi2Real value[]) {
    Instance *inst = (Instance *)c;
    size_t k;
    if (!inst || (nvr > 0 && (!vr || !value))) return fmi2Error;
    for (k = 0; k < nvr; k++)
        if (!set_real(inst, vr[k], value[k], "fmi2SetReal", "Real")) return fmi2Error;
    return fmi2OK;
}

fmi2Status fmi2GetInteger(fmi2Component c, const fmi2ValueReference vr[], size_t nvr, fmi2Integer value[]) {
    (void)vr; (void)value;
    return (c && nvr == 0) ? fmi2OK : fmi2Error;
}

fmi2Status fmi2SetInteger(fmi2Component c, const fmi2ValueReference vr[], size_t nvr, const fmi2Integer value[]) {
    (void)vr; (void)value;
    return (c && nvr == 0) ? fmi2OK : fmi2Error;
}

fmi2Status fmi2GetBoolean(fmi2Component c, const fmi2ValueReference vr[], size_t nvr, fmi2Boolean value[]) {
    Instance *inst = (Instance *)c;
    size_t k;
    if (!inst) return fmi2Error;
    for (k = 0; k < nvr; k++) {
        if (vr[k] != VR_STEADY_START) return fmi2Error;
        value[k] = inst->steady_start;
    }
    return fmi2OK;
}

fmi2Status fmi2SetBoolean(fmi2Component c, const fmi2ValueReference vr[], size_t nvr, const fmi2Boolean value[]) {
    Instance *inst = (Instance *)c;
    size_t k;
    if (!inst) return fmi2Error;
    for (k = 0; k < nvr; k++) {
        if (vr[k] != VR_STEADY_START || !parameters_settable(inst)) {
            log_error(inst, "fmi2SetBoolean: value reference %u cannot be set now", (unsigned)vr[k]);
            return fmi2Error;
        }
        inst->steady_start = value[k] ? fmi2True : fmi2False;
        inst->y_valid = 0;
    }
    return fmi2OK;
}

fmi2Status fmi2GetString(fmi2Component c, const fmi2ValueReference vr[], size_t nvr, fmi2String value[]) {
    (void)vr; (void)value;
    return (c && nvr == 0) ? fmi2OK : fmi2Error;
}

fmi2Status fmi2SetString(fmi2Component c, const fmi2ValueReference vr[], size_t nvr, const fmi2String value[]) {
    (void)vr; (void)value;
    return (c && nvr == 0) ? fmi2OK : fmi2Error;
}

/* ------------------------------------------------------------------ FMU state */
fmi2Status fmi2GetFMUstate(fmi2Component c, fmi2FMUstate *state) {
    Instance *inst = (Instance *)c;
    if (!inst || !state) return fmi2Error;
    *state = store_state(inst, *state, NULL);
    return *state ? fmi2OK : fmi2Error;
}

fmi2Status fmi2SetFMUstate(fmi2Component c, fmi2FMUstate state) {
    Instance *inst = (Instance *)c;
    if (!inst || !state) return fmi2Error;
    memcpy(inst, state, sizeof(Instance));
    return fmi2OK;
}

fmi2Status fmi2FreeFMUstate(fmi2Component c, fmi2FMUstate *state) {
    Instance *inst = (Instance *)c;
    if (!inst || !state) return fmi2Error;
    if (*state) inst->cb.freeMemory(*state);
    *state = NULL;
    return fmi2OK;
}

fmi2Status fmi2SerializedFMUstateSize(fmi2Component c, fmi2FMUstate state, size_t *size) {
    (void)state;
    if (!c || !size) return fmi2Error;
    *size = sizeof(Instance);
    return fmi2OK;
}

fmi2Status fmi2SerializeFMUstate(fmi2Component c, fmi2FMUstate state, fmi2Byte bytes[], size_t size) {
    if (!c || !state || size < sizeof(Instance)) return fmi2Error;
    memcpy(bytes, state, sizeof(Instance));
    return fmi2OK;
}

fmi2Status fmi2DeSerializeFMUstate(fmi2Component c, const fmi2Byte bytes[], size_t size, fmi2FMUstate *state) {
    Instance *inst = (Instance *)c;
    if (!inst || !state || size != sizeof(Instance)) return fmi2Error;
    *state = store_state(inst, *state, bytes);
    return *state ? fmi2OK : fmi2Error;
}

fmi2Status fmi2GetDirectionalDerivative(fmi2Component c, const fmi2ValueReference vUnknown_ref[], size_t nUnknown,
                                        const fmi2ValueReference vKnown_ref[], size_t nKnown,
                                        const fmi2Real dvKnown[], fmi2Real dvUnknown[]) {
    (void)vUnknown_ref; (void)nUnknown; (void)vKnown_ref; (void)nKnown; (void)dvKnown; (void)dvUnknown;
    log_error((Instance *)c, "directional derivatives are not provided");
    return fmi2Error;
}

/* ------------------------------------------------------------------ co-simulation */
fmi2Status fmi2SetRealInputDerivatives(fmi2Component c, const fmi2ValueReference vr[], size_t nvr,
                                       const fmi2Integer order[], const fmi2Real value[]) {
    (void)vr; (void)nvr; (void)order; (void)value;
    log_error((Instance *)c, "input derivatives are not supported (inputs are held)");
    return fmi2Error;
}

fmi2Status fmi2GetRealOutputDerivatives(fmi2Component c, const fmi2ValueReference vr[], size_t nvr,
                                        const fmi2Integer order[], fmi2Real value[]) {
    (void)vr; (void)nvr; (void)order; (void)value;
    log_error((Instance *)c, "output derivatives are not provided");
    return fmi2Error;
}

fmi2Status fmi2DoStep(fmi2Component c, fmi2Real currentCommunicationPoint, fmi2Real communicationStepSize,
                      fmi2Boolean noSetFMUStatePriorToCurrentPoint) {
    Instance *inst = (Instance *)c;
    (void)noSetFMUStatePriorToCurrentPoint;
    /* fmi2Error, not fmi2Discard: FMI 2.0 keeps Discard for a step done only in part, which a master
       retries with a shorter step (fmpy does, for ever, as fmi2Terminated is false); no step size helps. */
    return inst && do_step(inst, "fmi2DoStep", currentCommunicationPoint, communicationStepSize) ? fmi2OK
                                                                                                   : fmi2Error;
}

fmi2Status fmi2CancelStep(fmi2Component c) { (void)c; return fmi2Error; }

fmi2Status fmi2GetStatus(fmi2Component c, const fmi2StatusKind s, fmi2Status *value) {
    (void)s;
    if (!c || !value) return fmi2Error;
    *value = fmi2OK;
    return fmi2OK;
}

fmi2Status fmi2GetRealStatus(fmi2Component c, const fmi2StatusKind s, fmi2Real *value) {
    Instance *inst = (Instance *)c;
    if (!inst || !value) return fmi2Error;
    if (s == fmi2LastSuccessfulTime) { *value = inst->time; return fmi2OK; }
    return fmi2Discard;
}

fmi2Status fmi2GetIntegerStatus(fmi2Component c, const fmi2StatusKind s, fmi2Integer *value) {
    (void)c; (void)s; (void)value;
    return fmi2Discard;
}

fmi2Status fmi2GetBooleanStatus(fmi2Component c, const fmi2StatusKind s, fmi2Boolean *value) {
    if (!c || !value) return fmi2Error;
    if (s == fmi2Terminated) { *value = fmi2False; return fmi2OK; }
    return fmi2Discard;
}

fmi2Status fmi2GetStringStatus(fmi2Component c, const fmi2StatusKind s, fmi2String *value) {
    (void)c; (void)s; (void)value;
    return fmi2Discard;
}
