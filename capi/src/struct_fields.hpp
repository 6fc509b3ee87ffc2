// The fields of every versioned struct of the C ABI, as byte spans, so that a caller's
// struct_size can be checked against them: a size that ends inside a field (half a pointer, a
// torn double) is not the size of any version of the struct and is refused.
#pragma once

#include <cstddef>
#include <string>

#include "stiff/stiff.h"
#include "stiff/stiff_compensate.h"
#include "stiff/stiff_diagnose.h"
#include "stiff/stiff_fmu.h"
#include "stiff/stiff_plan.h"

namespace stiff::capi {

struct FieldSpan {
  size_t begin, end;
  const char* name;
};

template <typename T>
struct Fields;  // specialised below for every struct that starts with struct_size

#define STIFF_FIELD(T, f) \
  FieldSpan { offsetof(T, f), offsetof(T, f) + sizeof(T::f), #f }
#define STIFF_FIELDS(T, ...)                                      \
  template <>                                                     \
  struct Fields<T> {                                              \
    static constexpr FieldSpan spans[] = {__VA_ARGS__};           \
    static constexpr size_t count = sizeof spans / sizeof *spans; \
  }

STIFF_FIELDS(stiff_noise_options,
             STIFF_FIELD(stiff_noise_options, struct_size),
             STIFF_FIELD(stiff_noise_options, tracker_sigma_m),
             STIFF_FIELD(stiff_noise_options, tracker_ppm),
             STIFF_FIELD(stiff_noise_options, tracker_position_m),
             STIFF_FIELD(stiff_noise_options, force_relative),
             STIFF_FIELD(stiff_noise_options, force_absolute_N),
             STIFF_FIELD(stiff_noise_options, joint_sigma_rad),
             STIFF_FIELD(stiff_noise_options, outlier_rate),
             STIFF_FIELD(stiff_noise_options, outlier_size_m),
             STIFF_FIELD(stiff_noise_options, seed));
STIFF_FIELDS(stiff_design_random_options,
             STIFF_FIELD(stiff_design_random_options, struct_size),
             STIFF_FIELD(stiff_design_random_options, count),
             STIFF_FIELD(stiff_design_random_options, seed),
             STIFF_FIELD(stiff_design_random_options, range_fraction),
             STIFF_FIELD(stiff_design_random_options, load_min_N),
             STIFF_FIELD(stiff_design_random_options, load_max_N),
             STIFF_FIELD(stiff_design_random_options, load_step_N),
             STIFF_FIELD(stiff_design_random_options, min_sigma_m),
             STIFF_FIELD(stiff_design_random_options, q_fixed),
             STIFF_FIELD(stiff_design_random_options, q_fixed_count),
             STIFF_FIELD(stiff_design_random_options, use_workspace_box),
             STIFF_FIELD(stiff_design_random_options, box_min_m),
             STIFF_FIELD(stiff_design_random_options, box_max_m));
STIFF_FIELDS(stiff_identify_options,
             STIFF_FIELD(stiff_identify_options, struct_size),
             STIFF_FIELD(stiff_identify_options, model),
             STIFF_FIELD(stiff_identify_options, loss),
             STIFF_FIELD(stiff_identify_options, loss_scale_m),
             STIFF_FIELD(stiff_identify_options, max_iterations),
             STIFF_FIELD(stiff_identify_options, method),
             STIFF_FIELD(stiff_identify_options, progress),
             STIFF_FIELD(stiff_identify_options, progress_user_data),
             STIFF_FIELD(stiff_identify_options, max_relative_se),
             STIFF_FIELD(stiff_identify_options, start),
             STIFF_FIELD(stiff_identify_options, refit),
             STIFF_FIELD(stiff_identify_options, orientation_length_m),
             STIFF_FIELD(stiff_identify_options, select_terms));
STIFF_FIELDS(stiff_fit_statistics,
             STIFF_FIELD(stiff_fit_statistics, struct_size),
             STIFF_FIELD(stiff_fit_statistics, measurements),
             STIFF_FIELD(stiff_fit_statistics, rank),
             STIFF_FIELD(stiff_fit_statistics, dof),
             STIFF_FIELD(stiff_fit_statistics, rms_m),
             STIFF_FIELD(stiff_fit_statistics, sigma_hat_m),
             STIFF_FIELD(stiff_fit_statistics, noise_floor_m),
             STIFF_FIELD(stiff_fit_statistics, chi2),
             STIFF_FIELD(stiff_fit_statistics, condition_number),
             STIFF_FIELD(stiff_fit_statistics, outliers),
             STIFF_FIELD(stiff_fit_statistics, warnings),
             STIFF_FIELD(stiff_fit_statistics, oriented_rows),
             STIFF_FIELD(stiff_fit_statistics, orientation_rms_rad),
             STIFF_FIELD(stiff_fit_statistics, orientation_mean_rad),
             STIFF_FIELD(stiff_fit_statistics, orientation_max_rad),
             STIFF_FIELD(stiff_fit_statistics, orientation_length_m),
             STIFF_FIELD(stiff_fit_statistics, model_error_m),
             STIFF_FIELD(stiff_fit_statistics, model_error_rad));
STIFF_FIELDS(stiff_path_options,
             STIFF_FIELD(stiff_path_options, struct_size),
             STIFF_FIELD(stiff_path_options, frame),
             STIFF_FIELD(stiff_path_options, tool_rpy),
             STIFF_FIELD(stiff_path_options, flags),
             STIFF_FIELD(stiff_path_options, segment_m));
STIFF_FIELDS(stiff_diagnose_options,
             STIFF_FIELD(stiff_diagnose_options, struct_size),
             STIFF_FIELD(stiff_diagnose_options, model),
             STIFF_FIELD(stiff_diagnose_options, candidates),
             STIFF_FIELD(stiff_diagnose_options, alpha),
             STIFF_FIELD(stiff_diagnose_options, auto_steps),
             STIFF_FIELD(stiff_diagnose_options, command_prefix),
             STIFF_FIELD(stiff_diagnose_options, auto_loop),
             STIFF_FIELD(stiff_diagnose_options, repeatability_m));
STIFF_FIELDS(stiff_fmu_options,
             STIFF_FIELD(stiff_fmu_options, struct_size),
             STIFF_FIELD(stiff_fmu_options, fmi_version),
             STIFF_FIELD(stiff_fmu_options, model_identifier),
             STIFF_FIELD(stiff_fmu_options, binaries_dir),
             STIFF_FIELD(stiff_fmu_options, array_inputs));
STIFF_FIELDS(stiff_plan_options,
             STIFF_FIELD(stiff_plan_options, struct_size),
             STIFF_FIELD(stiff_plan_options, count),
             STIFF_FIELD(stiff_plan_options, criterion),
             STIFF_FIELD(stiff_plan_options, seed),
             STIFF_FIELD(stiff_plan_options, pool_poses),
             STIFF_FIELD(stiff_plan_options, pool_loads),
             STIFF_FIELD(stiff_plan_options, range_fraction),
             STIFF_FIELD(stiff_plan_options, load_min_N),
             STIFF_FIELD(stiff_plan_options, load_max_N),
             STIFF_FIELD(stiff_plan_options, load_step_N),
             STIFF_FIELD(stiff_plan_options, load_max_magnitude_N),
             STIFF_FIELD(stiff_plan_options, min_sigma_m),
             STIFF_FIELD(stiff_plan_options, q_fixed),
             STIFF_FIELD(stiff_plan_options, q_fixed_count),
             STIFF_FIELD(stiff_plan_options, optimizers),
             STIFF_FIELD(stiff_plan_options, annealing_iterations),
             STIFF_FIELD(stiff_plan_options, candidate_file),
             STIFF_FIELD(stiff_plan_options, task),
             STIFF_FIELD(stiff_plan_options, tracker_sigma_m),
             STIFF_FIELD(stiff_plan_options, tracker_ppm),
             STIFF_FIELD(stiff_plan_options, progress),
             STIFF_FIELD(stiff_plan_options, progress_user_data),
             STIFF_FIELD(stiff_plan_options, use_workspace_box),
             STIFF_FIELD(stiff_plan_options, box_min_m),
             STIFF_FIELD(stiff_plan_options, box_max_m),
             STIFF_FIELD(stiff_plan_options, fixture_directions),
             STIFF_FIELD(stiff_plan_options, fixture_direction_count),
             STIFF_FIELD(stiff_plan_options, fixture_forces_N),
             STIFF_FIELD(stiff_plan_options, fixture_force_count),
             STIFF_FIELD(stiff_plan_options, annealing_initial_temperature),
             STIFF_FIELD(stiff_plan_options, annealing_initial_swap_count));

STIFF_FIELDS(stiff_robot_options,
             STIFF_FIELD(stiff_robot_options, struct_size),
             STIFF_FIELD(stiff_robot_options, base_link),
             STIFF_FIELD(stiff_robot_options, tip_link),
             STIFF_FIELD(stiff_robot_options, set),
             STIFF_FIELD(stiff_robot_options, measured_point_m),
             STIFF_FIELD(stiff_robot_options, load_point_m),
             STIFF_FIELD(stiff_robot_options, tool_mass_kg),
             STIFF_FIELD(stiff_robot_options, tool_com_m));

#undef STIFF_FIELDS
#undef STIFF_FIELD

/// True if `size` is where a version of T ends: right after one of its fields, or there
/// rounded up to T's alignment (the padding a compiler adds at the end of that version).
template <typename T>
constexpr bool is_version_size(size_t size) {
  const size_t align = alignof(T);
  for (size_t i = 0; i < Fields<T>::count; ++i) {
    const size_t end = Fields<T>::spans[i].end;
    const size_t next = i + 1 < Fields<T>::count ? Fields<T>::spans[i + 1].begin : sizeof(T);
    const size_t padded = (end + align - 1) / align * align;
    if (size == end || (size == padded && padded <= next)) return true;
  }
  return false;
}

/// The field `size` ends inside of, as "bytes a..b", for the error message.
template <typename T>
std::string field_cut_by(size_t size) {
  for (size_t i = 0; i < Fields<T>::count; ++i)
    if (size > Fields<T>::spans[i].begin && size < Fields<T>::spans[i].end)
      return std::string("inside field '") + Fields<T>::spans[i].name + "' (bytes " +
             std::to_string(Fields<T>::spans[i].begin) + ".." +
             std::to_string(Fields<T>::spans[i].end) + ")";
  return "in the padding between fields";
}

}  // namespace stiff::capi
