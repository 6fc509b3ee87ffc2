/// \file identify.hpp
/// Identification of the compliance model from measurements.
#pragma once

#include "stiff/fit.hpp"

namespace stiff {

/// Options of the linear least-squares identification (method.md eq. 5).
struct LinearOptions {
  /// Relative tolerance on the column-scaled pivoted QR diagonal below which a direction is
  /// declared unidentifiable.
  double rank_tolerance = 1e-8;
  /// Weight rows by 1/sigma_d when the data has sigma_d.
  bool use_sigma = true;
};

/// Least-squares identification of the diagonal joint compliances (`joint` model), c =
/// argmin ||A c - X||, by column-pivoted QR of the column-scaled A. Joints whose columns the
/// data cannot identify (zero or dependent) are named in `warnings`, held at 0 and marked
/// unidentified. Throws InvalidArgument for bad data and NumericalError when nothing is
/// identifiable.
FitResult identify_joint_linear(const RobotModel& robot, const Dataset& data,
                                const LinearOptions& options = {});

}  // namespace stiff
