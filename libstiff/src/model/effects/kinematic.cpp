// kinematic: errors of each joint axis's position and direction (absolute rows).
#include "stiff/model/effects/common.hpp"

namespace stiff {
namespace {

/// Each joint axis is a line; its errors are two translations perpendicular to it and two
/// tilts about the perpendicular directions u, v, applied in the frame the joint is defined
/// in (after its `pre` transform; for DH robots u, v are that frame's x, y):
///   T_j = pre_j * Trans(du u + dv v) * Rot(ru u + rv v) * Rot(axis_j, q_j) * post_j.
/// With the joint offsets (rotation about the axis), the base registration and the tool this
/// is a complete model (4 per revolute joint, Mooring et al. 1991). It is continuous when
/// consecutive axes are parallel, where the DH parameters jump (Hayati & Mirmirani 1985:
/// the tilt about y is Hayati's beta); the directions the data cannot separate (a
/// translation along a parallel neighbour, the first axis against the registration) are
/// found numerically by the identifiability check.
class Kinematic : public EffectT<Kinematic> {
 public:
  explicit Kinematic(const EffectSetup& s) {
    const int n = s.robot->dof();
    u_.resize(3, n);
    v_.resize(3, n);
    for (int j = 0; j < n; ++j) {
      const Eigen::Vector3d a = s.robot->joints[j].axis.normalized();
      int least = 0;  // the frame axis least aligned with the joint axis
      a.cwiseAbs().minCoeff(&least);
      const Eigen::Vector3d e = Eigen::Vector3d::Unit(least);
      const Eigen::Vector3d u = (e - e.dot(a) * a).normalized();
      u_.col(j) = u;
      v_.col(j) = a.cross(u);
      const std::string k = std::to_string(j + 1);
      const bool parallel = j > 0 && (s.robot->joints[j - 1].post.topLeftCorner<3, 3>() *
                                      s.robot->joints[j].pre.topLeftCorner<3, 3>() * a)
                                             .cross(s.robot->joints[j - 1].axis)
                                             .norm() < 1e-6;
      const std::string note =
          parallel ? " (parallel to axis " + std::to_string(j) + ": Hayati parameter)" : "";
      params_.push_back(effects::parameter(
          "du" + k, "m", "translation of axis " + k + " along u" + k, -0.1, 0.1, 1e-4, 0.0, 0.0));
      params_.push_back(effects::parameter(
          "dv" + k, "m", "translation of axis " + k + " along v" + k, -0.1, 0.1, 1e-4, 0.0, 0.0));
      params_.push_back(effects::parameter(
          "ru" + k, "rad", "tilt of axis " + k + " about u" + k + note, -0.1, 0.1, 1e-3, 0.0, 0.0));
      params_.push_back(effects::parameter(
          "rv" + k, "rad", "tilt of axis " + k + " about v" + k + note, -0.1, 0.1, 1e-3, 0.0, 0.0));
    }
  }
  const std::string& name() const override { return name_; }
  std::string description() const override {
    return "kinematic errors: each joint axis translated and tilted perpendicular to itself "
           "(4 per joint, continuous at parallel axes; absolute data)";
  }
  std::string reference() const override {
    return "Hayati & Mirmirani, J. Robotic Systems 2(4), 1985; Mooring, Roth & Driels, "
           "Fundamentals of Manipulator Calibration (1991)";
  }
  const std::vector<ParameterSpec>& parameters() const override { return params_; }
  unsigned requirements() const override { return kNeedsAbsolute; }
  bool example_parameters(const Eigen::VectorXd& /*c*/, double* p) const override {
    // Machining and assembly tolerances: axes off by 0.1-0.3 mm and tilted by 0.2-0.8 mrad.
    static const double e[4][4] = {{2e-4, -1e-4, 5e-4, -3e-4},
                                   {-1.5e-4, 3e-4, -2e-4, 8e-4},
                                   {1e-4, 2e-4, 6e-4, -4e-4},
                                   {-3e-4, -1e-4, -7e-4, 2e-4}};
    for (int k = 0; k < size(); ++k) p[k] = e[(k / 4) % 4][k % 4];
    return true;
  }
  std::vector<std::string> experiment_hints() const override {
    return {
        "poses that move every joint over its range with large flange rotations (axis "
        "translations and tilts show as pose-dependent position errors; a second target on "
        "the tool separates them from the tool offset)"};
  }

  bool has_absolute_columns() const override { return true; }
  void absolute_columns(const double* /*p*/,
                        const EvalState<double>& /*s*/,
                        const AbsoluteTangents& t,
                        double* out) const override {
    // The translation moves joint_error's rows 0-2 along u, v; the tilt its rows 3-5.
    const int rows = t.rows();
    for (int j = 0; j < u_.cols(); ++j) {
      Eigen::Map<Eigen::Matrix<double, Eigen::Dynamic, 4>> c(out + 4 * rows * j, rows, 4);
      const auto move = t.joint_error.middleCols<3>(6 * j);
      const auto turn = t.joint_error.middleCols<3>(6 * j + 3);
      c.col(0) = move * u_.col(j);
      c.col(1) = move * v_.col(j);
      c.col(2) = turn * u_.col(j);
      c.col(3) = turn * v_.col(j);
    }
  }

  template <typename T>
  void geometry_t(const T* p, EvalState<T>& s) const {
    for (int j = 0; j < s.joint_error.cols(); ++j) {
      const T* e = p + 4 * j;
      for (int k = 0; k < 3; ++k) {
        s.joint_error(k, j) += e[0] * u_(k, j) + e[1] * v_(k, j);
        s.joint_error(3 + k, j) += e[2] * u_(k, j) + e[3] * v_(k, j);
      }
    }
  }

 private:
  std::string name_ = "kinematic";
  std::vector<ParameterSpec> params_;
  Eigen::Matrix3Xd u_, v_;  ///< per joint: the directions perpendicular to its axis
};

}  // namespace

std::unique_ptr<Effect> make_kinematic_effect(const EffectSetup& s) {
  return std::make_unique<Kinematic>(s);
}

}  // namespace stiff
