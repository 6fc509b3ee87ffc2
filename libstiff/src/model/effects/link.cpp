// link: link compliance by the virtual joint method (VJM), reduced to the rotational springs
// the joint compliances cannot absorb (docs/effects.md).
#include "stiff/kinematics/joint_torque.hpp"
#include "stiff/model/effects/common.hpp"

namespace stiff {
namespace {

/// A virtual rotational spring at the root of link i (on joint axis i), about a unit axis u
/// fixed in link frame i and perpendicular to joint axis i. It acts like an extra revolute
/// joint between joints i and i+1: d += c (u x (P - o)) (u x (L - o) . F + u . M).
/// Candidates per link are the two axes perpendicular to joint axis i (bending out of the
/// link's plane and torsion); a candidate parallel to joint axis i+1 is dropped because that
/// joint's compliance absorbs it (Klimchik's model reduction). Every link between two joints
/// carries springs; those of the upper arm and forearm (links 2 and 3, the long castings) are
/// the common case and are always fitted, the others (the column, the wrist) are optional
/// terms (ParameterSpec::optional_term) that a fit keeps only when the data support them.
class LinkCompliance : public EffectT<LinkCompliance> {
 public:
  explicit LinkCompliance(const EffectSetup& s) {
    const RobotModel& robot = *s.robot;
    const int n = robot.dof();
    const ChainState c0 = robot.chain(Eigen::VectorXd::Zero(n));
    for (int link = 1; link <= n - 1; ++link) {
      const Eigen::Matrix3d r = c0.link[link - 1].block<3, 3>(0, 0);
      const Eigen::Vector3d a = r.transpose() * c0.axis.col(link - 1);  // axis i, link frame
      const Eigen::Vector3d next = r.transpose() * c0.axis.col(link);   // axis i+1
      Eigen::Vector3d u1 = Eigen::Vector3d::UnitX() - a.x() * a;
      if (u1.norm() < 0.3) u1 = Eigen::Vector3d::UnitY() - a.y() * a;
      u1.normalize();
      const Eigen::Vector3d u2 = a.cross(u1).normalized();
      const Eigen::Vector3d cand[2] = {u1, u2};
      const char* label[2] = {"x", "y"};
      for (int k = 0; k < 2; ++k) {
        if (std::abs(cand[k].dot(next)) > 0.95) continue;  // collinear with joint i+1
        springs_.push_back({link - 1, cand[k], label[k]});
        ParameterSpec p =
            effects::parameter("c_link" + std::to_string(link) + "_" + label[k], "rad/(N*m)",
                               "compliance of a virtual rotational spring at the root of link " +
                                   std::to_string(link) + " about its frame's " + label[k] +
                                   " axis (bending or torsion of the link)",
                               0.0, 1e-2, 3e-6, 0.0, 1e-6);
        p.optional_term = !arm(link);
        params_.push_back(p);
      }
    }
    // The upper arm and forearm bend along their length too: a spring a fraction s of the way
    // from the root, or a beam's distributed bending, adds terms in s and s^2 that no spring
    // at the root has (the beam's bending compliance at its root; docs/effects.md). Bending
    // axes: joint i's (in the arm's plane) and those of the link's root springs; not one along
    // the link (torsion does not depend on where it gives), nor one parallel to joints i and
    // i+1 both: bending about it turns the arm as those two joints do, and its cross term is
    // their coupled compliance (`coupling`).
    const size_t roots = springs_.size();
    for (int link = 1; link <= n - 1; ++link) {
      if (!arm(link)) continue;
      const Eigen::Matrix3d r = c0.link[link - 1].block<3, 3>(0, 0);
      const Eigen::Vector3d span = r.transpose() * (c0.origin.col(link) - c0.origin.col(link - 1));
      const double length = span.norm();
      if (length < 1e-3) continue;  // joints i and i+1 meet: no lever along the link
      const Eigen::Vector3d e = span / length;
      const Eigen::Vector3d own = r.transpose() * c0.axis.col(link - 1);
      const Eigen::Vector3d next = r.transpose() * c0.axis.col(link);
      std::vector<std::pair<Eigen::Vector3d, std::string>> axes;
      if (std::abs(own.dot(next)) <= 0.95) axes.push_back({own, "z"});
      for (size_t k = 0; k < roots; ++k)
        if (springs_[k].link == link - 1) axes.push_back({springs_[k].axis, springs_[k].label});
      for (const auto& [u, label] : axes) {
        if (u.cross(e).norm() < 0.3) continue;  // torsion
        beams_.push_back({link - 1, u, length * u.cross(e)});
        const std::string where = "bending of link " + std::to_string(link) +
                                  " along its length about its " + label + " axis";
        ParameterSpec coupled = effects::parameter(
            "c_link" + std::to_string(link) + "_" + label + "_coupled", "rad/(N*m)",
            where +
                ": turn per lateral force times the link's length, shift per moment "
                "(-c s for a spring a fraction s along; a beam's cross compliance)",
            -1e-2, 1e-2, 1e-6, 0.0, 0.0);
        ParameterSpec lateral = effects::parameter(
            "c_link" + std::to_string(link) + "_" + label + "_lateral", "rad/(N*m)",
            where +
                ": shift of the link's far end per lateral force, over its length squared "
                "(c s^2 for a spring a fraction s along)",
            0.0, 1e-2, 1e-6, 0.0, 0.0);
        coupled.optional_term = lateral.optional_term = true;
        params_.push_back(coupled);
        params_.push_back(lateral);
      }
    }
  }
  const std::string& name() const override { return name_; }
  /// The upper arm's and forearm's root springs, the common case, are scored on their own too.
  /// The column's and wrist's springs and the bending terms (the refinement of a spring's
  /// place) are rare terms: a fit keeps them at a higher price (docs/identifiability.md).
  std::vector<std::vector<int>> sub_forms() const override {
    const std::vector<int> arm = arm_springs();
    if (arm.empty() || arm.size() == params_.size()) return {};
    return {arm};
  }
  /// And every root spring: a spring in the column or the wrist is not diluted among the
  /// bending terms.
  std::vector<std::vector<int>> score_forms() const override {
    std::vector<std::vector<int>> out = sub_forms();
    std::vector<int> roots;
    for (size_t k = 0; k < springs_.size(); ++k) roots.push_back(static_cast<int>(k));
    if (roots.size() > arm_springs().size() && roots.size() < params_.size()) out.push_back(roots);
    return out;
  }
  bool example_parameters(const Eigen::VectorXd& /*c*/, double* p) const override {
    for (int k = 0; k < size(); ++k) p[k] = 0.0;
    for (int k : arm_springs()) p[k] = 1.0 / 3e5;  // k = 3e5 N*m/rad, a stiff casting
    return true;
  }
  std::string description() const override {
    return "link compliance (virtual joint method): rotational springs in the links about the "
           "axes the joints cannot absorb, d += c_v (u x (P-o)) (u x (L-o) . F), and the upper "
           "arm's and forearm's bending along their length; the column's and the wrist's "
           "springs and the bending terms kept only when the data support them";
  }
  std::string reference() const override {
    return "Pashkevich, Chablat & Wenger, Mech. Mach. Theory 44(5), 2009; Klimchik et al., "
           "Robotics Comput.-Integr. Manuf. 2014 (model reduction)";
  }
  const std::vector<ParameterSpec>& parameters() const override { return params_; }
  bool linear() const override { return true; }
  bool has_displacement_derivatives() const override { return true; }
  void displacement_derivatives(const EvalState<double>& s, double* out) const override {
    Eigen::Vector3d u, o;
    for (size_t k = 0; k < springs_.size(); ++k) {
      axis(s.context->chain, k, u, o);
      Eigen::Map<Eigen::Vector3d>(out + 3 * k) =
          torque(u, o, s.p_load, s.force, s.moment) * cross(u, s.p_meas, o);
    }
    Eigen::Vector3d lateral;
    double* col = out + 3 * springs_.size();
    for (size_t k = 0; k < beams_.size(); ++k, col += 6) {
      beam(s.context->chain, k, u, o, lateral);
      const double t = torque(u, o, s.p_load, s.force, s.moment), b = lateral.dot(s.force);
      Eigen::Map<Eigen::Vector3d> coupled(col), shift(col + 3);
      coupled = t * lateral + b * cross(u, s.p_meas, o);
      shift = b * lateral;
    }
  }

  template <typename T>
  void cartesian_t(const T* p, EvalState<T>& s) const {
    const auto& chain = s.context->chain;
    Eigen::Vector3d u, o;
    const bool wrench_fixed = effects::constant(s.force) && effects::constant(s.moment);
    if (wrench_fixed && effects::constant(s.p_load) && effects::constant(s.p_meas)) {
      // Points and wrench without derivatives (a pass that differentiates other parameters):
      // torques and lever arms are plain numbers.
      const Eigen::Vector3d f = effects::value(s.force), m = effects::value(s.moment);
      const Eigen::Vector3d pl = effects::value(s.p_load), pm = effects::value(s.p_meas);
      for (size_t k = 0; k < springs_.size(); ++k) {
        axis(chain, k, u, o);
        const T angle = p[k] * torque(u, o, pl, f, m);
        effects::add_scaled(s.d, angle, cross(u, pm, o));
        effects::add_scaled(s.rot, angle, u);
      }
      Eigen::Vector3d lateral;
      const T* q = p + springs_.size();
      for (size_t k = 0; k < beams_.size(); ++k, q += 2) {
        beam(chain, k, u, o, lateral);
        const double t = torque(u, o, pl, f, m), b = lateral.dot(f);
        effects::add_scaled(s.d, q[0] * t + q[1] * b, lateral);
        effects::add_scaled(s.d, q[0] * b, cross(u, pm, o));
        effects::add_scaled(s.rot, q[0] * b, u);
      }
      return;
    }
    // The springs' sum c_v t_v (u_v x (P - o_v)) is w x P - sum c_v t_v (u_v x o_v) with
    // w = sum c_v t_v u_v (their rotation): one product with P for all springs.
    Vector3<T> w = Vector3<T>::Zero(), wo = Vector3<T>::Zero();
    for (size_t k = 0; k < springs_.size(); ++k) {
      axis(chain, k, u, o);
      T tk;  // the spring's torque
      if (wrench_fixed) {
        // (u x (L - o)) . F = L . (F x u) - o . (F x u): derivatives only through L.
        const Eigen::Vector3d f = effects::value(s.force), m = effects::value(s.moment);
        const Eigen::Vector3d a = f.cross(u);
        tk = effects::dot(s.p_load, a) + (m.dot(u) - o.dot(a));
      } else {
        tk = joint_torque(cross(u, s.p_load, o), u, s.force, s.moment);
      }
      const T angle = p[k] * tk;
      effects::add_scaled(w, angle, u);
      effects::add_scaled(wo, angle, u.cross(o));
    }
    // A bending term turns the arm like a spring at the root (its rotation joins w) and
    // shifts it along the lateral direction l = length (u x e): the cross term c by l.F about
    // u and by the root torque along l, the lateral term by l.F along l.
    Eigen::Vector3d lateral;
    const T* q = p + springs_.size();
    for (size_t k = 0; k < beams_.size(); ++k, q += 2) {
      beam(chain, k, u, o, lateral);
      const T tk = joint_torque(cross(u, s.p_load, o), u, s.force, s.moment);
      const T bk = effects::dot(s.force, lateral);
      const T angle = q[0] * bk;
      effects::add_scaled(w, angle, u);
      effects::add_scaled(wo, angle, u.cross(o));
      effects::add_scaled(s.d, q[0] * tk + q[1] * bk, lateral);
    }
    const Vector3<T>& pm = s.p_meas;
    s.d(0) += w(1) * pm(2) - w(2) * pm(1) - wo(0);
    s.d(1) += w(2) * pm(0) - w(0) * pm(2) - wo(1);
    s.d(2) += w(0) * pm(1) - w(1) * pm(0) - wo(2);
    s.rot += w;
  }

 private:
  // The upper arm and forearm (links 2 and 3), the long castings.
  static bool arm(int link) { return link == 2 || link == 3; }
  // The root springs of the upper arm and forearm: the springs that are not optional terms.
  std::vector<int> arm_springs() const {
    std::vector<int> out;
    for (size_t k = 0; k < springs_.size(); ++k)
      if (!params_[k].optional_term) out.push_back(static_cast<int>(k));
    return out;
  }
  // Bending term k's axis u and root o (base frame) and its lateral direction
  // l = length (u x e), e the unit vector from the link's root to the next joint's origin.
  void beam(const ChainState& chain,
            size_t k,
            Eigen::Vector3d& u,
            Eigen::Vector3d& o,
            Eigen::Vector3d& lateral) const {
    const Eigen::Matrix3d r = chain.link[beams_[k].link].block<3, 3>(0, 0);
    u = r * beams_[k].axis;
    o = chain.origin.col(beams_[k].link);
    lateral = r * beams_[k].lateral;
  }
  // The spring axis u and origin o do not depend on the parameters: kept in double so that
  // automatic differentiation only carries derivatives where they can be non-zero.
  void axis(const ChainState& chain, size_t k, Eigen::Vector3d& u, Eigen::Vector3d& o) const {
    const int i = springs_[k].link;
    u = chain.link[i].block<3, 3>(0, 0) * springs_[k].axis;
    o = chain.origin.col(i);
  }
  // Torque about the spring's axis u through o of the wrench (F at L, M) [N*m].
  static double torque(const Eigen::Vector3d& u,
                       const Eigen::Vector3d& o,
                       const Eigen::Vector3d& l,
                       const Eigen::Vector3d& f,
                       const Eigen::Vector3d& m) {
    return joint_torque(cross(u, l, o), u, f, m);
  }
  // The lever arm u x (p - o) of p about the spring's (constant) axis.
  template <typename T>
  static Vector3<T> cross(const Eigen::Vector3d& u, const Vector3<T>& p, const Eigen::Vector3d& o) {
    Vector3<T> w;
    lever_arm(u, o, p, w);
    return w;
  }
  struct Spring {
    int link;              ///< 0-based link index
    Eigen::Vector3d axis;  ///< unit axis in the link frame
    std::string label;     ///< its name in the parameters' ("x", "y")
  };
  struct Beam {
    int link;                 ///< 0-based link index
    Eigen::Vector3d axis;     ///< unit bending axis u in the link frame
    Eigen::Vector3d lateral;  ///< length (u x e) in the link frame [m]
  };
  std::string name_ = "link";
  std::vector<Spring> springs_;
  std::vector<Beam> beams_;  ///< parameters after the springs', (coupled, lateral) each
  std::vector<ParameterSpec> params_;
};

}  // namespace

std::unique_ptr<Effect> make_link_effect(const EffectSetup& s) {
  return std::make_unique<LinkCompliance>(s);
}

}  // namespace stiff
