// Robust location and scale of residuals, shared by the identification (robust loss scale)
// and the diagnosis (outlier screening).
#pragma once

#include <algorithm>
#include <cmath>
#include <vector>

namespace stiff::robust {

/// Median of v (the upper middle element for an even count); 0 for an empty vector.
inline double median(std::vector<double> v) {
  if (v.empty()) return 0.0;
  std::nth_element(v.begin(), v.begin() + static_cast<std::ptrdiff_t>(v.size() / 2), v.end());
  return v[v.size() / 2];
}

/// Normalised median absolute deviation: 1.4826 * median(|v - median(v)|), a consistent
/// estimator of the standard deviation of Gaussian data that ignores up to half of the values
/// as outliers (Rousseeuw & Croux 1993).
inline double mad_sigma(std::vector<double> v) {
  const double med = median(v);
  for (auto& x : v) x = std::abs(x - med);
  return 1.4826 * median(std::move(v));
}

}  // namespace stiff::robust
