// C ABI of the FMU export (stiff_fmu.h).
#include "boundary.hpp"
#include "handles.hpp"
#include "stiff/export/fmu_export.hpp"
#include "stiff/stiff_fmu.h"

extern "C" stiff_status stiff_fmu_export(const char* path,
                                         const stiff_robot* robot,
                                         const stiff_result* fit,
                                         const stiff_fmu_options* options) {
  return stiff::capi::guarded(__func__, [&] {
    stiff::capi::require_string(path, "path");
    stiff::capi::require(robot, "robot");
    stiff::capi::require(fit, "fit");
    const stiff_fmu_options o = stiff::capi::read_options(options);
    stiff::FmuExportOptions opt;
    opt.fmi_version = o.fmi_version == 0 ? 2 : static_cast<int>(o.fmi_version);
    if (o.model_identifier) opt.model_identifier = o.model_identifier;
    if (o.binaries_dir) opt.binaries_dir = o.binaries_dir;
    if (o.array_inputs > 1)
      throw stiff::InvalidArgument("array_inputs must be 0 (scalar inputs) or 1 (arrays), not " +
                                   std::to_string(o.array_inputs));
    opt.array_inputs = o.array_inputs == 1;
    stiff::export_fmu(robot->model, fit->fit, path, opt);
    return STIFF_OK;
  });
}
