// gravity_lumped: deflection under the robot's own weight without a mass model.
#include "stiff/kinematics/joint_torque.hpp"
#include "stiff/model/effects/common.hpp"

namespace stiff {
namespace {

/// The gravity torque on joint j is tau_j = z_j . sum_k (c_k - o_j) x m_k g over the links
/// k it carries. With each link's weight lumped at the next joint's origin o_k (and a last
/// one at the measured point), the joint deflection c_j tau_j is linear in the products
/// beta_jk = c_j m_k:  dtheta_j = sum_{k>j} beta_jk z_j . ((o_k - o_j) x g),
/// regressors from the nominal geometry (lumped parameters, Khalil & Dombre 2002 ch. 12).
/// Acts on absolute rows only (the weight cancels in loaded-minus-unloaded differences).
class GravityLumped : public EffectT<GravityLumped> {
 public:
  explicit GravityLumped(const EffectSetup& s) : n_(s.robot->dof()), g_(s.robot->gravity) {
    for (int j = 0; j < n_; ++j)
      for (int k = j + 1; k <= n_; ++k) {
        const std::string jn = std::to_string(j + 1);
        const std::string kn = k < n_ ? std::to_string(k + 1) : std::string("P");
        params_.push_back(effects::parameter(
            "b" + jn + "_" + kn, "rad*kg/(N*m)",
            "compliance of joint " + jn + " times the weight lumped at " +
                (k < n_ ? "the origin of joint " + kn : std::string("the measured point")),
            -1e-1, 1e-1, 1e-5, 0.0, 0.0));
      }
  }
  const std::string& name() const override { return name_; }
  std::string description() const override {
    return "deflection under self-weight without a mass model: dtheta_j = sum_k beta_jk z_j . "
           "((o_k - o_j) x g), lumped masses at the joint origins (absolute data)";
  }
  std::string reference() const override {
    return "Khalil & Dombre, Modeling, Identification and Control of Robots (2002), ch. 11-12 "
           "(lumped/base parameters)";
  }
  const std::vector<ParameterSpec>& parameters() const override { return params_; }
  bool linear() const override { return true; }
  unsigned requirements() const override { return kNeedsAbsolute; }
  bool example_parameters(const Eigen::VectorXd& c, double* p) const override {
    // Lumped weights of a 6 kg-payload arm: 12, 8, 4, 2, 1 kg at the origins of joints 2..6
    // and a 3 kg tool at P, times the compliance of each joint that carries them.
    static const double m[7] = {0.0, 12.0, 8.0, 4.0, 2.0, 1.0, 3.0};
    int i = 0;
    for (int j = 0; j < n_; ++j)
      for (int k = j + 1; k <= n_; ++k, ++i)
        p[i] = (j < c.size() ? c(j) : 0.0) * (k < n_ ? m[std::min(k, 5)] : m[6]);
    return true;
  }
  std::vector<std::string> experiment_hints() const override {
    return {effects::kHintGravityVariety,
            "the same poses with a known payload added (a deflection proportional to the "
            "weight, not a fixed geometric error)"};
  }

  bool has_absolute_columns() const override { return true; }
  void absolute_columns(const double* /*p*/,
                        const EvalState<double>& s,
                        const AbsoluteTangents& t,
                        double* out) const override {
    // dtheta_j is linear in beta_jk: each column is the regressor times joint j's tangent.
    const ChainState& c = s.context->chain;
    const int rows = t.rows();
    int i = 0;
    for (int j = 0; j < n_; ++j)
      for (int k = j + 1; k <= n_; ++k, ++i)
        Eigen::Map<Eigen::VectorXd>(out + rows * i, rows) =
            t.dtheta.col(j) * regressor(c, j, k, s.p_meas);
  }

  template <typename T>
  void joint_t(const T* p, EvalState<T>& s) const {
    if (!s.measurement->absolute) return;
    const ChainState& c = s.context->chain;
    int i = 0;
    for (int j = 0; j < n_; ++j)
      for (int k = j + 1; k <= n_; ++k, ++i) s.dtheta(j) += p[i] * regressor(c, j, k, s.p_meas);
  }

 private:
  /// z_j . ((c_k - o_j) x g): the torque on joint j of a unit weight at the origin of joint k
  /// (k < n) or, k = n, at the measured point pm.
  template <typename T>
  T regressor(const ChainState& c, int j, int k, const Vector3<T>& pm) const {
    const Eigen::Vector3d z = c.axis.col(j), o = c.origin.col(j);
    if (k < n_) {
      Eigen::Vector3d lever;
      lever_arm(z, o, c.origin.col(k), lever);
      return T(force_torque(lever, g_));
    }
    // P moves with the tool and point offsets: keep its derivatives.
    // z . ((P - o) x g) = (g x z) . (P - o).
    const Eigen::Vector3d gz = g_.cross(z);
    T lever = T(-gz.dot(o));
    for (int a = 0; a < 3; ++a) lever += T(gz(a)) * pm(a);
    return lever;
  }

  int n_;
  Eigen::Vector3d g_;
  std::string name_ = "gravity_lumped";
  std::vector<ParameterSpec> params_;
};

}  // namespace

std::unique_ptr<Effect> make_gravity_lumped_effect(const EffectSetup& s) {
  return std::make_unique<GravityLumped>(s);
}

}  // namespace stiff
