// coupling: symmetric off-diagonal joint compliance between joints
// (docs/effects.md).
#include <utility>

#include "stiff/model/effects/common.hpp"

namespace stiff {
namespace {

/// C is symmetric with an entry c_{jk} for every pair of joints j < k:
///   dtheta_j += c_{jk} tau_k, dtheta_k += c_{jk} tau_j.
/// Adjacent pairs are the common case (wrist gear trains, parallelogram drives, bearing tilt);
/// the others occur too: a coupled wrist transmission couples 4-5-6 (also 4 with 6), a tendon-
/// or belt-driven arm couples joints whose cables run past each other. Every entry is optional
/// (ParameterSpec::optional_term): a fit keeps the pairs the data support, so that a coupling
/// of one pair is not predicted through the noise of all the others.
/// A physical C is positive definite, |c_{jk}| < sqrt(c_j c_k); the fit does not enforce it
/// (check rho = c_{jk} / sqrt(c_j c_k) in the result).
class Coupling : public EffectT<Coupling> {
 public:
  explicit Coupling(const EffectSetup& s) {
    const int n = s.robot->dof();
    for (int j = 0; j < n; ++j)
      for (int k = j + 1; k < n; ++k) {
        const std::string a = std::to_string(j + 1), b = std::to_string(k + 1);
        ParameterSpec p = effects::parameter(
            "c" + a + (n > 9 ? "_" : "") + b, "rad/(N*m)",
            "coupling compliance of joints " + a + " and " + b + " (torque on one turns the other)",
            -1e-2, 1e-2, 3e-6, 0.0, 0.0);
        p.optional_term = true;
        params_.push_back(p);
        pairs_.emplace_back(j, k);
      }
  }
  const std::string& name() const override { return name_; }
  /// The adjacent pairs, the common case, are scored on their own too.
  std::vector<std::vector<int>> sub_forms() const override {
    std::vector<int> adjacent;
    for (size_t q = 0; q < pairs_.size(); ++q)
      if (pairs_[q].second == pairs_[q].first + 1) adjacent.push_back(static_cast<int>(q));
    if (adjacent.size() == pairs_.size()) return {};
    return {adjacent};
  }
  bool example_parameters(const Eigen::VectorXd& c, double* p) const override {
    set_parameter(p, "c23", 0.2 * std::sqrt(c(1) * c(2)));
    set_parameter(p, "c34", 0.1 * std::sqrt(c(2) * c(3)));
    set_parameter(p, "c45", 0.3 * std::sqrt(c(3) * c(4)));
    return true;
  }
  std::string description() const override {
    return "joint coupling: symmetric off-diagonal compliance c_jk of every pair of joints "
           "(torque on joint j deflects joint k), each pair kept only when the data support it";
  }
  std::string reference() const override {
    return "Oliveira & Trabasso (symmetric positive-definite joint stiffness identification); "
           "Abele et al., CIRP Annals 56(1), 2007";
  }
  const std::vector<ParameterSpec>& parameters() const override { return params_; }
  bool linear() const override { return true; }

  template <typename T>
  void joint_t(const T* p, EvalState<T>& s) const {
    const VectorX<T> tau = s.tau;
    for (size_t q = 0; q < pairs_.size(); ++q) {
      const auto [j, k] = pairs_[q];
      s.dtheta(j) += p[q] * tau(k);
      s.dtheta(k) += p[q] * tau(j);
    }
  }

 private:
  std::string name_ = "coupling";
  std::vector<ParameterSpec> params_;
  std::vector<std::pair<int, int>> pairs_;
};

}  // namespace

std::unique_ptr<Effect> make_coupling_effect(const EffectSetup& s) {
  return std::make_unique<Coupling>(s);
}

}  // namespace stiff
