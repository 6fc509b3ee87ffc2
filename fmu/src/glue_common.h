// The part of the FMI glue that is the same in FMI 2.0 and FMI 3.0, written once: the instance
// with its state machine and logging, the guarded call, instantiation (resource location, token
// and resource checks), the value get/set loops over value references, FMU states and their
// versioned, size-checked serialized form, the Model Exchange and Co-Simulation calls of the
// algebraic model. Everything here speaks stiff::fmu::Status; fmi2_glue.cpp and fmi3_glue.cpp
// keep only the version-specific signatures, the logger callback and the status mapping.
// Every operation takes the FMI function name `f`, which starts each of its messages.
#pragma once

#include <cstddef>
#include <cstdint>
#include <exception>
#include <memory>
#include <set>
#include <new>
#include <string>

#include "model.h"

namespace stiff::fmu {

/// State-machine states, as bits so that a call can name the states it is allowed in.
/// FMI 2 calls kStepMode "stepComplete".
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
/// The integer variable (wrench_frame, a tunable parameter) cannot change in Continuous-Time Mode.
constexpr unsigned kSetIntegerMask = kSetMask & ~unsigned{kContinuousTimeMode};

/// Declared in modelDescription.xml <LogCategories>, in this order.
constexpr const char* kCategories[] = {"logStatusError", "logStatusWarning", "logCalls"};
enum Category { kLogError, kLogWarning, kLogCalls, kCategoryCount };

/// Interface an instance was created for.
enum class Kind { me, cs };

/// One FMU instance; the glue derives from it to hold the importer's logger callback. The
/// fmi2Component / fmi3Instance handed to the importer is an Instance* (base).
class Instance {
 public:
  Instance() = default;
  Instance(Instance&&) = default;
  Instance& operator=(Instance&&) = default;
  virtual ~Instance() = default;

  std::string name;
  Kind kind = Kind::cs;
  bool logging_on = false;
  bool category_on[kCategoryCount] = {true, true, true};
  unsigned state = kInstantiated;
  std::unique_ptr<Model> model;
  /// FMU states this instance handed out and not yet freed: a handle not in here (freed
  /// twice, another instance's, garbage) is an Error, never a dereference.
  std::set<void*> live_states;

  /// Errors and warnings are always reported; OK-level messages only when asked for.
  void log(Status status, Category c, const std::string& msg) const;
  /// Log an error and enter the Error state.
  Status error(const std::string& msg);
  /// A rejected call that leaves the instance usable (bad argument, wrong state).
  Status reject(const std::string& msg);
  /// Log a model outcome other than ok (an error enters the Error state); returns `s`.
  Status from(Status s, const std::string& msg);
  /// False (and logs) when `f` is not allowed in the current state.
  bool allowed(const char* f, unsigned mask);

  /// Hand a message to the importer's logger (version-specific callback).
  virtual void emit(Status status, const char* category, const std::string& msg) const = 0;
  /// Move this (staged, on the stack) instance to the heap.
  virtual std::unique_ptr<Instance> relocate() = 0;
};

/// Run `body(Instance&)` (returning Status) for the instance `c` if `f` is allowed in its state:
/// NULL instance -> error, call logged to logCalls, exceptions -> Error state with a message.
template <typename Body>
Status guarded(void* c, const char* f, unsigned mask, Body&& body) {
  if (!c) return Status::error;
  auto* inst = static_cast<Instance*>(c);
  if (!inst->allowed(f, mask)) return Status::error;
  inst->log(Status::ok, kLogCalls, f);
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

/// Arguments of fmi2Instantiate / fmi3InstantiateModelExchange / ...CoSimulation.
struct InstantiateArgs {
  int fmi = 2;  ///< FMI major version: names in messages, form of `resources`
  const char* instance_name = nullptr;
  const char* token = nullptr;      ///< FMI 2 GUID / FMI 3 instantiationToken
  const char* resources = nullptr;  ///< FMI 2 resourceLocation (file: URI) / FMI 3 resourcePath
  bool known_type = true;           ///< FMI 2: fmuType is ModelExchange or CoSimulation
  Kind kind = Kind::cs;
  bool logging_on = false;
  /// The function called, for messages (fmi2Instantiate, fmi3InstantiateCoSimulation, ...).
  const char* function = nullptr;
  /// FMI 3 Co-Simulation: the importer asks for Event Mode, which this FMU does not have.
  bool event_mode_used = false;
};

/// Check the arguments, read resources/model.txt and check it against the version and the
/// token, then move `staged` (whose logger is set) to the heap with its model. nullptr after
/// logging an error through `staged`.
Instance* instantiate(Instance& staged, const InstantiateArgs& a);
void free_instance(void* c, const char* f);

Status set_debug_logging(
    void* c, const char* f, bool on, size_t n_categories, const char* const* categories);
/// Start time (finite); with `enter_initialization`, also enter Initialization Mode (FMI 3).
Status setup_experiment(void* c, const char* f, double start_time, bool enter_initialization);
Status enter_initialization_mode(void* c, const char* f);
/// Validate parameters and inputs; ME continues in Event Mode, CS in Step Mode.
Status exit_initialization_mode(void* c, const char* f);
Status terminate(void* c, const char* f);
Status reset(void* c, const char* f);

/// The value references of a get/set call. FMI 2 passes `n_values` = nullptr: every reference
/// must be a scalar of the type and is checked when the loop reaches it. FMI 3 passes &nValues:
/// all references are checked first (type; arrays allowed) and nValues must be their total size.
struct Refs {
  const uint32_t* vr;
  size_t nvr;
  const size_t* n_values;
};
Status get_float64(void* c, const char* f, const Refs& refs, double* values);
Status set_float64(void* c, const char* f, const Refs& refs, const double* values);
Status get_int32(void* c, const char* f, const Refs& refs, int32_t* values);
Status set_int32(void* c, const char* f, const Refs& refs, const int32_t* values);

/// For what the FMU has none of (variables of a type, states, event indicators): ok for n == 0,
/// else rejected with "<f>: <what>".
Status expect_none(void* c, const char* f, unsigned mask, size_t n, const char* what);
/// "<f> is not supported by this FMU".
Status not_supported(void* c, const char* f);

/// FMU state: a heap copy of the values and the state-machine state. `arg` is the name of the
/// FMU-state argument in messages ("FMUstate" in FMI 2, "FMUState" in FMI 3).
Status get_fmu_state(void* c, const char* f, const char* arg, void** fmu_state);
Status set_fmu_state(void* c, const char* f, const char* arg, void* fmu_state);
Status free_fmu_state(void* c, const char* f, const char* arg, void** fmu_state);
/// Serialized form: the model's blob (Model::serialize) followed by the state (u32).
Status serialized_fmu_state_size(void* c, const char* f, void* fmu_state, size_t* size);
Status serialize_fmu_state(void* c, const char* f, void* fmu_state, void* blob, size_t size);
/// Which check of a blob reports first when the model's blob and the trailing state are both
/// bad: FMI 2 checks the values first, FMI 3 the state.
enum class BlobOrder { values_first, state_first };
Status deserialize_fmu_state(
    void* c, const char* f, const void* blob, size_t size, void** fmu_state, BlobOrder order);

/// Model Exchange of the algebraic model (no states, no event indicators).
Status enter_continuous_time_mode(void* c, const char* f);
Status set_time(void* c, const char* f, double time);
template <typename Boolean>
Status completed_integrator_step(void* c,
                                 const char* f,
                                 Boolean* enter_event_mode,
                                 Boolean* terminate_simulation) {
  return guarded(c, f, kContinuousTimeMode, [&](Instance& inst) {
    if (!enter_event_mode || !terminate_simulation)
      return inst.reject(std::string(f) + ": NULL argument");
    *enter_event_mode = Boolean{false};
    *terminate_simulation = Boolean{false};
    return Status::ok;
  });
}

/// Co-Simulation: h > 0 and finite, the communication point at the FMU time; the FMU time
/// advances by h. FMI 3 passes its outputs (all set to "nothing happened"), FMI 2 nullptr.
struct StepOutputs {
  bool* event_handling_needed;
  bool* terminate_simulation;
  bool* early_return;
  double* last_successful_time;
};
Status do_step(void* c, const char* f, double point, double h, const StepOutputs* out);

}  // namespace stiff::fmu
