#include "glue_common.h"

#include <algorithm>
#include <cmath>
#include <cstring>

#include "glue_util.h"

namespace stiff::fmu {

void Instance::log(Status status, Category c, const std::string& msg) const {
  if (status == Status::ok && (!logging_on || !category_on[c])) return;
  emit(status, kCategories[c], msg);
}

Status Instance::error(const std::string& msg) {
  log(Status::error, kLogError, msg);
  state = kError;
  return Status::error;
}

Status Instance::reject(const std::string& msg) {
  log(Status::error, kLogError, msg);
  return Status::error;
}

Status Instance::from(Status s, const std::string& msg) {
  switch (s) {
    case Status::ok:
      return Status::ok;
    case Status::warning:
    case Status::discard:
      log(s, kLogWarning, msg);
      return s;
    default:
      return error(msg);
  }
}

bool Instance::allowed(const char* f, unsigned mask) {
  if (state & mask) return true;
  log(Status::error, kLogError, std::string(f) + " is not allowed in the current state");
  return false;
}

Instance* instantiate(Instance& staged, const InstantiateArgs& a) {
  const char* f = a.function ? a.function : a.fmi == 2 ? "fmi2Instantiate" : "fmi3Instantiate";
  // The token's name in messages, and in the resources.
  const char* token = a.fmi == 2 ? "GUID" : "instantiationToken";
  const char* resources_token = a.fmi == 2 ? "GUID" : "token";
  auto say = [&](const std::string& msg) {
    staged.log(Status::error, kLogError, std::string(f) + ": " + msg);
    return nullptr;
  };
  try {
    staged.name = a.instance_name ? a.instance_name : "";
    if (staged.name.empty()) return say("missing instance name");
    if (!a.token || !*a.token) return say(std::string("missing ") + token);
    if (!a.known_type) return say("unknown FMU type");
    if (a.event_mode_used)
      return say("eventModeUsed = true, but this FMU has no Event Mode (hasEventMode = false)");
    std::string dir;
    if (a.fmi == 2) {
      dir = uri_to_path(a.resources);
      if (dir.empty())
        return say(std::string("resource location '") + (a.resources ? a.resources : "(null)") +
                   "' is not a file: URI");
    } else {
      if (!a.resources || !*a.resources) return say("missing resourcePath");
      dir = a.resources;
    }
    auto layout = read_layout(dir);
    if (layout->fmi != a.fmi)
      return say(std::string("resources are for FMI ") + (a.fmi == 2 ? "3" : "2"));
    if (layout->guid != a.token)
      return say(std::string(token) + " '" + a.token + "' does not match the resources' " +
                 resources_token + " '" + layout->guid + "'");
    staged.kind = a.kind;
    staged.logging_on = a.logging_on;
    staged.model = std::make_unique<Model>(std::move(layout));
    auto inst = staged.relocate();
    inst->log(Status::ok, kLogCalls, f);
    return inst.release();
  } catch (const std::exception& e) {
    say(e.what());
  } catch (...) {
    say("unknown exception");
  }
  return nullptr;
}

void delete_states(Instance& inst);  // below, with the state copies

void free_instance(void* c, const char* f) {
  if (!c) return;
  auto* inst = static_cast<Instance*>(c);
  inst->log(Status::ok, kLogCalls, f);
  delete_states(*inst);
  delete inst;
}

Status set_debug_logging(
    void* c, const char* f, bool on, size_t n_categories, const char* const* categories) {
  return guarded(c, f, kAnyState, [&](Instance& inst) {
    if (n_categories > 0 && !categories) return inst.reject(std::string(f) + ": NULL categories");
    inst.logging_on = on;
    if (n_categories == 0)
      for (bool& b : inst.category_on) b = on;
    for (size_t i = 0; i < n_categories; ++i) {
      int k = -1;
      for (int j = 0; j < kCategoryCount; ++j)
        if (categories[i] && std::strcmp(categories[i], kCategories[j]) == 0) k = j;
      if (k < 0)
        return inst.reject(std::string(f) + ": unknown log category '" +
                           (categories[i] ? categories[i] : "(null)") + "'");
      inst.category_on[k] = on;
    }
    return Status::ok;
  });
}

Status setup_experiment(void* c, const char* f, double start_time, bool enter_initialization) {
  return guarded(c, f, kInstantiated, [&](Instance& inst) {
    if (!std::isfinite(start_time)) return inst.reject(std::string(f) + ": start time not finite");
    inst.model->set_time(start_time);
    if (enter_initialization) inst.state = kInitializationMode;
    return Status::ok;
  });
}

Status enter_initialization_mode(void* c, const char* f) {
  return guarded(c, f, kInstantiated, [&](Instance& inst) {
    inst.state = kInitializationMode;
    return Status::ok;
  });
}

Status exit_initialization_mode(void* c, const char* f) {
  return guarded(c, f, kInitializationMode, [&](Instance& inst) {
    std::string msg;
    if (inst.model->validate(&msg) != Status::ok) return inst.error(msg);
    inst.state = inst.kind == Kind::me ? kEventMode : kStepMode;
    return Status::ok;
  });
}

Status terminate(void* c, const char* f) {
  return guarded(c, f, kEventMode | kContinuousTimeMode | kStepMode | kError, [&](Instance& inst) {
    inst.state = kTerminated;
    return Status::ok;
  });
}

Status reset(void* c, const char* f) {
  return guarded(c, f, kAnyState, [&](Instance& inst) {
    inst.model->reset();
    inst.state = kInstantiated;
    return Status::ok;
  });
}

namespace {

// Start of a get/set call: NULL arrays; FMI 3 (n_values given): every reference known and of
// the type, nValues the total size of the variables.
bool check_refs(Instance& inst, const char* f, const Refs& refs, const void* values, bool integer) {
  const uint32_t* vr = refs.vr;
  const size_t nvr = refs.nvr;
  if (nvr > 0 && (!vr || !values)) return inst.reject(std::string(f) + ": NULL argument"), false;
  if (!refs.n_values) return true;
  size_t total = 0;
  for (size_t i = 0; i < nvr; ++i) {
    const Variable* v = inst.model->variable(vr[i]);
    if (!v)
      return inst.reject(std::string(f) + ": unknown value reference " + std::to_string(vr[i])),
             false;
    if (v->is_integer() != integer)
      return inst.reject(std::string(f) + ": value reference " + std::to_string(vr[i]) + " ('" +
                         v->name + "') has another type"),
             false;
    total += v->size(inst.model->dof());
  }
  if (total != *refs.n_values)
    return inst.reject(std::string(f) + ": nValues is " + std::to_string(*refs.n_values) +
                       ", the " + std::to_string(nvr) + " variables hold " + std::to_string(total)),
           false;
  return true;
}

// The variable of one reference: FMI 3 checked in check_refs; FMI 2 checked here (known, of the
// type, a scalar). nullptr (logged) when rejected.
const Variable* variable(
    Instance& inst, const char* f, uint32_t vr, const size_t* n_values, bool integer) {
  const Variable* v = inst.model->variable(vr);
  if (n_values) return v;
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

// The loop of a get/set call: check_refs, then `access(variable, index of its first value)`
// for each reference in order. An error ends the call (values before it are already accessed);
// otherwise the worst outcome (warning, discard: getters only) is returned.
template <typename Access>
Status for_each_variable(Instance& inst,
                         const char* f,
                         const Refs& refs,
                         const void* values,
                         bool integer,
                         Access&& access) {
  if (!check_refs(inst, f, refs, values, integer)) return Status::error;
  Status worst = Status::ok;
  size_t at = 0;
  for (size_t i = 0; i < refs.nvr; ++i) {
    const Variable* v = variable(inst, f, refs.vr[i], refs.n_values, integer);
    if (!v) return Status::error;
    const Status s = access(*v, at);
    if (s == Status::error) return s;
    worst = std::max(worst, s);
    at += v->size(inst.model->dof());
  }
  return worst;
}

// A model outcome other than ok, logged with the prefix "<f>: " (an error enters the Error
// state).
Status outcome(Instance& inst, const char* f, Status s, const std::string& msg) {
  if (s == Status::ok || (s == Status::warning && msg.empty())) return s;  // told already
  return inst.from(s, std::string(f) + ": " + msg);
}

}  // namespace

Status get_float64(void* c, const char* f, const Refs& refs, double* values) {
  return guarded(c, f, kGetMask, [&](Instance& inst) {
    return for_each_variable(inst, f, refs, values, false, [&](const Variable& v, size_t at) {
      std::string msg;
      const Status s = inst.model->get_real(v, &values[at], &msg);
      return outcome(inst, f, s, msg);
    });
  });
}

Status set_float64(void* c, const char* f, const Refs& refs, const double* values) {
  return guarded(c, f, kSetMask, [&](Instance& inst) {
    return for_each_variable(inst, f, refs, values, false, [&](const Variable& v, size_t at) {
      if (v.role == Role::parameter && inst.state == kContinuousTimeMode)
        return inst.reject(std::string(f) + ": parameter '" + v.name +
                           "' cannot be set in Continuous-Time Mode");
      std::string msg;
      const Status s = inst.model->set_real(v, &values[at], &msg);
      return outcome(inst, f, s, msg);
    });
  });
}

Status get_int32(void* c, const char* f, const Refs& refs, int32_t* values) {
  return guarded(c, f, kGetMask, [&](Instance& inst) {
    return for_each_variable(inst, f, refs, values, true, [&](const Variable& v, size_t at) {
      values[at] = static_cast<int32_t>(inst.model->get_integer(v));
      return Status::ok;
    });
  });
}

Status set_int32(void* c, const char* f, const Refs& refs, const int32_t* values) {
  return guarded(c, f, kSetIntegerMask, [&](Instance& inst) {
    return for_each_variable(inst, f, refs, values, true, [&](const Variable& v, size_t at) {
      std::string msg;
      const Status s = inst.model->set_integer(v, values[at], &msg);
      return outcome(inst, f, s, msg);
    });
  });
}

Status expect_none(void* c, const char* f, unsigned mask, size_t n, const char* what) {
  return guarded(c, f, mask, [&](Instance& inst) {
    return n == 0 ? Status::ok : inst.reject(std::string(f) + ": " + what);
  });
}

Status not_supported(void* c, const char* f) {
  if (!c) return Status::error;
  return static_cast<Instance*>(c)->reject(std::string(f) + " is not supported by this FMU");
}

namespace {

struct StateCopy {
  Values values;
  unsigned state;
  Kind kind;
};

}  // namespace

// States the host did not free die with their instance.
void delete_states(Instance& inst) {
  for (void* s : inst.live_states) delete static_cast<StateCopy*>(s);
  inst.live_states.clear();
}

namespace {

const char* kind_name(Kind k) { return k == Kind::cs ? "Co-Simulation" : "Model Exchange"; }

// The interface a state word belongs to: Step Mode only exists in Co-Simulation, Event and
// Continuous-Time Mode only in Model Exchange; the others in both.
bool state_fits(unsigned st, Kind k) {
  if (st == kStepMode) return k == Kind::cs;
  if (st == kEventMode || st == kContinuousTimeMode) return k == Kind::me;
  return true;
}

// A handle this instance handed out and has not freed, or nullptr after rejecting it.
StateCopy* live(Instance& inst, const char* f, void* handle) {
  if (!inst.live_states.count(handle)) {
    inst.reject(std::string(f) + ": not an FMU state of this instance (freed already, or "
                                 "another instance's)");
    return nullptr;
  }
  return static_cast<StateCopy*>(handle);
}

std::vector<uint8_t> serialize_state(Instance& inst, const StateCopy& copy) {
  const Values now = inst.model->save();
  inst.model->restore(copy.values);
  std::vector<uint8_t> b = inst.model->serialize();
  inst.model->restore(now);
  const uint32_t st = copy.state;
  b.insert(b.end(), reinterpret_cast<const uint8_t*>(&st),
           reinterpret_cast<const uint8_t*>(&st) + 4);
  return b;
}

}  // namespace

Status get_fmu_state(void* c, const char* f, const char* arg, void** fmu_state) {
  return guarded(c, f, kAnyState, [&](Instance& inst) {
    if (!fmu_state) return inst.reject(std::string(f) + ": NULL " + arg);
    if (*fmu_state) {
      StateCopy* copy = live(inst, f, *fmu_state);
      if (!copy) return Status::error;
      *copy = StateCopy{inst.model->save(), inst.state, inst.kind};
    } else {
      auto* copy = new StateCopy{inst.model->save(), inst.state, inst.kind};
      inst.live_states.insert(copy);
      *fmu_state = copy;
    }
    return Status::ok;
  });
}

Status set_fmu_state(void* c, const char* f, const char* arg, void* fmu_state) {
  return guarded(c, f, kAnyState, [&](Instance& inst) {
    if (!fmu_state) return inst.reject(std::string(f) + ": NULL " + arg);
    const StateCopy* copy = live(inst, f, fmu_state);
    if (!copy) return Status::error;
    if (copy->kind != inst.kind || !state_fits(copy->state, inst.kind))
      return inst.reject(std::string(f) + ": a " + kind_name(copy->kind) +
                         " state cannot be restored into a " + kind_name(inst.kind) + " instance");
    if (copy->values.q.size() != static_cast<size_t>(inst.model->dof()) ||
        copy->values.theta.size() != inst.model->values().theta.size())
      return inst.reject(std::string(f) + ": state of another model");
    inst.model->restore(copy->values);
    inst.state = copy->state;
    return Status::ok;
  });
}

Status free_fmu_state(void* c, const char* f, const char* arg, void** fmu_state) {
  return guarded(c, f, kAnyState, [&](Instance& inst) {
    if (!fmu_state) return inst.reject(std::string(f) + ": NULL " + arg);
    if (!*fmu_state) return Status::ok;  // freeing NULL does nothing
    StateCopy* copy = live(inst, f, *fmu_state);
    if (!copy) return Status::error;
    inst.live_states.erase(copy);
    delete copy;
    *fmu_state = nullptr;
    return Status::ok;
  });
}

Status serialized_fmu_state_size(void* c, const char* f, void* fmu_state, size_t* size) {
  return guarded(c, f, kAnyState, [&](Instance& inst) {
    if (!fmu_state || !size) return inst.reject(std::string(f) + ": NULL argument");
    const StateCopy* copy = live(inst, f, fmu_state);
    if (!copy) return Status::error;
    *size = serialize_state(inst, *copy).size();
    return Status::ok;
  });
}

Status serialize_fmu_state(void* c, const char* f, void* fmu_state, void* blob, size_t size) {
  return guarded(c, f, kAnyState, [&](Instance& inst) {
    if (!fmu_state || !blob) return inst.reject(std::string(f) + ": NULL argument");
    const StateCopy* copy = live(inst, f, fmu_state);
    if (!copy) return Status::error;
    const auto b = serialize_state(inst, *copy);
    if (size < b.size())
      return inst.reject(std::string(f) + ": buffer of " + std::to_string(size) + " bytes, " +
                         std::to_string(b.size()) + " needed");
    std::memcpy(blob, b.data(), b.size());
    return Status::ok;
  });
}

Status deserialize_fmu_state(
    void* c, const char* f, const void* blob, size_t size, void** fmu_state, BlobOrder order) {
  return guarded(c, f, kAnyState, [&](Instance& inst) {
    if (!blob || !fmu_state) return inst.reject(std::string(f) + ": NULL argument");
    if (size < 4) return inst.reject(std::string(f) + ": blob too short");
    const auto* bytes = static_cast<const uint8_t*>(blob);
    uint32_t st = 0;
    std::memcpy(&st, bytes + size - 4, 4);
    // Exactly one state bit, a known state.
    const bool state_ok = st != 0 && (st & (st - 1)) == 0 && st <= kError;
    const std::string invalid_state = std::string(f) + ": invalid state in blob";
    const Values now = inst.model->save();
    std::string msg;
    // The blob is the model's part and the 4-byte state word: sizes are told for the whole. A
    // blob of the wrong size is told as such (its "state word" is then any 4 bytes).
    const bool model_ok = inst.model->deserialize(bytes, size - 4, &msg, 4);
    const StateCopy copy{inst.model->save(), st, inst.kind};
    inst.model->restore(now);
    if (order == BlobOrder::state_first && !state_ok && model_ok) return inst.reject(invalid_state);
    if (!model_ok) return inst.reject(std::string(f) + ": " + msg);
    if (!state_ok) return inst.reject(invalid_state);
    if (!state_fits(st, inst.kind))
      return inst.reject(std::string(f) + ": the blob is a state of the other interface (not " +
                         kind_name(inst.kind) + ")");
    if (*fmu_state) {
      StateCopy* target = live(inst, f, *fmu_state);
      if (!target) return Status::error;
      *target = copy;
    } else {
      auto* fresh = new StateCopy(copy);
      inst.live_states.insert(fresh);
      *fmu_state = fresh;
    }
    return Status::ok;
  });
}

Status enter_continuous_time_mode(void* c, const char* f) {
  return guarded(c, f, kEventMode, [&](Instance& inst) {
    inst.state = kContinuousTimeMode;
    return Status::ok;
  });
}

Status set_time(void* c, const char* f, double time) {
  return guarded(c, f, kEventMode | kContinuousTimeMode, [&](Instance& inst) {
    if (!std::isfinite(time)) return inst.reject(std::string(f) + ": time is not finite");
    inst.model->set_time(time);
    return Status::ok;
  });
}

Status do_step(void* c, const char* f, double point, double h, const StepOutputs* out) {
  return guarded(c, f, kStepMode, [&](Instance& inst) {
    if (inst.kind != Kind::cs) return inst.reject(std::string(f) + ": instance is not CS");
    if (out && (!out->event_handling_needed || !out->terminate_simulation || !out->early_return ||
                !out->last_successful_time))
      return inst.reject(std::string(f) + ": NULL argument");
    if (!(h > 0) || !std::isfinite(h))
      return inst.reject(format("%s: step size %g must be > 0", f, h));
    const double t = inst.model->values().time;
    if (!(std::fabs(point - t) <= 1e-9 * std::max(1.0, std::fabs(t))))
      return inst.reject(
          format("%s: communication point %.17g differs from the FMU time %.17g", f, point, t));
    inst.model->set_time(point + h);
    if (out) {
      *out->event_handling_needed = false;
      *out->terminate_simulation = false;
      *out->early_return = false;
      *out->last_successful_time = inst.model->values().time;
    }
    return Status::ok;
  });
}

}  // namespace stiff::fmu
