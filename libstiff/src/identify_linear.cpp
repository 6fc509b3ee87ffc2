// Linear least-squares identification of joint compliances, method.md eqs. 4-5.
#include <Eigen/QR>
#include <Eigen/SVD>
#include <cmath>

#include "stiff/error.hpp"
#include "stiff/identify.hpp"

namespace stiff {

FitResult identify_joint_linear(const RobotModel& robot, const Dataset& data,
                                const LinearOptions& options) {
  validate_dataset(data, robot.dof(), true);
  const int n = robot.dof();
  const int N = static_cast<int>(data.rows.size());
  const int m = 3 * N;
  DeflectionModel model(robot, {"joint"}, &data);

  Eigen::MatrixXd a = observation_matrix(robot, data);
  bool weighted = options.use_sigma && data.has_sigma;
  for (const auto& row : data.rows) weighted = weighted && row.sigma_d > 0;
  Eigen::VectorXd x(m), w = Eigen::VectorXd::Ones(m);
  for (int r = 0; r < N; ++r) {
    x.segment<3>(3 * r) = data.rows[r].displacement;
    if (weighted) w.segment<3>(3 * r).setConstant(1.0 / data.rows[r].sigma_d);
  }
  const Eigen::MatrixXd aw = w.asDiagonal() * a;
  const Eigen::VectorXd xw = w.asDiagonal() * x;

  // Column scaling makes the rank decision independent of units and lever arms.
  Eigen::VectorXd norms = aw.colwise().norm().transpose();
  const double max_norm = norms.maxCoeff();
  if (!(max_norm > 0)) throw NumericalError("identify: every observation column is zero (no load?)");
  std::vector<int> candidates;
  FitResult f;
  for (int j = 0; j < n; ++j) {
    if (norms(j) > 1e-12 * max_norm)
      candidates.push_back(j);
    else
      f.warnings.push_back("joint " + std::to_string(j + 1) +
                           " is not identifiable: its column of A is zero for every measurement "
                           "(the load and the measured point give it no torque or no motion); "
                           "held at c = 0");
  }
  Eigen::MatrixXd as(m, candidates.size());
  for (size_t k = 0; k < candidates.size(); ++k) as.col(k) = aw.col(candidates[k]) / norms(candidates[k]);
  Eigen::ColPivHouseholderQR<Eigen::MatrixXd> qr(as);
  qr.setThreshold(options.rank_tolerance);
  const int rank = static_cast<int>(qr.rank());
  std::vector<int> ident;
  const auto& perm = qr.colsPermutation().indices();
  for (int k = 0; k < static_cast<int>(candidates.size()); ++k) {
    if (k < rank)
      ident.push_back(candidates[perm(k)]);
    else
      f.warnings.push_back("joint " + std::to_string(candidates[perm(k)] + 1) +
                           " is not identifiable from this data: its column of A depends on the "
                           "others; held at c = 0 (add poses or loads that move it)");
  }
  std::sort(ident.begin(), ident.end());
  if (ident.empty()) throw NumericalError("identify: no joint compliance is identifiable");
  if (m <= static_cast<int>(ident.size()))
    throw InvalidArgument("identify: " + std::to_string(N) + " measurements give " +
                          std::to_string(m) + " equations for " + std::to_string(ident.size()) +
                          " compliances; at least " + std::to_string(ident.size() / 3 + 1) +
                          " measurements are needed");

  const int p = static_cast<int>(ident.size());
  Eigen::MatrixXd ai(m, p);
  Eigen::VectorXd scale(p);
  for (int k = 0; k < p; ++k) {
    scale(k) = norms(ident[k]);
    ai.col(k) = aw.col(ident[k]) / scale(k);
  }
  Eigen::JacobiSVD<Eigen::MatrixXd> svd(ai, Eigen::ComputeThinU | Eigen::ComputeThinV);
  const auto& sv = svd.singularValues();
  const Eigen::VectorXd cs = svd.solve(xw);
  const Eigen::VectorXd rw = xw - ai * cs;
  const double rss_w = rw.squaredNorm();
  const int dof = m - p;
  const double s2 = rss_w / dof;
  // (A^T A)^-1 of the scaled system from the SVD: V S^-2 V^T.
  const Eigen::MatrixXd inv = svd.matrixV() * sv.cwiseInverse().cwiseAbs2().asDiagonal() *
                              svd.matrixV().transpose();

  f.robot_name = robot.name;
  f.robot_path = robot.source_path;
  f.model = {"joint"};
  f.method = "linear_least_squares";
  f.measurements = N;
  f.rank = p;
  f.dof = dof;
  f.condition_number = sv(0) / sv(p - 1);
  f.covariance = Eigen::MatrixXd::Constant(n, n, NAN);
  for (int j = 0; j < n; ++j) {
    FitParameter fp;
    const auto& spec = model.spec(j);
    fp.effect = "joint";
    fp.name = spec.name;
    fp.unit = spec.unit;
    fp.meaning = spec.meaning;
    fp.value = 0.0;
    fp.standard_error = NAN;
    fp.identified = false;
    f.parameters.push_back(fp);
  }
  for (int k = 0; k < p; ++k) {
    auto& fp = f.parameters[ident[k]];
    fp.value = cs(k) / scale(k);
    fp.identified = true;
    for (int l = 0; l < p; ++l)
      f.covariance(ident[k], ident[l]) = s2 * inv(k, l) / (scale(k) * scale(l));
    fp.standard_error = std::sqrt(f.covariance(ident[k], ident[k]));
    if (fp.value <= 0)
      f.warnings.push_back("joint " + std::to_string(ident[k] + 1) +
                           ": identified compliance is not positive (" + std::to_string(fp.value) +
                           " rad/(N*m)); the data cannot resolve this joint's stiffness");
  }
  Eigen::VectorXd theta(n);
  for (int j = 0; j < n; ++j) theta(j) = f.parameters[j].value;
  f.residuals = x - a * theta;
  f.weights = Eigen::VectorXd::Ones(N);
  f.rms_m = std::sqrt(f.residuals.squaredNorm() / m);
  f.noise_floor_m = stated_noise_m(data);
  f.sigma_hat_m = weighted ? std::sqrt(s2) * f.noise_floor_m : std::sqrt(s2);
  if (weighted)
    f.chi2 = rss_w;
  else if (f.noise_floor_m > 0)
    f.chi2 = f.residuals.squaredNorm() / (f.noise_floor_m * f.noise_floor_m);
  return f;
}

}  // namespace stiff
