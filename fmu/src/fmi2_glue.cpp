// FMI 2.0 glue (Model Exchange and Co-Simulation in one binary): the FMI 2 signatures, the
// logger callback and the status mapping. State machine, argument checks, logging, value access
// and FMU state are in glue_common.cpp (shared with fmi3_glue.cpp), the model in model.cpp.
#include <memory>
#include <string>
#include <type_traits>

#include "fmi2Functions.h"
#include "glue_common.h"

namespace {

namespace fmu = stiff::fmu;
using fmu::Instance;
using fmu::Status;

static_assert(std::is_same_v<fmi2ValueReference, uint32_t> &&
                  std::is_same_v<fmi2Integer, int32_t> && std::is_same_v<fmi2Real, double>,
              "glue_common.h value types");

fmi2Status st(Status s) {
  switch (s) {
    case Status::ok:
      return fmi2OK;
    case Status::warning:
      return fmi2Warning;
    case Status::discard:
      return fmi2Discard;
    default:
      return fmi2Error;
  }
}

// FMI 2 loggers take the instance name and a printf format: messages are passed as "%s".
class Fmi2Instance final : public Instance {
 public:
  explicit Fmi2Instance(const fmi2CallbackFunctions& callbacks) : callbacks_(callbacks) {}
  void emit(Status status, const char* category, const std::string& msg) const override {
    if (callbacks_.logger)
      callbacks_.logger(callbacks_.componentEnvironment, name.c_str(), st(status), category, "%s",
                        msg.c_str());
  }
  std::unique_ptr<Instance> relocate() override {
    return std::make_unique<Fmi2Instance>(std::move(*this));
  }

 private:
  fmi2CallbackFunctions callbacks_;
};

}  // namespace

// A call this FMU does not support: Error, "<Func> is not supported by this FMU". `Params` is
// the parameter list with the instance named c (fmi2Functions.h checks the signature).
#define STIFF_NOT_SUPPORTED(Func, Params) \
  fmi2Status Func Params { return st(fmu::not_supported(c, #Func)); }

extern "C" {

const char* fmi2GetTypesPlatform(void) { return fmi2TypesPlatform; }
const char* fmi2GetVersion(void) { return fmi2Version; }

fmi2Component fmi2Instantiate(fmi2String instanceName,
                              fmi2Type fmuType,
                              fmi2String fmuGUID,
                              fmi2String fmuResourceLocation,
                              const fmi2CallbackFunctions* functions,
                              fmi2Boolean /*visible*/,
                              fmi2Boolean loggingOn) {
  if (!functions || !functions->logger) return nullptr;
  Fmi2Instance staged(*functions);
  fmu::InstantiateArgs a;
  a.fmi = 2;
  a.instance_name = instanceName;
  a.token = fmuGUID;
  a.resources = fmuResourceLocation;
  a.known_type = fmuType == fmi2ModelExchange || fmuType == fmi2CoSimulation;
  a.kind = fmuType == fmi2ModelExchange ? fmu::Kind::me : fmu::Kind::cs;
  a.logging_on = loggingOn != fmi2False;
  return fmu::instantiate(staged, a);
}

void fmi2FreeInstance(fmi2Component c) { fmu::free_instance(c, "fmi2FreeInstance"); }

fmi2Status fmi2SetDebugLogging(fmi2Component c,
                               fmi2Boolean loggingOn,
                               size_t nCategories,
                               const fmi2String categories[]) {
  return st(fmu::set_debug_logging(c, "fmi2SetDebugLogging", loggingOn != fmi2False, nCategories,
                                   categories));
}

fmi2Status fmi2SetupExperiment(fmi2Component c,
                               fmi2Boolean /*toleranceDefined*/,
                               fmi2Real /*tolerance*/,
                               fmi2Real startTime,
                               fmi2Boolean /*stopTimeDefined*/,
                               fmi2Real /*stopTime*/) {
  return st(fmu::setup_experiment(c, "fmi2SetupExperiment", startTime, false));
}

fmi2Status fmi2EnterInitializationMode(fmi2Component c) {
  return st(fmu::enter_initialization_mode(c, "fmi2EnterInitializationMode"));
}

fmi2Status fmi2ExitInitializationMode(fmi2Component c) {
  return st(fmu::exit_initialization_mode(c, "fmi2ExitInitializationMode"));
}

fmi2Status fmi2Terminate(fmi2Component c) { return st(fmu::terminate(c, "fmi2Terminate")); }

fmi2Status fmi2Reset(fmi2Component c) { return st(fmu::reset(c, "fmi2Reset")); }

fmi2Status fmi2GetReal(fmi2Component c,
                       const fmi2ValueReference vr[],
                       size_t nvr,
                       fmi2Real value[]) {
  return st(fmu::get_float64(c, "fmi2GetReal", {vr, nvr, nullptr}, value));
}

fmi2Status fmi2GetInteger(fmi2Component c,
                          const fmi2ValueReference vr[],
                          size_t nvr,
                          fmi2Integer value[]) {
  return st(fmu::get_int32(c, "fmi2GetInteger", {vr, nvr, nullptr}, value));
}

fmi2Status fmi2GetBoolean(fmi2Component c, const fmi2ValueReference[], size_t nvr, fmi2Boolean[]) {
  return st(fmu::expect_none(c, "fmi2GetBoolean", fmu::kGetMask, nvr,
                             "this FMU has no Boolean variables"));
}

fmi2Status fmi2GetString(fmi2Component c, const fmi2ValueReference[], size_t nvr, fmi2String[]) {
  return st(
      fmu::expect_none(c, "fmi2GetString", fmu::kGetMask, nvr, "this FMU has no String variables"));
}

fmi2Status fmi2SetReal(fmi2Component c,
                       const fmi2ValueReference vr[],
                       size_t nvr,
                       const fmi2Real value[]) {
  return st(fmu::set_float64(c, "fmi2SetReal", {vr, nvr, nullptr}, value));
}

fmi2Status fmi2SetInteger(fmi2Component c,
                          const fmi2ValueReference vr[],
                          size_t nvr,
                          const fmi2Integer value[]) {
  return st(fmu::set_int32(c, "fmi2SetInteger", {vr, nvr, nullptr}, value));
}

fmi2Status fmi2SetBoolean(fmi2Component c,
                          const fmi2ValueReference[],
                          size_t nvr,
                          const fmi2Boolean[]) {
  return st(fmu::expect_none(c, "fmi2SetBoolean", fmu::kSetMask, nvr,
                             "this FMU has no Boolean variables"));
}

fmi2Status fmi2SetString(fmi2Component c,
                         const fmi2ValueReference[],
                         size_t nvr,
                         const fmi2String[]) {
  return st(
      fmu::expect_none(c, "fmi2SetString", fmu::kSetMask, nvr, "this FMU has no String variables"));
}

fmi2Status fmi2GetFMUstate(fmi2Component c, fmi2FMUstate* FMUstate) {
  return st(fmu::get_fmu_state(c, "fmi2GetFMUstate", "FMUstate", FMUstate));
}

fmi2Status fmi2SetFMUstate(fmi2Component c, fmi2FMUstate FMUstate) {
  return st(fmu::set_fmu_state(c, "fmi2SetFMUstate", "FMUstate", FMUstate));
}

fmi2Status fmi2FreeFMUstate(fmi2Component c, fmi2FMUstate* FMUstate) {
  return st(fmu::free_fmu_state(c, "fmi2FreeFMUstate", "FMUstate", FMUstate));
}

fmi2Status fmi2SerializedFMUstateSize(fmi2Component c, fmi2FMUstate FMUstate, size_t* size) {
  return st(fmu::serialized_fmu_state_size(c, "fmi2SerializedFMUstateSize", FMUstate, size));
}

fmi2Status fmi2SerializeFMUstate(fmi2Component c,
                                 fmi2FMUstate FMUstate,
                                 fmi2Byte serializedState[],
                                 size_t size) {
  return st(fmu::serialize_fmu_state(c, "fmi2SerializeFMUstate", FMUstate, serializedState, size));
}

fmi2Status fmi2DeSerializeFMUstate(fmi2Component c,
                                   const fmi2Byte serializedState[],
                                   size_t size,
                                   fmi2FMUstate* FMUstate) {
  return st(fmu::deserialize_fmu_state(c, "fmi2DeSerializeFMUstate", serializedState, size,
                                       FMUstate, fmu::BlobOrder::values_first));
}

STIFF_NOT_SUPPORTED(fmi2GetDirectionalDerivative,
                    (fmi2Component c,
                     const fmi2ValueReference[],
                     size_t,
                     const fmi2ValueReference[],
                     size_t,
                     const fmi2Real[],
                     fmi2Real[]))

// Model Exchange: the model is algebraic (no states, no event indicators).
fmi2Status fmi2EnterEventMode(fmi2Component c) {
  return st(fmu::guarded(c, "fmi2EnterEventMode", fmu::kEventMode | fmu::kContinuousTimeMode,
                         [&](Instance& inst) {
                           inst.state = fmu::kEventMode;
                           return Status::ok;
                         }));
}

fmi2Status fmi2NewDiscreteStates(fmi2Component c, fmi2EventInfo* info) {
  return st(fmu::guarded(c, "fmi2NewDiscreteStates", fmu::kEventMode, [&](Instance& inst) {
    if (!info) return inst.reject("fmi2NewDiscreteStates: NULL eventInfo");
    info->newDiscreteStatesNeeded = fmi2False;
    info->terminateSimulation = fmi2False;
    info->nominalsOfContinuousStatesChanged = fmi2False;
    info->valuesOfContinuousStatesChanged = fmi2False;
    info->nextEventTimeDefined = fmi2False;
    info->nextEventTime = 0.0;
    return Status::ok;
  }));
}

fmi2Status fmi2EnterContinuousTimeMode(fmi2Component c) {
  return st(fmu::enter_continuous_time_mode(c, "fmi2EnterContinuousTimeMode"));
}

fmi2Status fmi2CompletedIntegratorStep(fmi2Component c,
                                       fmi2Boolean /*noSetFMUStatePriorToCurrentPoint*/,
                                       fmi2Boolean* enterEventMode,
                                       fmi2Boolean* terminateSimulation) {
  return st(fmu::completed_integrator_step(c, "fmi2CompletedIntegratorStep", enterEventMode,
                                           terminateSimulation));
}

fmi2Status fmi2SetTime(fmi2Component c, fmi2Real time) {
  return st(fmu::set_time(c, "fmi2SetTime", time));
}

fmi2Status fmi2SetContinuousStates(fmi2Component c, const fmi2Real[], size_t nx) {
  return st(fmu::expect_none(c, "fmi2SetContinuousStates", fmu::kContinuousTimeMode, nx,
                             "the FMU has no states"));
}

fmi2Status fmi2GetDerivatives(fmi2Component c, fmi2Real[], size_t nx) {
  return st(fmu::expect_none(c, "fmi2GetDerivatives", fmu::kGetMask, nx, "the FMU has no states"));
}

fmi2Status fmi2GetEventIndicators(fmi2Component c, fmi2Real[], size_t ni) {
  return st(fmu::expect_none(c, "fmi2GetEventIndicators", fmu::kGetMask, ni,
                             "the FMU has no event indicators"));
}

fmi2Status fmi2GetContinuousStates(fmi2Component c, fmi2Real[], size_t nx) {
  return st(
      fmu::expect_none(c, "fmi2GetContinuousStates", fmu::kGetMask, nx, "the FMU has no states"));
}

fmi2Status fmi2GetNominalsOfContinuousStates(fmi2Component c, fmi2Real[], size_t nx) {
  return st(fmu::expect_none(c, "fmi2GetNominalsOfContinuousStates", fmu::kGetMask, nx,
                             "the FMU has no states"));
}

// Co-Simulation.
STIFF_NOT_SUPPORTED(
    fmi2SetRealInputDerivatives,
    (fmi2Component c, const fmi2ValueReference[], size_t, const fmi2Integer[], const fmi2Real[]))

STIFF_NOT_SUPPORTED(
    fmi2GetRealOutputDerivatives,
    (fmi2Component c, const fmi2ValueReference[], size_t, const fmi2Integer[], fmi2Real[]))

fmi2Status fmi2DoStep(fmi2Component c,
                      fmi2Real currentCommunicationPoint,
                      fmi2Real communicationStepSize,
                      fmi2Boolean /*noSetFMUStatePriorToCurrentPoint*/) {
  return st(
      fmu::do_step(c, "fmi2DoStep", currentCommunicationPoint, communicationStepSize, nullptr));
}

STIFF_NOT_SUPPORTED(fmi2CancelStep, (fmi2Component c))

STIFF_NOT_SUPPORTED(fmi2GetStatus, (fmi2Component c, const fmi2StatusKind, fmi2Status*))
fmi2Status fmi2GetRealStatus(fmi2Component c, const fmi2StatusKind s, fmi2Real* value) {
  return st(fmu::guarded(c, "fmi2GetRealStatus", fmu::kGetMask, [&](Instance& inst) {
    if (s != fmi2LastSuccessfulTime || !value)
      return inst.reject("fmi2GetRealStatus: only fmi2LastSuccessfulTime is supported");
    *value = inst.model->values().time;
    return Status::ok;
  }));
}
STIFF_NOT_SUPPORTED(fmi2GetIntegerStatus, (fmi2Component c, const fmi2StatusKind, fmi2Integer*))
STIFF_NOT_SUPPORTED(fmi2GetBooleanStatus, (fmi2Component c, const fmi2StatusKind, fmi2Boolean*))
STIFF_NOT_SUPPORTED(fmi2GetStringStatus, (fmi2Component c, const fmi2StatusKind, fmi2String*))

}  // extern "C"
