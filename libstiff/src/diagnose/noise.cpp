#include "diagnose/noise.hpp"

#include <algorithm>
#include <cmath>
#include <cstdlib>
#include <map>
#include <vector>

#include "identify/robust.hpp"
#include "stiff/identify/fit.hpp"

namespace stiff::diagnose_detail {
namespace {

using Eigen::VectorXd;

Noise noise_of_tracker(const Dataset& data);

double meta_number(const Dataset& data, const std::string& key) {
  const std::string meta = data.meta(key);
  if (meta.empty()) return 0.0;
  char* end = nullptr;
  const double v = std::strtod(meta.c_str(), &end);
  return end != meta.c_str() && std::isfinite(v) && v > 0 ? v : 0.0;
}

/// How the data states its force error: "a + b x" as a linear sum (the default, the convention
/// of instrument specifications) unless `# force_error_sum: quadrature`.
bool force_error_sum_is_linear(const Dataset& data) {
  return data.meta("force_error_sum") != "quadrature";
}

/// Add the displacement error caused by the stated force-sensor error (metadata
/// force_relative, force_absolute_N). Instrument specifications written "a + b x" are linear
/// sums (the convention of force-sensor data sheets and of ISO 10360 / ASME B89.4.19 MPEs):
/// per force component sigma_k = rel |F_k| + abs. `# force_error_sum: quadrature` states
/// sqrt((rel F_k)^2 + abs^2) instead. A force error dF moves the measured point by about
/// |d| |dF| / |F|, so per displacement axis sigma_F^2 = |d|^2 sum_k sigma_k^2 / (3 |F|^2): the
/// row's scale for outliers and reports. The tests use the error's direction too: G dF, G the
/// model's displacement per unit force (Analysis::W).
void add_force_noise(const Dataset& data, Noise& n) {
  const double rel = meta_number(data, "force_relative");
  const double abs_n = meta_number(data, "force_absolute_N");
  if (!(rel > 0 || abs_n > 0)) return;
  const bool linear = force_error_sum_is_linear(data);
  n.force_sigma = Eigen::MatrixX3d::Zero(static_cast<Eigen::Index>(data.rows.size()), 3);
  double sum = 0;
  for (size_t r = 0; r < data.rows.size(); ++r) {
    const auto& m = data.rows[r];
    const double f = m.force.norm();
    if (!(f > 0) || m.absolute) continue;  // the deflection is not what an absolute row holds
    double s2 = 0;
    for (int k = 0; k < 3; ++k) {
      const double a = rel * std::abs(m.force(k));
      const double sk = linear ? a + abs_n : std::hypot(a, abs_n);
      n.force_sigma(static_cast<Eigen::Index>(r), k) = sk;
      s2 += sk * sk;
    }
    const double v = m.displacement.squaredNorm() * s2 / (3 * f * f);
    n.sigma(r) = std::sqrt(n.sigma(r) * n.sigma(r) + v);
    sum += std::sqrt(v);
  }
  n.force_part_m = sum / std::max<size_t>(1, data.rows.size());
  n.floor_m = std::sqrt(n.sigma.squaredNorm() / std::max<Eigen::Index>(1, n.sigma.size()));
}

Noise noise_of_tracker(const Dataset& data) {
  Noise n;
  const int rows = static_cast<int>(data.rows.size());
  n.sigma = VectorXd::Ones(rows);
  // sigma_d of a displacement row, sigma_p of an absolute one: every row must state one.
  bool all_sigma = data.has_sigma || data.has_sigma_p;
  if (all_sigma)
    for (const auto& m : data.rows)
      if (!(m.sigma() > 0)) all_sigma = false;
  if (all_sigma) {
    for (int r = 0; r < rows; ++r) n.sigma(r) = data.rows[r].sigma();
    n.known = true;
    n.source = data.has_sigma_p ? "sigma_p" : "sigma_d";
    n.floor_m = stated_noise_m(data);
    return n;
  }
  const std::string meta = data.meta("tracker_sigma_m");
  if (!meta.empty()) {
    char* end = nullptr;
    const double v = std::strtod(meta.c_str(), &end);
    if (end != meta.c_str() && std::isfinite(v) && v > 0) {
      n.sigma.setConstant(v);
      n.known = true;
      n.source = "metadata";
      n.floor_m = v;
      return n;
    }
  }
  // Replicated measurements: same pose and load; pooled within-group spread.
  std::vector<int> group(rows, -1);
  int groups = 0;
  for (int a = 0; a < rows; ++a) {
    if (group[a] >= 0) continue;
    group[a] = groups;
    for (int b = a + 1; b < rows; ++b) {
      const auto& ma = data.rows[a];
      const auto& mb = data.rows[b];
      if (group[b] < 0 && ma.session == mb.session && ma.absolute == mb.absolute &&
          (ma.q - mb.q).norm() < 1e-9 &&
          (ma.force - mb.force).norm() < 1e-6 * (1.0 + ma.force.norm()) &&
          (ma.moment - mb.moment).norm() < 1e-6 * (1.0 + ma.moment.norm()))
        group[b] = groups;
    }
    ++groups;
  }
  std::vector<Eigen::Vector3d> sum(groups, Eigen::Vector3d::Zero());
  std::vector<int> count(groups, 0);
  for (int r = 0; r < rows; ++r) {
    sum[group[r]] += data.rows[r].observed();
    ++count[group[r]];
  }
  double ss = 0;
  int dof = 0;
  for (int r = 0; r < rows; ++r)
    ss += (data.rows[r].observed() - sum[group[r]] / count[group[r]]).squaredNorm();
  for (int g = 0; g < groups; ++g) dof += 3 * (count[g] - 1);
  if (dof >= 3 && ss > 0) {
    const double s = std::sqrt(ss / dof);
    n.sigma.setConstant(s);
    n.known = true;
    n.source = "replicates";
    n.floor_m = s;
  }
  return n;
}

}  // namespace

Noise noise_of(const Dataset& data) {
  Noise n = noise_of_tracker(data);
  n.tracker_m = n.floor_m;
  n.sigma_tracker = n.sigma;
  if (n.known) add_force_noise(data, n);
  return n;
}

}  // namespace stiff::diagnose_detail
