// The noise level of a data set for the diagnosis: per-row sigma and where it came from
// (docs/diagnosis.md, section 1). Private to diagnose/.
#pragma once

#include <Eigen/Core>
#include <string>

#include "stiff/io/dataset.hpp"

namespace stiff::diagnose_detail {

/// Noise level of the data: per-row sigma [m] and where it came from.
struct Noise {
  Eigen::VectorXd sigma;  ///< per row [m]; 1 (unit weights) when unknown
  bool known = false;
  double floor_m = 0.0;
  std::string source = "none";
  double force_part_m = 0.0;  ///< mean displacement error from the stated force error
  double tracker_m = 0.0;     ///< stated tracker sigma (median)
};

/// The noise of `data` from what it states (sigma columns, metadata) or its replicates.
Noise noise_of(const Dataset& data);

}  // namespace stiff::diagnose_detail
