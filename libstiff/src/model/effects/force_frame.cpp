// force_frame: orientation, scale and cross-talk errors of the force reading (docs/effects.md).
#include <utility>

#include "stiff/model/effects/common.hpp"

namespace stiff {
namespace {

/// Two physically common variants, both in the model so that the data chooses:
/// a sensor on the flange reports the load in its own frame, with a clocking error omega
/// (rotation about the flange axes) and per-axis gain errors s; a load applied through a
/// fixture (weights and pulleys, a cable to a load cell on the floor) has its direction and
/// gain errors fixed in the base frame (omega_b, s_b):
///   F_true = R(omega_b) diag(1 + s_b) R_06 R(omega) diag(1 + s) R_06^T F_meas  (and moment).
/// A common scale (s_x = s_y = s_z) is exactly collinear with the joint compliances,
/// A(sF) c = A(F) (s c): no displacement data can see it, only an independent force
/// reference (dead weights). identify() therefore holds one scale of each frame at 0 (the gains
/// are gauge parameters, ParameterSpec::gauge) and names the combination.
/// Each frame's map is the general linear one: besides the rotation (the antisymmetric part)
/// and the gains (the diagonal), a sensor's cross-axis sensitivity is the symmetric part off the
/// diagonal, (I + X), X_kl = X_lk = x_kl (the calibration matrix's off-diagonal error, a few per
/// cent on a strain-gauge sensor). The cross-talk terms are optional: a fit keeps those the data
/// support (sub_forms below).
class ForceFrame : public EffectT<ForceFrame> {
 public:
  explicit ForceFrame(const EffectSetup&) {
    const char* axis[3] = {"x", "y", "z"};
    for (int k = 0; k < 3; ++k)
      params_.push_back(
          effects::parameter(std::string("omega_") + axis[k], "rad",
                             std::string("rotation of the force-sensor frame about the flange ") +
                                 axis[k] + " axis (clocking)",
                             -0.5, 0.5, 0.02, 0.0, 0.0));
    for (int k = 0; k < 3; ++k) {
      params_.push_back(effects::parameter(
          std::string("scale_") + axis[k], "1",
          std::string("relative gain error of the force sensor's ") + axis[k] + " axis", -0.5, 0.5,
          0.02, 0.0, 0.0));
      params_.back().gauge = 1;  // the sensor's frame
    }
    for (int k = 0; k < 3; ++k)
      params_.push_back(
          effects::parameter(std::string("omega_base_") + axis[k], "rad",
                             std::string("rotation of the applied load about the base ") + axis[k] +
                                 " axis (fixture or load-cell alignment fixed in the base frame)",
                             -0.5, 0.5, 0.02, 0.0, 0.0));
    for (int k = 0; k < 3; ++k) {
      params_.push_back(effects::parameter(
          std::string("scale_base_") + axis[k], "1",
          std::string("relative gain error of the load along the base ") + axis[k] + " axis", -0.5,
          0.5, 0.02, 0.0, 0.0));
      params_.back().gauge = 2;  // the base frame
    }
    for (int frame = 0; frame < 2; ++frame)
      for (const auto& [k, l] : kPairs) {
        const std::string pair = std::string(axis[k]) + axis[l];
        params_.push_back(effects::parameter(
            std::string(frame == 0 ? "crosstalk_" : "crosstalk_base_") + pair, "1",
            std::string("cross-axis sensitivity between the ") +
                (frame == 0 ? "force sensor's " : "load's base ") + axis[k] + " and " + axis[l] +
                " axes (symmetric off-diagonal error of the " +
                (frame == 0 ? "sensor's" : "base-fixed reading's") + " calibration matrix)",
            -0.5, 0.5, 0.02, 0.0, 0.0));
        params_.back().optional_term = true;
      }
  }
  const std::string& name() const override { return name_; }
  bool example_parameters(const Eigen::VectorXd& /*c*/, double* p) const override {
    set_parameter(p, "omega_x", 0.01);
    set_parameter(p, "omega_y", -0.01);
    set_parameter(p, "omega_z", 0.087);  // 5 deg clocking of the sensor
    set_parameter(p, "scale_x", 0.02);
    set_parameter(p, "scale_y", -0.01);
    return true;
  }
  std::string description() const override {
    return "force frame: clocking omega, per-axis gain s and cross-talk X of a flange sensor, "
           "direction omega_b, gain s_b and cross-talk X_b of a load read in the base frame, F = "
           "R(omega_b) (I+X_b) diag(1+s_b) R_06 R(omega) (I+X) diag(1+s) R_06^T F_meas (X "
           "symmetric, zero diagonal, kept only where the data support it; a common gain is not "
           "identifiable)";
  }
  std::string reference() const override {
    return "OnRobot HEX-E/H datasheet (crosstalk < 5 %); docs/effects.md";
  }
  const std::vector<ParameterSpec>& parameters() const override { return params_; }
  /// The rotation and gains of each frame: a sensor mounted turned on the flange, a fixture
  /// pulling askew in the base frame. The cross-talk terms stay outside the common forms: a fit
  /// keeps one only at the extended information criterion's price (a term chosen among six).
  std::vector<std::vector<int>> sub_forms() const override {
    std::vector<int> flange(6), base(6);
    for (int k = 0; k < 6; ++k) flange[k] = k, base[k] = 6 + k;
    return {flange, base};
  }
  /// An experiment has one of the two (a sensor on the flange, or a load through a fixture):
  /// a fit drops the frame the data do not support as a whole (judged one term at a time, the
  /// other frame's terms stood in for some of the true frame's on 30 rows, and the price of
  /// each term dropped true ones).
  bool alternative_forms() const override { return true; }
  /// The score test tries both frames together, as one form of twelve terms.
  std::vector<std::vector<int>> score_forms() const override {
    std::vector<int> frame(12);
    for (int k = 0; k < 12; ++k) frame[k] = k;
    return {frame};
  }

  template <typename T>
  void wrench_t(const T* p, EvalState<T>& s) const {
    const Matrix3<T> rf = effects::flange_rotation(s);
    const Matrix3<T> r = effects::rotation_matrix(p);
    Vector3<T> gain;
    for (int k = 0; k < 3; ++k) gain(k) = T(1) + p[3 + k];
    const Matrix3<T> rb = effects::rotation_matrix(p + 6);
    Vector3<T> gain_b;
    for (int k = 0; k < 3; ++k) gain_b(k) = T(1) + p[9 + k];
    // The map applied factor by factor to each vector (3 x 3 times a vector, not the product
    // of seven matrices: the Jet passes of a fit evaluate this for every row).
    auto map = [&](const Vector3<T>& v) {
      const Vector3<T> sensor = cross<T>(p + 12, gain.cwiseProduct(rf.transpose() * v));
      return Vector3<T>(rb * cross<T>(p + 15, gain_b.cwiseProduct(rf * (r * sensor))));
    };
    s.force = map(s.force);
    s.moment = map(s.moment);
  }

 private:
  static constexpr std::pair<int, int> kPairs[3] = {{0, 1}, {0, 2}, {1, 2}};
  /// (I + X) v, X symmetric with a zero diagonal and x = (X_xy, X_xz, X_yz).
  template <typename T>
  static Vector3<T> cross(const T* x, const Vector3<T>& v) {
    Vector3<T> out = v;
    for (int i = 0; i < 3; ++i) {
      const auto [k, l] = kPairs[i];
      out(k) += x[i] * v(l);
      out(l) += x[i] * v(k);
    }
    return out;
  }
  std::string name_ = "force_frame";
  std::vector<ParameterSpec> params_;
};

}  // namespace

std::unique_ptr<Effect> make_force_frame_effect(const EffectSetup& s) {
  return std::make_unique<ForceFrame>(s);
}

}  // namespace stiff
