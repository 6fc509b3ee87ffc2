// FMI 3.0 glue (Model Exchange and Co-Simulation; Scheduled Execution is refused): the FMI 3
// signatures, the logger callback and the status mapping. State machine, argument checks,
// logging, value access and FMU state are in glue_common.cpp (shared with fmi2_glue.cpp), the
// model in model.cpp.
#include <memory>
#include <string>
#include <type_traits>

#include "fmi3Functions.h"
#include "glue_common.h"

namespace {

namespace fmu = stiff::fmu;
using fmu::Instance;
using fmu::Status;

static_assert(std::is_same_v<fmi3Boolean, bool> && std::is_same_v<fmi3Float64, double> &&
                  std::is_same_v<fmi3Int32, int32_t>,
              "glue_common.h value types");

fmi3Status st(Status s) {
  switch (s) {
    case Status::ok:
      return fmi3OK;
    case Status::warning:
      return fmi3Warning;
    case Status::discard:
      return fmi3Discard;
    default:
      return fmi3Error;
  }
}

class Fmi3Instance final : public Instance {
 public:
  Fmi3Instance(fmi3InstanceEnvironment env, fmi3LogMessageCallback logger)
      : env_(env), logger_(logger) {}
  void emit(Status status, const char* category, const std::string& msg) const override {
    if (logger_) logger_(env_, st(status), category, msg.c_str());
  }
  std::unique_ptr<Instance> relocate() override {
    return std::make_unique<Fmi3Instance>(std::move(*this));
  }

 private:
  fmi3InstanceEnvironment env_;
  fmi3LogMessageCallback logger_;
};

fmi3Instance instantiate(fmu::Kind kind,
                         const char* function,
                         bool event_mode_used,
                         fmi3String instanceName,
                         fmi3String token,
                         fmi3String resourcePath,
                         fmi3Boolean loggingOn,
                         fmi3InstanceEnvironment env,
                         fmi3LogMessageCallback logger) {
  Fmi3Instance staged(env, logger);
  fmu::InstantiateArgs a;
  a.fmi = 3;
  a.instance_name = instanceName;
  a.token = token;
  a.resources = resourcePath;
  a.kind = kind;
  a.logging_on = loggingOn;
  a.function = function;
  a.event_mode_used = event_mode_used;
  return fmu::instantiate(staged, a);
}

fmi3Status number_is_zero(fmi3Instance c, const char* f, size_t* n) {
  return st(fmu::guarded(c, f, fmu::kAnyState, [&](Instance& inst) {
    if (!n) return inst.reject(std::string(f) + ": NULL argument");
    *n = 0;
    return Status::ok;
  }));
}

}  // namespace

#define STIFF_NO_VARIABLES(Func, CType)                                                           \
  fmi3Status Func(fmi3Instance c, const fmi3ValueReference[], size_t nvr, CType[], size_t) {      \
    return st(fmu::expect_none(c, #Func, fmu::kAnyState, nvr, "this FMU has no such variables")); \
  }

// A call this FMU does not support: Error, "<Func> is not supported by this FMU". `Params` is
// the parameter list with the instance named c (fmi3Functions.h checks the signature).
#define STIFF_NOT_SUPPORTED(Func, Params) \
  fmi3Status Func Params { return st(fmu::not_supported(c, #Func)); }

extern "C" {

const char* fmi3GetVersion(void) { return fmi3Version; }

fmi3Instance fmi3InstantiateModelExchange(fmi3String instanceName,
                                          fmi3String instantiationToken,
                                          fmi3String resourcePath,
                                          fmi3Boolean /*visible*/,
                                          fmi3Boolean loggingOn,
                                          fmi3InstanceEnvironment instanceEnvironment,
                                          fmi3LogMessageCallback logMessage) {
  return instantiate(fmu::Kind::me, "fmi3InstantiateModelExchange", false, instanceName,
                     instantiationToken, resourcePath, loggingOn, instanceEnvironment, logMessage);
}

fmi3Instance fmi3InstantiateCoSimulation(fmi3String instanceName,
                                         fmi3String instantiationToken,
                                         fmi3String resourcePath,
                                         fmi3Boolean /*visible*/,
                                         fmi3Boolean loggingOn,
                                         fmi3Boolean eventModeUsed,
                                         fmi3Boolean /*earlyReturnAllowed*/,
                                         const fmi3ValueReference /*requiredIntermediate*/[],
                                         size_t /*nRequiredIntermediateVariables*/,
                                         fmi3InstanceEnvironment instanceEnvironment,
                                         fmi3LogMessageCallback logMessage,
                                         fmi3IntermediateUpdateCallback /*intermediateUpdate*/) {
  return instantiate(fmu::Kind::cs, "fmi3InstantiateCoSimulation", eventModeUsed, instanceName,
                     instantiationToken, resourcePath, loggingOn, instanceEnvironment, logMessage);
}

fmi3Instance fmi3InstantiateScheduledExecution(fmi3String,
                                               fmi3String,
                                               fmi3String,
                                               fmi3Boolean,
                                               fmi3Boolean,
                                               fmi3InstanceEnvironment instanceEnvironment,
                                               fmi3LogMessageCallback logMessage,
                                               fmi3ClockUpdateCallback,
                                               fmi3LockPreemptionCallback,
                                               fmi3UnlockPreemptionCallback) {
  if (logMessage)
    logMessage(instanceEnvironment, fmi3Error, fmu::kCategories[fmu::kLogError],
               "fmi3InstantiateScheduledExecution: not supported by this FMU");
  return nullptr;
}

void fmi3FreeInstance(fmi3Instance c) { fmu::free_instance(c, "fmi3FreeInstance"); }

fmi3Status fmi3SetDebugLogging(fmi3Instance c,
                               fmi3Boolean loggingOn,
                               size_t nCategories,
                               const fmi3String categories[]) {
  return st(fmu::set_debug_logging(c, "fmi3SetDebugLogging", loggingOn, nCategories, categories));
}

fmi3Status fmi3EnterInitializationMode(fmi3Instance c,
                                       fmi3Boolean /*toleranceDefined*/,
                                       fmi3Float64 /*tolerance*/,
                                       fmi3Float64 startTime,
                                       fmi3Boolean /*stopTimeDefined*/,
                                       fmi3Float64 /*stopTime*/) {
  return st(fmu::setup_experiment(c, "fmi3EnterInitializationMode", startTime, true));
}

fmi3Status fmi3ExitInitializationMode(fmi3Instance c) {
  return st(fmu::exit_initialization_mode(c, "fmi3ExitInitializationMode"));
}

fmi3Status fmi3EnterEventMode(fmi3Instance c) {
  return st(fmu::guarded(c, "fmi3EnterEventMode",
                         fmu::kEventMode | fmu::kContinuousTimeMode | fmu::kStepMode,
                         [&](Instance& inst) {
                           if (inst.kind != fmu::Kind::me)
                             return inst.reject("fmi3EnterEventMode: event mode is not used in CS");
                           inst.state = fmu::kEventMode;
                           return Status::ok;
                         }));
}

fmi3Status fmi3Terminate(fmi3Instance c) { return st(fmu::terminate(c, "fmi3Terminate")); }

fmi3Status fmi3Reset(fmi3Instance c) { return st(fmu::reset(c, "fmi3Reset")); }

fmi3Status fmi3GetFloat64(fmi3Instance c,
                          const fmi3ValueReference vr[],
                          size_t nvr,
                          fmi3Float64 values[],
                          size_t nValues) {
  return st(fmu::get_float64(c, "fmi3GetFloat64", {vr, nvr, &nValues}, values));
}

fmi3Status fmi3SetFloat64(fmi3Instance c,
                          const fmi3ValueReference vr[],
                          size_t nvr,
                          const fmi3Float64 values[],
                          size_t nValues) {
  return st(fmu::set_float64(c, "fmi3SetFloat64", {vr, nvr, &nValues}, values));
}

fmi3Status fmi3GetInt32(
    fmi3Instance c, const fmi3ValueReference vr[], size_t nvr, fmi3Int32 values[], size_t nValues) {
  return st(fmu::get_int32(c, "fmi3GetInt32", {vr, nvr, &nValues}, values));
}

fmi3Status fmi3SetInt32(fmi3Instance c,
                        const fmi3ValueReference vr[],
                        size_t nvr,
                        const fmi3Int32 values[],
                        size_t nValues) {
  return st(fmu::set_int32(c, "fmi3SetInt32", {vr, nvr, &nValues}, values));
}

STIFF_NO_VARIABLES(fmi3GetFloat32, fmi3Float32)
STIFF_NO_VARIABLES(fmi3GetInt8, fmi3Int8)
STIFF_NO_VARIABLES(fmi3GetUInt8, fmi3UInt8)
STIFF_NO_VARIABLES(fmi3GetInt16, fmi3Int16)
STIFF_NO_VARIABLES(fmi3GetUInt16, fmi3UInt16)
STIFF_NO_VARIABLES(fmi3GetUInt32, fmi3UInt32)
STIFF_NO_VARIABLES(fmi3GetInt64, fmi3Int64)
STIFF_NO_VARIABLES(fmi3GetUInt64, fmi3UInt64)
STIFF_NO_VARIABLES(fmi3GetBoolean, fmi3Boolean)
STIFF_NO_VARIABLES(fmi3GetString, fmi3String)
STIFF_NO_VARIABLES(fmi3SetFloat32, const fmi3Float32)
STIFF_NO_VARIABLES(fmi3SetInt8, const fmi3Int8)
STIFF_NO_VARIABLES(fmi3SetUInt8, const fmi3UInt8)
STIFF_NO_VARIABLES(fmi3SetInt16, const fmi3Int16)
STIFF_NO_VARIABLES(fmi3SetUInt16, const fmi3UInt16)
STIFF_NO_VARIABLES(fmi3SetUInt32, const fmi3UInt32)
STIFF_NO_VARIABLES(fmi3SetInt64, const fmi3Int64)
STIFF_NO_VARIABLES(fmi3SetUInt64, const fmi3UInt64)
STIFF_NO_VARIABLES(fmi3SetBoolean, const fmi3Boolean)
STIFF_NO_VARIABLES(fmi3SetString, const fmi3String)

STIFF_NOT_SUPPORTED(
    fmi3GetBinary,
    (fmi3Instance c, const fmi3ValueReference[], size_t, size_t[], fmi3Binary[], size_t))
STIFF_NOT_SUPPORTED(fmi3SetBinary,
                    (fmi3Instance c,
                     const fmi3ValueReference[],
                     size_t,
                     const size_t[],
                     const fmi3Binary[],
                     size_t))
STIFF_NOT_SUPPORTED(fmi3GetClock, (fmi3Instance c, const fmi3ValueReference[], size_t, fmi3Clock[]))
STIFF_NOT_SUPPORTED(fmi3SetClock,
                    (fmi3Instance c, const fmi3ValueReference[], size_t, const fmi3Clock[]))

STIFF_NOT_SUPPORTED(fmi3GetNumberOfVariableDependencies,
                    (fmi3Instance c, fmi3ValueReference, size_t*))
STIFF_NOT_SUPPORTED(fmi3GetVariableDependencies,
                    (fmi3Instance c,
                     fmi3ValueReference,
                     size_t[],
                     fmi3ValueReference[],
                     size_t[],
                     fmi3DependencyKind[],
                     size_t))

fmi3Status fmi3GetFMUState(fmi3Instance c, fmi3FMUState* FMUState) {
  return st(fmu::get_fmu_state(c, "fmi3GetFMUState", "FMUState", FMUState));
}

fmi3Status fmi3SetFMUState(fmi3Instance c, fmi3FMUState FMUState) {
  return st(fmu::set_fmu_state(c, "fmi3SetFMUState", "FMUState", FMUState));
}

fmi3Status fmi3FreeFMUState(fmi3Instance c, fmi3FMUState* FMUState) {
  return st(fmu::free_fmu_state(c, "fmi3FreeFMUState", "FMUState", FMUState));
}

fmi3Status fmi3SerializedFMUStateSize(fmi3Instance c, fmi3FMUState FMUState, size_t* size) {
  return st(fmu::serialized_fmu_state_size(c, "fmi3SerializedFMUStateSize", FMUState, size));
}

fmi3Status fmi3SerializeFMUState(fmi3Instance c,
                                 fmi3FMUState FMUState,
                                 fmi3Byte serializedState[],
                                 size_t size) {
  return st(fmu::serialize_fmu_state(c, "fmi3SerializeFMUState", FMUState, serializedState, size));
}

fmi3Status fmi3DeserializeFMUState(fmi3Instance c,
                                   const fmi3Byte serializedState[],
                                   size_t size,
                                   fmi3FMUState* FMUState) {
  return st(fmu::deserialize_fmu_state(c, "fmi3DeserializeFMUState", serializedState, size,
                                       FMUState, fmu::BlobOrder::state_first));
}

STIFF_NOT_SUPPORTED(fmi3GetDirectionalDerivative,
                    (fmi3Instance c,
                     const fmi3ValueReference[],
                     size_t,
                     const fmi3ValueReference[],
                     size_t,
                     const fmi3Float64[],
                     size_t,
                     fmi3Float64[],
                     size_t))
STIFF_NOT_SUPPORTED(fmi3GetAdjointDerivative,
                    (fmi3Instance c,
                     const fmi3ValueReference[],
                     size_t,
                     const fmi3ValueReference[],
                     size_t,
                     const fmi3Float64[],
                     size_t,
                     fmi3Float64[],
                     size_t))

STIFF_NOT_SUPPORTED(fmi3EnterConfigurationMode, (fmi3Instance c))
STIFF_NOT_SUPPORTED(fmi3ExitConfigurationMode, (fmi3Instance c))
STIFF_NOT_SUPPORTED(
    fmi3GetIntervalDecimal,
    (fmi3Instance c, const fmi3ValueReference[], size_t, fmi3Float64[], fmi3IntervalQualifier[]))
STIFF_NOT_SUPPORTED(fmi3GetIntervalFraction,
                    (fmi3Instance c,
                     const fmi3ValueReference[],
                     size_t,
                     fmi3UInt64[],
                     fmi3UInt64[],
                     fmi3IntervalQualifier[]))
STIFF_NOT_SUPPORTED(fmi3GetShiftDecimal,
                    (fmi3Instance c, const fmi3ValueReference[], size_t, fmi3Float64[]))
STIFF_NOT_SUPPORTED(
    fmi3GetShiftFraction,
    (fmi3Instance c, const fmi3ValueReference[], size_t, fmi3UInt64[], fmi3UInt64[]))
STIFF_NOT_SUPPORTED(fmi3SetIntervalDecimal,
                    (fmi3Instance c, const fmi3ValueReference[], size_t, const fmi3Float64[]))
STIFF_NOT_SUPPORTED(
    fmi3SetIntervalFraction,
    (fmi3Instance c, const fmi3ValueReference[], size_t, const fmi3UInt64[], const fmi3UInt64[]))
STIFF_NOT_SUPPORTED(fmi3SetShiftDecimal,
                    (fmi3Instance c, const fmi3ValueReference[], size_t, const fmi3Float64[]))
STIFF_NOT_SUPPORTED(
    fmi3SetShiftFraction,
    (fmi3Instance c, const fmi3ValueReference[], size_t, const fmi3UInt64[], const fmi3UInt64[]))

fmi3Status fmi3EvaluateDiscreteStates(fmi3Instance c) {
  return st(fmu::guarded(c, "fmi3EvaluateDiscreteStates",
                         fmu::kEventMode | fmu::kContinuousTimeMode,
                         [&](Instance&) { return Status::ok; }));
}

fmi3Status fmi3UpdateDiscreteStates(fmi3Instance c,
                                    fmi3Boolean* discreteStatesNeedUpdate,
                                    fmi3Boolean* terminateSimulation,
                                    fmi3Boolean* nominalsOfContinuousStatesChanged,
                                    fmi3Boolean* valuesOfContinuousStatesChanged,
                                    fmi3Boolean* nextEventTimeDefined,
                                    fmi3Float64* nextEventTime) {
  return st(fmu::guarded(c, "fmi3UpdateDiscreteStates", fmu::kEventMode, [&](Instance& inst) {
    if (!discreteStatesNeedUpdate || !terminateSimulation || !nominalsOfContinuousStatesChanged ||
        !valuesOfContinuousStatesChanged || !nextEventTimeDefined || !nextEventTime)
      return inst.reject("fmi3UpdateDiscreteStates: NULL argument");
    *discreteStatesNeedUpdate = fmi3False;
    *terminateSimulation = fmi3False;
    *nominalsOfContinuousStatesChanged = fmi3False;
    *valuesOfContinuousStatesChanged = fmi3False;
    *nextEventTimeDefined = fmi3False;
    *nextEventTime = 0.0;
    return Status::ok;
  }));
}

fmi3Status fmi3EnterContinuousTimeMode(fmi3Instance c) {
  return st(fmu::enter_continuous_time_mode(c, "fmi3EnterContinuousTimeMode"));
}

fmi3Status fmi3CompletedIntegratorStep(fmi3Instance c,
                                       fmi3Boolean /*noSetFMUStatePriorToCurrentPoint*/,
                                       fmi3Boolean* enterEventMode,
                                       fmi3Boolean* terminateSimulation) {
  return st(fmu::completed_integrator_step(c, "fmi3CompletedIntegratorStep", enterEventMode,
                                           terminateSimulation));
}

fmi3Status fmi3SetTime(fmi3Instance c, fmi3Float64 time) {
  return st(fmu::set_time(c, "fmi3SetTime", time));
}

fmi3Status fmi3SetContinuousStates(fmi3Instance c, const fmi3Float64[], size_t nx) {
  return st(fmu::expect_none(c, "fmi3SetContinuousStates", fmu::kContinuousTimeMode, nx,
                             "the FMU has no states"));
}

fmi3Status fmi3GetContinuousStateDerivatives(fmi3Instance c, fmi3Float64[], size_t nx) {
  return st(fmu::expect_none(c, "fmi3GetContinuousStateDerivatives", fmu::kGetMask, nx,
                             "the FMU has no states"));
}

fmi3Status fmi3GetEventIndicators(fmi3Instance c, fmi3Float64[], size_t ni) {
  return st(fmu::expect_none(c, "fmi3GetEventIndicators", fmu::kGetMask, ni,
                             "the FMU has no event indicators"));
}

fmi3Status fmi3GetContinuousStates(fmi3Instance c, fmi3Float64[], size_t nx) {
  return st(
      fmu::expect_none(c, "fmi3GetContinuousStates", fmu::kGetMask, nx, "the FMU has no states"));
}

fmi3Status fmi3GetNominalsOfContinuousStates(fmi3Instance c, fmi3Float64[], size_t nx) {
  return st(fmu::expect_none(c, "fmi3GetNominalsOfContinuousStates", fmu::kGetMask, nx,
                             "the FMU has no states"));
}

fmi3Status fmi3GetNumberOfEventIndicators(fmi3Instance c, size_t* n) {
  return number_is_zero(c, "fmi3GetNumberOfEventIndicators", n);
}

fmi3Status fmi3GetNumberOfContinuousStates(fmi3Instance c, size_t* n) {
  return number_is_zero(c, "fmi3GetNumberOfContinuousStates", n);
}

fmi3Status fmi3EnterStepMode(fmi3Instance c) {
  return st(fmu::guarded(c, "fmi3EnterStepMode", fmu::kEventMode, [&](Instance& inst) {
    if (inst.kind != fmu::Kind::cs) return inst.reject("fmi3EnterStepMode: instance is not CS");
    inst.state = fmu::kStepMode;
    return Status::ok;
  }));
}

STIFF_NOT_SUPPORTED(
    fmi3GetOutputDerivatives,
    (fmi3Instance c, const fmi3ValueReference[], size_t, const fmi3Int32[], fmi3Float64[], size_t))

fmi3Status fmi3DoStep(fmi3Instance c,
                      fmi3Float64 currentCommunicationPoint,
                      fmi3Float64 communicationStepSize,
                      fmi3Boolean /*noSetFMUStatePriorToCurrentPoint*/,
                      fmi3Boolean* eventHandlingNeeded,
                      fmi3Boolean* terminateSimulation,
                      fmi3Boolean* earlyReturn,
                      fmi3Float64* lastSuccessfulTime) {
  const fmu::StepOutputs out{eventHandlingNeeded, terminateSimulation, earlyReturn,
                             lastSuccessfulTime};
  return st(fmu::do_step(c, "fmi3DoStep", currentCommunicationPoint, communicationStepSize, &out));
}

STIFF_NOT_SUPPORTED(fmi3ActivateModelPartition, (fmi3Instance c, fmi3ValueReference, fmi3Float64))

}  // extern "C"
