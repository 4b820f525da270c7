/* Instance life cycle, logging and the fixed-grid RK4 co-simulation step shared by all models. */
#include <math.h>
#include <stdarg.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "model.h"

#define MESSAGE_BUFFER_SIZE 1024
#define GRID_TOLERANCE 1e-9

static const char *stateName(ModelState state) {
    switch (state) {
    case StartAndEnd: return "StartAndEnd";
    case Instantiated: return "Instantiated";
    case InitializationMode: return "InitializationMode";
    case StepMode: return "StepMode";
    case Terminated: return "Terminated";
    default: return "Unknown";
    }
}

static void logMessage(const ModelInstance *comp, Status status, const char *category,
                       const char *format, va_list args) {
    if (!comp || !comp->log) {
        return;
    }
    char message[MESSAGE_BUFFER_SIZE];
    vsnprintf(message, sizeof(message), format, args);
    comp->log(comp, status, category, message);
}

void logEvent(const ModelInstance *comp, const char *format, ...) {
    if (!comp || !comp->loggingOn) {
        return;
    }
    va_list args;
    va_start(args, format);
    logMessage(comp, OK, "logEvents", format, args);
    va_end(args);
}

void logError(const ModelInstance *comp, const char *format, ...) {
    va_list args;
    va_start(args, format);
    logMessage(comp, Error, "logStatusError", format, args);
    va_end(args);
}

bool invalidState(ModelInstance *comp, const char *function, int allowedStates) {
    if (!comp) {
        return true;
    }
    if (!(comp->state & allowedStates)) {
        logError(comp, "%s must not be called in state %s.", function, stateName(comp->state));
        return true;
    }
    return false;
}

ModelInstance *createModelInstance(const char *instanceName, int fmiVersion, void *environment,
                                   void *logger, LogFunction log, bool loggingOn) {
    ModelInstance *comp = calloc(1, sizeof(ModelInstance));
    if (!comp) {
        return NULL;
    }
    const char *name = instanceName ? instanceName : "instance";
    comp->instanceName = malloc(strlen(name) + 1);
    if (!comp->instanceName) {
        free(comp);
        return NULL;
    }
    strcpy(comp->instanceName, name);
    comp->fmiVersion = fmiVersion;
    comp->environment = environment;
    comp->logger = logger;
    comp->log = log;
    comp->loggingOn = loggingOn;
    resetModelInstance(comp);
    return comp;
}

void freeModelInstance(ModelInstance *comp) {
    if (!comp) {
        return;
    }
    free(comp->instanceName);
    free(comp);
}

void resetModelInstance(ModelInstance *comp) {
    comp->state = Instantiated;
    comp->startTime = 0.0;
    comp->time = 0.0;
    comp->nSteps = 0;
    memset(comp->x, 0, sizeof(comp->x));
    memset(comp->y, 0, sizeof(comp->y));
    memset(&comp->data, 0, sizeof(comp->data));
    setStartValues(comp);
    comp->isDirtyValues = true;
}

Status enterInitialization(ModelInstance *comp, double startTime) {
    if (!isfinite(startTime)) {
        logError(comp, "startTime = %g must be finite.", startTime);
        return Error;
    }
    comp->startTime = startTime;
    comp->time = startTime;
    comp->nSteps = 0;
    comp->state = InitializationMode;
    return OK;
}

Status exitInitialization(ModelInstance *comp) {
    Status status = validateParameters(comp);
    if (status > Warning) {
        return status;
    }
    status = initializeModel(comp);
    if (status > Warning) {
        return status;
    }
    memcpy(comp->y, comp->x, sizeof(comp->x));
    prepareInterval(comp, internalStepSize(comp));
    calculateValues(comp);
    comp->state = StepMode;
    return OK;
}

static void rk4(ModelInstance *comp, const double x[NX], double h, double out[NX]) {
    double k1[NX], k2[NX], k3[NX], k4[NX], tmp[NX];
    getDerivatives(comp, x, k1);
    for (int i = 0; i < NX; i++) tmp[i] = x[i] + 0.5 * h * k1[i];
    getDerivatives(comp, tmp, k2);
    for (int i = 0; i < NX; i++) tmp[i] = x[i] + 0.5 * h * k2[i];
    getDerivatives(comp, tmp, k3);
    for (int i = 0; i < NX; i++) tmp[i] = x[i] + h * k3[i];
    getDerivatives(comp, tmp, k4);
    for (int i = 0; i < NX; i++) out[i] = x[i] + h / 6.0 * (k1[i] + 2.0 * k2[i] + 2.0 * k3[i] + k4[i]);
}

Status doFixedStep(ModelInstance *comp, double currentCommunicationPoint,
                   double communicationStepSize) {
    if (!(communicationStepSize > 0.0) || !isfinite(communicationStepSize)) {
        logError(comp, "DoStep: communicationStepSize = %g must be positive and finite.",
                 communicationStepSize);
        return Error;
    }
    const double tolerance = GRID_TOLERANCE * fmax(1.0, fabs(comp->time));
    if (!isfinite(currentCommunicationPoint) ||
        fabs(currentCommunicationPoint - comp->time) > tolerance) {
        logError(comp, "DoStep: currentCommunicationPoint = %.17g does not match the FMU time %.17g.",
                 currentCommunicationPoint, comp->time);
        return Error;
    }
    const double h = internalStepSize(comp);
    const double target = currentCommunicationPoint + communicationStepSize;
    const long long nTarget = (long long)floor((target - comp->startTime) / h + GRID_TOLERANCE);
    while (comp->nSteps < nTarget) {
        prepareInterval(comp, h);
        rk4(comp, comp->x, h, comp->x);
        commitInterval(comp, h);
        comp->nSteps++;
    }
    const double remainder = target - (comp->startTime + (double)comp->nSteps * h);
    prepareInterval(comp, h);
    if (remainder > GRID_TOLERANCE * h) {
        rk4(comp, comp->x, remainder, comp->y);
    } else {
        memcpy(comp->y, comp->x, sizeof(comp->x));
    }
    for (int i = 0; i < NX; i++) {
        if (!isfinite(comp->y[i])) {
            logError(comp, "DoStep: state %d became %g at t = %.17g.", i, comp->y[i], target);
            return Error;
        }
    }
    comp->time = target;
    calculateValues(comp);
    return OK;
}
