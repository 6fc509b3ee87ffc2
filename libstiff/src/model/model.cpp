#include "stiff/model/model.hpp"

#include <ceres/rotation.h>

#include <Eigen/QR>
#include <algorithm>
#include <cstdint>
#include <cstring>
#include <map>
#include <set>
#include <type_traits>

#include "kinematics/fast_chain.hpp"
#include "stiff/error.hpp"
#include "stiff/kinematics/joint_torque.hpp"
#include "stiff/model/effects/common.hpp"

namespace stiff {

std::vector<std::string> parse_model_string(const std::string& text) {
  std::vector<std::string> names;
  std::set<std::string> seen;
  size_t start = 0;
  while (true) {
    const size_t plus = text.find('+', start);
    std::string name =
        text.substr(start, plus == std::string::npos ? std::string::npos : plus - start);
    const auto b = name.find_first_not_of(" \t");
    const auto e = name.find_last_not_of(" \t");
    name = b == std::string::npos ? std::string() : name.substr(b, e - b + 1);
    if (name.empty()) throw InvalidArgument("model '" + text + "': empty effect name");
    if (!seen.insert(name).second)
      throw InvalidArgument("model '" + text + "': effect '" + name + "' given twice");
    names.push_back(name);
    if (plus == std::string::npos) break;
    start = plus + 1;
  }
  return names;
}

DeflectionModel::DeflectionModel(const RobotModel& robot,
                                 const std::vector<std::string>& effects,
                                 const Dataset* data,
                                 const std::vector<std::string>& sessions,
                                 const std::map<std::string, double>* decide_at)
    : DeflectionModel(robot, effects, data, sessions, true, decide_at) {}

DeflectionModel::DeflectionModel(const RobotModel& robot,
                                 const std::vector<std::string>& effects,
                                 const Dataset* data,
                                 const std::vector<std::string>& sessions,
                                 bool backfit,
                                 const std::map<std::string, double>* decide_at)
    : robot_(robot) {
  if (robot.dof() == 0) throw InvalidArgument("robot has no joints");
  if (effects.empty()) throw InvalidArgument("model has no effect (e.g. 'joint')");
  if (data) {
    for (const auto& m : data->rows)
      if (!sessions_.count(m.session)) {
        const int k = static_cast<int>(sessions_.size());
        sessions_[m.session] = k;
      }
  }
  if (!data)
    for (const auto& label : sessions)
      if (!sessions_.count(label)) {
        const int k = static_cast<int>(sessions_.size());
        sessions_[label] = k;
      }
  EffectSetup setup;
  setup.robot = &robot_;
  setup.data = data;
  setup.sessions = std::max<int>(1, static_cast<int>(sessions_.size()));
  setup.session_labels = session_labels();
  std::set<std::string> seen;
  for (const auto& name : effects) {
    if (!seen.insert(name).second)
      throw InvalidArgument("model: effect '" + name + "' given twice");
    // An effect that decides parameters from the data decides them on what the others leave:
    // which effects do is read from one built without data (cheap: nothing to decide), so that
    // the decision itself runs once.
    EffectSetup with_others = setup;
    if (backfit && data && effects.size() > 1) {
      EffectSetup bare = setup;
      bare.data = nullptr;
      const auto probe = make_effect(name, bare);  // owns what ps refers to
      const auto& ps = probe->parameters();
      if (std::any_of(ps.begin(), ps.end(), [](const ParameterSpec& p) { return p.from_data; })) {
        std::vector<std::string> others;
        for (const auto& other : effects)
          if (other != name) others.push_back(other);
        const DeflectionModel om(robot_, others, data, sessions, false, nullptr);
        with_others.companion_columns = companion_columns(om, *data);
        if (decide_at) with_others.companion_rows = companion_rows(om, *data, *decide_at);
      }
    }
    auto e = make_effect(name, with_others);
    jet_jacobians_ = jet_jacobians_ || e->reads_jacobians();
    deflects_ = deflects_ || e->reads_jacobians() ||
                (e->stages() & (unsigned{kJointStage} | unsigned{kCartesianStage}));
    linear_ = linear_ && e->linear();
    scatters_ = scatters_ || e->scatters();
    offsets_.push_back(count_);
    count_ += e->size();
    effects_.push_back(std::move(e));
  }
  bool derivatives = false, wrench_only = true;
  for (const auto& e : effects_) {
    if (e->has_displacement_derivatives())
      derivatives = true;
    else
      wrench_only = wrench_only && (e->stages() & ~unsigned{kWrenchStage}) == 0;
  }
  analytic_ = derivatives && wrench_only;
  for (size_t e = 0; e < effects_.size(); ++e)
    if (!analytic_ || !effects_[e]->has_displacement_derivatives())
      for (int k = 0; k < effects_[e]->size(); ++k) jet_parameters_.push_back(offsets_[e] + k);
  // Absolute rows: the tangents map what the analytic effects write; an effect without
  // columns may only change the wrench stage's inputs, which the one pass differentiates.
  int measuring = 0;
  analytic_absolute_ = robot.dof() <= kMaxTangentJoints;  // within corrected_point<Jet>'s too
  for (const auto& e : effects_) {
    measuring += (e->stages() & kMeasurementStage) != 0;
    if (!e->has_absolute_columns() && (e->stages() & ~unsigned{kWrenchStage}) != 0)
      analytic_absolute_ = false;
  }
  analytic_absolute_ = analytic_absolute_ && measuring <= 1;
  for (size_t e = 0; e < effects_.size(); ++e)
    if (!effects_[e]->has_absolute_columns())
      for (int k = 0; k < effects_[e]->size(); ++k)
        absolute_jet_parameters_.push_back(offsets_[e] + k);
}

std::vector<std::string> DeflectionModel::effect_names() const {
  std::vector<std::string> n;
  for (const auto& e : effects_) n.push_back(e->name());
  return n;
}

std::string DeflectionModel::model_string() const {
  std::string s;
  for (const auto& e : effects_) s += (s.empty() ? "" : "+") + e->name();
  return s;
}

int DeflectionModel::find(const std::string& effect) const {
  for (size_t i = 0; i < effects_.size(); ++i)
    if (effects_[i]->name() == effect) return static_cast<int>(i);
  return -1;
}

const Effect& DeflectionModel::owner(int k) const {
  for (size_t e = effects_.size(); e-- > 0;)
    if (k >= offsets_[e]) return *effects_[e];
  throw InvalidArgument("parameter index out of range");
}

const ParameterSpec& DeflectionModel::spec(int k) const {
  for (size_t e = effects_.size(); e-- > 0;)
    if (k >= offsets_[e]) return effects_[e]->parameters()[k - offsets_[e]];
  throw InvalidArgument("parameter index out of range");
}

Eigen::VectorXd DeflectionModel::null_parameters() const {
  Eigen::VectorXd t(count_);
  for (int k = 0; k < count_; ++k) t(k) = spec(k).null_value;
  return t;
}

Eigen::VectorXd DeflectionModel::start_parameters() const {
  Eigen::VectorXd t(count_);
  for (int k = 0; k < count_; ++k) t(k) = spec(k).start;
  return t;
}

Eigen::MatrixXd DeflectionModel::companion_columns(const DeflectionModel& model,
                                                   const Dataset& data) {
  const RobotModel& robot = model.robot_;
  const Eigen::VectorXd theta = model.start_parameters();
  const int n = static_cast<int>(data.rows.size());
  Eigen::MatrixXd all = Eigen::MatrixXd::Zero(3 * n, model.parameter_count());
  for (int r = 0; r < n; ++r) {
    const Measurement& m = data.rows[r];
    if (m.absolute || m.q.size() != robot.dof() || !m.q.allFinite()) continue;
    all.middleRows<3>(3 * r) = model.displacement_jacobian(theta, m, model.context(m, r));
  }
  std::vector<int> keep;
  for (int k = 0; k < model.parameter_count(); ++k)
    if (!model.spec(k).from_data && all.col(k).allFinite() && all.col(k).squaredNorm() > 0)
      keep.push_back(k);
  Eigen::MatrixXd out(3 * n, keep.size());
  for (size_t i = 0; i < keep.size(); ++i) out.col(i) = all.col(keep[i]);
  return out;
}

template <typename T>
inline void DeflectionModel::wrench_stage(const T* theta,
                                          const Measurement& m,
                                          const MeasurementContext& c,
                                          EvalState<T>& s) const {
  s.robot = &robot_;
  s.measurement = &m;
  s.context = &c;
  s.force = m.force.cast<T>();
  s.moment = m.moment.cast<T>();
  s.r_meas = robot_.measured_point.cast<T>();
  s.r_load = robot_.load_point.cast<T>();
  for (size_t e = 0; e < effects_.size(); ++e) effects_[e]->wrench(theta + offsets_[e], s);
}

std::vector<EffectSetup::CompanionRow> DeflectionModel::companion_rows(
    const DeflectionModel& model,
    const Dataset& data,
    const std::map<std::string, double>& values) {
  const RobotModel& robot = model.robot_;
  Eigen::VectorXd theta = model.start_parameters();
  for (int k = 0; k < model.parameter_count(); ++k) {
    const auto it = values.find(model.owner(k).name() + "." + model.spec(k).name);
    if (it != values.end() && std::isfinite(it->second)) theta(k) = it->second;
  }
  const std::vector<MeasurementContext> ctx = model.contexts(data);
  std::vector<EffectSetup::CompanionRow> rows(data.rows.size());
  bool moved = false;
  for (size_t r = 0; r < data.rows.size(); ++r) {
    const Measurement& m = data.rows[r];
    EvalState<double> s;
    model.wrench_stage(theta.data(), m, ctx[r], s);
    rows[r] = {s.r_meas, s.r_load, s.force, s.moment};
    moved = moved || s.r_meas != robot.measured_point || s.r_load != robot.load_point ||
            s.force != m.force || s.moment != m.moment;
  }
  // Nothing moved: the default (and the decision's cache key of the robot file's points).
  if (!moved) rows.clear();
  return rows;
}

std::vector<std::string> DeflectionModel::session_labels() const {
  std::vector<std::string> labels(sessions_.size());
  for (const auto& kv : sessions_) labels[kv.second] = kv.first;
  return labels;
}

int DeflectionModel::session_index(const std::string& label) const {
  const auto it = sessions_.find(label);
  return it == sessions_.end() ? 0 : it->second;
}

MeasurementContext DeflectionModel::context(const Measurement& m, int row) const {
  check_joint_vector(robot_, m.q, "measurement '" + m.id + "'");
  MeasurementContext c;
  c.chain = robot_.chain(m.q);
  c.tau_gravity_links = gravity_torques_by_link(robot_, c.chain);
  c.tau_gravity = c.tau_gravity_links.rowwise().sum();
  c.session = session_index(m.session);
  c.time = m.time != 0.0 ? m.time : static_cast<double>(row);
  return c;
}

std::vector<MeasurementContext> DeflectionModel::contexts(const Dataset& data) const {
  // context() of every row, the kinematics by a chain specialised once (equal to
  // RobotModel::chain up to round-off).
  const int n = robot_.dof();
  const detail::FastChain fk(robot_);
  std::vector<Eigen::Matrix4d> links(n);
  Eigen::Matrix3d rf;
  Eigen::Vector3d pf;
  std::vector<MeasurementContext> out(data.rows.size());
  // Time axis: the `t` column, else the row order, counted from the session's first reading
  // in this data (a new session, e.g. a validation file, restarts the warm-up), so that
  // identify, predict and diagnose see the same times.
  std::map<std::string, double> first;
  for (size_t r = 0; r < data.rows.size(); ++r) {
    const double t = data.has_time ? data.rows[r].time : static_cast<double>(r);
    auto it = first.find(data.rows[r].session);
    if (it == first.end())
      first.emplace(data.rows[r].session, t);
    else
      it->second = std::min(it->second, t);
  }
  for (size_t r = 0; r < data.rows.size(); ++r) {
    const Measurement& m = data.rows[r];
    if (m.q.size() != n || !m.q.allFinite())
      check_joint_vector(robot_, m.q, "measurement '" + m.id + "'");  // throws
    MeasurementContext& c = out[r];
    c.chain.axis.resize(3, n);
    c.chain.origin.resize(3, n);
    fk(m.q, c.chain.axis, c.chain.origin, rf, pf, links.data());
    c.chain.link = links;
    c.chain.flange.setIdentity();
    c.chain.flange.topLeftCorner<3, 3>() = rf;
    c.chain.flange.topRightCorner<3, 1>() = pf;
    c.tau_gravity_links = gravity_torques_by_link(robot_, c.chain);
    c.tau_gravity = c.tau_gravity_links.rowwise().sum();
    c.session = session_index(m.session);
    c.time = (data.has_time ? m.time : static_cast<double>(r)) - first[m.session];
  }
  return out;
}

template <typename T>
void DeflectionModel::evaluate(const T* theta,
                               const Measurement& m,
                               const MeasurementContext& c,
                               Vector3<T>* d,
                               Vector3<T>* rot,
                               Vector3<T>* o) const {
  EvalState<T> s;
  const bool orient = o && m.absolute && m.has_orientation;
  evaluate_into(theta, m, c, s, true, orient);
  *d = s.d;
  if (rot) *rot = s.rot;
  if (o) *o = orient ? orientation_discrepancy(s.orientation, m.orientation) : Vector3<T>::Zero();
}

void DeflectionModel::evaluate_double(const double* theta,
                                      const Measurement& m,
                                      const MeasurementContext& c,
                                      EvalState<double>& s,
                                      Vector3<double>* d,
                                      Vector3<double>* o) const {
  constexpr int kMax = 32;
  const int n = robot_.dof();
  if (o) o->setZero();
  if (n > kMax || jet_jacobians_ || m.absolute) {
    const bool orient = o && m.absolute && m.has_orientation;
    evaluate_into(theta, m, c, s, true, orient);
    *d = s.d;
    if (orient) *o = orientation_discrepancy(s.orientation, m.orientation);
    return;
  }
  // evaluate_into without the 6 x n Jacobians that no effect of this model reads.
  wrench_stage(theta, m, c, s);
  const Eigen::Matrix4d& fl = c.chain.flange;
  for (int k = 0; k < 3; ++k) {
    s.p_meas(k) =
        fl(k, 0) * s.r_meas(0) + fl(k, 1) * s.r_meas(1) + fl(k, 2) * s.r_meas(2) + fl(k, 3);
    s.p_load(k) =
        fl(k, 0) * s.r_load(0) + fl(k, 1) * s.r_load(1) + fl(k, 2) * s.r_load(2) + fl(k, 3);
  }
  s.jac_meas.resize(6, 0);
  s.jac_load.resize(6, 0);
  s.tau.resize(n);
  double jm[kMax][3];
  for (int j = 0; j < n; ++j) {
    const double* z = c.chain.axis.data() + 3 * j;
    const double* origin = c.chain.origin.data() + 3 * j;
    lever_arm(z, origin, s.p_meas, jm[j]);
    double wl[3];
    lever_arm(z, origin, s.p_load, wl);
    s.tau(j) = joint_torque(wl, z, s.force, s.moment);
  }
  s.dtheta.setZero(n);
  for (size_t e = 0; e < effects_.size(); ++e) effects_[e]->joint(theta + offsets_[e], s);
  s.d.setZero();
  s.rot.setZero();
  for (int j = 0; j < n; ++j) {
    const double* z = c.chain.axis.data() + 3 * j;
    for (int k = 0; k < 3; ++k) {
      s.d(k) += jm[j][k] * s.dtheta(j);
      s.rot(k) += z[k] * s.dtheta(j);
    }
  }
  for (size_t e = 0; e < effects_.size(); ++e) effects_[e]->cartesian(theta + offsets_[e], s);
  for (size_t e = 0; e < effects_.size(); ++e) effects_[e]->measurement(theta + offsets_[e], s);
  *d = s.d;
}

namespace {

/// Position [m], base frame, of the point r (flange frame) through the chain with joint
/// angles q + dq and, after each joint's `pre`, the small transform of joint_error's column
/// (translation, rotation vector): T = prod_j pre_j E_j Rot(axis_j, q_j + dq_j) post_j.
template <typename T>
void corrected_flange(const RobotModel& robot,
                      const Eigen::VectorXd& q,
                      const VectorX<T>& dq,
                      const Matrix6X<T>& joint_error,
                      Matrix3<T>& rot,
                      Vector3<T>& pos) {
  using std::cos;
  using std::sin;
  rot = Matrix3<T>::Identity();
  pos = Vector3<T>::Zero();
  // Products with the constant transforms stay T x double (half the work of T x T).
  auto apply = [&](const Eigen::Matrix4d& a) {  // (rot, pos) <- (rot, pos) * a
    pos += rot * a.topRightCorner<3, 1>();
    rot = (rot * a.topLeftCorner<3, 3>()).eval();
  };
  for (int j = 0; j < robot.dof(); ++j) {
    const Joint& jt = robot.joints[j];
    apply(jt.pre);
    // Always applied: a Jet at value 0 still carries the derivatives.
    const Eigen::Matrix<T, 6, 1> e = joint_error.col(j);
    Matrix3<T> re;
    ceres::AngleAxisToRotationMatrix(e.data() + 3, re.data());
    pos += rot * e.template head<3>();
    rot = (rot * re).eval();
    // Rodrigues: Rot(a, t) = I + sin t [a]x + (1 - cos t) [a]x^2; in double as one product
    // with the rotation matrix (a third of the work).
    const T t = T(q(j)) + dq(j);
    if constexpr (std::is_same<T, double>::value) {
      rot = (rot * Eigen::AngleAxisd(t, jt.axis).toRotationMatrix()).eval();
    } else {
      Eigen::Matrix3d k;
      const Eigen::Vector3d& a = jt.axis;
      k << 0, -a(2), a(1), a(2), 0, -a(0), -a(1), a(0), 0;
      const Eigen::Matrix3d k2 = k * k;
      const T st = sin(t), ct = T(1) - cos(t);
      const Matrix3<T> rk = rot * k, rk2 = rot * k2;
      for (int u = 0; u < 3; ++u)
        for (int v = 0; v < 3; ++v) rot(u, v) += st * rk(u, v) + ct * rk2(u, v);
    }
    apply(jt.post);
  }
}

/// The corrected chain's position of the flange point r and, with `flange`, its flange
/// rotation (base frame). `s` serves the Jet overload below (its kept values) only.
template <typename T>
Vector3<T> corrected_point(const RobotModel& robot,
                           const Eigen::VectorXd& q,
                           const VectorX<T>& dq,
                           const Matrix6X<T>& joint_error,
                           const Vector3<T>& r,
                           Matrix3<T>* flange = nullptr,
                           EvalState<T>* /*s*/ = nullptr) {
  Matrix3<T> rot;
  Vector3<T> pos;
  corrected_flange(robot, q, dq, joint_error, rot, pos);
  if (flange) *flange = rot;
  return rot * r + pos;
}

/// The corrected chain corrected_point<Jet> keeps in EvalState::kept (the order of its
/// `keep`): per joint R_B, R_E, J_r (3 x 3, column-major), p_B, p_E, z_E, then the final
/// rotation and position (see there).
struct KeptChain {
  static constexpr int kPerJoint = 36;
  static size_t size(int n) { return static_cast<size_t>(kPerJoint * n + 12); }
  const double* k;
  int n;
  Eigen::Map<const Eigen::Matrix3d> rb(int j) const {
    return Eigen::Map<const Eigen::Matrix3d>(at(j, 0));
  }
  Eigen::Map<const Eigen::Matrix3d> re(int j) const {
    return Eigen::Map<const Eigen::Matrix3d>(at(j, 9));
  }
  Eigen::Map<const Eigen::Matrix3d> jr(int j) const {
    return Eigen::Map<const Eigen::Matrix3d>(at(j, 18));
  }
  Eigen::Map<const Eigen::Vector3d> pe(int j) const {
    return Eigen::Map<const Eigen::Vector3d>(at(j, 30));
  }
  Eigen::Map<const Eigen::Vector3d> ze(int j) const {
    return Eigen::Map<const Eigen::Vector3d>(at(j, 33));
  }
  Eigen::Map<const Eigen::Matrix3d> rot() const {
    return Eigen::Map<const Eigen::Matrix3d>(at(n, 0));
  }
  Eigen::Map<const Eigen::Vector3d> pos() const {
    return Eigen::Map<const Eigen::Vector3d>(at(n, 9));
  }

 private:
  const double* at(int j, int i) const { return k + kPerJoint * j + i; }
};

/// corrected_point for Jets by the chain rule: the chain once in double, then the point's
/// derivatives with respect to each joint's dq, error translation and error rotation vector
/// and to r, applied to the Jets' derivative parts. The same first derivatives as the Jet
/// chain product (which costs about twenty times as much: 3 x 3 products of Jets per joint).
/// With the error transform after joint j's `pre` frame B = (R_B, p_B) and its rotation
/// frame E = (R_E, p_E) = B * (R(w), t), a change of
///  - dq_j turns everything after E about z = R_E a_j through p_E: dP = z x (P - p_E);
///  - t_j moves it: dP = R_B dt;
///  - w_j turns it about R_E J_r(w) dw through p_E (R(w + dw) = R(w) Exp(J_r(w) dw), J_r the
///    right Jacobian of SO(3)): dP = (R_E J_r dw) x (P - p_E);
///  - r moves P by R_T dr (R_T the final rotation).
/// The same turns, summed as a rotation vector phi (base frame), turn the flange rotation:
/// R_T(theta + dtheta) = Exp(phi) R_T, so its derivatives are [phi]x R_T.
Vector3<Jet> corrected_point(const RobotModel& robot,
                             const Eigen::VectorXd& q,
                             const VectorX<Jet>& dq,
                             const Matrix6X<Jet>& joint_error,
                             const Vector3<Jet>& r,
                             Matrix3<Jet>* flange,
                             EvalState<Jet>* state) {
  const int n = robot.dof();
  constexpr int kMax = 32;
  static_assert(kMax >= kMaxTangentJoints, "absolute_jacobian reads the chain kept here");
  if (n > kMax) return corrected_point<Jet>(robot, q, dq, joint_error, r, flange);
  Eigen::Matrix3d rb[kMax], re[kMax], jr[kMax];
  Eigen::Vector3d pb[kMax], pe[kMax], ze[kMax];
  Eigen::Matrix3d rot = Eigen::Matrix3d::Identity();
  Eigen::Vector3d pos = Eigen::Vector3d::Zero();
  // The chain in double depends on the values only: the row's later passes (other derivative
  // directions at the same values) take it from the first.
  const size_t kept_size = KeptChain::size(n);
  auto keep = [&](bool store) {  // in the layout KeptChain reads
    double* k = state->kept.data();
    auto move = [&](double* x, int len) {
      if (store)
        std::copy(x, x + len, k);
      else
        std::copy(k, k + len, x);
      k += len;
    };
    for (int j = 0; j < n; ++j) {
      move(rb[j].data(), 9);
      move(re[j].data(), 9);
      move(jr[j].data(), 9);
      move(pb[j].data(), 3);
      move(pe[j].data(), 3);
      move(ze[j].data(), 3);
    }
    move(rot.data(), 9);
    move(pos.data(), 3);
  };
  const bool reuse = state && state->same_values && state->kept.size() == kept_size;
  if (reuse) keep(false);
  for (int j = 0; j < n && !reuse; ++j) {
    const Joint& jt = robot.joints[j];
    pos += rot * jt.pre.topRightCorner<3, 1>();
    rot = (rot * jt.pre.topLeftCorner<3, 3>()).eval();
    rb[j] = rot;
    pb[j] = pos;
    Eigen::Vector3d t, w;
    for (int k = 0; k < 3; ++k) {
      t(k) = joint_error(k, j).a;
      w(k) = joint_error(3 + k, j).a;
    }
    Eigen::Matrix3d rw;
    ceres::AngleAxisToRotationMatrix(w.data(), rw.data());
    pos += rot * t;
    rot = (rot * rw).eval();
    re[j] = rot;
    pe[j] = pos;
    ze[j] = rot * jt.axis;
    jr[j] = effects::right_jacobian(w);
    rot = (rot * Eigen::AngleAxisd(q(j) + dq(j).a, jt.axis).toRotationMatrix()).eval();
    pos += rot * jt.post.topRightCorner<3, 1>();
    rot = (rot * jt.post.topLeftCorner<3, 3>()).eval();
  }
  if (state && !reuse) {
    state->kept.resize(kept_size);
    keep(true);
  }
  const Eigen::Vector3d ra(r(0).a, r(1).a, r(2).a);
  const Eigen::Vector3d p = rot * ra + pos;
  using Vec = Eigen::Matrix<double, kJetStride, 1>;
  Vec v[3] = {Vec::Zero(), Vec::Zero(), Vec::Zero()};
  auto add = [&](const Eigen::Vector3d& col, const Vec& d) {
    for (int k = 0; k < 3; ++k) v[k] += col(k) * d;
  };
  // A pass that moves no joint correction (absolute_jacobian's: those columns are analytic)
  // skips their terms. Exact zeros: the OR of the bits without the sign.
  std::uint64_t moved = 0;
  for (int j = 0; j < n; ++j) {
    std::uint64_t b[7 * kJetStride];
    std::memcpy(b, dq(j).v.data(), sizeof(double) * kJetStride);
    for (int i = 0; i < 6; ++i)
      std::memcpy(b + (i + 1) * kJetStride, joint_error(i, j).v.data(),
                  sizeof(double) * kJetStride);
    for (int i = 0; i < 7 * kJetStride; ++i) moved |= b[i] << 1;
  }
  for (int j = 0; j < n && moved; ++j) {
    const Eigen::Vector3d lever = p - pe[j];
    add(ze[j].cross(lever), dq(j).v);
    // (R_E J_r e_i) x lever for each component i of w.
    const Eigen::Matrix3d turn = re[j] * jr[j];
    for (int i = 0; i < 3; ++i) {
      add(rb[j].col(i), joint_error(i, j).v);
      add(turn.col(i).cross(lever), joint_error(3 + i, j).v);
    }
  }
  for (int i = 0; i < 3; ++i) add(rot.col(i), r(i).v);
  Vector3<Jet> out;
  for (int k = 0; k < 3; ++k) out(k) = Jet(p(k), v[k]);
  if (flange) {
    Vec phi[3] = {Vec::Zero(), Vec::Zero(), Vec::Zero()};
    for (int j = 0; j < n && moved; ++j) {
      const Eigen::Matrix3d turn = re[j] * jr[j];
      for (int k = 0; k < 3; ++k) {
        phi[k] += ze[j](k) * dq(j).v;
        for (int i = 0; i < 3; ++i) phi[k] += turn(k, i) * joint_error(3 + i, j).v;
      }
    }
    for (int u = 0; u < 3; ++u) {
      const int u1 = (u + 1) % 3, u2 = (u + 2) % 3;
      for (int c = 0; c < 3; ++c)
        (*flange)(u, c) = Jet(rot(u, c), phi[u1] * rot(u2, c) - phi[u2] * rot(u1, c));
    }
  }
  return out;
}

/// The predicted probe rotation (base frame) of an absolute row: the corrected chain's flange
/// rotation times the probe's rotation on the flange, turned by the deflection's small
/// rotation (exact rotation of its rotation vector).
template <typename T>
void probe_orientation(EvalState<T>& s, const Matrix3<T>& flange, bool deflected) {
  s.orientation = flange * s.probe;
  if (deflected) s.orientation = (effects::rotation_matrix(s.rot.data()) * s.orientation).eval();
}

/// m = I: a Jet's value and derivative part written directly (Eigen's generic identity builds a
/// temporary Jet per element, a measurable share of a Jacobian pass).
template <typename T>
void set_identity(Matrix3<T>& m) {
  if constexpr (std::is_same<T, Jet>::value) {
    for (int c = 0; c < 3; ++c)
      for (int u = 0; u < 3; ++u) {
        m(u, c).a = u == c ? 1.0 : 0.0;
        m(u, c).v.setZero();
      }
  } else {
    m.setIdentity();
  }
}

/// Before the measurement stage: absolute_jacobian's first pass asks for the stage's map of
/// the position it receives (derivative directions 0-2) and for that position.
template <typename T>
void seed_instrument(EvalState<T>& s) {
  if constexpr (std::is_same<T, Jet>::value) {
    if (!s.seed_instrument) return;
    for (int k = 0; k < 3; ++k) {
      s.instrument_input(k) = s.d(k).a;
      s.d(k).v(k) += 1.0;
    }
    if (!s.oriented) return;
    // The same directions on the orientation, R -> Exp(phi) R (d R / d phi_i = e_i x R, column
    // by column): the stage maps the position and the orientation each from itself alone.
    for (int c = 0; c < 3; ++c)
      for (int u = 0; u < 3; ++u) s.instrument_orientation(u, c) = s.orientation(u, c).a;
    const Eigen::Matrix3d& r = s.instrument_orientation;
    for (int c = 0; c < 3; ++c) {
      s.orientation(1, c).v(0) -= r(2, c);
      s.orientation(2, c).v(0) += r(1, c);
      s.orientation(0, c).v(1) += r(2, c);
      s.orientation(2, c).v(1) -= r(0, c);
      s.orientation(0, c).v(2) -= r(1, c);
      s.orientation(1, c).v(2) += r(0, c);
    }
  }
}

}  // namespace

template <typename T>
void DeflectionModel::evaluate_into(const T* theta,
                                    const Measurement& m,
                                    const MeasurementContext& c,
                                    EvalState<T>& s,
                                    bool instrument,
                                    bool orient) const {
  const int n = robot_.dof();
  s.oriented = orient && m.absolute;
  if (m.absolute) {
    set_identity(s.probe);
    set_identity(s.orientation);
  }
  wrench_stage(theta, m, c, s);

  // Stage 1 geometry: Jacobians at the (possibly offset) measured and load points.
  const Matrix3<T> rf = c.chain.flange.block<3, 3>(0, 0).cast<T>();
  const Vector3<T> pf = c.chain.flange.block<3, 1>(0, 3).cast<T>();
  s.p_meas = rf * s.r_meas + pf;
  s.p_load = rf * s.r_load + pf;
  if (m.absolute) {
    // A purely geometric model of an absolute row needs no Jacobians and no deflection.
    if (!deflects_) {
      s.tau = VectorX<T>::Zero(n);
      s.dtheta = VectorX<T>::Zero(n);
      s.d.setZero();
      s.rot.setZero();
      s.dq = VectorX<T>::Zero(n);
      s.joint_error = Matrix6X<T>::Zero(6, n);
      for (size_t e = 0; e < effects_.size(); ++e) effects_[e]->geometry(theta + offsets_[e], s);
      Matrix3<T> fr;
      s.d += corrected_point(robot_, m.q, s.dq, s.joint_error, s.r_meas, s.oriented ? &fr : nullptr,
                             &s);
      if (s.oriented) probe_orientation(s, fr, false);
      seed_instrument(s);
      if (instrument)
        for (size_t e = 0; e < effects_.size(); ++e)
          effects_[e]->measurement(theta + offsets_[e], s);
      return;
    }
  }
  s.jac_meas.resize(6, n);
  s.jac_load.resize(6, n);
  s.tau.resize(n);
  for (int j = 0; j < n; ++j) {
    const Vector3<T> z = c.chain.axis.col(j).cast<T>();
    const Vector3<T> o = c.chain.origin.col(j).cast<T>();
    Vector3<T> wm, wl;
    lever_arm(z, o, s.p_meas, wm);
    lever_arm(z, o, s.p_load, wl);
    s.jac_meas.template block<3, 1>(0, j) = wm;
    s.jac_meas.template block<3, 1>(3, j) = z;
    s.jac_load.template block<3, 1>(0, j) = wl;
    s.jac_load.template block<3, 1>(3, j) = z;
    s.tau(j) = joint_torque(wl, z, s.force, s.moment);
  }
  // An absolute pose is reached under the robot's own weight too (zero without a mass model;
  // a displacement row's difference cancels it).
  if (m.absolute && c.tau_gravity.size() == n)
    for (int j = 0; j < n; ++j) s.tau(j) += T(c.tau_gravity(j));
  s.dtheta = VectorX<T>::Zero(n);
  for (size_t e = 0; e < effects_.size(); ++e) effects_[e]->joint(theta + offsets_[e], s);
  s.d = s.jac_meas.template topRows<3>() * s.dtheta;
  s.rot = s.jac_meas.template bottomRows<3>() * s.dtheta;
  for (size_t e = 0; e < effects_.size(); ++e) effects_[e]->cartesian(theta + offsets_[e], s);
  if (m.absolute) {
    // Geometry stage, then the corrected forward kinematics of P plus its deflection.
    s.dq = VectorX<T>::Zero(n);
    s.joint_error = Matrix6X<T>::Zero(6, n);
    for (size_t e = 0; e < effects_.size(); ++e) effects_[e]->geometry(theta + offsets_[e], s);
    Matrix3<T> fr;
    s.d +=
        corrected_point(robot_, m.q, s.dq, s.joint_error, s.r_meas, s.oriented ? &fr : nullptr, &s);
    if (s.oriented) probe_orientation(s, fr, true);
    seed_instrument(s);
  }
  if (instrument)
    for (size_t e = 0; e < effects_.size(); ++e) effects_[e]->measurement(theta + offsets_[e], s);
}

template void DeflectionModel::evaluate<double>(const double*,
                                                const Measurement&,
                                                const MeasurementContext&,
                                                Vector3<double>*,
                                                Vector3<double>*,
                                                Vector3<double>*) const;
template void DeflectionModel::evaluate<Jet>(const Jet*,
                                             const Measurement&,
                                             const MeasurementContext&,
                                             Vector3<Jet>*,
                                             Vector3<Jet>*,
                                             Vector3<Jet>*) const;

void DeflectionModel::evaluate_jet(const Jet* theta,
                                   const Measurement& m,
                                   const MeasurementContext& c,
                                   EvalState<Jet>& s,
                                   Vector3<Jet>* d,
                                   Vector3<Jet>* o) const {
  constexpr int S = kJetStride;
  constexpr int kMax = 32;  // joints held in fixed-capacity buffers (no allocation)
  using Vec = Eigen::Matrix<double, S, 1>;
  const int n = robot_.dof();
  // An absolute row of a purely geometric model takes evaluate_into's short cut (no deflection
  // at all); with a deflection effect it runs here: the deflection as for a displacement row,
  // under the gravity torque too, then the corrected chain by the chain rule.
  const bool orient = o && m.absolute && m.has_orientation;
  if (n > kMax || (m.absolute && !deflects_)) {
    evaluate_into(theta, m, c, s, true, orient);
    *d = s.d;
    if (o)
      *o = orient ? orientation_discrepancy(s.orientation, m.orientation) : Vector3<Jet>::Zero();
    return;
  }
  s.oriented = orient;
  if (m.absolute) {
    set_identity(s.probe);
    set_identity(s.orientation);
  }
  const bool gravity = m.absolute && c.tau_gravity.size() == n;
  wrench_stage(theta, m, c, s);

  // Stage 1 geometry in double, derivative parts as [3][S] arrays (plain loops over S that
  // vectorise); the derivative work only when the wrench stage moved the points or the wrench.
  double rm[3], rl[3], f[3], mo[3];
  double rmv[3][S], rlv[3][S], fv[3][S], mv[3][S];
  std::uint64_t points_nz = 0, wrench_nz = 0;  // OR of the bits without the sign: 0 iff all zero
  for (int k = 0; k < 3; ++k) {
    rm[k] = s.r_meas(k).a;
    rl[k] = s.r_load(k).a;
    f[k] = s.force(k).a;
    mo[k] = s.moment(k).a;
    std::memcpy(rmv[k], s.r_meas(k).v.data(), sizeof rmv[k]);
    std::memcpy(rlv[k], s.r_load(k).v.data(), sizeof rlv[k]);
    std::memcpy(fv[k], s.force(k).v.data(), sizeof fv[k]);
    std::memcpy(mv[k], s.moment(k).v.data(), sizeof mv[k]);
  }
  {
    std::uint64_t b[4][3 * S];
    std::memcpy(b[0], rmv, sizeof b[0]);
    std::memcpy(b[1], rlv, sizeof b[1]);
    std::memcpy(b[2], fv, sizeof b[2]);
    std::memcpy(b[3], mv, sizeof b[3]);
    for (int i = 0; i < 3 * S; ++i) {
      points_nz |= (b[0][i] | b[1][i]) << 1;
      wrench_nz |= (b[2][i] | b[3][i]) << 1;
    }
  }
  const bool moved = points_nz != 0, wrench_moved = wrench_nz != 0;
  const Eigen::Matrix4d& fl = c.chain.flange;
  double pm[3], pl[3], pmv[3][S], plv[3][S];
  for (int k = 0; k < 3; ++k) {
    pm[k] = fl(k, 0) * rm[0] + fl(k, 1) * rm[1] + fl(k, 2) * rm[2] + fl(k, 3);
    pl[k] = fl(k, 0) * rl[0] + fl(k, 1) * rl[1] + fl(k, 2) * rl[2] + fl(k, 3);
    for (int i = 0; i < S; ++i) {
      pmv[k][i] = moved ? fl(k, 0) * rmv[0][i] + fl(k, 1) * rmv[1][i] + fl(k, 2) * rmv[2][i] : 0.0;
      plv[k][i] = moved ? fl(k, 0) * rlv[0][i] + fl(k, 1) * rlv[1][i] + fl(k, 2) * rlv[2][i] : 0.0;
    }
    s.p_meas(k) = Jet(pm[k], Eigen::Map<const Vec>(pmv[k]));
    s.p_load(k) = Jet(pl[k], Eigen::Map<const Vec>(plv[k]));
  }
  // The Jacobians at P and L as Jets only for effects that read them (complementary).
  if (jet_jacobians_) {
    s.jac_meas.resize(6, n);
    s.jac_load.resize(6, n);
  } else {
    s.jac_meas.resize(6, 0);
    s.jac_load.resize(6, 0);
  }
  s.tau.resize(n);
  double jm[kMax][3];  // J_p(P) translational columns
  for (int j = 0; j < n; ++j) {
    const double* z = c.chain.axis.data() + 3 * j;
    const double* origin = c.chain.origin.data() + 3 * j;
    double wm[3], wl[3];
    lever_arm(z, origin, pm, wm);
    lever_arm(z, origin, pl, wl);
    for (int k = 0; k < 3; ++k) jm[j][k] = wm[k];
    const double tau = joint_torque(wl, z, f, mo) + (gravity ? c.tau_gravity(j) : 0.0);
    Vec tv = Vec::Zero();
    if (moved) {
      // (z x L') . F = L' . (F x z): one dot product per derivative instead of a cross product.
      const double fz[3] = {f[1] * z[2] - f[2] * z[1], f[2] * z[0] - f[0] * z[2],
                            f[0] * z[1] - f[1] * z[0]};
      tv = fz[0] * Eigen::Map<const Vec>(plv[0]) + fz[1] * Eigen::Map<const Vec>(plv[1]) +
           fz[2] * Eigen::Map<const Vec>(plv[2]);
    }
    if (wrench_moved)
      for (int i = 0; i < S; ++i) tv[i] += joint_torque(wl, z, Lane<S>{fv, i}, Lane<S>{mv, i});
    if (jet_jacobians_) {
      for (int k = 0; k < 3; ++k) {
        const int k1 = (k + 1) % 3, k2 = (k + 2) % 3;
        Vec wmv, wlv;  // derivative parts of z x P and z x L
        for (int i = 0; i < S; ++i) {
          wmv(i) = z[k1] * pmv[k2][i] - z[k2] * pmv[k1][i];
          wlv(i) = z[k1] * plv[k2][i] - z[k2] * plv[k1][i];
        }
        s.jac_meas(k, j) = Jet(wm[k], wmv);
        s.jac_load(k, j) = Jet(wl[k], wlv);
        s.jac_meas(3 + k, j) = Jet(z[k]);
        s.jac_load(3 + k, j) = Jet(z[k]);
      }
    }
    s.tau(j) = Jet(tau, tv);
  }
  s.dtheta.resize(n);
  for (int j = 0; j < n; ++j) s.dtheta(j) = Jet(0.0);
  for (size_t e = 0; e < effects_.size(); ++e) effects_[e]->joint(theta + offsets_[e], s);
  // d = J_p dtheta, rot = J_r dtheta as small products of the values and derivative parts
  // (fixed-size vectors: GCC left the same loops over [3][S] arrays scalar).
  double da[3] = {0, 0, 0}, ra[3] = {0, 0, 0};
  Vec dv[3], rv[3];
  for (int k = 0; k < 3; ++k) {
    dv[k].setZero();
    rv[k].setZero();
  }
  for (int j = 0; j < n; ++j) {
    const double dt = s.dtheta(j).a;
    const Vec& dtv = s.dtheta(j).v;
    const double* z = c.chain.axis.data() + 3 * j;
    for (int k = 0; k < 3; ++k) {
      da[k] += jm[j][k] * dt;
      ra[k] += z[k] * dt;
      dv[k] += jm[j][k] * dtv;
      rv[k] += z[k] * dtv;
    }
  }
  if (moved) {
    // Moving P adds sum_j dtheta_j (z_j x P') = rot x P': one cross product for all joints.
    const Eigen::Map<const Vec> p0(pmv[0]), p1(pmv[1]), p2(pmv[2]);
    dv[0] += ra[1] * p2 - ra[2] * p1;
    dv[1] += ra[2] * p0 - ra[0] * p2;
    dv[2] += ra[0] * p1 - ra[1] * p0;
  }
  for (int k = 0; k < 3; ++k) {
    s.d(k) = Jet(da[k], dv[k]);
    s.rot(k) = Jet(ra[k], rv[k]);
  }
  for (size_t e = 0; e < effects_.size(); ++e) effects_[e]->cartesian(theta + offsets_[e], s);
  if (m.absolute) {
    s.dq = VectorX<Jet>::Zero(n);
    s.joint_error = Matrix6X<Jet>::Zero(6, n);
    for (size_t e = 0; e < effects_.size(); ++e) effects_[e]->geometry(theta + offsets_[e], s);
    Matrix3<Jet> fr;
    s.d += corrected_point(robot_, m.q, s.dq, s.joint_error, s.r_meas, orient ? &fr : nullptr, &s);
    if (orient) probe_orientation(s, fr, true);
    seed_instrument(s);
  }
  for (size_t e = 0; e < effects_.size(); ++e) effects_[e]->measurement(theta + offsets_[e], s);
  *d = s.d;
  if (o) *o = orient ? orientation_discrepancy(s.orientation, m.orientation) : Vector3<Jet>::Zero();
}

namespace {
/// The plain values of a pass (the wrench, the points) into the state an effect's analytic
/// derivatives read.
void plain_values(const EvalState<Jet>& js, EvalState<double>& ds) {
  ds.robot = js.robot;
  ds.measurement = js.measurement;
  ds.context = js.context;
  for (int k = 0; k < 3; ++k) {
    ds.force(k) = js.force(k).a;
    ds.moment(k) = js.moment(k).a;
    ds.r_meas(k) = js.r_meas(k).a;
    ds.r_load(k) = js.r_load(k).a;
    ds.p_meas(k) = js.p_meas(k).a;
    ds.p_load(k) = js.p_load(k).a;
  }
}
}  // namespace

void DeflectionModel::analytic_columns(const EvalState<Jet>& js,
                                       EvalState<double>& ds,
                                       double* jac) const {
  if (!analytic_) return;
  const int n = robot_.dof();
  plain_values(js, ds);
  ds.jac_meas = robot_.jacobian_at(js.context->chain, ds.p_meas);
  ds.tau.resize(n);
  for (int j = 0; j < n; ++j) ds.tau(j) = js.tau(j).a;
  for (size_t e = 0; e < effects_.size(); ++e)
    if (effects_[e]->has_displacement_derivatives())
      effects_[e]->displacement_derivatives(ds, jac + 3 * offsets_[e]);
}

void DeflectionModel::absolute_jacobian(const double* theta,
                                        const Measurement& m,
                                        const MeasurementContext& c,
                                        EvalState<Jet>& s,
                                        EvalState<double>& ds,
                                        std::vector<Jet>& t,
                                        double* d,
                                        double* jac,
                                        int dim) const {
  if (!analytic_absolute_ || !m.absolute || (dim != 3 && dim != 6))
    throw InvalidArgument(
        "absolute_jacobian: needs an absolute row, 3 or 6 rows and a model whose effects "
        "give their columns (analytic_absolute)");
  const int n = robot_.dof();
  const bool orient = dim == 6 && m.has_orientation;
  t.resize(count_);
  for (int k = 0; k < count_; ++k) t[k] = Jet(theta[k]);
  std::fill(jac, jac + dim * count_, 0.0);
  // The first pass's directions 0-2 are the measurement stage's inputs (the position and, on a
  // row with orientation, the orientation), the wrench-stage parameters take the rest and
  // kJetStride per later pass (which reuse the first's chain).
  const std::vector<int>& jc = absolute_jet_parameters_;
  const int nc = static_cast<int>(jc.size());
  Eigen::Matrix3d instrument, turn = Eigen::Matrix3d::Zero();
  Vector3<Jet> y, o;
  for (int pass = 0, done = 0; pass == 0 || done < nc; ++pass) {
    const int first = pass == 0 ? 3 : 0;
    const int last = std::min(nc, done + kJetStride - first);
    for (int i = done; i < last; ++i) t[jc[i]].v(first + i - done) = 1.0;
    s.same_values = pass > 0;
    s.seed_instrument = pass == 0;
    evaluate_jet(t.data(), m, c, s, &y, dim == 6 ? &o : nullptr);
    for (int i = done; i < last; ++i) {
      t[jc[i]].v(first + i - done) = 0.0;
      for (int r = 0; r < 3; ++r) jac[dim * jc[i] + r] = y(r).v(first + i - done);
      if (dim == 6)
        for (int r = 0; r < 3; ++r) jac[dim * jc[i] + 3 + r] = o(r).v(first + i - done);
    }
    if (pass == 0)
      for (int r = 0; r < 3; ++r)
        for (int k = 0; k < 3; ++k) {
          instrument(r, k) = y(r).v(k);
          if (orient) turn(r, k) = o(r).v(k);
        }
    done = last;
  }
  s.seed_instrument = false;
  s.same_values = false;
  for (int r = 0; r < 3; ++r) d[r] = y(r).a;
  if (dim == 6)
    for (int r = 0; r < 3; ++r) d[3 + r] = o(r).a;

  // The tangents (AbsoluteTangents) at this row's values, from the chain the pass kept.
  AbsoluteTangents tg;
  tg.instrument = instrument;
  tg.position = s.instrument_input;
  tg.turn = turn;
  tg.orientation = s.instrument_orientation;
  tg.dq.resize(dim, n);
  tg.joint_error.resize(dim, 6 * n);
  tg.dtheta.resize(dim, n);
  const KeptChain kc{s.kept.data(), n};
  const Eigen::Vector3d r(s.r_meas(0).a, s.r_meas(1).a, s.r_meas(2).a);
  const Eigen::Vector3d p = kc.rot() * r + kc.pos();
  const Eigen::Vector3d pm(s.p_meas(0).a, s.p_meas(1).a, s.p_meas(2).a);
  // The orientation Exp(rot) F P: a turn phi of the flange F reaches it as Exp(rot) phi, a
  // change of the deflection's rotation vector as J_l(rot) (left Jacobian, J_r(-rot)).
  const Eigen::Vector3d rot(s.rot(0).a, s.rot(1).a, s.rot(2).a);
  const Eigen::Matrix3d flange_turn = turn * effects::rotation_matrix(rot.data());
  const Eigen::Matrix3d deflection_turn = turn * effects::right_jacobian(-rot);
  for (int j = 0; j < n; ++j) {
    const Eigen::Vector3d lever = p - kc.pe(j);
    tg.dq.col(j).head<3>() = instrument * kc.ze(j).cross(lever);
    const Eigen::Matrix3d axes = kc.re(j) * kc.jr(j);
    for (int i = 0; i < 3; ++i) {
      tg.joint_error.col(6 * j + i).head<3>() = instrument * kc.rb(j).col(i);
      tg.joint_error.col(6 * j + 3 + i).head<3>() = instrument * axes.col(i).cross(lever);
    }
    Eigen::Vector3d w;
    lever_arm(c.chain.axis.col(j), c.chain.origin.col(j), pm, w);
    tg.dtheta.col(j).head<3>() = instrument * w;
    if (dim == 6) {
      tg.dq.col(j).tail<3>() = flange_turn * kc.ze(j);
      for (int i = 0; i < 3; ++i) {
        tg.joint_error.col(6 * j + i).tail<3>().setZero();
        tg.joint_error.col(6 * j + 3 + i).tail<3>() = flange_turn * axes.col(i);
      }
      tg.dtheta.col(j).tail<3>() = deflection_turn * c.chain.axis.col(j);
    }
  }
  plain_values(s, ds);
  for (size_t e = 0; e < effects_.size(); ++e)
    if (effects_[e]->has_absolute_columns())
      effects_[e]->absolute_columns(theta + offsets_[e], ds, tg, jac + dim * offsets_[e]);
}

Eigen::Matrix<double, 6, 1> DeflectionModel::predict(const Eigen::VectorXd& theta,
                                                     const Measurement& m,
                                                     const MeasurementContext& c) const {
  if (theta.size() != count_)
    throw InvalidArgument("predict: " + std::to_string(theta.size()) +
                          " parameters for a model with " + std::to_string(count_));
  EvalState<double> s;
  evaluate_into(theta.data(), m, c, s, true, m.absolute);
  Eigen::Matrix<double, 6, 1> out;
  out << s.d, s.rot;
  if (m.absolute) {
    // The probe's orientation in the instrument frame as a rotation vector.
    const Eigen::AngleAxisd aa(s.orientation);
    out.tail<3>() = aa.angle() * aa.axis();
  }
  return out;
}

bool DeflectionModel::predicts_orientation() const {
  for (const auto& e : effects_)
    if (e->requirements() & unsigned{kNeedsOrientation}) return true;
  return false;
}

bool DeflectionModel::absolute_accuracy() const {
  for (const auto& e : effects_)
    if ((e->stages() & unsigned{kGeometryStage}) || (e->requirements() & unsigned{kNeedsAbsolute}))
      return true;
  return false;
}

Eigen::Matrix4d DeflectionModel::tool_pose(const Eigen::VectorXd& theta,
                                           const Measurement& m,
                                           const MeasurementContext& c) const {
  if (theta.size() != count_)
    throw InvalidArgument("tool_pose: " + std::to_string(theta.size()) +
                          " parameters for a model with " + std::to_string(count_));
  if (!m.absolute) throw InvalidArgument("tool_pose: needs an absolute row");
  EvalState<double> s;
  evaluate_into(theta.data(), m, c, s, false);
  // s.d is the corrected position with its deflection; the orientation is the corrected
  // chain's flange turned by the deflection's small rotation (zero for a geometric model).
  Eigen::Matrix3d rot;
  Eigen::Vector3d pos;
  corrected_flange(robot_, m.q, s.dq, s.joint_error, rot, pos);
  Eigen::Matrix4d t = Eigen::Matrix4d::Identity();
  t.topLeftCorner<3, 3>() = rot;
  t.topRightCorner<3, 1>() = s.d;
  const double angle = s.rot.norm();
  if (angle > 0)
    t.topLeftCorner<3, 3>() = Eigen::AngleAxisd(angle, s.rot / angle).toRotationMatrix() * rot;
  return t;
}

namespace {

/// The 3 x P Jacobian of the displacement (or, with `orientation`, of the orientation
/// discrepancy) by kJetStride parameters per pass of evaluate_jet.
Eigen::Matrix<double, 3, Eigen::Dynamic> jet_jacobian(const DeflectionModel& model,
                                                      const Eigen::VectorXd& theta,
                                                      const Measurement& m,
                                                      const MeasurementContext& c,
                                                      bool orientation,
                                                      int from = 0) {
  const int count = model.parameter_count();
  Eigen::Matrix<double, 3, Eigen::Dynamic> out = Eigen::Matrix3Xd::Zero(3, count);
  std::vector<Jet> t(count);
  for (int k = 0; k < count; ++k) t[k] = Jet(theta(k));
  EvalState<Jet> s;  // later passes reuse the first's chain (the same values)
  const int start = std::max(0, from);
  for (int first = start; first < count; first += kJetStride) {
    const int last = std::min(count, first + kJetStride);
    for (int k = first; k < last; ++k) t[k].v(k - first) = 1.0;
    Vector3<Jet> d, o;
    s.same_values = first > start;
    model.evaluate_jet(t.data(), m, c, s, &d, orientation ? &o : nullptr);
    for (int k = first; k < last; ++k) {
      t[k].v(k - first) = 0.0;
      for (int r = 0; r < 3; ++r) out(r, k) = (orientation ? o : d)(r).v(k - first);
    }
  }
  return out;
}

}  // namespace

Eigen::Matrix<double, 3, Eigen::Dynamic> DeflectionModel::orientation_jacobian(
    const Eigen::VectorXd& theta, const Measurement& m, const MeasurementContext& c) const {
  return jet_jacobian(*this, theta, m, c, true);
}

Eigen::Matrix<double, 3, Eigen::Dynamic> DeflectionModel::displacement_jacobian(
    const Eigen::VectorXd& theta,
    const Measurement& m,
    const MeasurementContext& c,
    int from) const {
  return jet_jacobian(*this, theta, m, c, false, from);
}

Eigen::Matrix3d DeflectionModel::displacement_scatter(const Eigen::VectorXd& theta,
                                                      const Measurement& m,
                                                      const MeasurementContext& c) const {
  const int n = robot_.dof();
  if (m.absolute || !deflects_ || !scatters_) return Eigen::Matrix3d::Zero();
  EvalState<double> s;
  evaluate_into(theta.data(), m, c, s, false);
  Eigen::VectorXd var = Eigen::VectorXd::Zero(n);
  for (size_t e = 0; e < effects_.size(); ++e)
    effects_[e]->joint_scatter(theta.data() + offsets_[e], s, var);
  const Eigen::Matrix3Xd jp = s.jac_meas.topRows<3>();
  return jp * var.asDiagonal() * jp.transpose();
}

Eigen::VectorXd DeflectionModel::align_sessions(const Eigen::VectorXd& theta,
                                                const Dataset& data,
                                                const std::vector<MeasurementContext>& ctx,
                                                int* estimated) const {
  if (estimated) *estimated = 0;
  std::vector<int> cols;
  for (int k = 0; k < count_; ++k)
    if (spec(k).per_session) cols.push_back(k);
  Eigen::VectorXd out = theta;
  if (cols.empty() || data.rows.empty()) return out;
  const int n = static_cast<int>(data.rows.size());
  Eigen::MatrixXd z(3 * n, cols.size());
  Eigen::VectorXd e(3 * n);
  // Gauss-Newton on the session's parameters alone; the effects that carry them are linear in
  // them (an offset and a rate), so the first step is the solution and the second checks it.
  for (int it = 0; it < 2; ++it) {
    for (int r = 0; r < n; ++r) {
      const Measurement& m = data.rows[r];
      e.segment<3>(3 * r) = m.observed() - predict(out, m, ctx[r]).head<3>();
      const auto jac = displacement_jacobian(out, m, ctx[r]);
      for (size_t i = 0; i < cols.size(); ++i) z.block<3, 1>(3 * r, i) = jac.col(cols[i]);
    }
    // Columns with no effect on these rows (another session's parameters) drop out through
    // the rank of the decomposition.
    Eigen::ColPivHouseholderQR<Eigen::MatrixXd> qr(z);
    const double top = qr.maxPivot();
    if (!(top > 0)) return out;
    qr.setThreshold(1e-10);
    const Eigen::VectorXd step = qr.solve(e);
    for (size_t i = 0; i < cols.size(); ++i) out(cols[i]) += step(i);
    if (estimated) *estimated = static_cast<int>(qr.rank());
  }
  return out;
}

std::vector<Eigen::Vector3d> DeflectionModel::predict_cross_fitted(
    const Eigen::VectorXd& theta,
    const Dataset& data,
    const std::vector<MeasurementContext>& ctx,
    int* estimated,
    double* leverage) const {
  if (estimated) *estimated = 0;
  if (leverage) *leverage = 0.0;
  const size_t n = data.rows.size();
  bool per_session = false;
  for (int k = 0; k < count_; ++k) per_session |= spec(k).per_session;
  const bool displacement = std::none_of(data.rows.begin(), data.rows.end(),
                                         [](const Measurement& m) { return m.absolute; });
  std::vector<Eigen::Vector3d> p(n);
  if (!per_session || !displacement || n < 4) {
    for (size_t r = 0; r < n; ++r) p[r] = predict(theta, data.rows[r], ctx[r]).head<3>();
    return p;
  }
  Dataset half[2] = {data, data};
  std::vector<MeasurementContext> hctx[2];
  half[0].rows.clear();
  half[1].rows.clear();
  for (size_t r = 0; r < n; ++r) {
    half[r % 2].rows.push_back(data.rows[r]);
    hctx[r % 2].push_back(ctx[r]);
  }
  Eigen::VectorXd aligned[2];  // [h]: estimated from half h, predicts the other half
  int used[2] = {0, 0};
  for (int h = 0; h < 2; ++h) aligned[h] = align_sessions(theta, half[h], hctx[h], &used[h]);
  for (size_t r = 0; r < n; ++r) p[r] = predict(aligned[1 - r % 2], data.rows[r], ctx[r]).head<3>();
  if (estimated) *estimated = std::max(used[0], used[1]);
  // A row predicted with q values estimated from the other half's 3 m_h equations has a mean
  // leverage of about q / (3 m_h) per component (offset and rate over rows spread alike).
  if (leverage)
    *leverage =
        0.5 * (used[0] / (3.0 * half[0].rows.size()) + used[1] / (3.0 * half[1].rows.size()));
  return p;
}

Eigen::Matrix<double, 3, Eigen::Dynamic> observation_block(
    const Matrix6X<double>& jac_meas,
    const Matrix6X<double>& jac_load,
    const Eigen::Matrix<double, 6, 1>& wrench) {
  const Eigen::VectorXd tau = jac_load.transpose() * wrench;
  return jac_meas.topRows<3>() * tau.asDiagonal();
}

Eigen::MatrixXd observation_matrix(const RobotModel& robot, const Dataset& data) {
  const int n = robot.dof();
  Eigen::MatrixXd a(3 * data.rows.size(), n);
  for (size_t r = 0; r < data.rows.size(); ++r) {
    const auto& m = data.rows[r];
    check_joint_vector(robot, m.q, "measurement '" + m.id + "'");
    const ChainState s = robot.chain(m.q);
    const Matrix6X<double> jm = robot.jacobian_at(s, robot.point_position(s, robot.measured_point));
    const Matrix6X<double> jl = robot.jacobian_at(s, robot.point_position(s, robot.load_point));
    Eigen::Matrix<double, 6, 1> w;
    w << m.force, m.moment;
    a.block(3 * r, 0, 3, n) = observation_block(jm, jl, w);
  }
  return a;
}

}  // namespace stiff
