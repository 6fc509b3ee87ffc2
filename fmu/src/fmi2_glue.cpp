// FMI 2.0 glue (Model Exchange and Co-Simulation in one binary): state machine, argument
// checks, logging with the declared categories, FMU state. The model is in model.cpp.
#include <cmath>
#include <cstring>
#include <exception>
#include <memory>
#include <new>
#include <string>

#include "fmi2Functions.h"
#include "glue_util.h"
#include "model.h"

namespace {

using stiff::fmu::Model;
using stiff::fmu::Status;
using stiff::fmu::Variable;

enum State : unsigned {
  kInstantiated = 1u << 0,
  kInitializationMode = 1u << 1,
  kEventMode = 1u << 2,
  kContinuousTimeMode = 1u << 3,
  kStepComplete = 1u << 4,
  kTerminated = 1u << 5,
  kError = 1u << 6,
};
constexpr unsigned kAnyState = ~0u;
constexpr unsigned kGetMask =
    kInitializationMode | kEventMode | kContinuousTimeMode | kStepComplete | kTerminated | kError;
constexpr unsigned kSetMask =
    kInstantiated | kInitializationMode | kEventMode | kContinuousTimeMode | kStepComplete;

// Declared in modelDescription.xml <LogCategories>, in this order.
constexpr const char* kCategories[] = {"logStatusError", "logStatusWarning", "logCalls"};
enum Category { kLogError, kLogWarning, kLogCalls, kCategoryCount };

struct Instance {
  std::string name;
  fmi2Type type = fmi2CoSimulation;
  fmi2CallbackFunctions callbacks{};
  bool logging_on = false;
  bool category_on[kCategoryCount] = {true, true, true};
  unsigned state = kInstantiated;
  std::unique_ptr<Model> model;

  void log(fmi2Status status, Category c, const std::string& msg) const {
    // Errors and warnings are always reported; OK-level messages only when asked for.
    if (status == fmi2OK && (!logging_on || !category_on[c])) return;
    if (callbacks.logger)
      callbacks.logger(callbacks.componentEnvironment, name.c_str(), status, kCategories[c], "%s",
                       msg.c_str());
  }
  fmi2Status error(const std::string& msg) {
    log(fmi2Error, kLogError, msg);
    state = kError;
    return fmi2Error;
  }
  // A rejected call that leaves the instance usable (bad argument, wrong state).
  fmi2Status reject(const std::string& msg) {
    log(fmi2Error, kLogError, msg);
    return fmi2Error;
  }
  fmi2Status from(Status s, const std::string& msg) {
    switch (s) {
      case Status::ok:
        return fmi2OK;
      case Status::warning:
        log(fmi2Warning, kLogWarning, msg);
        return fmi2Warning;
      case Status::discard:
        log(fmi2Discard, kLogWarning, msg);
        return fmi2Discard;
      default:
        return error(msg);
    }
  }
  // False (and logs) when `f` is not allowed in the current state.
  bool allowed(const char* f, unsigned mask) {
    if (state & mask) return true;
    log(fmi2Error, kLogError, std::string(f) + " is not allowed in the current state");
    return false;
  }
};

template <typename Body>
fmi2Status guarded(fmi2Component c, const char* f, unsigned mask, Body&& body) {
  if (!c) return fmi2Error;
  auto* inst = static_cast<Instance*>(c);
  if (!inst->allowed(f, mask)) return fmi2Error;
  inst->log(fmi2OK, kLogCalls, f);
  try {
    return body(*inst);
  } catch (const std::bad_alloc&) {
    return inst->error(std::string(f) + ": out of memory");
  } catch (const std::exception& e) {
    return inst->error(std::string(f) + ": " + e.what());
  } catch (...) {
    return inst->error(std::string(f) + ": unknown exception");
  }
}

fmi2Status check_array(
    Instance& inst, const char* f, const fmi2ValueReference* vr, size_t nvr, const void* value) {
  if (nvr > 0 && (!vr || !value)) return inst.reject(std::string(f) + ": NULL argument");
  return fmi2OK;
}

const Variable* lookup(Instance& inst, const char* f, fmi2ValueReference vr, bool integer) {
  const Variable* v = inst.model->variable(vr);
  if (!v) {
    inst.reject(std::string(f) + ": unknown value reference " + std::to_string(vr));
    return nullptr;
  }
  if (v->is_integer() != integer || v->size(inst.model->dof()) != 1) {
    inst.reject(std::string(f) + ": value reference " + std::to_string(vr) + " ('" + v->name +
                "') has another type");
    return nullptr;
  }
  return v;
}

fmi2Status not_supported(fmi2Component c, const char* f) {
  if (!c) return fmi2Error;
  return static_cast<Instance*>(c)->reject(std::string(f) + " is not supported by this FMU");
}

}  // namespace

extern "C" {

const char* fmi2GetTypesPlatform(void) { return fmi2TypesPlatform; }
const char* fmi2GetVersion(void) { return fmi2Version; }

fmi2Component fmi2Instantiate(fmi2String instanceName,
                              fmi2Type fmuType,
                              fmi2String fmuGUID,
                              fmi2String fmuResourceLocation,
                              const fmi2CallbackFunctions* functions,
                              fmi2Boolean visible,
                              fmi2Boolean loggingOn) {
  (void)visible;
  if (!functions || !functions->logger) return nullptr;
  auto say = [&](const std::string& msg) {
    functions->logger(functions->componentEnvironment, instanceName ? instanceName : "", fmi2Error,
                      kCategories[kLogError], "%s", msg.c_str());
  };
  if (!instanceName || !*instanceName)
    return say("fmi2Instantiate: missing instance name"), nullptr;
  if (!fmuGUID || !*fmuGUID) return say("fmi2Instantiate: missing GUID"), nullptr;
  if (fmuType != fmi2ModelExchange && fmuType != fmi2CoSimulation)
    return say("fmi2Instantiate: unknown FMU type"), nullptr;
  const std::string dir = stiff::fmu::uri_to_path(fmuResourceLocation);
  if (dir.empty())
    return say(std::string("fmi2Instantiate: resource location '") +
               (fmuResourceLocation ? fmuResourceLocation : "(null)") + "' is not a file: URI"),
           nullptr;
  try {
    auto layout = stiff::fmu::read_layout(dir);
    if (layout->fmi != 2) return say("fmi2Instantiate: resources are for FMI 3"), nullptr;
    if (layout->guid != fmuGUID)
      return say(std::string("fmi2Instantiate: GUID '") + fmuGUID +
                 "' does not match the resources' GUID '" + layout->guid + "'"),
             nullptr;
    auto inst = std::make_unique<Instance>();
    inst->name = instanceName;
    inst->type = fmuType;
    inst->callbacks = *functions;
    inst->logging_on = loggingOn != fmi2False;
    inst->model = std::make_unique<Model>(std::move(layout));
    inst->log(fmi2OK, kLogCalls, "fmi2Instantiate");
    return inst.release();
  } catch (const std::exception& e) {
    say(std::string("fmi2Instantiate: ") + e.what());
  } catch (...) {
    say("fmi2Instantiate: unknown exception");
  }
  return nullptr;
}

void fmi2FreeInstance(fmi2Component c) {
  if (!c) return;
  auto* inst = static_cast<Instance*>(c);
  inst->log(fmi2OK, kLogCalls, "fmi2FreeInstance");
  delete inst;
}

fmi2Status fmi2SetDebugLogging(fmi2Component c,
                               fmi2Boolean loggingOn,
                               size_t nCategories,
                               const fmi2String categories[]) {
  return guarded(c, "fmi2SetDebugLogging", kAnyState, [&](Instance& inst) {
    if (nCategories > 0 && !categories) return inst.reject("fmi2SetDebugLogging: NULL categories");
    inst.logging_on = loggingOn != fmi2False;
    if (nCategories == 0)
      for (bool& on : inst.category_on) on = inst.logging_on;
    for (size_t i = 0; i < nCategories; ++i) {
      int k = -1;
      for (int j = 0; j < kCategoryCount; ++j)
        if (categories[i] && std::strcmp(categories[i], kCategories[j]) == 0) k = j;
      if (k < 0)
        return inst.reject(std::string("fmi2SetDebugLogging: unknown log category '") +
                           (categories[i] ? categories[i] : "(null)") + "'");
      inst.category_on[k] = loggingOn != fmi2False;
    }
    return fmi2OK;
  });
}

fmi2Status fmi2SetupExperiment(fmi2Component c,
                               fmi2Boolean toleranceDefined,
                               fmi2Real tolerance,
                               fmi2Real startTime,
                               fmi2Boolean stopTimeDefined,
                               fmi2Real stopTime) {
  (void)toleranceDefined, (void)tolerance, (void)stopTimeDefined, (void)stopTime;
  return guarded(c, "fmi2SetupExperiment", kInstantiated, [&](Instance& inst) {
    if (!std::isfinite(startTime)) return inst.reject("fmi2SetupExperiment: start time not finite");
    inst.model->set_time(startTime);
    return fmi2OK;
  });
}

fmi2Status fmi2EnterInitializationMode(fmi2Component c) {
  return guarded(c, "fmi2EnterInitializationMode", kInstantiated, [&](Instance& inst) {
    inst.state = kInitializationMode;
    return fmi2OK;
  });
}

fmi2Status fmi2ExitInitializationMode(fmi2Component c) {
  return guarded(c, "fmi2ExitInitializationMode", kInitializationMode, [&](Instance& inst) {
    std::string msg;
    if (inst.model->validate(&msg) != Status::ok) return inst.error(msg);
    inst.state = inst.type == fmi2ModelExchange ? kEventMode : kStepComplete;
    return fmi2OK;
  });
}

fmi2Status fmi2Terminate(fmi2Component c) {
  return guarded(c, "fmi2Terminate", kEventMode | kContinuousTimeMode | kStepComplete | kError,
                 [&](Instance& inst) {
                   inst.state = kTerminated;
                   return fmi2OK;
                 });
}

fmi2Status fmi2Reset(fmi2Component c) {
  return guarded(c, "fmi2Reset", kAnyState, [&](Instance& inst) {
    inst.model->reset();
    inst.state = kInstantiated;
    return fmi2OK;
  });
}

fmi2Status fmi2GetReal(fmi2Component c,
                       const fmi2ValueReference vr[],
                       size_t nvr,
                       fmi2Real value[]) {
  return guarded(c, "fmi2GetReal", kGetMask, [&](Instance& inst) {
    if (check_array(inst, "fmi2GetReal", vr, nvr, value) != fmi2OK) return fmi2Error;
    fmi2Status worst = fmi2OK;
    for (size_t i = 0; i < nvr; ++i) {
      const Variable* v = lookup(inst, "fmi2GetReal", vr[i], false);
      if (!v) return fmi2Error;
      std::string msg;
      const Status s = inst.model->get_real(*v, &value[i], &msg);
      if (s != Status::ok) {
        const fmi2Status f = inst.from(s, "fmi2GetReal: " + msg);
        if (f == fmi2Error) return f;
        if (f > worst) worst = f;
      }
    }
    return worst;
  });
}

fmi2Status fmi2GetInteger(fmi2Component c,
                          const fmi2ValueReference vr[],
                          size_t nvr,
                          fmi2Integer value[]) {
  return guarded(c, "fmi2GetInteger", kGetMask, [&](Instance& inst) {
    if (check_array(inst, "fmi2GetInteger", vr, nvr, value) != fmi2OK) return fmi2Error;
    for (size_t i = 0; i < nvr; ++i) {
      const Variable* v = lookup(inst, "fmi2GetInteger", vr[i], true);
      if (!v) return fmi2Error;
      value[i] = static_cast<fmi2Integer>(inst.model->get_integer(*v));
    }
    return fmi2OK;
  });
}

fmi2Status fmi2GetBoolean(fmi2Component c,
                          const fmi2ValueReference vr[],
                          size_t nvr,
                          fmi2Boolean value[]) {
  (void)vr, (void)value;
  return guarded(c, "fmi2GetBoolean", kGetMask, [&](Instance& inst) {
    return nvr == 0 ? fmi2OK : inst.reject("fmi2GetBoolean: this FMU has no Boolean variables");
  });
}

fmi2Status fmi2GetString(fmi2Component c,
                         const fmi2ValueReference vr[],
                         size_t nvr,
                         fmi2String value[]) {
  (void)vr, (void)value;
  return guarded(c, "fmi2GetString", kGetMask, [&](Instance& inst) {
    return nvr == 0 ? fmi2OK : inst.reject("fmi2GetString: this FMU has no String variables");
  });
}

fmi2Status fmi2SetReal(fmi2Component c,
                       const fmi2ValueReference vr[],
                       size_t nvr,
                       const fmi2Real value[]) {
  return guarded(c, "fmi2SetReal", kSetMask, [&](Instance& inst) {
    if (check_array(inst, "fmi2SetReal", vr, nvr, value) != fmi2OK) return fmi2Error;
    for (size_t i = 0; i < nvr; ++i) {
      const Variable* v = lookup(inst, "fmi2SetReal", vr[i], false);
      if (!v) return fmi2Error;
      if (v->role == stiff::fmu::Role::parameter && inst.state == kContinuousTimeMode)
        return inst.reject("fmi2SetReal: parameter '" + v->name +
                           "' cannot be set in Continuous-Time Mode");
      std::string msg;
      const Status s = inst.model->set_real(*v, &value[i], &msg);
      if (s != Status::ok) return inst.from(s, "fmi2SetReal: " + msg);
    }
    return fmi2OK;
  });
}

fmi2Status fmi2SetInteger(fmi2Component c,
                          const fmi2ValueReference vr[],
                          size_t nvr,
                          const fmi2Integer value[]) {
  return guarded(c, "fmi2SetInteger", kSetMask & ~unsigned{kContinuousTimeMode},
                 [&](Instance& inst) {
                   if (check_array(inst, "fmi2SetInteger", vr, nvr, value) != fmi2OK)
                     return fmi2Error;
                   for (size_t i = 0; i < nvr; ++i) {
                     const Variable* v = lookup(inst, "fmi2SetInteger", vr[i], true);
                     if (!v) return fmi2Error;
                     std::string msg;
                     const Status s = inst.model->set_integer(*v, value[i], &msg);
                     if (s != Status::ok) return inst.from(s, "fmi2SetInteger: " + msg);
                   }
                   return fmi2OK;
                 });
}

fmi2Status fmi2SetBoolean(fmi2Component c,
                          const fmi2ValueReference vr[],
                          size_t nvr,
                          const fmi2Boolean value[]) {
  (void)vr, (void)value;
  return guarded(c, "fmi2SetBoolean", kSetMask, [&](Instance& inst) {
    return nvr == 0 ? fmi2OK : inst.reject("fmi2SetBoolean: this FMU has no Boolean variables");
  });
}

fmi2Status fmi2SetString(fmi2Component c,
                         const fmi2ValueReference vr[],
                         size_t nvr,
                         const fmi2String value[]) {
  (void)vr, (void)value;
  return guarded(c, "fmi2SetString", kSetMask, [&](Instance& inst) {
    return nvr == 0 ? fmi2OK : inst.reject("fmi2SetString: this FMU has no String variables");
  });
}

// FMU state: a heap copy of the instance's values and state-machine state.
struct StateCopy {
  stiff::fmu::Values values;
  unsigned state;
};

fmi2Status fmi2GetFMUstate(fmi2Component c, fmi2FMUstate* FMUstate) {
  return guarded(c, "fmi2GetFMUstate", kAnyState, [&](Instance& inst) {
    if (!FMUstate) return inst.reject("fmi2GetFMUstate: NULL FMUstate");
    auto* copy = static_cast<StateCopy*>(*FMUstate);
    if (copy) {
      copy->values = inst.model->save();
      copy->state = inst.state;
    } else {
      *FMUstate = new StateCopy{inst.model->save(), inst.state};
    }
    return fmi2OK;
  });
}

fmi2Status fmi2SetFMUstate(fmi2Component c, fmi2FMUstate FMUstate) {
  return guarded(c, "fmi2SetFMUstate", kAnyState, [&](Instance& inst) {
    if (!FMUstate) return inst.reject("fmi2SetFMUstate: NULL FMUstate");
    const auto* copy = static_cast<const StateCopy*>(FMUstate);
    if (copy->values.q.size() != static_cast<size_t>(inst.model->dof()) ||
        copy->values.theta.size() != inst.model->values().theta.size())
      return inst.reject("fmi2SetFMUstate: state of another model");
    inst.model->restore(copy->values);
    inst.state = copy->state;
    return fmi2OK;
  });
}

fmi2Status fmi2FreeFMUstate(fmi2Component c, fmi2FMUstate* FMUstate) {
  return guarded(c, "fmi2FreeFMUstate", kAnyState, [&](Instance& inst) {
    if (!FMUstate) return inst.reject("fmi2FreeFMUstate: NULL FMUstate");
    delete static_cast<StateCopy*>(*FMUstate);
    *FMUstate = nullptr;
    return fmi2OK;
  });
}

// Serialized form: the model's blob followed by the state-machine state (u32).
static std::vector<uint8_t> serialize_state(Instance& inst, const StateCopy& copy) {
  const stiff::fmu::Values now = inst.model->save();
  inst.model->restore(copy.values);
  std::vector<uint8_t> b = inst.model->serialize();
  inst.model->restore(now);
  const uint32_t st = copy.state;
  b.insert(b.end(), reinterpret_cast<const uint8_t*>(&st),
           reinterpret_cast<const uint8_t*>(&st) + 4);
  return b;
}

fmi2Status fmi2SerializedFMUstateSize(fmi2Component c, fmi2FMUstate FMUstate, size_t* size) {
  return guarded(c, "fmi2SerializedFMUstateSize", kAnyState, [&](Instance& inst) {
    if (!FMUstate || !size) return inst.reject("fmi2SerializedFMUstateSize: NULL argument");
    *size = serialize_state(inst, *static_cast<const StateCopy*>(FMUstate)).size();
    return fmi2OK;
  });
}

fmi2Status fmi2SerializeFMUstate(fmi2Component c,
                                 fmi2FMUstate FMUstate,
                                 fmi2Byte serializedState[],
                                 size_t size) {
  return guarded(c, "fmi2SerializeFMUstate", kAnyState, [&](Instance& inst) {
    if (!FMUstate || !serializedState) return inst.reject("fmi2SerializeFMUstate: NULL argument");
    const auto b = serialize_state(inst, *static_cast<const StateCopy*>(FMUstate));
    if (size < b.size())
      return inst.reject("fmi2SerializeFMUstate: buffer of " + std::to_string(size) + " bytes, " +
                         std::to_string(b.size()) + " needed");
    std::memcpy(serializedState, b.data(), b.size());
    return fmi2OK;
  });
}

fmi2Status fmi2DeSerializeFMUstate(fmi2Component c,
                                   const fmi2Byte serializedState[],
                                   size_t size,
                                   fmi2FMUstate* FMUstate) {
  return guarded(c, "fmi2DeSerializeFMUstate", kAnyState, [&](Instance& inst) {
    if (!serializedState || !FMUstate) return inst.reject("fmi2DeSerializeFMUstate: NULL argument");
    if (size < 4) return inst.reject("fmi2DeSerializeFMUstate: blob too short");
    const auto* bytes = reinterpret_cast<const uint8_t*>(serializedState);
    uint32_t st = 0;
    std::memcpy(&st, bytes + size - 4, 4);
    const stiff::fmu::Values now = inst.model->save();
    std::string msg;
    if (!inst.model->deserialize(bytes, size - 4, &msg))
      return inst.reject("fmi2DeSerializeFMUstate: " + msg);
    auto copy = std::make_unique<StateCopy>(StateCopy{inst.model->save(), st});
    inst.model->restore(now);
    if (st == 0 || (st & (st - 1)) != 0 || st > kError)
      return inst.reject("fmi2DeSerializeFMUstate: invalid state in blob");
    if (*FMUstate) {
      *static_cast<StateCopy*>(*FMUstate) = *copy;
    } else {
      *FMUstate = copy.release();
    }
    return fmi2OK;
  });
}

fmi2Status fmi2GetDirectionalDerivative(fmi2Component c,
                                        const fmi2ValueReference vUnknown_ref[],
                                        size_t nUnknown,
                                        const fmi2ValueReference vKnown_ref[],
                                        size_t nKnown,
                                        const fmi2Real dvKnown[],
                                        fmi2Real dvUnknown[]) {
  (void)vUnknown_ref, (void)nUnknown, (void)vKnown_ref, (void)nKnown, (void)dvKnown,
      (void)dvUnknown;
  return not_supported(c, "fmi2GetDirectionalDerivative");
}

// Model Exchange: the model is algebraic (no states, no event indicators).
fmi2Status fmi2EnterEventMode(fmi2Component c) {
  return guarded(c, "fmi2EnterEventMode", kEventMode | kContinuousTimeMode, [&](Instance& inst) {
    inst.state = kEventMode;
    return fmi2OK;
  });
}

fmi2Status fmi2NewDiscreteStates(fmi2Component c, fmi2EventInfo* info) {
  return guarded(c, "fmi2NewDiscreteStates", kEventMode, [&](Instance& inst) {
    if (!info) return inst.reject("fmi2NewDiscreteStates: NULL eventInfo");
    info->newDiscreteStatesNeeded = fmi2False;
    info->terminateSimulation = fmi2False;
    info->nominalsOfContinuousStatesChanged = fmi2False;
    info->valuesOfContinuousStatesChanged = fmi2False;
    info->nextEventTimeDefined = fmi2False;
    info->nextEventTime = 0.0;
    return fmi2OK;
  });
}

fmi2Status fmi2EnterContinuousTimeMode(fmi2Component c) {
  return guarded(c, "fmi2EnterContinuousTimeMode", kEventMode, [&](Instance& inst) {
    inst.state = kContinuousTimeMode;
    return fmi2OK;
  });
}

fmi2Status fmi2CompletedIntegratorStep(fmi2Component c,
                                       fmi2Boolean noSetFMUStatePriorToCurrentPoint,
                                       fmi2Boolean* enterEventMode,
                                       fmi2Boolean* terminateSimulation) {
  (void)noSetFMUStatePriorToCurrentPoint;
  return guarded(c, "fmi2CompletedIntegratorStep", kContinuousTimeMode, [&](Instance& inst) {
    if (!enterEventMode || !terminateSimulation)
      return inst.reject("fmi2CompletedIntegratorStep: NULL argument");
    *enterEventMode = fmi2False;
    *terminateSimulation = fmi2False;
    return fmi2OK;
  });
}

fmi2Status fmi2SetTime(fmi2Component c, fmi2Real time) {
  return guarded(c, "fmi2SetTime", kEventMode | kContinuousTimeMode, [&](Instance& inst) {
    if (!std::isfinite(time)) return inst.reject("fmi2SetTime: time is not finite");
    inst.model->set_time(time);
    return fmi2OK;
  });
}

fmi2Status fmi2SetContinuousStates(fmi2Component c, const fmi2Real x[], size_t nx) {
  (void)x;
  return guarded(c, "fmi2SetContinuousStates", kContinuousTimeMode, [&](Instance& inst) {
    return nx == 0 ? fmi2OK : inst.reject("fmi2SetContinuousStates: the FMU has no states");
  });
}

fmi2Status fmi2GetDerivatives(fmi2Component c, fmi2Real derivatives[], size_t nx) {
  (void)derivatives;
  return guarded(c, "fmi2GetDerivatives", kGetMask, [&](Instance& inst) {
    return nx == 0 ? fmi2OK : inst.reject("fmi2GetDerivatives: the FMU has no states");
  });
}

fmi2Status fmi2GetEventIndicators(fmi2Component c, fmi2Real eventIndicators[], size_t ni) {
  (void)eventIndicators;
  return guarded(c, "fmi2GetEventIndicators", kGetMask, [&](Instance& inst) {
    return ni == 0 ? fmi2OK
                   : inst.reject("fmi2GetEventIndicators: the FMU has no event indicators");
  });
}

fmi2Status fmi2GetContinuousStates(fmi2Component c, fmi2Real x[], size_t nx) {
  (void)x;
  return guarded(c, "fmi2GetContinuousStates", kGetMask, [&](Instance& inst) {
    return nx == 0 ? fmi2OK : inst.reject("fmi2GetContinuousStates: the FMU has no states");
  });
}

fmi2Status fmi2GetNominalsOfContinuousStates(fmi2Component c, fmi2Real x_nominal[], size_t nx) {
  (void)x_nominal;
  return guarded(c, "fmi2GetNominalsOfContinuousStates", kGetMask, [&](Instance& inst) {
    return nx == 0 ? fmi2OK
                   : inst.reject("fmi2GetNominalsOfContinuousStates: the FMU has no states");
  });
}

// Co-Simulation.
fmi2Status fmi2SetRealInputDerivatives(fmi2Component c,
                                       const fmi2ValueReference vr[],
                                       size_t nvr,
                                       const fmi2Integer order[],
                                       const fmi2Real value[]) {
  (void)vr, (void)nvr, (void)order, (void)value;
  return not_supported(c, "fmi2SetRealInputDerivatives");
}

fmi2Status fmi2GetRealOutputDerivatives(fmi2Component c,
                                        const fmi2ValueReference vr[],
                                        size_t nvr,
                                        const fmi2Integer order[],
                                        fmi2Real value[]) {
  (void)vr, (void)nvr, (void)order, (void)value;
  return not_supported(c, "fmi2GetRealOutputDerivatives");
}

fmi2Status fmi2DoStep(fmi2Component c,
                      fmi2Real currentCommunicationPoint,
                      fmi2Real communicationStepSize,
                      fmi2Boolean noSetFMUStatePriorToCurrentPoint) {
  (void)noSetFMUStatePriorToCurrentPoint;
  return guarded(c, "fmi2DoStep", kStepComplete, [&](Instance& inst) {
    if (inst.type != fmi2CoSimulation) return inst.reject("fmi2DoStep: instance is not CS");
    if (!(communicationStepSize > 0) || !std::isfinite(communicationStepSize))
      return inst.reject(
          stiff::fmu::format("fmi2DoStep: step size %g must be > 0", communicationStepSize));
    const double t = inst.model->values().time;
    if (!(std::fabs(currentCommunicationPoint - t) <= 1e-9 * std::max(1.0, std::fabs(t))))
      return inst.reject(stiff::fmu::format(
          "fmi2DoStep: communication point %.17g differs from the FMU time %.17g",
          currentCommunicationPoint, t));
    inst.model->set_time(currentCommunicationPoint + communicationStepSize);
    return fmi2OK;
  });
}

fmi2Status fmi2CancelStep(fmi2Component c) { return not_supported(c, "fmi2CancelStep"); }

fmi2Status fmi2GetStatus(fmi2Component c, const fmi2StatusKind s, fmi2Status* value) {
  (void)s, (void)value;
  return not_supported(c, "fmi2GetStatus");
}
fmi2Status fmi2GetRealStatus(fmi2Component c, const fmi2StatusKind s, fmi2Real* value) {
  return guarded(c, "fmi2GetRealStatus", kGetMask, [&](Instance& inst) {
    if (s != fmi2LastSuccessfulTime || !value)
      return inst.reject("fmi2GetRealStatus: only fmi2LastSuccessfulTime is supported");
    *value = inst.model->values().time;
    return fmi2OK;
  });
}
fmi2Status fmi2GetIntegerStatus(fmi2Component c, const fmi2StatusKind s, fmi2Integer* value) {
  (void)s, (void)value;
  return not_supported(c, "fmi2GetIntegerStatus");
}
fmi2Status fmi2GetBooleanStatus(fmi2Component c, const fmi2StatusKind s, fmi2Boolean* value) {
  (void)s, (void)value;
  return not_supported(c, "fmi2GetBooleanStatus");
}
fmi2Status fmi2GetStringStatus(fmi2Component c, const fmi2StatusKind s, fmi2String* value) {
  (void)s, (void)value;
  return not_supported(c, "fmi2GetStringStatus");
}

}  // extern "C"
