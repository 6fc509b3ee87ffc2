// registration: the instrument frame of each session (absolute rows).
#include <ceres/rotation.h>

#include "stiff/model/effects/common.hpp"

namespace stiff {
namespace {

/// An instrument placed once per session reports positions in its own frame:
/// p_instrument = R(omega_s) p_base + t_s, a rigid motion per session (rotation vector
/// omega_s, exact; translation t_s); a 6-D probe's orientation R_instrument = R(omega_s) R_base.
/// Started from the first alignment of the nominal robot on the data (Arun, Huang & Blostein 1987).
/// Acts on absolute rows only.
class Registration : public EffectT<Registration> {
 public:
  explicit Registration(const EffectSetup& s) {
    std::vector<std::string> labels = s.session_labels;
    effects::Alignment start;
    if (s.data && s.data->absolute_rows() > 0) start = effects::alignment(*s.robot, *s.data);
    if (labels.empty()) labels.assign(std::max(1, s.sessions), "");
    for (size_t k = 0; k < labels.size(); ++k) {
      const std::string tag = labels[k].empty() ? std::to_string(k + 1) : labels[k];
      double w[3] = {0, 0, 0};
      Eigen::Vector3d t = Eigen::Vector3d::Zero();
      if (k < start.rotation.size()) {
        const Eigen::Matrix3d r = start.rotation[k];
        ceres::RotationMatrixToAngleAxis(r.data(), w);
        t = start.translation[k];
      }
      const char* axis[3] = {"x", "y", "z"};
      for (int a = 0; a < 3; ++a)
        params_.push_back(effects::parameter(
            std::string("omega_") + axis[a] + "_" + tag, "rad",
            "rotation vector (instrument <- base) of session " + tag + ", " + axis[a], -4.0, 4.0,
            1e-3, w[a], w[a]));
      for (int a = 0; a < 3; ++a)
        params_.push_back(effects::parameter(
            std::string("t_") + axis[a] + "_" + tag, "m",
            "base origin in the instrument frame of session " + tag + ", " + axis[a], -1e3, 1e3,
            1e-3, t(a), t(a)));
    }
  }
  const std::string& name() const override { return name_; }
  std::string description() const override {
    return "registration of the instrument frame per session: p_instrument = R(omega_s) p + t_s "
           "(absolute data)";
  }
  std::string reference() const override {
    return "Arun, Huang & Blostein, IEEE PAMI 9(5), 1987; Mooring, Roth & Driels (1991), base "
           "and world frames";
  }
  unsigned requirements() const override { return kNeedsSessions | kNeedsAbsolute; }
  bool example_parameters(const Eigen::VectorXd& /*c*/, double* p) const override {
    // A tracker placed about 2.4 m from the base, turned 34 deg about the vertical and 2-3 deg
    // about the horizontal axes.
    static const double w[6] = {0.03, -0.05, 0.6, 2.0, -1.2, 0.4};
    for (int k = 0; k < size(); ++k) p[k] = w[k % 6];
    return true;
  }
  std::vector<std::string> experiment_hints() const override {
    return {
        "a second tracker placement (a new session) measuring part of the same poses: "
        "the registration changes, the robot's geometry does not"};
  }
  const std::vector<ParameterSpec>& parameters() const override { return params_; }

  bool has_absolute_columns() const override { return true; }
  void absolute_columns(const double* p,
                        const EvalState<double>& s,
                        const AbsoluteTangents& t,
                        double* out) const override {
    // y = R(omega) x + t: R(omega + dw) = R Exp(J_r dw) turns y by R ((J_r dw) x x), i.e.
    // dy/domega = -R [x]x J_r (the session's block only; the other sessions' columns are 0).
    // The orientation R(omega) R_base turns the same way: as R_base -> Exp(J_r dw) R_base,
    // which t.turn maps.
    const int k = session(s);
    const int rows = t.rows();
    const Eigen::Map<const Eigen::Vector3d> w(p + 6 * k);
    const Eigen::Matrix3d r = effects::rotation_matrix(w.data());
    const Eigen::Matrix3d jr = effects::right_jacobian(w);
    const Eigen::Vector3d& x = t.position;
    Eigen::Matrix3d cross;
    cross << 0, -x(2), x(1), x(2), 0, -x(0), -x(1), x(0), 0;
    Eigen::Map<Eigen::Matrix<double, Eigen::Dynamic, 6>> c(out + 6 * rows * k, rows, 6);
    c.topLeftCorner<3, 3>() = -r * cross * jr;
    c.topRightCorner<3, 3>().setIdentity();
    if (rows == 6) c.bottomLeftCorner<3, 3>() = t.turn * jr;
  }

  template <typename T>
  void measurement_t(const T* p, EvalState<T>& s) const {
    if (!s.measurement->absolute) return;
    const T* w = p + 6 * session(s);
    const Matrix3<T> r = effects::rotation_matrix(w);
    const Vector3<T> x = s.d;
    for (int a = 0; a < 3; ++a)
      s.d(a) = r(a, 0) * x(0) + r(a, 1) * x(1) + r(a, 2) * x(2) + w[3 + a];
    // A 6-D probe's orientation turns with the frame: R_instrument = R(omega_s) R_base.
    if (s.oriented) s.orientation = (r * s.orientation).eval();
  }

 private:
  /// The row's session (the first for a session the model does not know).
  template <typename T>
  int session(const EvalState<T>& s) const {
    const int k = s.context->session;
    return k < 0 || 6 * k >= static_cast<int>(params_.size()) ? 0 : k;
  }
  std::string name_ = "registration";
  std::vector<ParameterSpec> params_;
};

}  // namespace

std::unique_ptr<Effect> make_registration_effect(const EffectSetup& s) {
  return std::make_unique<Registration>(s);
}

}  // namespace stiff
