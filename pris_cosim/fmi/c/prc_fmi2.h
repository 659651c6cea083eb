/* The FMI 2.0 layer of a network FMU.
 *
 * In an FMI 2.0 FMU the functions below are the exported fmi2* functions.
 * Built with PRC_FMI3 defined (FMI 3.0 FMUs), the same code is compiled
 * under the internal names prc2_fmi2* (hidden in the shared library), and
 * prc_fmi3.c implements the FMI 3.0 interface on top of it.
 */
#ifndef PRC_FMI2_H
#define PRC_FMI2_H

#ifdef PRC_FMI3
#include "fmi2FunctionTypes.h"
#define PRC2(name) prc2_##name
#ifndef fmi2Version
#define fmi2Version "2.0"
#endif
#if defined(__GNUC__) && __GNUC__ >= 4 && !defined(_WIN32)
#define PRC2_API __attribute__((visibility("hidden")))
#else
#define PRC2_API
#endif
PRC2_API fmi2GetTypesPlatformTYPE prc2_fmi2GetTypesPlatform;
PRC2_API fmi2GetVersionTYPE prc2_fmi2GetVersion;
PRC2_API fmi2SetDebugLoggingTYPE prc2_fmi2SetDebugLogging;
PRC2_API fmi2InstantiateTYPE prc2_fmi2Instantiate;
PRC2_API fmi2FreeInstanceTYPE prc2_fmi2FreeInstance;
PRC2_API fmi2SetupExperimentTYPE prc2_fmi2SetupExperiment;
PRC2_API fmi2EnterInitializationModeTYPE prc2_fmi2EnterInitializationMode;
PRC2_API fmi2ExitInitializationModeTYPE prc2_fmi2ExitInitializationMode;
PRC2_API fmi2TerminateTYPE prc2_fmi2Terminate;
PRC2_API fmi2ResetTYPE prc2_fmi2Reset;
PRC2_API fmi2GetRealTYPE prc2_fmi2GetReal;
PRC2_API fmi2GetIntegerTYPE prc2_fmi2GetInteger;
PRC2_API fmi2GetBooleanTYPE prc2_fmi2GetBoolean;
PRC2_API fmi2GetStringTYPE prc2_fmi2GetString;
PRC2_API fmi2SetRealTYPE prc2_fmi2SetReal;
PRC2_API fmi2SetIntegerTYPE prc2_fmi2SetInteger;
PRC2_API fmi2SetBooleanTYPE prc2_fmi2SetBoolean;
PRC2_API fmi2SetStringTYPE prc2_fmi2SetString;
PRC2_API fmi2GetFMUstateTYPE prc2_fmi2GetFMUstate;
PRC2_API fmi2SetFMUstateTYPE prc2_fmi2SetFMUstate;
PRC2_API fmi2FreeFMUstateTYPE prc2_fmi2FreeFMUstate;
PRC2_API fmi2SerializedFMUstateSizeTYPE prc2_fmi2SerializedFMUstateSize;
PRC2_API fmi2SerializeFMUstateTYPE prc2_fmi2SerializeFMUstate;
PRC2_API fmi2DeSerializeFMUstateTYPE prc2_fmi2DeSerializeFMUstate;
PRC2_API fmi2GetDirectionalDerivativeTYPE prc2_fmi2GetDirectionalDerivative;
PRC2_API fmi2EnterEventModeTYPE prc2_fmi2EnterEventMode;
PRC2_API fmi2NewDiscreteStatesTYPE prc2_fmi2NewDiscreteStates;
PRC2_API fmi2EnterContinuousTimeModeTYPE prc2_fmi2EnterContinuousTimeMode;
PRC2_API fmi2CompletedIntegratorStepTYPE prc2_fmi2CompletedIntegratorStep;
PRC2_API fmi2SetTimeTYPE prc2_fmi2SetTime;
PRC2_API fmi2SetContinuousStatesTYPE prc2_fmi2SetContinuousStates;
PRC2_API fmi2GetDerivativesTYPE prc2_fmi2GetDerivatives;
PRC2_API fmi2GetEventIndicatorsTYPE prc2_fmi2GetEventIndicators;
PRC2_API fmi2GetContinuousStatesTYPE prc2_fmi2GetContinuousStates;
PRC2_API fmi2GetNominalsOfContinuousStatesTYPE prc2_fmi2GetNominalsOfContinuousStates;
PRC2_API fmi2SetRealInputDerivativesTYPE prc2_fmi2SetRealInputDerivatives;
PRC2_API fmi2GetRealOutputDerivativesTYPE prc2_fmi2GetRealOutputDerivatives;
PRC2_API fmi2DoStepTYPE prc2_fmi2DoStep;
PRC2_API fmi2CancelStepTYPE prc2_fmi2CancelStep;
PRC2_API fmi2GetStatusTYPE prc2_fmi2GetStatus;
PRC2_API fmi2GetRealStatusTYPE prc2_fmi2GetRealStatus;
PRC2_API fmi2GetIntegerStatusTYPE prc2_fmi2GetIntegerStatus;
PRC2_API fmi2GetBooleanStatusTYPE prc2_fmi2GetBooleanStatus;
PRC2_API fmi2GetStringStatusTYPE prc2_fmi2GetStringStatus;
/* Simulation time of an instance (s). */
PRC2_API double prc2_time(fmi2Component comp);
#else
#include "fmi2Functions.h"
#define PRC2(name) name
#endif

#endif
