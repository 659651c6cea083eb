/* FMI 3.0 interface (Co-Simulation and Model Exchange) of a generated network FMU.
 *
 * A thin layer over the FMI 2.0 functions of prc_fmi2.c, compiled under
 * internal names (PRC_FMI3): the same network assembly, exact ZOH steps,
 * PRBS time events, checks, FMU states and directional derivatives.
 *
 * Value references: FMI 3.0 numbers all variables in one space. Float64
 * variables keep their FMI 2.0 Real value reference r; Int32 variables get
 * n_real + i for FMI 2.0 Integer reference i; the independent variable time
 * is n_real + n_int.
 */
#include <stdarg.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "prc_fmi2.h"
#include "prc_model.h"

#include "fmi3Functions.h"

#define MSG_LEN 1024

typedef struct {
    fmi2Component inner;
    fmi3InstanceEnvironment env;
    fmi3LogMessageCallback log;
    char name[128];
} prc3_inst;

static void logger2(fmi2ComponentEnvironment env, fmi2String name, fmi2Status status, fmi2String category,
                    fmi2String fmt, ...) {
    prc3_inst *w = (prc3_inst *)env;
    char buf[MSG_LEN];
    va_list ap;
    (void)name;
    if (!w || !w->log) return;
    va_start(ap, fmt);
    vsnprintf(buf, sizeof buf, fmt, ap);
    va_end(ap);
    w->log(w->env, (fmi3Status)status, category, buf);
}

static void *calloc2(size_t n, size_t size) { return calloc(n, size); }

static fmi3Status st(fmi2Status s) { return (fmi3Status)s; }

static fmi2Component in(fmi3Instance instance) { return instance ? ((prc3_inst *)instance)->inner : NULL; }

static void say(fmi3Instance instance, const char *fmt, ...) {
    prc3_inst *w = (prc3_inst *)instance;
    char buf[MSG_LEN];
    va_list ap;
    if (!w || !w->log) return;
    va_start(ap, fmt);
    vsnprintf(buf, sizeof buf, fmt, ap);
    va_end(ap);
    w->log(w->env, fmi3Error, "logStatusError", buf);
}

static fmi3Instance instantiate(fmi3String name, fmi3String token, fmi2Type type, fmi3Boolean loggingOn,
                                fmi3InstanceEnvironment env, fmi3LogMessageCallback log) {
    prc3_inst *w = (prc3_inst *)calloc(1, sizeof(prc3_inst));
    fmi2CallbackFunctions cb;
    if (!w) return NULL;
    w->env = env;
    w->log = log;
    snprintf(w->name, sizeof w->name, "%s", name ? name : "");
    cb.logger = logger2;
    cb.allocateMemory = calloc2;
    cb.freeMemory = free;
    cb.stepFinished = NULL;
    cb.componentEnvironment = w;
    /* the FMI 2.0 layer keeps a copy of the callbacks */
    w->inner = prc2_fmi2Instantiate(name, type, token, "", &cb, fmi2False, loggingOn);
    if (!w->inner) {
        free(w);
        return NULL;
    }
    return w;
}

/* ------------------------------------------------------------------ common functions */

const char *fmi3GetVersion(void) { return fmi3Version; }

fmi3Status fmi3SetDebugLogging(fmi3Instance instance, fmi3Boolean loggingOn, size_t nCategories,
                               const fmi3String categories[]) {
    return st(prc2_fmi2SetDebugLogging(in(instance), loggingOn, nCategories, categories));
}

fmi3Instance fmi3InstantiateModelExchange(fmi3String instanceName, fmi3String instantiationToken,
                                          fmi3String resourcePath, fmi3Boolean visible, fmi3Boolean loggingOn,
                                          fmi3InstanceEnvironment instanceEnvironment,
                                          fmi3LogMessageCallback logMessage) {
    (void)resourcePath; (void)visible;
    return instantiate(instanceName, instantiationToken, fmi2ModelExchange, loggingOn, instanceEnvironment,
                       logMessage);
}

fmi3Instance fmi3InstantiateCoSimulation(fmi3String instanceName, fmi3String instantiationToken,
                                         fmi3String resourcePath, fmi3Boolean visible, fmi3Boolean loggingOn,
                                         fmi3Boolean eventModeUsed, fmi3Boolean earlyReturnAllowed,
                                         const fmi3ValueReference requiredIntermediateVariables[],
                                         size_t nRequiredIntermediateVariables,
                                         fmi3InstanceEnvironment instanceEnvironment,
                                         fmi3LogMessageCallback logMessage,
                                         fmi3IntermediateUpdateCallback intermediateUpdate) {
    (void)resourcePath; (void)visible; (void)earlyReturnAllowed; (void)requiredIntermediateVariables;
    (void)nRequiredIntermediateVariables; (void)intermediateUpdate;
    if (eventModeUsed) {
        if (logMessage) logMessage(instanceEnvironment, fmi3Error, "logStatusError",
                                   "fmi3InstantiateCoSimulation: event mode is not supported (hasEventMode=false)");
        return NULL;
    }
    return instantiate(instanceName, instantiationToken, fmi2CoSimulation, loggingOn, instanceEnvironment,
                       logMessage);
}

fmi3Instance fmi3InstantiateScheduledExecution(fmi3String instanceName, fmi3String instantiationToken,
                                               fmi3String resourcePath, fmi3Boolean visible, fmi3Boolean loggingOn,
                                               fmi3InstanceEnvironment instanceEnvironment,
                                               fmi3LogMessageCallback logMessage, fmi3ClockUpdateCallback clockUpdate,
                                               fmi3LockPreemptionCallback lockPreemption,
                                               fmi3UnlockPreemptionCallback unlockPreemption) {
    (void)instanceName; (void)instantiationToken; (void)resourcePath; (void)visible; (void)loggingOn;
    (void)clockUpdate; (void)lockPreemption; (void)unlockPreemption;
    if (logMessage) logMessage(instanceEnvironment, fmi3Error, "logStatusError",
                               "fmi3InstantiateScheduledExecution: scheduled execution is not supported");
    return NULL;
}

void fmi3FreeInstance(fmi3Instance instance) {
    prc3_inst *w = (prc3_inst *)instance;
    if (!w) return;
    prc2_fmi2FreeInstance(w->inner);
    free(w);
}

fmi3Status fmi3EnterInitializationMode(fmi3Instance instance, fmi3Boolean toleranceDefined, fmi3Float64 tolerance,
                                       fmi3Float64 startTime, fmi3Boolean stopTimeDefined, fmi3Float64 stopTime) {
    fmi2Status s = prc2_fmi2SetupExperiment(in(instance), toleranceDefined, tolerance, startTime, stopTimeDefined,
                                            stopTime);
    if (s != fmi2OK) return st(s);
    return st(prc2_fmi2EnterInitializationMode(in(instance)));
}

fmi3Status fmi3ExitInitializationMode(fmi3Instance instance) {
    return st(prc2_fmi2ExitInitializationMode(in(instance)));
}

fmi3Status fmi3EnterEventMode(fmi3Instance instance) { return st(prc2_fmi2EnterEventMode(in(instance))); }

fmi3Status fmi3Terminate(fmi3Instance instance) { return st(prc2_fmi2Terminate(in(instance))); }

fmi3Status fmi3Reset(fmi3Instance instance) { return st(prc2_fmi2Reset(in(instance))); }

/* ------------------------------------------------------------------ getting and setting values */

static const int TIME_VR_OFFSET = 0;

static int time_vr(void) { return PRC_MODEL.n_real + PRC_MODEL.n_int + TIME_VR_OFFSET; }

fmi3Status fmi3GetFloat64(fmi3Instance instance, const fmi3ValueReference valueReferences[],
                          size_t nValueReferences, fmi3Float64 values[], size_t nValues) {
    size_t i;
    if (!instance) return fmi3Error;
    if (nValues != nValueReferences) {
        say(instance, "fmi3GetFloat64: %lu values for %lu value references", (unsigned long)nValues,
            (unsigned long)nValueReferences);
        return fmi3Error;
    }
    for (i = 0; i < nValueReferences; i++) {
        fmi2ValueReference vr = valueReferences[i];
        if ((int)vr == time_vr()) {
            values[i] = prc2_time(in(instance));
        } else {
            fmi2Status s = prc2_fmi2GetReal(in(instance), &vr, 1, &values[i]);
            if (s != fmi2OK) return st(s);
        }
    }
    return fmi3OK;
}

fmi3Status fmi3SetFloat64(fmi3Instance instance, const fmi3ValueReference valueReferences[],
                          size_t nValueReferences, const fmi3Float64 values[], size_t nValues) {
    if (!instance) return fmi3Error;
    if (nValues != nValueReferences) {
        say(instance, "fmi3SetFloat64: %lu values for %lu value references", (unsigned long)nValues,
            (unsigned long)nValueReferences);
        return fmi3Error;
    }
    return st(prc2_fmi2SetReal(in(instance), valueReferences, nValueReferences, values));
}

fmi3Status fmi3GetInt32(fmi3Instance instance, const fmi3ValueReference valueReferences[], size_t nValueReferences,
                        fmi3Int32 values[], size_t nValues) {
    size_t i;
    if (!instance || nValues != nValueReferences) return fmi3Error;
    for (i = 0; i < nValueReferences; i++) {
        fmi2ValueReference vr = valueReferences[i] - (fmi2ValueReference)PRC_MODEL.n_real;
        fmi2Integer v;
        fmi2Status s;
        if ((int)valueReferences[i] < PRC_MODEL.n_real) {
            say(instance, "fmi3GetInt32: value reference %u is no Int32 variable", valueReferences[i]);
            return fmi3Error;
        }
        s = prc2_fmi2GetInteger(in(instance), &vr, 1, &v);
        if (s != fmi2OK) return st(s);
        values[i] = v;
    }
    return fmi3OK;
}

fmi3Status fmi3SetInt32(fmi3Instance instance, const fmi3ValueReference valueReferences[], size_t nValueReferences,
                        const fmi3Int32 values[], size_t nValues) {
    size_t i;
    if (!instance || nValues != nValueReferences) return fmi3Error;
    for (i = 0; i < nValueReferences; i++) {
        fmi2ValueReference vr = valueReferences[i] - (fmi2ValueReference)PRC_MODEL.n_real;
        fmi2Integer v = values[i];
        fmi2Status s;
        if ((int)valueReferences[i] < PRC_MODEL.n_real) {
            say(instance, "fmi3SetInt32: value reference %u is no Int32 variable", valueReferences[i]);
            return fmi3Error;
        }
        s = prc2_fmi2SetInteger(in(instance), &vr, 1, &v);
        if (s != fmi2OK) return st(s);
    }
    return fmi3OK;
}

#define NO_SUCH_TYPE(fn, T, CONST)                                                                              \
    fmi3Status fn(fmi3Instance instance, const fmi3ValueReference valueReferences[], size_t nValueReferences,    \
                  CONST T values[], size_t nValues) {                                                           \
        (void)valueReferences; (void)values; (void)nValues;                                                     \
        if (nValueReferences == 0) return fmi3OK;                                                               \
        say(instance, "%s: the FMU has no variables of this type (value reference %u)", #fn, valueReferences[0]); \
        return fmi3Error;                                                                                        \
    }

NO_SUCH_TYPE(fmi3GetFloat32, fmi3Float32, )
NO_SUCH_TYPE(fmi3GetInt8, fmi3Int8, )
NO_SUCH_TYPE(fmi3GetUInt8, fmi3UInt8, )
NO_SUCH_TYPE(fmi3GetInt16, fmi3Int16, )
NO_SUCH_TYPE(fmi3GetUInt16, fmi3UInt16, )
NO_SUCH_TYPE(fmi3GetUInt32, fmi3UInt32, )
NO_SUCH_TYPE(fmi3GetInt64, fmi3Int64, )
NO_SUCH_TYPE(fmi3GetUInt64, fmi3UInt64, )
NO_SUCH_TYPE(fmi3GetBoolean, fmi3Boolean, )
NO_SUCH_TYPE(fmi3GetString, fmi3String, )
NO_SUCH_TYPE(fmi3SetFloat32, fmi3Float32, const)
NO_SUCH_TYPE(fmi3SetInt8, fmi3Int8, const)
NO_SUCH_TYPE(fmi3SetUInt8, fmi3UInt8, const)
NO_SUCH_TYPE(fmi3SetInt16, fmi3Int16, const)
NO_SUCH_TYPE(fmi3SetUInt16, fmi3UInt16, const)
NO_SUCH_TYPE(fmi3SetUInt32, fmi3UInt32, const)
NO_SUCH_TYPE(fmi3SetInt64, fmi3Int64, const)
NO_SUCH_TYPE(fmi3SetUInt64, fmi3UInt64, const)
NO_SUCH_TYPE(fmi3SetBoolean, fmi3Boolean, const)
NO_SUCH_TYPE(fmi3SetString, fmi3String, const)

fmi3Status fmi3GetBinary(fmi3Instance instance, const fmi3ValueReference valueReferences[], size_t nValueReferences,
                         size_t valueSizes[], fmi3Binary values[], size_t nValues) {
    (void)valueReferences; (void)valueSizes; (void)values; (void)nValues;
    if (nValueReferences == 0) return fmi3OK;
    say(instance, "fmi3GetBinary: the FMU has no Binary variables");
    return fmi3Error;
}

fmi3Status fmi3SetBinary(fmi3Instance instance, const fmi3ValueReference valueReferences[], size_t nValueReferences,
                         const size_t valueSizes[], const fmi3Binary values[], size_t nValues) {
    (void)valueReferences; (void)valueSizes; (void)values; (void)nValues;
    if (nValueReferences == 0) return fmi3OK;
    say(instance, "fmi3SetBinary: the FMU has no Binary variables");
    return fmi3Error;
}

fmi3Status fmi3GetClock(fmi3Instance instance, const fmi3ValueReference valueReferences[], size_t nValueReferences,
                        fmi3Clock values[]) {
    (void)valueReferences; (void)values;
    if (nValueReferences == 0) return fmi3OK;
    say(instance, "fmi3GetClock: the FMU has no clocks");
    return fmi3Error;
}

fmi3Status fmi3SetClock(fmi3Instance instance, const fmi3ValueReference valueReferences[], size_t nValueReferences,
                        const fmi3Clock values[]) {
    (void)valueReferences; (void)values;
    if (nValueReferences == 0) return fmi3OK;
    say(instance, "fmi3SetClock: the FMU has no clocks");
    return fmi3Error;
}

/* ------------------------------------------------------------------ dependencies, states, derivatives */

fmi3Status fmi3GetNumberOfVariableDependencies(fmi3Instance instance, fmi3ValueReference valueReference,
                                               size_t *nDependencies) {
    (void)valueReference; (void)nDependencies;
    say(instance, "fmi3GetNumberOfVariableDependencies: dependencies are given in the model description");
    return fmi3Error;
}

fmi3Status fmi3GetVariableDependencies(fmi3Instance instance, fmi3ValueReference dependent,
                                       size_t elementIndicesOfDependent[], fmi3ValueReference independents[],
                                       size_t elementIndicesOfIndependents[], fmi3DependencyKind dependencyKinds[],
                                       size_t nDependencies) {
    (void)dependent; (void)elementIndicesOfDependent; (void)independents; (void)elementIndicesOfIndependents;
    (void)dependencyKinds; (void)nDependencies;
    say(instance, "fmi3GetVariableDependencies: dependencies are given in the model description");
    return fmi3Error;
}

fmi3Status fmi3GetFMUState(fmi3Instance instance, fmi3FMUState *FMUState) {
    return st(prc2_fmi2GetFMUstate(in(instance), FMUState));
}

fmi3Status fmi3SetFMUState(fmi3Instance instance, fmi3FMUState FMUState) {
    return st(prc2_fmi2SetFMUstate(in(instance), FMUState));
}

fmi3Status fmi3FreeFMUState(fmi3Instance instance, fmi3FMUState *FMUState) {
    return st(prc2_fmi2FreeFMUstate(in(instance), FMUState));
}

fmi3Status fmi3SerializedFMUStateSize(fmi3Instance instance, fmi3FMUState FMUState, size_t *size) {
    return st(prc2_fmi2SerializedFMUstateSize(in(instance), FMUState, size));
}

fmi3Status fmi3SerializeFMUState(fmi3Instance instance, fmi3FMUState FMUState, fmi3Byte serializedState[],
                                 size_t size) {
    return st(prc2_fmi2SerializeFMUstate(in(instance), FMUState, (fmi2Byte *)serializedState, size));
}

fmi3Status fmi3DeserializeFMUState(fmi3Instance instance, const fmi3Byte serializedState[], size_t size,
                                   fmi3FMUState *FMUState) {
    return st(prc2_fmi2DeSerializeFMUstate(in(instance), (const fmi2Byte *)serializedState, size, FMUState));
}

fmi3Status fmi3GetDirectionalDerivative(fmi3Instance instance, const fmi3ValueReference unknowns[], size_t nUnknowns,
                                        const fmi3ValueReference knowns[], size_t nKnowns, const fmi3Float64 seed[],
                                        size_t nSeed, fmi3Float64 sensitivity[], size_t nSensitivity) {
    if (nSeed != nKnowns || nSensitivity != nUnknowns) {
        say(instance, "fmi3GetDirectionalDerivative: array sizes do not match (scalar variables only)");
        return fmi3Error;
    }
    return st(prc2_fmi2GetDirectionalDerivative(in(instance), unknowns, nUnknowns, knowns, nKnowns, seed,
                                                sensitivity));
}

fmi3Status fmi3GetAdjointDerivative(fmi3Instance instance, const fmi3ValueReference unknowns[], size_t nUnknowns,
                                    const fmi3ValueReference knowns[], size_t nKnowns, const fmi3Float64 seed[],
                                    size_t nSeed, fmi3Float64 sensitivity[], size_t nSensitivity) {
    (void)unknowns; (void)nUnknowns; (void)knowns; (void)nKnowns; (void)seed; (void)nSeed; (void)sensitivity;
    (void)nSensitivity;
    say(instance, "fmi3GetAdjointDerivative: not provided (providesAdjointDerivatives=false)");
    return fmi3Error;
}

fmi3Status fmi3EnterConfigurationMode(fmi3Instance instance) {
    say(instance, "fmi3EnterConfigurationMode: the FMU has no structural parameters");
    return fmi3Error;
}

fmi3Status fmi3ExitConfigurationMode(fmi3Instance instance) {
    say(instance, "fmi3ExitConfigurationMode: the FMU has no structural parameters");
    return fmi3Error;
}

#define NO_CLOCKS(fn, ...)                                                    \
    fmi3Status fn(fmi3Instance instance, __VA_ARGS__) {                       \
        say(instance, "%s: the FMU has no clocks", #fn);                      \
        return fmi3Error;                                                     \
    }

NO_CLOCKS(fmi3GetIntervalDecimal, const fmi3ValueReference v[], size_t n, fmi3Float64 i[],
          fmi3IntervalQualifier q[])
NO_CLOCKS(fmi3GetIntervalFraction, const fmi3ValueReference v[], size_t n, fmi3UInt64 c[], fmi3UInt64 r[],
          fmi3IntervalQualifier q[])
NO_CLOCKS(fmi3GetShiftDecimal, const fmi3ValueReference v[], size_t n, fmi3Float64 s[])
NO_CLOCKS(fmi3GetShiftFraction, const fmi3ValueReference v[], size_t n, fmi3UInt64 c[], fmi3UInt64 r[])
NO_CLOCKS(fmi3SetIntervalDecimal, const fmi3ValueReference v[], size_t n, const fmi3Float64 i[])
NO_CLOCKS(fmi3SetIntervalFraction, const fmi3ValueReference v[], size_t n, const fmi3UInt64 c[],
          const fmi3UInt64 r[])
NO_CLOCKS(fmi3SetShiftDecimal, const fmi3ValueReference v[], size_t n, const fmi3Float64 s[])
NO_CLOCKS(fmi3SetShiftFraction, const fmi3ValueReference v[], size_t n, const fmi3UInt64 c[], const fmi3UInt64 r[])

fmi3Status fmi3EvaluateDiscreteStates(fmi3Instance instance) { return instance ? fmi3OK : fmi3Error; }

fmi3Status fmi3UpdateDiscreteStates(fmi3Instance instance, fmi3Boolean *discreteStatesNeedUpdate,
                                    fmi3Boolean *terminateSimulation, fmi3Boolean *nominalsOfContinuousStatesChanged,
                                    fmi3Boolean *valuesOfContinuousStatesChanged, fmi3Boolean *nextEventTimeDefined,
                                    fmi3Float64 *nextEventTime) {
    fmi2EventInfo info;
    fmi2Status s;
    memset(&info, 0, sizeof info);
    s = prc2_fmi2NewDiscreteStates(in(instance), &info);
    if (s != fmi2OK) return st(s);
    *discreteStatesNeedUpdate = info.newDiscreteStatesNeeded ? fmi3True : fmi3False;
    *terminateSimulation = info.terminateSimulation ? fmi3True : fmi3False;
    *nominalsOfContinuousStatesChanged = info.nominalsOfContinuousStatesChanged ? fmi3True : fmi3False;
    *valuesOfContinuousStatesChanged = info.valuesOfContinuousStatesChanged ? fmi3True : fmi3False;
    *nextEventTimeDefined = info.nextEventTimeDefined ? fmi3True : fmi3False;
    *nextEventTime = info.nextEventTime;
    return fmi3OK;
}

/* ------------------------------------------------------------------ model exchange */

fmi3Status fmi3EnterContinuousTimeMode(fmi3Instance instance) {
    return st(prc2_fmi2EnterContinuousTimeMode(in(instance)));
}

fmi3Status fmi3CompletedIntegratorStep(fmi3Instance instance, fmi3Boolean noSetFMUStatePriorToCurrentPoint,
                                       fmi3Boolean *enterEventMode, fmi3Boolean *terminateSimulation) {
    fmi2Boolean e = fmi2False, t = fmi2False;
    fmi2Status s = prc2_fmi2CompletedIntegratorStep(in(instance), noSetFMUStatePriorToCurrentPoint, &e, &t);
    *enterEventMode = e ? fmi3True : fmi3False;
    *terminateSimulation = t ? fmi3True : fmi3False;
    return st(s);
}

fmi3Status fmi3SetTime(fmi3Instance instance, fmi3Float64 time) { return st(prc2_fmi2SetTime(in(instance), time)); }

fmi3Status fmi3SetContinuousStates(fmi3Instance instance, const fmi3Float64 continuousStates[],
                                   size_t nContinuousStates) {
    return st(prc2_fmi2SetContinuousStates(in(instance), continuousStates, nContinuousStates));
}

fmi3Status fmi3GetContinuousStateDerivatives(fmi3Instance instance, fmi3Float64 derivatives[],
                                             size_t nContinuousStates) {
    return st(prc2_fmi2GetDerivatives(in(instance), derivatives, nContinuousStates));
}

fmi3Status fmi3GetEventIndicators(fmi3Instance instance, fmi3Float64 eventIndicators[], size_t nEventIndicators) {
    return st(prc2_fmi2GetEventIndicators(in(instance), eventIndicators, nEventIndicators));
}

fmi3Status fmi3GetContinuousStates(fmi3Instance instance, fmi3Float64 continuousStates[],
                                   size_t nContinuousStates) {
    return st(prc2_fmi2GetContinuousStates(in(instance), continuousStates, nContinuousStates));
}

fmi3Status fmi3GetNominalsOfContinuousStates(fmi3Instance instance, fmi3Float64 nominals[],
                                             size_t nContinuousStates) {
    return st(prc2_fmi2GetNominalsOfContinuousStates(in(instance), nominals, nContinuousStates));
}

fmi3Status fmi3GetNumberOfEventIndicators(fmi3Instance instance, size_t *nEventIndicators) {
    if (!instance) return fmi3Error;
    *nEventIndicators = 0;
    return fmi3OK;
}

fmi3Status fmi3GetNumberOfContinuousStates(fmi3Instance instance, size_t *nContinuousStates) {
    if (!instance) return fmi3Error;
    *nContinuousStates = (size_t)(PRC_MODEL.n_q1 + PRC_MODEL.n_l);
    return fmi3OK;
}

/* ------------------------------------------------------------------ co-simulation */

fmi3Status fmi3EnterStepMode(fmi3Instance instance) { return instance ? fmi3OK : fmi3Error; }

fmi3Status fmi3GetOutputDerivatives(fmi3Instance instance, const fmi3ValueReference valueReferences[],
                                    size_t nValueReferences, const fmi3Int32 orders[], fmi3Float64 values[],
                                    size_t nValues) {
    (void)valueReferences; (void)nValueReferences; (void)orders; (void)values; (void)nValues;
    say(instance, "fmi3GetOutputDerivatives: not provided (maxOutputDerivativeOrder=0)");
    return fmi3Error;
}

fmi3Status fmi3DoStep(fmi3Instance instance, fmi3Float64 currentCommunicationPoint, fmi3Float64 communicationStepSize,
                      fmi3Boolean noSetFMUStatePriorToCurrentPoint, fmi3Boolean *eventHandlingNeeded,
                      fmi3Boolean *terminateSimulation, fmi3Boolean *earlyReturn, fmi3Float64 *lastSuccessfulTime) {
    fmi2Status s = prc2_fmi2DoStep(in(instance), currentCommunicationPoint, communicationStepSize,
                                   noSetFMUStatePriorToCurrentPoint);
    *eventHandlingNeeded = fmi3False;
    *terminateSimulation = fmi3False;
    *earlyReturn = fmi3False;
    *lastSuccessfulTime = prc2_time(in(instance));
    return st(s);
}

fmi3Status fmi3ActivateModelPartition(fmi3Instance instance, fmi3ValueReference clockReference,
                                      fmi3Float64 activationTime) {
    (void)clockReference; (void)activationTime;
    say(instance, "fmi3ActivateModelPartition: scheduled execution is not supported");
    return fmi3Error;
}
