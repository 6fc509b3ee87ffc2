// Model diagnosis over the C ABI (stiff_diagnose.h).
#include "stiff/diagnose/diagnose.hpp"

#include <algorithm>
#include <limits>

#include "boundary.hpp"
#include "handles.hpp"
#include "stiff/stiff_diagnose.h"

using namespace stiff;
using namespace stiff::capi;

struct stiff_diagnosis {
  stiff::Diagnosis diagnosis;
  std::string json;  ///< serialised once
};

namespace {

const stiff_diagnosis& diagnosis_of(const stiff_diagnosis* d) {
  require(d, "diagnosis");
  return *d;
}

}  // namespace

extern "C" {

stiff_status stiff_diagnose_options_init(stiff_diagnose_options* options, size_t struct_size) {
  return guarded(__func__, [&] {
    // The core's DiagnosisOptions{}: nothing is restated here.
    const DiagnosisOptions d;
    stiff_diagnose_options o{};
    o.model = kDefaultModel;
    o.candidates = nullptr;  // every registered effect not in the model (d.candidates empty)
    o.alpha = d.alpha;
    o.auto_steps = 0u;  // with auto_loop: the core's number of steps (d.max_steps)
    o.auto_loop = d.auto_loop ? 1u : 0u;
    o.repeatability_m = d.repeatability_m;
    o.command_prefix = static_string([] { return DiagnosisOptions{}.command_prefix; });
    return init_options(options, struct_size, offsetof(stiff_diagnose_options, auto_loop),
                        "stiff_diagnose_options", o);
  });
}

stiff_status stiff_diagnose(stiff_diagnosis** out,
                            const stiff_robot* robot,
                            const stiff_dataset* calibration,
                            const stiff_dataset* validation,
                            const stiff_diagnose_options* options) {
  if (out) *out = nullptr;
  return guarded(__func__, [&] {
    require(out, "out");
    require(robot, "robot");
    require(calibration, "calibration");
    const stiff_diagnose_options o = read_options(options);
    const std::vector<std::string> model = parse_model_string(o.model ? o.model : kDefaultModel);
    // Zero fields keep the core's defaults; every value is checked once, by diagnose().
    DiagnosisOptions d;
    if (o.candidates) d.candidates = parse_model_string(o.candidates);
    if (o.alpha != 0) d.alpha = o.alpha;
    d.auto_loop = o.auto_steps > 0 || o.auto_loop != 0;
    if (o.auto_steps > 0)
      d.max_steps =
          static_cast<int>(std::min<uint32_t>(o.auto_steps, std::numeric_limits<int>::max()));
    if (o.command_prefix) d.command_prefix = o.command_prefix;
    d.repeatability_m = o.repeatability_m;  // 0: not stated, as in the core
    auto r = std::make_unique<stiff_diagnosis>();
    r->diagnosis = diagnose(robot->model, calibration->data,
                            validation ? &validation->data : nullptr, model, d);
    r->json = diagnosis_to_json(r->diagnosis);
    *out = r.release();
    return STIFF_OK;
  });
}

stiff_status stiff_diagnosis_json(char* json,
                                  size_t capacity,
                                  size_t* needed,
                                  const stiff_diagnosis* diagnosis) {
  return guarded(__func__,
                 [&] { return copy_string(diagnosis_of(diagnosis).json, json, capacity, needed); });
}

stiff_status stiff_diagnosis_verdict(char* verdict,
                                     size_t capacity,
                                     size_t* needed,
                                     const stiff_diagnosis* diagnosis) {
  return guarded(__func__, [&] {
    return copy_string(diagnosis_of(diagnosis).diagnosis.verdict, verdict, capacity, needed);
  });
}

void stiff_diagnosis_destroy(stiff_diagnosis* diagnosis) { delete diagnosis; }

}  // extern "C"
