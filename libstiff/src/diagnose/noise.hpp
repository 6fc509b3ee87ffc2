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
  /// Per row, the part of sigma that is not the force reading's [m] (the tracker's).
  Eigen::VectorXd sigma_tracker;
  /// Per row and base axis, the stated error of the force reading [N] (N x 3; no rows when the
  /// data states none): the analysis carries it through the model's force response into each
  /// row's 3 x 3 covariance (Analysis::W).
  Eigen::MatrixX3d force_sigma;
  bool known = false;
  double floor_m = 0.0;
  std::string source = "none";
  double force_part_m = 0.0;  ///< mean displacement error from the stated force error
  double tracker_m = 0.0;     ///< stated tracker sigma (median)

  /// The data state the force reading's error (force_sigma has rows).
  bool force_error_stated() const { return known && force_sigma.rows() > 0; }
};

/// The noise of `data` from what it states (sigma columns, metadata) or its replicates.
Noise noise_of(const Dataset& data);

}  // namespace stiff::diagnose_detail
