#include "stiff/model.hpp"

#include <set>

#include "stiff/error.hpp"

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
                                 const Dataset* data)
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
  EffectSetup setup;
  setup.robot = &robot_;
  setup.data = data;
  setup.sessions = std::max<int>(1, static_cast<int>(sessions_.size()));
  std::set<std::string> seen;
  for (const auto& name : effects) {
    if (!seen.insert(name).second)
      throw InvalidArgument("model: effect '" + name + "' given twice");
    auto e = make_effect(name, setup);
    offsets_.push_back(count_);
    count_ += e->size();
    effects_.push_back(std::move(e));
  }
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

int DeflectionModel::session_index(const std::string& label) const {
  const auto it = sessions_.find(label);
  return it == sessions_.end() ? 0 : it->second;
}

MeasurementContext DeflectionModel::context(const Measurement& m, int row) const {
  check_joint_vector(robot_, m.q, "measurement '" + m.id + "'");
  MeasurementContext c;
  c.chain = robot_.chain(m.q);
  c.tau_gravity = gravity_torques(robot_, c.chain);
  c.session = session_index(m.session);
  c.time = m.time != 0.0 ? m.time : static_cast<double>(row);
  return c;
}

std::vector<MeasurementContext> DeflectionModel::contexts(const Dataset& data) const {
  std::vector<MeasurementContext> out;
  out.reserve(data.rows.size());
  for (size_t r = 0; r < data.rows.size(); ++r) {
    out.push_back(context(data.rows[r], static_cast<int>(r)));
    if (!data.has_time) out.back().time = static_cast<double>(r);
  }
  return out;
}

template <typename T>
void DeflectionModel::evaluate(const T* theta,
                               const Measurement& m,
                               const MeasurementContext& c,
                               Vector3<T>* d,
                               Vector3<T>* rot) const {
  const int n = robot_.dof();
  EvalState<T> s;
  s.robot = &robot_;
  s.measurement = &m;
  s.context = &c;
  s.force = m.force.cast<T>();
  s.moment = m.moment.cast<T>();
  s.r_meas = robot_.measured_point.cast<T>();
  s.r_load = robot_.load_point.cast<T>();
  for (size_t e = 0; e < effects_.size(); ++e) effects_[e]->wrench(theta + offsets_[e], s);

  // Stage 1 geometry: Jacobians at the (possibly offset) measured and load points.
  const Matrix3<T> rf = c.chain.flange.block<3, 3>(0, 0).cast<T>();
  const Vector3<T> pf = c.chain.flange.block<3, 1>(0, 3).cast<T>();
  s.p_meas = rf * s.r_meas + pf;
  s.p_load = rf * s.r_load + pf;
  s.jac_meas.resize(6, n);
  s.jac_load.resize(6, n);
  s.tau.resize(n);
  for (int j = 0; j < n; ++j) {
    const Vector3<T> z = c.chain.axis.col(j).cast<T>();
    const Vector3<T> o = c.chain.origin.col(j).cast<T>();
    s.jac_meas.template block<3, 1>(0, j) = z.cross(s.p_meas - o);
    s.jac_meas.template block<3, 1>(3, j) = z;
    s.jac_load.template block<3, 1>(0, j) = z.cross(s.p_load - o);
    s.jac_load.template block<3, 1>(3, j) = z;
    s.tau(j) = s.jac_load.template block<3, 1>(0, j).dot(s.force) + z.dot(s.moment);
  }
  s.dtheta = VectorX<T>::Zero(n);
  for (size_t e = 0; e < effects_.size(); ++e) effects_[e]->joint(theta + offsets_[e], s);
  s.d = s.jac_meas.template topRows<3>() * s.dtheta;
  s.rot = s.jac_meas.template bottomRows<3>() * s.dtheta;
  for (size_t e = 0; e < effects_.size(); ++e) effects_[e]->cartesian(theta + offsets_[e], s);
  for (size_t e = 0; e < effects_.size(); ++e) effects_[e]->measurement(theta + offsets_[e], s);
  *d = s.d;
  if (rot) *rot = s.rot;
}

template void DeflectionModel::evaluate<double>(const double*,
                                                const Measurement&,
                                                const MeasurementContext&,
                                                Vector3<double>*,
                                                Vector3<double>*) const;
template void DeflectionModel::evaluate<Jet>(
    const Jet*, const Measurement&, const MeasurementContext&, Vector3<Jet>*, Vector3<Jet>*) const;

void DeflectionModel::evaluate_jet(const Jet* theta,
                                   const Measurement& m,
                                   const MeasurementContext& c,
                                   EvalState<Jet>& s,
                                   Vector3<Jet>* d) const {
  using Block = Eigen::Matrix<double, 3, kJetStride>;
  constexpr int kMax = 32;  // joints held in fixed-capacity buffers (no allocation)
  const int n = robot_.dof();
  if (n > kMax) {
    evaluate<Jet>(theta, m, c, d, nullptr);
    return;
  }
  s.robot = &robot_;
  s.measurement = &m;
  s.context = &c;
  for (int k = 0; k < 3; ++k) {
    s.force(k) = Jet(m.force(k));
    s.moment(k) = Jet(m.moment(k));
    s.r_meas(k) = Jet(robot_.measured_point(k));
    s.r_load(k) = Jet(robot_.load_point(k));
  }
  for (size_t e = 0; e < effects_.size(); ++e) effects_[e]->wrench(theta + offsets_[e], s);

  // Stage 1 geometry in double; derivative parts as 3 x kJetStride blocks.
  Eigen::Vector3d rm, rl, f, mo;
  Block rmv, rlv, fv, mv;
  for (int k = 0; k < 3; ++k) {
    rm(k) = s.r_meas(k).a;
    rl(k) = s.r_load(k).a;
    f(k) = s.force(k).a;
    mo(k) = s.moment(k).a;
    rmv.row(k) = s.r_meas(k).v.transpose();
    rlv.row(k) = s.r_load(k).v.transpose();
    fv.row(k) = s.force(k).v.transpose();
    mv.row(k) = s.moment(k).v.transpose();
  }
  const bool moved = !rmv.isZero(0.0) || !rlv.isZero(0.0);
  const bool wrench_moved = !fv.isZero(0.0) || !mv.isZero(0.0);
  const Eigen::Matrix3d rf = c.chain.flange.block<3, 3>(0, 0);
  const Eigen::Vector3d pf = c.chain.flange.block<3, 1>(0, 3);
  const Eigen::Vector3d pm = rf * rm + pf, pl = rf * rl + pf;
  Block pmv, plv;
  if (moved) {
    pmv.noalias() = rf * rmv;
    plv.noalias() = rf * rlv;
  } else {
    pmv.setZero();
    plv.setZero();
  }
  for (int k = 0; k < 3; ++k) {
    s.p_meas(k) = Jet(pm(k), pmv.row(k).transpose());
    s.p_load(k) = Jet(pl(k), plv.row(k).transpose());
  }
  s.jac_meas.resize(6, n);
  s.jac_load.resize(6, n);
  s.tau.resize(n);
  auto cross_block = [](const Eigen::Vector3d& z, const Block& v) {
    Block out;
    out.row(0) = z(1) * v.row(2) - z(2) * v.row(1);
    out.row(1) = z(2) * v.row(0) - z(0) * v.row(2);
    out.row(2) = z(0) * v.row(1) - z(1) * v.row(0);
    return out;
  };
  Eigen::Matrix<double, 3, Eigen::Dynamic, 0, 3, kMax> jm(3, n);
  for (int j = 0; j < n; ++j) {
    const Eigen::Vector3d z = c.chain.axis.col(j);
    const Eigen::Vector3d o = c.chain.origin.col(j);
    const Eigen::Vector3d wm = z.cross(pm - o), wl = z.cross(pl - o);
    jm.col(j) = wm;
    const double tau = wl.dot(f) + z.dot(mo);
    Eigen::Matrix<double, kJetStride, 1> tv = Eigen::Matrix<double, kJetStride, 1>::Zero();
    if (moved) {
      const Block wmv = cross_block(z, pmv), wlv = cross_block(z, plv);
      for (int k = 0; k < 3; ++k) {
        s.jac_meas(k, j) = Jet(wm(k), wmv.row(k).transpose());
        s.jac_load(k, j) = Jet(wl(k), wlv.row(k).transpose());
      }
      tv.noalias() += wlv.transpose() * f;
    } else {
      for (int k = 0; k < 3; ++k) {
        s.jac_meas(k, j) = Jet(wm(k));
        s.jac_load(k, j) = Jet(wl(k));
      }
    }
    if (wrench_moved) tv.noalias() += fv.transpose() * wl + mv.transpose() * z;
    for (int k = 0; k < 3; ++k) {
      s.jac_meas(3 + k, j) = Jet(z(k));
      s.jac_load(3 + k, j) = Jet(z(k));
    }
    s.tau(j) = Jet(tau, tv);
  }
  s.dtheta.resize(n);
  for (int j = 0; j < n; ++j) s.dtheta(j) = Jet(0.0);
  for (size_t e = 0; e < effects_.size(); ++e) effects_[e]->joint(theta + offsets_[e], s);
  // d = J_p dtheta, rot = J_r dtheta as small products of the values and derivative parts.
  Eigen::Matrix<double, Eigen::Dynamic, 1, 0, kMax, 1> dt(n);
  Eigen::Matrix<double, Eigen::Dynamic, kJetStride, 0, kMax, kJetStride> dtv(n, kJetStride);
  for (int j = 0; j < n; ++j) {
    dt(j) = s.dtheta(j).a;
    dtv.row(j) = s.dtheta(j).v.transpose();
  }
  const Eigen::Vector3d da = jm * dt;
  Block dv = jm * dtv;
  if (moved)
    for (int j = 0; j < n; ++j)
      for (int k = 0; k < 3; ++k) dv.row(k) += dt(j) * s.jac_meas(k, j).v.transpose();
  const Eigen::Vector3d ra = c.chain.axis * dt;
  const Block rv = c.chain.axis * dtv;
  for (int k = 0; k < 3; ++k) {
    s.d(k) = Jet(da(k), dv.row(k).transpose());
    s.rot(k) = Jet(ra(k), rv.row(k).transpose());
  }
  for (size_t e = 0; e < effects_.size(); ++e) effects_[e]->cartesian(theta + offsets_[e], s);
  for (size_t e = 0; e < effects_.size(); ++e) effects_[e]->measurement(theta + offsets_[e], s);
  *d = s.d;
}

Eigen::Matrix<double, 6, 1> DeflectionModel::predict(const Eigen::VectorXd& theta,
                                                     const Measurement& m,
                                                     const MeasurementContext& c) const {
  if (theta.size() != count_)
    throw InvalidArgument("predict: " + std::to_string(theta.size()) +
                          " parameters for a model with " + std::to_string(count_));
  Vector3<double> d, rot;
  evaluate<double>(theta.data(), m, c, &d, &rot);
  Eigen::Matrix<double, 6, 1> out;
  out << d, rot;
  return out;
}

Eigen::Matrix<double, 3, Eigen::Dynamic> DeflectionModel::displacement_jacobian(
    const Eigen::VectorXd& theta, const Measurement& m, const MeasurementContext& c) const {
  Eigen::Matrix<double, 3, Eigen::Dynamic> out(3, count_);
  std::vector<Jet> t(count_);
  for (int k = 0; k < count_; ++k) t[k] = Jet(theta(k));
  // Differentiate kJetStride parameters per pass.
  for (int first = 0; first < count_; first += kJetStride) {
    for (int k = 0; k < count_; ++k) t[k].v.setZero();
    const int last = std::min(count_, first + kJetStride);
    for (int k = first; k < last; ++k) t[k].v(k - first) = 1.0;
    Vector3<Jet> d;
    evaluate<Jet>(t.data(), m, c, &d, nullptr);
    for (int k = first; k < last; ++k)
      for (int r = 0; r < 3; ++r) out(r, k) = d(r).v(k - first);
  }
  return out;
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
