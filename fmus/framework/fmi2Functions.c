/* FMI 2.0 co-simulation interface on top of the shared framework (model.h). */
#include <string.h>

#include "fmi2Functions.h"
#include "model.h"

#define ALL_STATES (StartAndEnd | Instantiated | InitializationMode | StepMode | Terminated)
#define SETTABLE_STATES (Instantiated | InitializationMode | StepMode)
#define GETTABLE_STATES (InitializationMode | StepMode | Terminated)

#define NOT_SUPPORTED(f)                                                                    \
    do {                                                                                    \
        logError((ModelInstance *)c, "%s is not supported by this FMU.", #f);               \
        return fmi2Error;                                                                   \
    } while (0)

static void logFmi2(const ModelInstance *comp, Status status, const char *category,
                    const char *message) {
    fmi2CallbackLogger logger = (fmi2CallbackLogger)comp->logger;
    if (!logger) {
        return;
    }
    /* The FMI 2.0 logger takes a printf format: escape '%' so the text arrives verbatim. */
    char escaped[2048];
    size_t j = 0;
    for (size_t i = 0; message[i] != '\0' && j + 2 < sizeof(escaped); i++) {
        if (message[i] == '%') escaped[j++] = '%';
        escaped[j++] = message[i];
    }
    escaped[j] = '\0';
    logger(comp->environment, comp->instanceName, (fmi2Status)status, category, escaped);
}

const char *fmi2GetTypesPlatform(void) { return fmi2TypesPlatform; }

const char *fmi2GetVersion(void) { return fmi2Version; }

fmi2Status fmi2SetDebugLogging(fmi2Component c, fmi2Boolean loggingOn, size_t nCategories,
                               const fmi2String categories[]) {
    (void)nCategories; (void)categories;
    ModelInstance *comp = (ModelInstance *)c;
    if (invalidState(comp, "fmi2SetDebugLogging", ALL_STATES)) return fmi2Error;
    comp->loggingOn = loggingOn;
    return fmi2OK;
}

fmi2Component fmi2Instantiate(fmi2String instanceName, fmi2Type fmuType, fmi2String fmuGUID,
                              fmi2String fmuResourceLocation,
                              const fmi2CallbackFunctions *functions, fmi2Boolean visible,
                              fmi2Boolean loggingOn) {
    (void)fmuResourceLocation; (void)visible;
    if (!functions || !functions->logger) {
        return NULL;
    }
    if (fmuType != fmi2CoSimulation) {
        functions->logger(functions->componentEnvironment, instanceName, fmi2Error,
                          "logStatusError", "fmi2Instantiate: this FMU supports co-simulation only.");
        return NULL;
    }
    if (!fmuGUID || strcmp(fmuGUID, INSTANTIATION_TOKEN) != 0) {
        functions->logger(functions->componentEnvironment, instanceName, fmi2Error,
                          "logStatusError", "fmi2Instantiate: GUID does not match " INSTANTIATION_TOKEN ".");
        return NULL;
    }
    return createModelInstance(instanceName, 2, functions->componentEnvironment,
                               (void *)functions->logger, logFmi2, loggingOn);
}

void fmi2FreeInstance(fmi2Component c) { freeModelInstance((ModelInstance *)c); }

fmi2Status fmi2SetupExperiment(fmi2Component c, fmi2Boolean toleranceDefined, fmi2Real tolerance,
                               fmi2Real startTime, fmi2Boolean stopTimeDefined,
                               fmi2Real stopTime) {
    (void)toleranceDefined; (void)tolerance; (void)stopTimeDefined; (void)stopTime;
    ModelInstance *comp = (ModelInstance *)c;
    if (invalidState(comp, "fmi2SetupExperiment", Instantiated)) return fmi2Error;
    comp->startTime = startTime;
    return fmi2OK;
}

fmi2Status fmi2EnterInitializationMode(fmi2Component c) {
    ModelInstance *comp = (ModelInstance *)c;
    if (invalidState(comp, "fmi2EnterInitializationMode", Instantiated)) return fmi2Error;
    return (fmi2Status)enterInitialization(comp, comp->startTime);
}

fmi2Status fmi2ExitInitializationMode(fmi2Component c) {
    ModelInstance *comp = (ModelInstance *)c;
    if (invalidState(comp, "fmi2ExitInitializationMode", InitializationMode)) return fmi2Error;
    return (fmi2Status)exitInitialization(comp);
}

fmi2Status fmi2Terminate(fmi2Component c) {
    ModelInstance *comp = (ModelInstance *)c;
    if (invalidState(comp, "fmi2Terminate", StepMode | InitializationMode)) return fmi2Error;
    comp->state = Terminated;
    return fmi2OK;
}

fmi2Status fmi2Reset(fmi2Component c) {
    ModelInstance *comp = (ModelInstance *)c;
    if (invalidState(comp, "fmi2Reset", ALL_STATES)) return fmi2Error;
    resetModelInstance(comp);
    return fmi2OK;
}

fmi2Status fmi2GetReal(fmi2Component c, const fmi2ValueReference vr[], size_t nvr,
                       fmi2Real value[]) {
    ModelInstance *comp = (ModelInstance *)c;
    if (invalidState(comp, "fmi2GetReal", GETTABLE_STATES)) return fmi2Error;
    size_t index = 0;
    for (size_t i = 0; i < nvr; i++) {
        Status s = getFloat64(comp, (ValueReference)vr[i], value, nvr, &index);
        if (s > Warning) return (fmi2Status)s;
    }
    return fmi2OK;
}

fmi2Status fmi2SetReal(fmi2Component c, const fmi2ValueReference vr[], size_t nvr,
                       const fmi2Real value[]) {
    ModelInstance *comp = (ModelInstance *)c;
    if (invalidState(comp, "fmi2SetReal", SETTABLE_STATES)) return fmi2Error;
    size_t index = 0;
    for (size_t i = 0; i < nvr; i++) {
        Status s = setFloat64(comp, (ValueReference)vr[i], value, nvr, &index);
        if (s > Warning) return (fmi2Status)s;
    }
    return fmi2OK;
}

fmi2Status fmi2GetInteger(fmi2Component c, const fmi2ValueReference vr[], size_t nvr,
                          fmi2Integer value[]) {
    ModelInstance *comp = (ModelInstance *)c;
    if (invalidState(comp, "fmi2GetInteger", GETTABLE_STATES)) return fmi2Error;
    size_t index = 0;
    for (size_t i = 0; i < nvr; i++) {
        Status s = getInt32(comp, (ValueReference)vr[i], value, nvr, &index);
        if (s > Warning) return (fmi2Status)s;
    }
    return fmi2OK;
}

fmi2Status fmi2SetInteger(fmi2Component c, const fmi2ValueReference vr[], size_t nvr,
                          const fmi2Integer value[]) {
    ModelInstance *comp = (ModelInstance *)c;
    if (invalidState(comp, "fmi2SetInteger", SETTABLE_STATES)) return fmi2Error;
    size_t index = 0;
    for (size_t i = 0; i < nvr; i++) {
        Status s = setInt32(comp, (ValueReference)vr[i], value, nvr, &index);
        if (s > Warning) return (fmi2Status)s;
    }
    return fmi2OK;
}

fmi2Status fmi2GetBoolean(fmi2Component c, const fmi2ValueReference vr[], size_t nvr,
                          fmi2Boolean value[]) {
    (void)vr; (void)nvr; (void)value;
    NOT_SUPPORTED(fmi2GetBoolean);
}

fmi2Status fmi2GetString(fmi2Component c, const fmi2ValueReference vr[], size_t nvr,
                         fmi2String value[]) {
    (void)vr; (void)nvr; (void)value;
    NOT_SUPPORTED(fmi2GetString);
}

fmi2Status fmi2SetBoolean(fmi2Component c, const fmi2ValueReference vr[], size_t nvr,
                          const fmi2Boolean value[]) {
    (void)vr; (void)nvr; (void)value;
    NOT_SUPPORTED(fmi2SetBoolean);
}

fmi2Status fmi2SetString(fmi2Component c, const fmi2ValueReference vr[], size_t nvr,
                         const fmi2String value[]) {
    (void)vr; (void)nvr; (void)value;
    NOT_SUPPORTED(fmi2SetString);
}

fmi2Status fmi2GetFMUstate(fmi2Component c, fmi2FMUstate *FMUstate) {
    (void)FMUstate;
    NOT_SUPPORTED(fmi2GetFMUstate);
}

fmi2Status fmi2SetFMUstate(fmi2Component c, fmi2FMUstate FMUstate) {
    (void)FMUstate;
    NOT_SUPPORTED(fmi2SetFMUstate);
}

fmi2Status fmi2FreeFMUstate(fmi2Component c, fmi2FMUstate *FMUstate) {
    (void)FMUstate;
    NOT_SUPPORTED(fmi2FreeFMUstate);
}

fmi2Status fmi2SerializedFMUstateSize(fmi2Component c, fmi2FMUstate FMUstate, size_t *size) {
    (void)FMUstate; (void)size;
    NOT_SUPPORTED(fmi2SerializedFMUstateSize);
}

fmi2Status fmi2SerializeFMUstate(fmi2Component c, fmi2FMUstate FMUstate, fmi2Byte serializedState[],
                                 size_t size) {
    (void)FMUstate; (void)serializedState; (void)size;
    NOT_SUPPORTED(fmi2SerializeFMUstate);
}

fmi2Status fmi2DeSerializeFMUstate(fmi2Component c, const fmi2Byte serializedState[], size_t size,
                                   fmi2FMUstate *FMUstate) {
    (void)serializedState; (void)size; (void)FMUstate;
    NOT_SUPPORTED(fmi2DeSerializeFMUstate);
}

fmi2Status fmi2GetDirectionalDerivative(fmi2Component c, const fmi2ValueReference vUnknown_ref[],
                                        size_t nUnknown, const fmi2ValueReference vKnown_ref[],
                                        size_t nKnown, const fmi2Real dvKnown[],
                                        fmi2Real dvUnknown[]) {
    (void)vUnknown_ref; (void)nUnknown; (void)vKnown_ref; (void)nKnown; (void)dvKnown;
    (void)dvUnknown;
    NOT_SUPPORTED(fmi2GetDirectionalDerivative);
}

fmi2Status fmi2EnterEventMode(fmi2Component c) { NOT_SUPPORTED(fmi2EnterEventMode); }

fmi2Status fmi2NewDiscreteStates(fmi2Component c, fmi2EventInfo *eventInfo) {
    (void)eventInfo;
    NOT_SUPPORTED(fmi2NewDiscreteStates);
}

fmi2Status fmi2EnterContinuousTimeMode(fmi2Component c) {
    NOT_SUPPORTED(fmi2EnterContinuousTimeMode);
}

fmi2Status fmi2CompletedIntegratorStep(fmi2Component c, fmi2Boolean noSetFMUStatePriorToCurrentPoint,
                                       fmi2Boolean *enterEventMode,
                                       fmi2Boolean *terminateSimulation) {
    (void)noSetFMUStatePriorToCurrentPoint; (void)enterEventMode; (void)terminateSimulation;
    NOT_SUPPORTED(fmi2CompletedIntegratorStep);
}

fmi2Status fmi2SetTime(fmi2Component c, fmi2Real time) {
    (void)time;
    NOT_SUPPORTED(fmi2SetTime);
}

fmi2Status fmi2SetContinuousStates(fmi2Component c, const fmi2Real x[], size_t nx) {
    (void)x; (void)nx;
    NOT_SUPPORTED(fmi2SetContinuousStates);
}

fmi2Status fmi2GetDerivatives(fmi2Component c, fmi2Real derivatives[], size_t nx) {
    (void)derivatives; (void)nx;
    NOT_SUPPORTED(fmi2GetDerivatives);
}

fmi2Status fmi2GetEventIndicators(fmi2Component c, fmi2Real eventIndicators[], size_t ni) {
    (void)eventIndicators; (void)ni;
    NOT_SUPPORTED(fmi2GetEventIndicators);
}

fmi2Status fmi2GetContinuousStates(fmi2Component c, fmi2Real x[], size_t nx) {
    (void)x; (void)nx;
    NOT_SUPPORTED(fmi2GetContinuousStates);
}

fmi2Status fmi2GetNominalsOfContinuousStates(fmi2Component c, fmi2Real x_nominal[], size_t nx) {
    (void)x_nominal; (void)nx;
    NOT_SUPPORTED(fmi2GetNominalsOfContinuousStates);
}

fmi2Status fmi2SetRealInputDerivatives(fmi2Component c, const fmi2ValueReference vr[], size_t nvr,
                                       const fmi2Integer order[], const fmi2Real value[]) {
    (void)vr; (void)nvr; (void)order; (void)value;
    NOT_SUPPORTED(fmi2SetRealInputDerivatives);
}

fmi2Status fmi2GetRealOutputDerivatives(fmi2Component c, const fmi2ValueReference vr[], size_t nvr,
                                        const fmi2Integer order[], fmi2Real value[]) {
    (void)vr; (void)nvr; (void)order; (void)value;
    NOT_SUPPORTED(fmi2GetRealOutputDerivatives);
}

fmi2Status fmi2DoStep(fmi2Component c, fmi2Real currentCommunicationPoint,
                      fmi2Real communicationStepSize, fmi2Boolean noSetFMUStatePriorToCurrentPoint) {
    (void)noSetFMUStatePriorToCurrentPoint;
    ModelInstance *comp = (ModelInstance *)c;
    if (invalidState(comp, "fmi2DoStep", StepMode)) return fmi2Error;
    return (fmi2Status)doFixedStep(comp, currentCommunicationPoint, communicationStepSize);
}

fmi2Status fmi2CancelStep(fmi2Component c) { NOT_SUPPORTED(fmi2CancelStep); }

fmi2Status fmi2GetStatus(fmi2Component c, const fmi2StatusKind s, fmi2Status *value) {
    (void)s; (void)value;
    NOT_SUPPORTED(fmi2GetStatus);
}

fmi2Status fmi2GetRealStatus(fmi2Component c, const fmi2StatusKind s, fmi2Real *value) {
    (void)s; (void)value;
    NOT_SUPPORTED(fmi2GetRealStatus);
}

fmi2Status fmi2GetIntegerStatus(fmi2Component c, const fmi2StatusKind s, fmi2Integer *value) {
    (void)s; (void)value;
    NOT_SUPPORTED(fmi2GetIntegerStatus);
}

fmi2Status fmi2GetBooleanStatus(fmi2Component c, const fmi2StatusKind s, fmi2Boolean *value) {
    (void)s; (void)value;
    NOT_SUPPORTED(fmi2GetBooleanStatus);
}

fmi2Status fmi2GetStringStatus(fmi2Component c, const fmi2StatusKind s, fmi2String *value) {
    (void)s; (void)value;
    NOT_SUPPORTED(fmi2GetStringStatus);
}
