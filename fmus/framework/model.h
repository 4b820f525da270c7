/* Shared FMU framework: the contract between the FMI glue (fmi2Functions.c, fmi3Functions.c,
 * cosimulation.c) and one model (config.h + model.c). Models never edit the framework.
 *
 * The model integrates its continuous states on a fixed grid t = startTime + nSteps * h.
 * Discrete quantities (held inputs, noise samples) are held over one grid interval. A
 * communication point that falls between grid points is served by one partial RK4 step from
 * the last grid state into the separate output state y; the grid state x is never moved off
 * the grid, so time is never accumulated.
 */
#ifndef FMUS_FRAMEWORK_MODEL_H
#define FMUS_FRAMEWORK_MODEL_H

#include <stdbool.h>
#include <stddef.h>
#include <stdint.h>

#include "config.h"

typedef enum { OK, Warning, Discard, Error, Fatal } Status;

typedef enum {
    StartAndEnd = 1 << 0,
    Instantiated = 1 << 1,
    InitializationMode = 1 << 2,
    StepMode = 1 << 3,
    Terminated = 1 << 4
} ModelState;

typedef struct ModelInstance ModelInstance;

typedef void (*LogFunction)(const ModelInstance *comp, Status status, const char *category,
                            const char *message);

struct ModelInstance {
    char *instanceName;
    ModelState state;
    int fmiVersion;
    void *environment;
    void *logger;
    LogFunction log;
    bool loggingOn;
    bool isDirtyValues;
    double startTime;
    long long nSteps;
    double time;
    double x[NX];
    double y[NX];
    ModelData data;
};

/* Implemented by the model (model.c). */
void setStartValues(ModelInstance *comp);
Status validateParameters(ModelInstance *comp);
Status initializeModel(ModelInstance *comp);
double internalStepSize(const ModelInstance *comp);
void prepareInterval(ModelInstance *comp, double h);
void getDerivatives(const ModelInstance *comp, const double x[NX], double dx[NX]);
void commitInterval(ModelInstance *comp, double h);
void calculateValues(ModelInstance *comp);
Status getFloat64(ModelInstance *comp, ValueReference vr, double values[], size_t nValues,
                  size_t *index);
Status setFloat64(ModelInstance *comp, ValueReference vr, const double values[], size_t nValues,
                  size_t *index);
Status getInt32(ModelInstance *comp, ValueReference vr, int32_t values[], size_t nValues,
                size_t *index);
Status setInt32(ModelInstance *comp, ValueReference vr, const int32_t values[], size_t nValues,
                size_t *index);

/* Implemented by the framework (cosimulation.c). */
ModelInstance *createModelInstance(const char *instanceName, int fmiVersion, void *environment,
                                   void *logger, LogFunction log, bool loggingOn);
void freeModelInstance(ModelInstance *comp);
void resetModelInstance(ModelInstance *comp);
Status enterInitialization(ModelInstance *comp, double startTime);
Status exitInitialization(ModelInstance *comp);
Status doFixedStep(ModelInstance *comp, double currentCommunicationPoint,
                   double communicationStepSize);
bool invalidState(ModelInstance *comp, const char *function, int allowedStates);
void logEvent(const ModelInstance *comp, const char *format, ...);
void logError(const ModelInstance *comp, const char *format, ...);

#endif
