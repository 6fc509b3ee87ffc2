// Validation on a set-up the calibration has not seen: the new placement of the instrument is
// registered from part of its rows, the model is scored on the others (docs/diagnosis.md,
// section 1).
#include <algorithm>
#include <cmath>
#include <limits>
#include <map>
#include <random>
#include <set>

#include "diagnose/analysis.hpp"
#include "stiff/error.hpp"
#include "stiff/identify/identify.hpp"
#include "stiff/kinematics/rigid_fit.hpp"

namespace stiff::diagnose_detail {

namespace {
constexpr int kMinRegistering = 6;  // a rigid motion from 6 points: 12 redundant equations
constexpr int kMinScored = 3;
}  // namespace

// Every combination of the interval ends: a decision is the sign of a function monotone in each
// parameter, so the ends give every decision the interval allows.
Eigen::Vector3d closest_error(const DeflectionModel& model,
                              const VectorXd& theta,
                              const Measurement& m,
                              const MeasurementContext& c,
                              const Eigen::Vector3d& e,
                              bool* uncertain) {
  constexpr double kChange = 1e-12;  // m: a prediction that moves (not a smooth sign's far tail)
  // Decisions of one row combined exhaustively (2^6 predictions); beyond that the parameters
  // that move its prediction most.
  constexpr size_t kMaxCombined = 6;
  // From the prediction at the decided values: trying the ends of the confidence sets is this
  // scoring's own account of what the calibration left open, which a spread would count twice.
  VectorXd t = theta;
  for (int k = 0; k < model.parameter_count(); ++k)
    if (model.spec(k).spread) t(k) = 0;
  const Eigen::Vector3d blurred = model.predict(theta, m, c).head<3>();
  const Eigen::Vector3d point = model.predict(t, m, c).head<3>();
  const Eigen::Vector3d sharp = e - (point - blurred);
  std::vector<std::pair<double, int>> moves;  // (largest change of the prediction, parameter)
  for (int k = 0; k < model.parameter_count(); ++k) {
    const ParameterSpec& sp = model.spec(k);
    if (!sp.from_data || !std::isfinite(sp.confidence_lower) || !std::isfinite(sp.confidence_upper))
      continue;
    double change = 0;
    for (const double v : {sp.confidence_lower, sp.confidence_upper}) {
      t(k) = v;
      change = std::max(change, (model.predict(t, m, c).head<3>() - point).norm());
    }
    t(k) = theta(k);
    if (change > kChange) moves.emplace_back(change, k);
  }
  std::sort(moves.begin(), moves.end(),
            [](const auto& a, const auto& b) { return a.first > b.first; });
  if (moves.size() > kMaxCombined) moves.resize(kMaxCombined);
  *uncertain = !moves.empty();
  Eigen::Vector3d best = sharp;
  for (unsigned mask = 0; !moves.empty() && mask < (1u << moves.size()); ++mask) {
    for (size_t i = 0; i < moves.size(); ++i) {
      const ParameterSpec& sp = model.spec(moves[i].second);
      t(moves[i].second) = (mask >> i) & 1u ? sp.confidence_upper : sp.confidence_lower;
    }
    const Eigen::Vector3d ei = sharp - (model.predict(t, m, c).head<3>() - point);
    if (ei.squaredNorm() < best.squaredNorm()) best = ei;
  }
  return best;
}

bool has_confidence_sets(const DeflectionModel& model) {
  for (int k = 0; k < model.parameter_count(); ++k)
    if (model.spec(k).from_data && std::isfinite(model.spec(k).confidence_lower)) return true;
  return false;
}

double paired_fall_p(const std::vector<double>& a, const std::vector<double>& b) {
  // The loss is the error's length, not its square: a step that removes a few very large
  // errors makes the squares' differences so heavy-tailed that their own variance hides the
  // fall (93.5 -> 37.2 um RMS per axis over 40 poses: p = 0.055 on the squares, 0.025 on the
  // lengths).
  std::vector<double> dif;
  for (size_t r = 0; r < std::min(a.size(), b.size()); ++r)
    if (std::isfinite(a[r]) && std::isfinite(b[r])) dif.push_back(a[r] - b[r]);
  const size_t m = dif.size();
  if (m < 3) return 1.0;
  double mean = 0, sq = 0;
  for (double x : dif) mean += x / m;
  for (double x : dif) sq += (x - mean) * (x - mean);
  const double se = std::sqrt(sq / (m - 1) / m);
  if (!(mean > 0)) return 1.0;
  if (!(se > 0)) return 0.0;
  const double t = mean / se;
  return 0.5 * stats::f_sf(t * t, 1.0, static_cast<double>(m - 1));
}

ValidationSplit split_validation(const Dataset& calibration,
                                 const Dataset& validation,
                                 const std::vector<std::string>& model,
                                 double fraction) {
  ValidationSplit out;
  out.scored = validation;
  out.scored.rows.clear();
  out.registering = out.scored;
  const bool registered = std::find(model.begin(), model.end(), "registration") != model.end();
  std::set<std::string> known;
  for (const auto& m : calibration.rows) known.insert(m.session);
  std::map<std::string, std::vector<int>> fresh;  // new session -> its rows, in file order
  std::vector<std::string> order;
  for (size_t r = 0; r < validation.rows.size(); ++r) {
    const Measurement& m = validation.rows[r];
    if (registered && m.absolute && !known.count(m.session)) {
      if (!fresh.count(m.session)) order.push_back(m.session);
      fresh[m.session].push_back(static_cast<int>(r));
    } else {
      out.scored.rows.push_back(m);
    }
  }
  for (const auto& label : order) {
    const std::vector<int>& rows = fresh[label];
    const int n = static_cast<int>(rows.size());
    if (n < kMinRegistering + kMinScored)
      throw InvalidArgument("diagnose: validation session '" + label +
                            "' is a set-up the calibration data do not have: it is registered "
                            "from part of its rows and scored on the others, which needs at "
                            "least " +
                            std::to_string(kMinRegistering + kMinScored) + " rows (it has " +
                            std::to_string(n) + ")");
    // Evenly spread, at least kMinRegistering, at least kMinScored left to score.
    const double f = std::clamp(fraction, static_cast<double>(kMinRegistering) / n,
                                1.0 - static_cast<double>(kMinScored) / n);
    int registering = 0;
    for (int i = 0; i < n; ++i) {
      const Measurement& m = validation.rows[rows[i]];
      if (std::floor((i + 1) * f) > std::floor(i * f)) {
        out.registering.rows.push_back(m);
        ++registering;
      } else {
        out.scored.rows.push_back(m);
      }
    }
    out.notes.push_back("validation session '" + label + "' is a new set-up: registered from " +
                        std::to_string(registering) + " of its " + std::to_string(n) +
                        " rows (spread evenly), scored on the other " +
                        std::to_string(n - registering));
  }
  return out;
}

std::vector<Eigen::Vector3d> validation_errors(const DeflectionModel& model,
                                               const VectorXd& theta,
                                               const ValidationSplit& split,
                                               int* session_parameters,
                                               double* session_leverage,
                                               std::vector<Eigen::Vector3d>* closest,
                                               int* uncertain_rows) {
  if (session_parameters) *session_parameters = 0;
  if (session_leverage) *session_leverage = 0.0;
  if (closest) closest->clear();
  if (uncertain_rows) *uncertain_rows = 0;
  const bool decided = has_confidence_sets(model);
  auto close = [&](const Measurement& m, const MeasurementContext& c, const Eigen::Vector3d& e) {
    if (!closest) return;
    bool u = false;
    closest->push_back(decided ? closest_error(model, theta, m, c, e, &u) : e);
    if (u && uncertain_rows) ++*uncertain_rows;
  };
  // The validation file is another session: the parameters of the session itself (its drift:
  // a warm-up restarts, and its course depends on the day and the protocol) are its own and
  // only its own readings tell them; the robot's are carried over. They are cross-fitted: the
  // rows of even position are predicted with the session's parameters estimated from the odd
  // ones and the other way round, so that no row is scored by parameters fitted to it (an
  // alignment on the scored rows themselves would also absorb outliers and the structure a
  // wrong model leaves). Absolute rows keep the fit's: their new set-ups are registered below.
  const bool displacement = std::none_of(split.scored.rows.begin(), split.scored.rows.end(),
                                         [](const Measurement& m) { return m.absolute; });
  if (displacement) {
    const auto ctx = model.contexts(split.scored);
    const auto p =
        model.predict_cross_fitted(theta, split.scored, ctx, session_parameters, session_leverage);
    std::vector<Eigen::Vector3d> e(p.size());
    for (size_t r = 0; r < p.size(); ++r) {
      e[r] = split.scored.rows[r].observed() - p[r];
      close(split.scored.rows[r], ctx[r], e[r]);
    }
    return e;
  }
  // A new session is predicted with some other session's registration; the rigid motion
  // fitted on its registering rows replaces it (a composition of rigid motions is one).
  auto predicted = [&](const Dataset& d) {
    const auto ctx = model.contexts(d);
    std::vector<Eigen::Vector3d> p(d.rows.size());
    for (size_t r = 0; r < d.rows.size(); ++r)
      p[r] = model.predict(theta, d.rows[r], ctx[r]).head<3>();
    return p;
  };
  std::map<std::string, std::pair<Eigen::Matrix3d, Eigen::Vector3d>> motion;
  if (!split.registering.rows.empty()) {
    const auto p = predicted(split.registering);
    std::map<std::string, std::vector<int>> rows;
    for (size_t r = 0; r < split.registering.rows.size(); ++r)
      rows[split.registering.rows[r].session].push_back(static_cast<int>(r));
    for (const auto& [label, idx] : rows) {
      Eigen::Matrix3Xd x(3, idx.size()), y(3, idx.size());
      for (size_t c = 0; c < idx.size(); ++c) {
        x.col(static_cast<Eigen::Index>(c)) = p[idx[c]];
        y.col(static_cast<Eigen::Index>(c)) = split.registering.rows[idx[c]].observed();
      }
      Eigen::Matrix3d r;
      Eigen::Vector3d t;
      if (!fit_rigid_motion(x, y, &r, &t))
        throw InvalidArgument("diagnose: validation session '" + label +
                              "': the rows that register it are (nearly) collinear; a new "
                              "set-up needs validation poses spread in space");
      motion[label] = {r, t};
    }
  }
  const auto p = predicted(split.scored);
  const auto ctx =
      closest && decided ? model.contexts(split.scored) : std::vector<MeasurementContext>();
  std::vector<Eigen::Vector3d> e(p.size());
  for (size_t r = 0; r < p.size(); ++r) {
    const Measurement& m = split.scored.rows[r];
    const auto it = motion.find(m.session);
    const Eigen::Vector3d q =
        it == motion.end() ? p[r] : it->second.first * p[r] + it->second.second;
    e[r] = m.observed() - q;
    if (!closest) continue;
    if (!decided) {
      closest->push_back(e[r]);
      continue;
    }
    // The alternatives change the model's prediction, which the registration turns: the
    // error in the model's frame is R^T e.
    const Eigen::Matrix3d rot = it == motion.end() ? Eigen::Matrix3d::Identity() : it->second.first;
    bool u = false;
    closest->push_back(rot * closest_error(model, theta, m, ctx[r], rot.transpose() * e[r], &u));
    if (u && uncertain_rows) ++*uncertain_rows;
  }
  return e;
}

std::vector<double> cross_validation_errors(const Context& cx, const Analysis& a, int folds) {
  const Dataset& calib = *cx.calib;
  const size_t rows = calib.rows.size();
  // Folds within each session, so that every training set registers every session. The order
  // is pseudo-random but fixed (a 32-bit Mersenne twister is specified bit for bit, and the
  // shuffle is written here): a grid measured row by row must not put neighbours, or every
  // k-th pose, into one fold, and the same data must give the same folds on every platform.
  std::map<std::string, std::vector<int>> by_session;
  for (int r : a.used_rows) by_session[calib.rows[r].session].push_back(r);
  std::vector<int> fold(rows, -1);
  std::mt19937 rng(0x5eed);
  for (auto& [label, idx] : by_session) {
    if (static_cast<int>(idx.size()) < 2 * folds) return {};
    for (size_t i = idx.size() - 1; i > 0; --i) std::swap(idx[i], idx[rng() % (i + 1)]);
    for (size_t i = 0; i < idx.size(); ++i) fold[idx[i]] = static_cast<int>(i % folds);
  }
  std::vector<double> e(rows, std::numeric_limits<double>::quiet_NaN());
  for (int f = 0; f < folds; ++f) {
    Dataset train = calib, test = calib;
    train.rows.clear();
    test.rows.clear();
    std::vector<int> test_rows;
    for (int r : a.used_rows) {
      if (fold[r] == f) {
        test.rows.push_back(calib.rows[r]);
        test_rows.push_back(r);
      } else {
        train.rows.push_back(calib.rows[r]);
      }
    }
    try {
      const FitResult fit = fit_model(*cx.robot, train, a.effects);
      const DeflectionModel model(*cx.robot, a.effects, &train);
      const VectorXd theta = fit.theta();
      const auto ctx = model.contexts(test);
      for (size_t i = 0; i < test.rows.size(); ++i)
        e[test_rows[i]] =
            (test.rows[i].observed() - model.predict(theta, test.rows[i], ctx[i]).head<3>()).norm();
    } catch (const Error&) {
      return {};  // a fold the model cannot be fitted to: no cross-validation
    }
  }
  return e;
}

}  // namespace stiff::diagnose_detail
