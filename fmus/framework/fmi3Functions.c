/* FMI 3.0 co-simulation interface on top of the shared framework (model.h). */
#include <math.h>
#include <string.h>

#include "fmi3Functions.h"
#include "model.h"

#define ALL_STATES (StartAndEnd | Instantiated | InitializationMode | StepMode | Terminated)
#define SETTABLE_STATES (Instantiated | InitializationMode | StepMode)
#define GETTABLE_STATES (InitializationMode | StepMode | Terminated)

#define NOT_SUPPORTED(f)                                                                    \
    do {                                                                                    \
        logError((ModelInstance *)instance, "%s is not supported by this FMU.", #f);        \
        return fmi3Error;                                                                   \
    } while (0)

static void logFmi3(const ModelInstance *comp, Status status, const char *category,
                    const char *message) {
    fmi3LogMessageCallback callback = (fmi3LogMessageCallback)comp->logger;
    if (callback) {
        callback(comp->environment, (fmi3Status)status, category, message);
    }
}

const char *fmi3GetVersion(void) { return fmi3Version; }

fmi3Status fmi3SetDebugLogging(fmi3Instance instance, fmi3Boolean loggingOn, size_t nCategories,
                               const fmi3String categories[]) {
    (void)nCategories;
    (void)categories;
    ModelInstance *comp = (ModelInstance *)instance;
    if (invalidState(comp, "fmi3SetDebugLogging", ALL_STATES)) return fmi3Error;
    comp->loggingOn = loggingOn;
    return fmi3OK;
}

fmi3Instance fmi3InstantiateModelExchange(fmi3String instanceName, fmi3String instantiationToken,
                                          fmi3String resourcePath, fmi3Boolean visible,
                                          fmi3Boolean loggingOn,
                                          fmi3InstanceEnvironment instanceEnvironment,
                                          fmi3LogMessageCallback logMessage) {
    (void)instanceName; (void)instantiationToken; (void)resourcePath; (void)visible;
    (void)loggingOn;
    if (logMessage) {
        logMessage(instanceEnvironment, fmi3Error, "logStatusError",
                   "fmi3InstantiateModelExchange: this FMU supports co-simulation only.");
    }
    return NULL;
}

fmi3Instance fmi3InstantiateCoSimulation(
    fmi3String instanceName, fmi3String instantiationToken, fmi3String resourcePath,
    fmi3Boolean visible, fmi3Boolean loggingOn, fmi3Boolean eventModeUsed,
    fmi3Boolean earlyReturnAllowed, const fmi3ValueReference requiredIntermediateVariables[],
    size_t nRequiredIntermediateVariables, fmi3InstanceEnvironment instanceEnvironment,
    fmi3LogMessageCallback logMessage, fmi3IntermediateUpdateCallback intermediateUpdate) {
    (void)resourcePath; (void)visible; (void)earlyReturnAllowed;
    (void)requiredIntermediateVariables; (void)nRequiredIntermediateVariables;
    (void)intermediateUpdate;
    if (!instantiationToken || strcmp(instantiationToken, INSTANTIATION_TOKEN) != 0) {
        if (logMessage) {
            logMessage(instanceEnvironment, fmi3Error, "logStatusError",
                       "fmi3InstantiateCoSimulation: instantiationToken does not match "
                       INSTANTIATION_TOKEN ".");
        }
        return NULL;
    }
    if (eventModeUsed) {
        if (logMessage) {
            logMessage(instanceEnvironment, fmi3Error, "logStatusError",
                       "fmi3InstantiateCoSimulation: event mode is not supported.");
        }
        return NULL;
    }
    return createModelInstance(instanceName, 3, instanceEnvironment, (void *)logMessage, logFmi3,
                               loggingOn);
}

fmi3Instance fmi3InstantiateScheduledExecution(
    fmi3String instanceName, fmi3String instantiationToken, fmi3String resourcePath,
    fmi3Boolean visible, fmi3Boolean loggingOn, fmi3InstanceEnvironment instanceEnvironment,
    fmi3LogMessageCallback logMessage, fmi3ClockUpdateCallback clockUpdate,
    fmi3LockPreemptionCallback lockPreemption, fmi3UnlockPreemptionCallback unlockPreemption) {
    (void)instanceName; (void)instantiationToken; (void)resourcePath; (void)visible;
    (void)loggingOn; (void)clockUpdate; (void)lockPreemption; (void)unlockPreemption;
    if (logMessage) {
        logMessage(instanceEnvironment, fmi3Error, "logStatusError",
                   "fmi3InstantiateScheduledExecution: this FMU supports co-simulation only.");
    }
    return NULL;
}

void fmi3FreeInstance(fmi3Instance instance) { freeModelInstance((ModelInstance *)instance); }

fmi3Status fmi3EnterInitializationMode(fmi3Instance instance, fmi3Boolean toleranceDefined,
                                       fmi3Float64 tolerance, fmi3Float64 startTime,
                                       fmi3Boolean stopTimeDefined, fmi3Float64 stopTime) {
    (void)toleranceDefined; (void)tolerance; (void)stopTimeDefined; (void)stopTime;
    ModelInstance *comp = (ModelInstance *)instance;
    if (invalidState(comp, "fmi3EnterInitializationMode", Instantiated)) return fmi3Error;
    return (fmi3Status)enterInitialization(comp, startTime);
}

fmi3Status fmi3ExitInitializationMode(fmi3Instance instance) {
    ModelInstance *comp = (ModelInstance *)instance;
    if (invalidState(comp, "fmi3ExitInitializationMode", InitializationMode)) return fmi3Error;
    return (fmi3Status)exitInitialization(comp);
}

fmi3Status fmi3EnterEventMode(fmi3Instance instance) { NOT_SUPPORTED(fmi3EnterEventMode); }

fmi3Status fmi3Terminate(fmi3Instance instance) {
    ModelInstance *comp = (ModelInstance *)instance;
    if (invalidState(comp, "fmi3Terminate", StepMode | InitializationMode)) return fmi3Error;
    comp->state = Terminated;
    return fmi3OK;
}

fmi3Status fmi3Reset(fmi3Instance instance) {
    ModelInstance *comp = (ModelInstance *)instance;
    if (invalidState(comp, "fmi3Reset", ALL_STATES)) return fmi3Error;
    resetModelInstance(comp);
    return fmi3OK;
}

fmi3Status fmi3GetFloat64(fmi3Instance instance, const fmi3ValueReference valueReferences[],
                          size_t nValueReferences, fmi3Float64 values[], size_t nValues) {
    ModelInstance *comp = (ModelInstance *)instance;
    if (invalidState(comp, "fmi3GetFloat64", GETTABLE_STATES)) return fmi3Error;
    size_t index = 0;
    Status status = OK;
    for (size_t i = 0; i < nValueReferences; i++) {
        Status s = getFloat64(comp, (ValueReference)valueReferences[i], values, nValues, &index);
        if (s > status) status = s;
        if (status > Warning) return (fmi3Status)status;
    }
    return (fmi3Status)status;
}

fmi3Status fmi3SetFloat64(fmi3Instance instance, const fmi3ValueReference valueReferences[],
                          size_t nValueReferences, const fmi3Float64 values[], size_t nValues) {
    ModelInstance *comp = (ModelInstance *)instance;
    if (invalidState(comp, "fmi3SetFloat64", SETTABLE_STATES)) return fmi3Error;
    size_t index = 0;
    Status status = OK;
    for (size_t i = 0; i < nValueReferences; i++) {
        Status s = setFloat64(comp, (ValueReference)valueReferences[i], values, nValues, &index);
        if (s > status) status = s;
        if (status > Warning) return (fmi3Status)status;
    }
    return (fmi3Status)status;
}

fmi3Status fmi3GetInt32(fmi3Instance instance, const fmi3ValueReference valueReferences[],
                        size_t nValueReferences, fmi3Int32 values[], size_t nValues) {
    ModelInstance *comp = (ModelInstance *)instance;
    if (invalidState(comp, "fmi3GetInt32", GETTABLE_STATES | Instantiated)) return fmi3Error;
    size_t index = 0;
    for (size_t i = 0; i < nValueReferences; i++) {
        Status s = getInt32(comp, (ValueReference)valueReferences[i], values, nValues, &index);
        if (s > Warning) return (fmi3Status)s;
    }
    return fmi3OK;
}

fmi3Status fmi3SetInt32(fmi3Instance instance, const fmi3ValueReference valueReferences[],
                        size_t nValueReferences, const fmi3Int32 values[], size_t nValues) {
    ModelInstance *comp = (ModelInstance *)instance;
    if (invalidState(comp, "fmi3SetInt32", SETTABLE_STATES)) return fmi3Error;
    size_t index = 0;
    for (size_t i = 0; i < nValueReferences; i++) {
        Status s = setInt32(comp, (ValueReference)valueReferences[i], values, nValues, &index);
        if (s > Warning) return (fmi3Status)s;
    }
    return fmi3OK;
}

#define UNSUPPORTED_GETTER(name, type)                                                       \
    fmi3Status name(fmi3Instance instance, const fmi3ValueReference valueReferences[],       \
                    size_t nValueReferences, type values[], size_t nValues) {                \
        (void)valueReferences; (void)nValueReferences; (void)values; (void)nValues;          \
        NOT_SUPPORTED(name);                                                                 \
    }
#define UNSUPPORTED_SETTER(name, type)                                                       \
    fmi3Status name(fmi3Instance instance, const fmi3ValueReference valueReferences[],       \
                    size_t nValueReferences, const type values[], size_t nValues) {          \
        (void)valueReferences; (void)nValueReferences; (void)values; (void)nValues;          \
        NOT_SUPPORTED(name);                                                                 \
    }

UNSUPPORTED_GETTER(fmi3GetFloat32, fmi3Float32)
UNSUPPORTED_GETTER(fmi3GetInt8, fmi3Int8)
UNSUPPORTED_GETTER(fmi3GetUInt8, fmi3UInt8)
UNSUPPORTED_GETTER(fmi3GetInt16, fmi3Int16)
UNSUPPORTED_GETTER(fmi3GetUInt16, fmi3UInt16)
UNSUPPORTED_GETTER(fmi3GetUInt32, fmi3UInt32)
UNSUPPORTED_GETTER(fmi3GetInt64, fmi3Int64)
UNSUPPORTED_GETTER(fmi3GetUInt64, fmi3UInt64)
UNSUPPORTED_GETTER(fmi3GetBoolean, fmi3Boolean)
UNSUPPORTED_GETTER(fmi3GetString, fmi3String)
UNSUPPORTED_SETTER(fmi3SetFloat32, fmi3Float32)
UNSUPPORTED_SETTER(fmi3SetInt8, fmi3Int8)
UNSUPPORTED_SETTER(fmi3SetUInt8, fmi3UInt8)
UNSUPPORTED_SETTER(fmi3SetInt16, fmi3Int16)
UNSUPPORTED_SETTER(fmi3SetUInt16, fmi3UInt16)
UNSUPPORTED_SETTER(fmi3SetUInt32, fmi3UInt32)
UNSUPPORTED_SETTER(fmi3SetInt64, fmi3Int64)
UNSUPPORTED_SETTER(fmi3SetUInt64, fmi3UInt64)
UNSUPPORTED_SETTER(fmi3SetBoolean, fmi3Boolean)
UNSUPPORTED_SETTER(fmi3SetString, fmi3String)

fmi3Status fmi3GetBinary(fmi3Instance instance, const fmi3ValueReference valueReferences[],
                         size_t nValueReferences, size_t valueSizes[], fmi3Binary values[],
                         size_t nValues) {
    (void)valueReferences; (void)nValueReferences; (void)valueSizes; (void)values; (void)nValues;
    NOT_SUPPORTED(fmi3GetBinary);
}

fmi3Status fmi3SetBinary(fmi3Instance instance, const fmi3ValueReference valueReferences[],
                         size_t nValueReferences, const size_t valueSizes[],
                         const fmi3Binary values[], size_t nValues) {
    (void)valueReferences; (void)nValueReferences; (void)valueSizes; (void)values; (void)nValues;
    NOT_SUPPORTED(fmi3SetBinary);
}

fmi3Status fmi3GetClock(fmi3Instance instance, const fmi3ValueReference valueReferences[],
                        size_t nValueReferences, fmi3Clock values[]) {
    (void)valueReferences; (void)nValueReferences; (void)values;
    NOT_SUPPORTED(fmi3GetClock);
}

fmi3Status fmi3SetClock(fmi3Instance instance, const fmi3ValueReference valueReferences[],
                        size_t nValueReferences, const fmi3Clock values[]) {
    (void)valueReferences; (void)nValueReferences; (void)values;
    NOT_SUPPORTED(fmi3SetClock);
}

fmi3Status fmi3GetNumberOfVariableDependencies(fmi3Instance instance,
                                               fmi3ValueReference valueReference,
                                               size_t *nDependencies) {
    (void)valueReference; (void)nDependencies;
    NOT_SUPPORTED(fmi3GetNumberOfVariableDependencies);
}

fmi3Status fmi3GetVariableDependencies(fmi3Instance instance, fmi3ValueReference dependent,
                                       size_t elementIndicesOfDependent[],
                                       fmi3ValueReference independents[],
                                       size_t elementIndicesOfIndependents[],
                                       fmi3DependencyKind dependencyKinds[],
                                       size_t nDependencies) {
    (void)dependent; (void)elementIndicesOfDependent; (void)independents;
    (void)elementIndicesOfIndependents; (void)dependencyKinds; (void)nDependencies;
    NOT_SUPPORTED(fmi3GetVariableDependencies);
}

fmi3Status fmi3GetFMUState(fmi3Instance instance, fmi3FMUState *FMUState) {
    (void)FMUState;
    NOT_SUPPORTED(fmi3GetFMUState);
}

fmi3Status fmi3SetFMUState(fmi3Instance instance, fmi3FMUState FMUState) {
    (void)FMUState;
    NOT_SUPPORTED(fmi3SetFMUState);
}

fmi3Status fmi3FreeFMUState(fmi3Instance instance, fmi3FMUState *FMUState) {
    (void)FMUState;
    NOT_SUPPORTED(fmi3FreeFMUState);
}

fmi3Status fmi3SerializedFMUStateSize(fmi3Instance instance, fmi3FMUState FMUState, size_t *size) {
    (void)FMUState; (void)size;
    NOT_SUPPORTED(fmi3SerializedFMUStateSize);
}

fmi3Status fmi3SerializeFMUState(fmi3Instance instance, fmi3FMUState FMUState,
                                 fmi3Byte serializedState[], size_t size) {
    (void)FMUState; (void)serializedState; (void)size;
    NOT_SUPPORTED(fmi3SerializeFMUState);
}

fmi3Status fmi3DeserializeFMUState(fmi3Instance instance, const fmi3Byte serializedState[],
                                   size_t size, fmi3FMUState *FMUState) {
    (void)serializedState; (void)size; (void)FMUState;
    NOT_SUPPORTED(fmi3DeserializeFMUState);
}

fmi3Status fmi3GetDirectionalDerivative(fmi3Instance instance, const fmi3ValueReference unknowns[],
                                        size_t nUnknowns, const fmi3ValueReference knowns[],
                                        size_t nKnowns, const fmi3Float64 seed[], size_t nSeed,
                                        fmi3Float64 sensitivity[], size_t nSensitivity) {
    (void)unknowns; (void)nUnknowns; (void)knowns; (void)nKnowns; (void)seed; (void)nSeed;
    (void)sensitivity; (void)nSensitivity;
    NOT_SUPPORTED(fmi3GetDirectionalDerivative);
}

fmi3Status fmi3GetAdjointDerivative(fmi3Instance instance, const fmi3ValueReference unknowns[],
                                    size_t nUnknowns, const fmi3ValueReference knowns[],
                                    size_t nKnowns, const fmi3Float64 seed[], size_t nSeed,
                                    fmi3Float64 sensitivity[], size_t nSensitivity) {
    (void)unknowns; (void)nUnknowns; (void)knowns; (void)nKnowns; (void)seed; (void)nSeed;
    (void)sensitivity; (void)nSensitivity;
    NOT_SUPPORTED(fmi3GetAdjointDerivative);
}

fmi3Status fmi3EnterConfigurationMode(fmi3Instance instance) {
    NOT_SUPPORTED(fmi3EnterConfigurationMode);
}

fmi3Status fmi3ExitConfigurationMode(fmi3Instance instance) {
    NOT_SUPPORTED(fmi3ExitConfigurationMode);
}

fmi3Status fmi3GetIntervalDecimal(fmi3Instance instance, const fmi3ValueReference valueReferences[],
                                  size_t nValueReferences, fmi3Float64 intervals[],
                                  fmi3IntervalQualifier qualifiers[]) {
    (void)valueReferences; (void)nValueReferences; (void)intervals; (void)qualifiers;
    NOT_SUPPORTED(fmi3GetIntervalDecimal);
}

fmi3Status fmi3GetIntervalFraction(fmi3Instance instance,
                                   const fmi3ValueReference valueReferences[],
                                   size_t nValueReferences, fmi3UInt64 counters[],
                                   fmi3UInt64 resolutions[], fmi3IntervalQualifier qualifiers[]) {
    (void)valueReferences; (void)nValueReferences; (void)counters; (void)resolutions;
    (void)qualifiers;
    NOT_SUPPORTED(fmi3GetIntervalFraction);
}

fmi3Status fmi3GetShiftDecimal(fmi3Instance instance, const fmi3ValueReference valueReferences[],
                               size_t nValueReferences, fmi3Float64 shifts[]) {
    (void)valueReferences; (void)nValueReferences; (void)shifts;
    NOT_SUPPORTED(fmi3GetShiftDecimal);
}

fmi3Status fmi3GetShiftFraction(fmi3Instance instance, const fmi3ValueReference valueReferences[],
                                size_t nValueReferences, fmi3UInt64 counters[],
                                fmi3UInt64 resolutions[]) {
    (void)valueReferences; (void)nValueReferences; (void)counters; (void)resolutions;
    NOT_SUPPORTED(fmi3GetShiftFraction);
}

fmi3Status fmi3SetIntervalDecimal(fmi3Instance instance, const fmi3ValueReference valueReferences[],
                                  size_t nValueReferences, const fmi3Float64 intervals[]) {
    (void)valueReferences; (void)nValueReferences; (void)intervals;
    NOT_SUPPORTED(fmi3SetIntervalDecimal);
}

fmi3Status fmi3SetIntervalFraction(fmi3Instance instance,
                                   const fmi3ValueReference valueReferences[],
                                   size_t nValueReferences, const fmi3UInt64 counters[],
                                   const fmi3UInt64 resolutions[]) {
    (void)valueReferences; (void)nValueReferences; (void)counters; (void)resolutions;
    NOT_SUPPORTED(fmi3SetIntervalFraction);
}

fmi3Status fmi3SetShiftDecimal(fmi3Instance instance, const fmi3ValueReference valueReferences[],
                               size_t nValueReferences, const fmi3Float64 shifts[]) {
    (void)valueReferences; (void)nValueReferences; (void)shifts;
    NOT_SUPPORTED(fmi3SetShiftDecimal);
}

fmi3Status fmi3SetShiftFraction(fmi3Instance instance, const fmi3ValueReference valueReferences[],
                                size_t nValueReferences, const fmi3UInt64 counters[],
                                const fmi3UInt64 resolutions[]) {
    (void)valueReferences; (void)nValueReferences; (void)counters; (void)resolutions;
    NOT_SUPPORTED(fmi3SetShiftFraction);
}

fmi3Status fmi3EvaluateDiscreteStates(fmi3Instance instance) {
    NOT_SUPPORTED(fmi3EvaluateDiscreteStates);
}

fmi3Status fmi3UpdateDiscreteStates(fmi3Instance instance, fmi3Boolean *discreteStatesNeedUpdate,
                                    fmi3Boolean *terminateSimulation,
                                    fmi3Boolean *nominalsOfContinuousStatesChanged,
                                    fmi3Boolean *valuesOfContinuousStatesChanged,
                                    fmi3Boolean *nextEventTimeDefined,
                                    fmi3Float64 *nextEventTime) {
    (void)discreteStatesNeedUpdate; (void)terminateSimulation;
    (void)nominalsOfContinuousStatesChanged; (void)valuesOfContinuousStatesChanged;
    (void)nextEventTimeDefined; (void)nextEventTime;
    NOT_SUPPORTED(fmi3UpdateDiscreteStates);
}

fmi3Status fmi3EnterContinuousTimeMode(fmi3Instance instance) {
    NOT_SUPPORTED(fmi3EnterContinuousTimeMode);
}

fmi3Status fmi3CompletedIntegratorStep(fmi3Instance instance,
                                       fmi3Boolean noSetFMUStatePriorToCurrentPoint,
                                       fmi3Boolean *enterEventMode,
                                       fmi3Boolean *terminateSimulation) {
    (void)noSetFMUStatePriorToCurrentPoint; (void)enterEventMode; (void)terminateSimulation;
    NOT_SUPPORTED(fmi3CompletedIntegratorStep);
}

fmi3Status fmi3SetTime(fmi3Instance instance, fmi3Float64 time) {
    (void)time;
    NOT_SUPPORTED(fmi3SetTime);
}

fmi3Status fmi3SetContinuousStates(fmi3Instance instance, const fmi3Float64 continuousStates[],
                                   size_t nContinuousStates) {
    (void)continuousStates; (void)nContinuousStates;
    NOT_SUPPORTED(fmi3SetContinuousStates);
}

fmi3Status fmi3GetContinuousStateDerivatives(fmi3Instance instance, fmi3Float64 derivatives[],
                                             size_t nContinuousStates) {
    (void)derivatives; (void)nContinuousStates;
    NOT_SUPPORTED(fmi3GetContinuousStateDerivatives);
}

fmi3Status fmi3GetEventIndicators(fmi3Instance instance, fmi3Float64 eventIndicators[],
                                  size_t nEventIndicators) {
    (void)eventIndicators; (void)nEventIndicators;
    NOT_SUPPORTED(fmi3GetEventIndicators);
}

fmi3Status fmi3GetContinuousStates(fmi3Instance instance, fmi3Float64 continuousStates[],
                                   size_t nContinuousStates) {
    (void)continuousStates; (void)nContinuousStates;
    NOT_SUPPORTED(fmi3GetContinuousStates);
}

fmi3Status fmi3GetNominalsOfContinuousStates(fmi3Instance instance, fmi3Float64 nominals[],
                                             size_t nContinuousStates) {
    (void)nominals; (void)nContinuousStates;
    NOT_SUPPORTED(fmi3GetNominalsOfContinuousStates);
}

fmi3Status fmi3GetNumberOfEventIndicators(fmi3Instance instance, size_t *nEventIndicators) {
    (void)nEventIndicators;
    NOT_SUPPORTED(fmi3GetNumberOfEventIndicators);
}

fmi3Status fmi3GetNumberOfContinuousStates(fmi3Instance instance, size_t *nContinuousStates) {
    (void)nContinuousStates;
    NOT_SUPPORTED(fmi3GetNumberOfContinuousStates);
}

fmi3Status fmi3EnterStepMode(fmi3Instance instance) { NOT_SUPPORTED(fmi3EnterStepMode); }

fmi3Status fmi3GetOutputDerivatives(fmi3Instance instance, const fmi3ValueReference valueReferences[],
                                    size_t nValueReferences, const fmi3Int32 orders[],
                                    fmi3Float64 values[], size_t nValues) {
    (void)valueReferences; (void)nValueReferences; (void)orders; (void)values; (void)nValues;
    NOT_SUPPORTED(fmi3GetOutputDerivatives);
}

fmi3Status fmi3DoStep(fmi3Instance instance, fmi3Float64 currentCommunicationPoint,
                      fmi3Float64 communicationStepSize,
                      fmi3Boolean noSetFMUStatePriorToCurrentPoint,
                      fmi3Boolean *eventHandlingNeeded, fmi3Boolean *terminateSimulation,
                      fmi3Boolean *earlyReturn, fmi3Float64 *lastSuccessfulTime) {
    (void)noSetFMUStatePriorToCurrentPoint;
    ModelInstance *comp = (ModelInstance *)instance;
    if (invalidState(comp, "fmi3DoStep", StepMode)) return fmi3Error;
    Status status = doFixedStep(comp, currentCommunicationPoint, communicationStepSize);
    if (eventHandlingNeeded) *eventHandlingNeeded = fmi3False;
    if (terminateSimulation) *terminateSimulation = fmi3False;
    if (earlyReturn) *earlyReturn = fmi3False;
    if (lastSuccessfulTime) *lastSuccessfulTime = comp->time;
    return (fmi3Status)status;
}

fmi3Status fmi3ActivateModelPartition(fmi3Instance instance, fmi3ValueReference clockReference,
                                      fmi3Float64 activationTime) {
    (void)clockReference; (void)activationTime;
    NOT_SUPPORTED(fmi3ActivateModelPartition);
}
