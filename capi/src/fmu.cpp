// C ABI of the FMU export (stiff_fmu.h).
#include <dlfcn.h>
#include <sys/stat.h>

#include <algorithm>
#include <cstddef>
#include <cstdlib>
#include <limits>
#include <string>

#include "boundary.hpp"
#include "handles.hpp"
#include "stiff/export/fmu_export.hpp"
#include "stiff/stiff_fmu.h"

namespace {

bool is_dir(const std::string& p) {
  struct stat st;
  return !p.empty() && ::stat(p.c_str(), &st) == 0 && S_ISDIR(st.st_mode);
}

/// Where an installed package keeps the generic FMU binaries: the folder `fmu` next to the
/// loaded libstiff_c.so (the Python package's stiff/_lib/fmu). Empty when there is none. The
/// core knows only an explicit folder, $STIFF_FMU_BINARIES and the build tree's.
std::string packaged_binaries_dir() {
  Dl_info info;
  if (!dladdr(reinterpret_cast<void*>(&packaged_binaries_dir), &info) || !info.dli_fname) return "";
  const std::string lib = info.dli_fname;
  const size_t slash = lib.rfind('/');
  const std::string dir = (slash == std::string::npos ? "." : lib.substr(0, slash)) + "/fmu";
  return is_dir(dir) ? dir : "";
}

}  // namespace

extern "C" stiff_status stiff_fmu_options_init(stiff_fmu_options* options, size_t struct_size) {
  return stiff::capi::guarded(__func__, [&] {
    // The core's FmuExportOptions{}: nothing is restated here.
    const stiff::FmuExportOptions f;
    stiff_fmu_options o{};
    o.fmi_version = static_cast<uint32_t>(f.fmi_version);
    o.model_identifier =
        stiff::capi::static_string([] { return stiff::FmuExportOptions{}.model_identifier; });
    o.binaries_dir =
        stiff::capi::static_string([] { return stiff::FmuExportOptions{}.binaries_dir; });
    o.array_inputs = f.array_inputs ? 1u : 0u;
    return stiff::capi::init_options(
        options, struct_size, offsetof(stiff_fmu_options, array_inputs), "stiff_fmu_options", o);
  });
}

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
    if (o.fmi_version != 0)
      opt.fmi_version =
          static_cast<int>(std::min<uint32_t>(o.fmi_version, std::numeric_limits<int>::max()));
    if (o.model_identifier) opt.model_identifier = o.model_identifier;
    if (o.binaries_dir) opt.binaries_dir = o.binaries_dir;
    if (opt.binaries_dir.empty() && !is_dir(stiff::fmu_binaries_dir(opt)))
      opt.binaries_dir = packaged_binaries_dir();
    if (o.array_inputs > 1)
      throw stiff::InvalidArgument("array_inputs must be 0 (scalar inputs) or 1 (arrays), not " +
                                   std::to_string(o.array_inputs));
    opt.array_inputs = o.array_inputs == 1;
    stiff::export_fmu(robot->model, fit->fit, path, opt);
    return STIFF_OK;
  });
}
