// FMI 3.0 glue (Model Exchange and Co-Simulation; Scheduled Execution is refused): state
// machine, argument checks, logging with the declared categories, FMU state. The model is in
// model.cpp, shared with fmi2_glue.cpp.
#include <cmath>
#include <cstring>
#include <exception>
#include <memory>
#include <new>
#include <string>

#include "fmi3Functions.h"
#include "glue_util.h"
#include "model.h"

namespace {

using stiff::fmu::Model;
using stiff::fmu::Role;
using stiff::fmu::Status;
using stiff::fmu::Variable;

enum State : unsigned {
  kInstantiated = 1u << 0,
  kInitializationMode = 1u << 1,
  kEventMode = 1u << 2,
  kContinuousTimeMode = 1u << 3,
  kStepMode = 1u << 4,
  kTerminated = 1u << 5,
  kError = 1u << 6,
};
constexpr unsigned kAnyState = ~0u;
constexpr unsigned kGetMask =
    kInitializationMode | kEventMode | kContinuousTimeMode | kStepMode | kTerminated | kError;
constexpr unsigned kSetMask =
    kInstantiated | kInitializationMode | kEventMode | kContinuousTimeMode | kStepMode;

constexpr const char* kCategories[] = {"logStatusError", "logStatusWarning", "logCalls"};
enum Category { kLogError, kLogWarning, kLogCalls, kCategoryCount };

enum class Kind { me, cs };

struct Instance {
  std::string name;
  Kind kind = Kind::cs;
  fmi3InstanceEnvironment env = nullptr;
  fmi3LogMessageCallback logger = nullptr;
  bool logging_on = false;
  bool category_on[kCategoryCount] = {true, true, true};
  unsigned state = kInstantiated;
  std::unique_ptr<Model> model;

  void log(fmi3Status status, Category c, const std::string& msg) const {
    if (status == fmi3OK && (!logging_on || !category_on[c])) return;
    if (logger) logger(env, status, kCategories[c], msg.c_str());
  }
  fmi3Status error(const std::string& msg) {
    log(fmi3Error, kLogError, msg);
    state = kError;
    return fmi3Error;
  }
  fmi3Status reject(const std::string& msg) {
    log(fmi3Error, kLogError, msg);
    return fmi3Error;
  }
  fmi3Status from(Status s, const std::string& msg) {
    switch (s) {
      case Status::ok:
        return fmi3OK;
      case Status::warning:
        log(fmi3Warning, kLogWarning, msg);
        return fmi3Warning;
      case Status::discard:
        log(fmi3Discard, kLogWarning, msg);
        return fmi3Discard;
      default:
        return error(msg);
    }
  }
  bool allowed(const char* f, unsigned mask) {
    if (state & mask) return true;
    log(fmi3Error, kLogError, std::string(f) + " is not allowed in the current state");
    return false;
  }
};

template <typename Body>
fmi3Status guarded(fmi3Instance c, const char* f, unsigned mask, Body&& body) {
  if (!c) return fmi3Error;
  auto* inst = static_cast<Instance*>(c);
  if (!inst->allowed(f, mask)) return fmi3Error;
  inst->log(fmi3OK, kLogCalls, f);
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

enum class Type { float64, int32 };

// Look up the variables, check their type and that nValues is the sum of their sizes.
bool check_refs(Instance& inst,
                const char* f,
                const fmi3ValueReference* vr,
                size_t nvr,
                const void* values,
                size_t nValues,
                Type type) {
  if (nvr > 0 && (!vr || !values)) return inst.reject(std::string(f) + ": NULL argument"), false;
  size_t total = 0;
  for (size_t i = 0; i < nvr; ++i) {
    const Variable* v = inst.model->variable(vr[i]);
    if (!v)
      return inst.reject(std::string(f) + ": unknown value reference " + std::to_string(vr[i])),
             false;
    if (v->is_integer() != (type == Type::int32))
      return inst.reject(std::string(f) + ": value reference " + std::to_string(vr[i]) + " ('" +
                         v->name + "') has another type"),
             false;
    total += v->size(inst.model->dof());
  }
  if (total != nValues)
    return inst.reject(std::string(f) + ": nValues is " + std::to_string(nValues) + ", the " +
                       std::to_string(nvr) + " variables hold " + std::to_string(total)),
           false;
  return true;
}

fmi3Status not_supported(fmi3Instance c, const char* f) {
  if (!c) return fmi3Error;
  return static_cast<Instance*>(c)->reject(std::string(f) + " is not supported by this FMU");
}

fmi3Instance instantiate(Kind kind,
                         fmi3String instanceName,
                         fmi3String token,
                         fmi3String resourcePath,
                         fmi3Boolean loggingOn,
                         fmi3InstanceEnvironment env,
                         fmi3LogMessageCallback logger) {
  auto say = [&](const std::string& msg) {
    if (logger) logger(env, fmi3Error, kCategories[kLogError], msg.c_str());
  };
  if (!instanceName || !*instanceName)
    return say("fmi3Instantiate: missing instance name"), nullptr;
  if (!token || !*token) return say("fmi3Instantiate: missing instantiationToken"), nullptr;
  if (!resourcePath || !*resourcePath) return say("fmi3Instantiate: missing resourcePath"), nullptr;
  try {
    auto layout = stiff::fmu::read_layout(resourcePath);
    if (layout->fmi != 3) return say("fmi3Instantiate: resources are for FMI 2"), nullptr;
    if (layout->guid != token)
      return say(std::string("fmi3Instantiate: instantiationToken '") + token +
                 "' does not match the resources' token '" + layout->guid + "'"),
             nullptr;
    auto inst = std::make_unique<Instance>();
    inst->name = instanceName;
    inst->kind = kind;
    inst->env = env;
    inst->logger = logger;
    inst->logging_on = loggingOn;
    inst->model = std::make_unique<Model>(std::move(layout));
    inst->log(fmi3OK, kLogCalls, "fmi3Instantiate");
    return inst.release();
  } catch (const std::exception& e) {
    say(std::string("fmi3Instantiate: ") + e.what());
  } catch (...) {
    say("fmi3Instantiate: unknown exception");
  }
  return nullptr;
}

struct StateCopy {
  stiff::fmu::Values values;
  unsigned state;
};

std::vector<uint8_t> serialize_state(Instance& inst, const StateCopy& copy) {
  const stiff::fmu::Values now = inst.model->save();
  inst.model->restore(copy.values);
  std::vector<uint8_t> b = inst.model->serialize();
  inst.model->restore(now);
  const uint32_t st = copy.state;
  b.insert(b.end(), reinterpret_cast<const uint8_t*>(&st),
           reinterpret_cast<const uint8_t*>(&st) + 4);
  return b;
}

}  // namespace

#define STIFF_NO_VARIABLES(Func, CType)                                                      \
  fmi3Status Func(fmi3Instance c, const fmi3ValueReference vr[], size_t nvr, CType values[], \
                  size_t nValues) {                                                          \
    (void)vr, (void)values, (void)nValues;                                                   \
    return guarded(c, #Func, kAnyState, [&](Instance& inst) {                                \
      return nvr == 0 ? fmi3OK : inst.reject(#Func ": this FMU has no such variables");      \
    });                                                                                      \
  }

extern "C" {

const char* fmi3GetVersion(void) { return fmi3Version; }

fmi3Instance fmi3InstantiateModelExchange(fmi3String instanceName,
                                          fmi3String instantiationToken,
                                          fmi3String resourcePath,
                                          fmi3Boolean visible,
                                          fmi3Boolean loggingOn,
                                          fmi3InstanceEnvironment instanceEnvironment,
                                          fmi3LogMessageCallback logMessage) {
  (void)visible;
  return instantiate(Kind::me, instanceName, instantiationToken, resourcePath, loggingOn,
                     instanceEnvironment, logMessage);
}

fmi3Instance fmi3InstantiateCoSimulation(fmi3String instanceName,
                                         fmi3String instantiationToken,
                                         fmi3String resourcePath,
                                         fmi3Boolean visible,
                                         fmi3Boolean loggingOn,
                                         fmi3Boolean eventModeUsed,
                                         fmi3Boolean earlyReturnAllowed,
                                         const fmi3ValueReference requiredIntermediateVariables[],
                                         size_t nRequiredIntermediateVariables,
                                         fmi3InstanceEnvironment instanceEnvironment,
                                         fmi3LogMessageCallback logMessage,
                                         fmi3IntermediateUpdateCallback intermediateUpdate) {
  (void)visible, (void)eventModeUsed, (void)earlyReturnAllowed, (void)requiredIntermediateVariables,
      (void)nRequiredIntermediateVariables, (void)intermediateUpdate;
  return instantiate(Kind::cs, instanceName, instantiationToken, resourcePath, loggingOn,
                     instanceEnvironment, logMessage);
}

fmi3Instance fmi3InstantiateScheduledExecution(fmi3String instanceName,
                                               fmi3String instantiationToken,
                                               fmi3String resourcePath,
                                               fmi3Boolean visible,
                                               fmi3Boolean loggingOn,
                                               fmi3InstanceEnvironment instanceEnvironment,
                                               fmi3LogMessageCallback logMessage,
                                               fmi3ClockUpdateCallback clockUpdate,
                                               fmi3LockPreemptionCallback lockPreemption,
                                               fmi3UnlockPreemptionCallback unlockPreemption) {
  (void)instanceName, (void)instantiationToken, (void)resourcePath, (void)visible, (void)loggingOn,
      (void)clockUpdate, (void)lockPreemption, (void)unlockPreemption;
  if (logMessage)
    logMessage(instanceEnvironment, fmi3Error, kCategories[kLogError],
               "fmi3InstantiateScheduledExecution: not supported by this FMU");
  return nullptr;
}

void fmi3FreeInstance(fmi3Instance c) {
  if (!c) return;
  auto* inst = static_cast<Instance*>(c);
  inst->log(fmi3OK, kLogCalls, "fmi3FreeInstance");
  delete inst;
}

fmi3Status fmi3SetDebugLogging(fmi3Instance c,
                               fmi3Boolean loggingOn,
                               size_t nCategories,
                               const fmi3String categories[]) {
  return guarded(c, "fmi3SetDebugLogging", kAnyState, [&](Instance& inst) {
    if (nCategories > 0 && !categories) return inst.reject("fmi3SetDebugLogging: NULL categories");
    inst.logging_on = loggingOn;
    if (nCategories == 0)
      for (bool& on : inst.category_on) on = loggingOn;
    for (size_t i = 0; i < nCategories; ++i) {
      int k = -1;
      for (int j = 0; j < kCategoryCount; ++j)
        if (categories[i] && std::strcmp(categories[i], kCategories[j]) == 0) k = j;
      if (k < 0)
        return inst.reject(std::string("fmi3SetDebugLogging: unknown log category '") +
                           (categories[i] ? categories[i] : "(null)") + "'");
      inst.category_on[k] = loggingOn;
    }
    return fmi3OK;
  });
}

fmi3Status fmi3EnterInitializationMode(fmi3Instance c,
                                       fmi3Boolean toleranceDefined,
                                       fmi3Float64 tolerance,
                                       fmi3Float64 startTime,
                                       fmi3Boolean stopTimeDefined,
                                       fmi3Float64 stopTime) {
  (void)toleranceDefined, (void)tolerance, (void)stopTimeDefined, (void)stopTime;
  return guarded(c, "fmi3EnterInitializationMode", kInstantiated, [&](Instance& inst) {
    if (!std::isfinite(startTime))
      return inst.reject("fmi3EnterInitializationMode: start time not finite");
    inst.model->set_time(startTime);
    inst.state = kInitializationMode;
    return fmi3OK;
  });
}

fmi3Status fmi3ExitInitializationMode(fmi3Instance c) {
  return guarded(c, "fmi3ExitInitializationMode", kInitializationMode, [&](Instance& inst) {
    std::string msg;
    if (inst.model->validate(&msg) != Status::ok) return inst.error(msg);
    inst.state = inst.kind == Kind::me ? kEventMode : kStepMode;
    return fmi3OK;
  });
}

fmi3Status fmi3EnterEventMode(fmi3Instance c) {
  return guarded(c, "fmi3EnterEventMode", kEventMode | kContinuousTimeMode | kStepMode,
                 [&](Instance& inst) {
                   if (inst.kind != Kind::me)
                     return inst.reject("fmi3EnterEventMode: event mode is not used in CS");
                   inst.state = kEventMode;
                   return fmi3OK;
                 });
}

fmi3Status fmi3Terminate(fmi3Instance c) {
  return guarded(c, "fmi3Terminate", kEventMode | kContinuousTimeMode | kStepMode | kError,
                 [&](Instance& inst) {
                   inst.state = kTerminated;
                   return fmi3OK;
                 });
}

fmi3Status fmi3Reset(fmi3Instance c) {
  return guarded(c, "fmi3Reset", kAnyState, [&](Instance& inst) {
    inst.model->reset();
    inst.state = kInstantiated;
    return fmi3OK;
  });
}

fmi3Status fmi3GetFloat64(fmi3Instance c,
                          const fmi3ValueReference vr[],
                          size_t nvr,
                          fmi3Float64 values[],
                          size_t nValues) {
  return guarded(c, "fmi3GetFloat64", kGetMask, [&](Instance& inst) {
    if (!check_refs(inst, "fmi3GetFloat64", vr, nvr, values, nValues, Type::float64))
      return fmi3Error;
    fmi3Status worst = fmi3OK;
    size_t at = 0;
    for (size_t i = 0; i < nvr; ++i) {
      const Variable& v = *inst.model->variable(vr[i]);
      std::string msg;
      const Status s = inst.model->get_real(v, &values[at], &msg);
      at += v.size(inst.model->dof());
      if (s != Status::ok) {
        const fmi3Status f = inst.from(s, "fmi3GetFloat64: " + msg);
        if (f == fmi3Error) return f;
        if (f > worst) worst = f;
      }
    }
    return worst;
  });
}

fmi3Status fmi3SetFloat64(fmi3Instance c,
                          const fmi3ValueReference vr[],
                          size_t nvr,
                          const fmi3Float64 values[],
                          size_t nValues) {
  return guarded(c, "fmi3SetFloat64", kSetMask, [&](Instance& inst) {
    if (!check_refs(inst, "fmi3SetFloat64", vr, nvr, values, nValues, Type::float64))
      return fmi3Error;
    size_t at = 0;
    for (size_t i = 0; i < nvr; ++i) {
      const Variable& v = *inst.model->variable(vr[i]);
      if (v.role == Role::parameter && inst.state == kContinuousTimeMode)
        return inst.reject("fmi3SetFloat64: parameter '" + v.name +
                           "' cannot be set in Continuous-Time Mode");
      std::string msg;
      const Status s = inst.model->set_real(v, &values[at], &msg);
      at += v.size(inst.model->dof());
      if (s != Status::ok) return inst.from(s, "fmi3SetFloat64: " + msg);
    }
    return fmi3OK;
  });
}

fmi3Status fmi3GetInt32(
    fmi3Instance c, const fmi3ValueReference vr[], size_t nvr, fmi3Int32 values[], size_t nValues) {
  return guarded(c, "fmi3GetInt32", kGetMask, [&](Instance& inst) {
    if (!check_refs(inst, "fmi3GetInt32", vr, nvr, values, nValues, Type::int32)) return fmi3Error;
    for (size_t i = 0; i < nvr; ++i)
      values[i] = static_cast<fmi3Int32>(inst.model->get_integer(*inst.model->variable(vr[i])));
    return fmi3OK;
  });
}

fmi3Status fmi3SetInt32(fmi3Instance c,
                        const fmi3ValueReference vr[],
                        size_t nvr,
                        const fmi3Int32 values[],
                        size_t nValues) {
  return guarded(c, "fmi3SetInt32", kInstantiated | kInitializationMode | kEventMode | kStepMode,
                 [&](Instance& inst) {
                   if (!check_refs(inst, "fmi3SetInt32", vr, nvr, values, nValues, Type::int32))
                     return fmi3Error;
                   for (size_t i = 0; i < nvr; ++i) {
                     std::string msg;
                     const Status s =
                         inst.model->set_integer(*inst.model->variable(vr[i]), values[i], &msg);
                     if (s != Status::ok) return inst.from(s, "fmi3SetInt32: " + msg);
                   }
                   return fmi3OK;
                 });
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

fmi3Status fmi3GetBinary(fmi3Instance c,
                         const fmi3ValueReference vr[],
                         size_t nvr,
                         size_t valueSizes[],
                         fmi3Binary values[],
                         size_t nValues) {
  (void)vr, (void)nvr, (void)valueSizes, (void)values, (void)nValues;
  return not_supported(c, "fmi3GetBinary");
}
fmi3Status fmi3SetBinary(fmi3Instance c,
                         const fmi3ValueReference vr[],
                         size_t nvr,
                         const size_t valueSizes[],
                         const fmi3Binary values[],
                         size_t nValues) {
  (void)vr, (void)nvr, (void)valueSizes, (void)values, (void)nValues;
  return not_supported(c, "fmi3SetBinary");
}
fmi3Status fmi3GetClock(fmi3Instance c,
                        const fmi3ValueReference vr[],
                        size_t nvr,
                        fmi3Clock values[]) {
  (void)vr, (void)nvr, (void)values;
  return not_supported(c, "fmi3GetClock");
}
fmi3Status fmi3SetClock(fmi3Instance c,
                        const fmi3ValueReference vr[],
                        size_t nvr,
                        const fmi3Clock values[]) {
  (void)vr, (void)nvr, (void)values;
  return not_supported(c, "fmi3SetClock");
}

fmi3Status fmi3GetNumberOfVariableDependencies(fmi3Instance c,
                                               fmi3ValueReference vr,
                                               size_t* nDependencies) {
  (void)vr, (void)nDependencies;
  return not_supported(c, "fmi3GetNumberOfVariableDependencies");
}
fmi3Status fmi3GetVariableDependencies(fmi3Instance c,
                                       fmi3ValueReference dependent,
                                       size_t elementIndicesOfDependent[],
                                       fmi3ValueReference independents[],
                                       size_t elementIndicesOfIndependents[],
                                       fmi3DependencyKind dependencyKinds[],
                                       size_t nDependencies) {
  (void)dependent, (void)elementIndicesOfDependent, (void)independents,
      (void)elementIndicesOfIndependents, (void)dependencyKinds, (void)nDependencies;
  return not_supported(c, "fmi3GetVariableDependencies");
}

fmi3Status fmi3GetFMUState(fmi3Instance c, fmi3FMUState* FMUState) {
  return guarded(c, "fmi3GetFMUState", kAnyState, [&](Instance& inst) {
    if (!FMUState) return inst.reject("fmi3GetFMUState: NULL FMUState");
    auto* copy = static_cast<StateCopy*>(*FMUState);
    if (copy) {
      copy->values = inst.model->save();
      copy->state = inst.state;
    } else {
      *FMUState = new StateCopy{inst.model->save(), inst.state};
    }
    return fmi3OK;
  });
}

fmi3Status fmi3SetFMUState(fmi3Instance c, fmi3FMUState FMUState) {
  return guarded(c, "fmi3SetFMUState", kAnyState, [&](Instance& inst) {
    if (!FMUState) return inst.reject("fmi3SetFMUState: NULL FMUState");
    const auto* copy = static_cast<const StateCopy*>(FMUState);
    if (copy->values.q.size() != static_cast<size_t>(inst.model->dof()) ||
        copy->values.theta.size() != inst.model->values().theta.size())
      return inst.reject("fmi3SetFMUState: state of another model");
    inst.model->restore(copy->values);
    inst.state = copy->state;
    return fmi3OK;
  });
}

fmi3Status fmi3FreeFMUState(fmi3Instance c, fmi3FMUState* FMUState) {
  return guarded(c, "fmi3FreeFMUState", kAnyState, [&](Instance& inst) {
    if (!FMUState) return inst.reject("fmi3FreeFMUState: NULL FMUState");
    delete static_cast<StateCopy*>(*FMUState);
    *FMUState = nullptr;
    return fmi3OK;
  });
}

fmi3Status fmi3SerializedFMUStateSize(fmi3Instance c, fmi3FMUState FMUState, size_t* size) {
  return guarded(c, "fmi3SerializedFMUStateSize", kAnyState, [&](Instance& inst) {
    if (!FMUState || !size) return inst.reject("fmi3SerializedFMUStateSize: NULL argument");
    *size = serialize_state(inst, *static_cast<const StateCopy*>(FMUState)).size();
    return fmi3OK;
  });
}

fmi3Status fmi3SerializeFMUState(fmi3Instance c,
                                 fmi3FMUState FMUState,
                                 fmi3Byte serializedState[],
                                 size_t size) {
  return guarded(c, "fmi3SerializeFMUState", kAnyState, [&](Instance& inst) {
    if (!FMUState || !serializedState) return inst.reject("fmi3SerializeFMUState: NULL argument");
    const auto b = serialize_state(inst, *static_cast<const StateCopy*>(FMUState));
    if (size < b.size())
      return inst.reject("fmi3SerializeFMUState: buffer of " + std::to_string(size) + " bytes, " +
                         std::to_string(b.size()) + " needed");
    std::memcpy(serializedState, b.data(), b.size());
    return fmi3OK;
  });
}

fmi3Status fmi3DeserializeFMUState(fmi3Instance c,
                                   const fmi3Byte serializedState[],
                                   size_t size,
                                   fmi3FMUState* FMUState) {
  return guarded(c, "fmi3DeserializeFMUState", kAnyState, [&](Instance& inst) {
    if (!serializedState || !FMUState) return inst.reject("fmi3DeserializeFMUState: NULL argument");
    if (size < 4) return inst.reject("fmi3DeserializeFMUState: blob too short");
    uint32_t st = 0;
    std::memcpy(&st, serializedState + size - 4, 4);
    if (st == 0 || (st & (st - 1)) != 0 || st > kError)
      return inst.reject("fmi3DeserializeFMUState: invalid state in blob");
    const stiff::fmu::Values now = inst.model->save();
    std::string msg;
    if (!inst.model->deserialize(serializedState, size - 4, &msg))
      return inst.reject("fmi3DeserializeFMUState: " + msg);
    StateCopy copy{inst.model->save(), st};
    inst.model->restore(now);
    if (*FMUState)
      *static_cast<StateCopy*>(*FMUState) = copy;
    else
      *FMUState = new StateCopy(copy);
    return fmi3OK;
  });
}

fmi3Status fmi3GetDirectionalDerivative(fmi3Instance c,
                                        const fmi3ValueReference unknowns[],
                                        size_t nUnknowns,
                                        const fmi3ValueReference knowns[],
                                        size_t nKnowns,
                                        const fmi3Float64 seed[],
                                        size_t nSeed,
                                        fmi3Float64 sensitivity[],
                                        size_t nSensitivity) {
  (void)unknowns, (void)nUnknowns, (void)knowns, (void)nKnowns, (void)seed, (void)nSeed,
      (void)sensitivity, (void)nSensitivity;
  return not_supported(c, "fmi3GetDirectionalDerivative");
}
fmi3Status fmi3GetAdjointDerivative(fmi3Instance c,
                                    const fmi3ValueReference unknowns[],
                                    size_t nUnknowns,
                                    const fmi3ValueReference knowns[],
                                    size_t nKnowns,
                                    const fmi3Float64 seed[],
                                    size_t nSeed,
                                    fmi3Float64 sensitivity[],
                                    size_t nSensitivity) {
  (void)unknowns, (void)nUnknowns, (void)knowns, (void)nKnowns, (void)seed, (void)nSeed,
      (void)sensitivity, (void)nSensitivity;
  return not_supported(c, "fmi3GetAdjointDerivative");
}

fmi3Status fmi3EnterConfigurationMode(fmi3Instance c) {
  return not_supported(c, "fmi3EnterConfigurationMode");
}
fmi3Status fmi3ExitConfigurationMode(fmi3Instance c) {
  return not_supported(c, "fmi3ExitConfigurationMode");
}
fmi3Status fmi3GetIntervalDecimal(fmi3Instance c,
                                  const fmi3ValueReference vr[],
                                  size_t nvr,
                                  fmi3Float64 intervals[],
                                  fmi3IntervalQualifier qualifiers[]) {
  (void)vr, (void)nvr, (void)intervals, (void)qualifiers;
  return not_supported(c, "fmi3GetIntervalDecimal");
}
fmi3Status fmi3GetIntervalFraction(fmi3Instance c,
                                   const fmi3ValueReference vr[],
                                   size_t nvr,
                                   fmi3UInt64 counters[],
                                   fmi3UInt64 resolutions[],
                                   fmi3IntervalQualifier qualifiers[]) {
  (void)vr, (void)nvr, (void)counters, (void)resolutions, (void)qualifiers;
  return not_supported(c, "fmi3GetIntervalFraction");
}
fmi3Status fmi3GetShiftDecimal(fmi3Instance c,
                               const fmi3ValueReference vr[],
                               size_t nvr,
                               fmi3Float64 shifts[]) {
  (void)vr, (void)nvr, (void)shifts;
  return not_supported(c, "fmi3GetShiftDecimal");
}
fmi3Status fmi3GetShiftFraction(fmi3Instance c,
                                const fmi3ValueReference vr[],
                                size_t nvr,
                                fmi3UInt64 counters[],
                                fmi3UInt64 resolutions[]) {
  (void)vr, (void)nvr, (void)counters, (void)resolutions;
  return not_supported(c, "fmi3GetShiftFraction");
}
fmi3Status fmi3SetIntervalDecimal(fmi3Instance c,
                                  const fmi3ValueReference vr[],
                                  size_t nvr,
                                  const fmi3Float64 intervals[]) {
  (void)vr, (void)nvr, (void)intervals;
  return not_supported(c, "fmi3SetIntervalDecimal");
}
fmi3Status fmi3SetIntervalFraction(fmi3Instance c,
                                   const fmi3ValueReference vr[],
                                   size_t nvr,
                                   const fmi3UInt64 counters[],
                                   const fmi3UInt64 resolutions[]) {
  (void)vr, (void)nvr, (void)counters, (void)resolutions;
  return not_supported(c, "fmi3SetIntervalFraction");
}
fmi3Status fmi3SetShiftDecimal(fmi3Instance c,
                               const fmi3ValueReference vr[],
                               size_t nvr,
                               const fmi3Float64 shifts[]) {
  (void)vr, (void)nvr, (void)shifts;
  return not_supported(c, "fmi3SetShiftDecimal");
}
fmi3Status fmi3SetShiftFraction(fmi3Instance c,
                                const fmi3ValueReference vr[],
                                size_t nvr,
                                const fmi3UInt64 counters[],
                                const fmi3UInt64 resolutions[]) {
  (void)vr, (void)nvr, (void)counters, (void)resolutions;
  return not_supported(c, "fmi3SetShiftFraction");
}

fmi3Status fmi3EvaluateDiscreteStates(fmi3Instance c) {
  return guarded(c, "fmi3EvaluateDiscreteStates", kEventMode | kContinuousTimeMode,
                 [&](Instance&) { return fmi3OK; });
}

fmi3Status fmi3UpdateDiscreteStates(fmi3Instance c,
                                    fmi3Boolean* discreteStatesNeedUpdate,
                                    fmi3Boolean* terminateSimulation,
                                    fmi3Boolean* nominalsOfContinuousStatesChanged,
                                    fmi3Boolean* valuesOfContinuousStatesChanged,
                                    fmi3Boolean* nextEventTimeDefined,
                                    fmi3Float64* nextEventTime) {
  return guarded(c, "fmi3UpdateDiscreteStates", kEventMode, [&](Instance& inst) {
    if (!discreteStatesNeedUpdate || !terminateSimulation || !nominalsOfContinuousStatesChanged ||
        !valuesOfContinuousStatesChanged || !nextEventTimeDefined || !nextEventTime)
      return inst.reject("fmi3UpdateDiscreteStates: NULL argument");
    *discreteStatesNeedUpdate = fmi3False;
    *terminateSimulation = fmi3False;
    *nominalsOfContinuousStatesChanged = fmi3False;
    *valuesOfContinuousStatesChanged = fmi3False;
    *nextEventTimeDefined = fmi3False;
    *nextEventTime = 0.0;
    return fmi3OK;
  });
}

fmi3Status fmi3EnterContinuousTimeMode(fmi3Instance c) {
  return guarded(c, "fmi3EnterContinuousTimeMode", kEventMode, [&](Instance& inst) {
    inst.state = kContinuousTimeMode;
    return fmi3OK;
  });
}

fmi3Status fmi3CompletedIntegratorStep(fmi3Instance c,
                                       fmi3Boolean noSetFMUStatePriorToCurrentPoint,
                                       fmi3Boolean* enterEventMode,
                                       fmi3Boolean* terminateSimulation) {
  (void)noSetFMUStatePriorToCurrentPoint;
  return guarded(c, "fmi3CompletedIntegratorStep", kContinuousTimeMode, [&](Instance& inst) {
    if (!enterEventMode || !terminateSimulation)
      return inst.reject("fmi3CompletedIntegratorStep: NULL argument");
    *enterEventMode = fmi3False;
    *terminateSimulation = fmi3False;
    return fmi3OK;
  });
}

fmi3Status fmi3SetTime(fmi3Instance c, fmi3Float64 time) {
  return guarded(c, "fmi3SetTime", kEventMode | kContinuousTimeMode, [&](Instance& inst) {
    if (!std::isfinite(time)) return inst.reject("fmi3SetTime: time is not finite");
    inst.model->set_time(time);
    return fmi3OK;
  });
}

fmi3Status fmi3SetContinuousStates(fmi3Instance c, const fmi3Float64 x[], size_t nx) {
  (void)x;
  return guarded(c, "fmi3SetContinuousStates", kContinuousTimeMode, [&](Instance& inst) {
    return nx == 0 ? fmi3OK : inst.reject("fmi3SetContinuousStates: the FMU has no states");
  });
}

fmi3Status fmi3GetContinuousStateDerivatives(fmi3Instance c, fmi3Float64 derivatives[], size_t nx) {
  (void)derivatives;
  return guarded(c, "fmi3GetContinuousStateDerivatives", kGetMask, [&](Instance& inst) {
    return nx == 0 ? fmi3OK
                   : inst.reject("fmi3GetContinuousStateDerivatives: the FMU has no states");
  });
}

fmi3Status fmi3GetEventIndicators(fmi3Instance c, fmi3Float64 eventIndicators[], size_t ni) {
  (void)eventIndicators;
  return guarded(c, "fmi3GetEventIndicators", kGetMask, [&](Instance& inst) {
    return ni == 0 ? fmi3OK
                   : inst.reject("fmi3GetEventIndicators: the FMU has no event indicators");
  });
}

fmi3Status fmi3GetContinuousStates(fmi3Instance c, fmi3Float64 x[], size_t nx) {
  (void)x;
  return guarded(c, "fmi3GetContinuousStates", kGetMask, [&](Instance& inst) {
    return nx == 0 ? fmi3OK : inst.reject("fmi3GetContinuousStates: the FMU has no states");
  });
}

fmi3Status fmi3GetNominalsOfContinuousStates(fmi3Instance c, fmi3Float64 nominals[], size_t nx) {
  (void)nominals;
  return guarded(c, "fmi3GetNominalsOfContinuousStates", kGetMask, [&](Instance& inst) {
    return nx == 0 ? fmi3OK
                   : inst.reject("fmi3GetNominalsOfContinuousStates: the FMU has no states");
  });
}

fmi3Status fmi3GetNumberOfEventIndicators(fmi3Instance c, size_t* n) {
  return guarded(c, "fmi3GetNumberOfEventIndicators", kAnyState, [&](Instance& inst) {
    if (!n) return inst.reject("fmi3GetNumberOfEventIndicators: NULL argument");
    *n = 0;
    return fmi3OK;
  });
}

fmi3Status fmi3GetNumberOfContinuousStates(fmi3Instance c, size_t* n) {
  return guarded(c, "fmi3GetNumberOfContinuousStates", kAnyState, [&](Instance& inst) {
    if (!n) return inst.reject("fmi3GetNumberOfContinuousStates: NULL argument");
    *n = 0;
    return fmi3OK;
  });
}

fmi3Status fmi3EnterStepMode(fmi3Instance c) {
  return guarded(c, "fmi3EnterStepMode", kEventMode, [&](Instance& inst) {
    if (inst.kind != Kind::cs) return inst.reject("fmi3EnterStepMode: instance is not CS");
    inst.state = kStepMode;
    return fmi3OK;
  });
}

fmi3Status fmi3GetOutputDerivatives(fmi3Instance c,
                                    const fmi3ValueReference vr[],
                                    size_t nvr,
                                    const fmi3Int32 orders[],
                                    fmi3Float64 values[],
                                    size_t nValues) {
  (void)vr, (void)nvr, (void)orders, (void)values, (void)nValues;
  return not_supported(c, "fmi3GetOutputDerivatives");
}

fmi3Status fmi3DoStep(fmi3Instance c,
                      fmi3Float64 currentCommunicationPoint,
                      fmi3Float64 communicationStepSize,
                      fmi3Boolean noSetFMUStatePriorToCurrentPoint,
                      fmi3Boolean* eventHandlingNeeded,
                      fmi3Boolean* terminateSimulation,
                      fmi3Boolean* earlyReturn,
                      fmi3Float64* lastSuccessfulTime) {
  (void)noSetFMUStatePriorToCurrentPoint;
  return guarded(c, "fmi3DoStep", kStepMode, [&](Instance& inst) {
    if (inst.kind != Kind::cs) return inst.reject("fmi3DoStep: instance is not CS");
    if (!eventHandlingNeeded || !terminateSimulation || !earlyReturn || !lastSuccessfulTime)
      return inst.reject("fmi3DoStep: NULL argument");
    if (!(communicationStepSize > 0) || !std::isfinite(communicationStepSize))
      return inst.reject(
          stiff::fmu::format("fmi3DoStep: step size %g must be > 0", communicationStepSize));
    const double t = inst.model->values().time;
    if (!(std::fabs(currentCommunicationPoint - t) <= 1e-9 * std::max(1.0, std::fabs(t))))
      return inst.reject(stiff::fmu::format(
          "fmi3DoStep: communication point %.17g differs from the FMU time %.17g",
          currentCommunicationPoint, t));
    inst.model->set_time(currentCommunicationPoint + communicationStepSize);
    *eventHandlingNeeded = fmi3False;
    *terminateSimulation = fmi3False;
    *earlyReturn = fmi3False;
    *lastSuccessfulTime = inst.model->values().time;
    return fmi3OK;
  });
}

fmi3Status fmi3ActivateModelPartition(fmi3Instance c,
                                      fmi3ValueReference clockReference,
                                      fmi3Float64 activationTime) {
  (void)clockReference, (void)activationTime;
  return not_supported(c, "fmi3ActivateModelPartition");
}

}  // extern "C"
