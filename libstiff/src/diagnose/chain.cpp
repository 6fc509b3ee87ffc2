// The verdict: the loop of levels, the noise-floor check and the chains of candidates that
// must explain the data (docs/diagnosis.md, section 5).
#include <algorithm>
#include <cmath>
#include <cstdint>

#include "diagnose/analysis.hpp"
#include "diagnose/text.hpp"
#include "stiff/error.hpp"

namespace stiff::diagnose_detail {

const Level* Chain::next(size_t i) {
  if (!claims(levels[i])) return nullptr;
  if (levels.size() <= i + 1) {
    std::vector<std::string> eff = levels[i].a.effects;
    const std::string top = levels[i].scores[levels[i].pick].effect;
    eff.push_back(top);
    std::vector<std::string> rest;
    for (const auto& c : candidates)
      if (std::find(eff.begin(), eff.end(), c) == eff.end()) rest.push_back(c);
    try {
      Analysis a = analyse(*cx, eff, fixed, rest);
      levels.push_back(score_level(*cx, std::move(a), rest));
    } catch (const NumericalError& e) {
      warnings.push_back("re-fit with " + top + " failed: " + e.what());
      return nullptr;
    }
  }
  return &levels[i + 1];
}

bool Chain::at_floor(const Level& L, std::string* why, bool* weak) const {
  const ModelQuality& q = L.a.quality;
  const double alpha = cx->opt->alpha;
  // Evidence at alpha / 10 <= p < alpha is marginal (the rule of decide() for candidates): a
  // model that fails only on such evidence is not refuted, only not confirmed.
  auto marginal = [&](double p) { return p >= alpha / 10; };
  *weak = true;
  bool at = true;
  if (cx->noise->known) {
    if (q.floor_p >= alpha) {
      // At the stated floor, unless the residual keeps a trend beyond the marginal that no
      // candidate takes up (a stated noise level can be generous, and allows for some): a
      // significant candidate's own evidence is the chain's to judge (decide()).
      for (const auto& c : L.scores)
        if (c.significant) return true;
      const std::optional<CovariateTest> t = strong_trend(*cx, L);
      if (!t) return true;
      *why = "it reaches the stated noise floor, but its residual still follows " + trend_text(*t) +
             ": structure remains that no candidate explains";
      *weak = false;
      return false;
    }
    const std::string held_out =
        std::isfinite(q.validation_to_floor)
            ? " and the validation errors " + num(q.validation_to_floor, 3) + " times"
            : "";
    *why = "the residual is " + num(q.residual_to_floor, 3) + " times the stated noise floor" +
           held_out + " (improbable even for a noise " + num(100 * cx->opt->noise_uncertainty, 2) +
           " % above the stated one, p = " + num(q.floor_p, 2) + ")";
    *weak = marginal(q.floor_p);
    return false;
  }
  if (q.has_validation && q.validation_to_fit_p < alpha) {
    *why = "it predicts the validation poses " + num(q.validation_to_fit, 3) +
           " times worse than its fit residual allows (p = " + num(q.validation_to_fit_p, 2) +
           " allowing " + num(100 * cx->opt->noise_uncertainty, 2) +
           " % between sessions): structure remains";
    *weak = marginal(q.validation_to_fit_p);
    if (!*weak) return false;  // strong already: the trend tests cannot make it marginal
    at = false;
  }
  Diagnosis d;
  where(*cx, L, d);
  for (const auto& c : d.covariates)
    if (c.structure) {
      if (at)
        *why = "its residual still follows " + trend_text(c) +
               ": structure remains that no candidate explains";
      *weak = *weak && marginal(c.p_adjusted);
      at = false;
    }
  return at;
}

namespace {
/// Validation RMS of a model with the prediction variance of the validation session's own
/// parameters (cross-fitted drift) taken out, so that models with and without them compare
/// like with like: that variance is the leverage times the noise variance, estimated by the
/// fit's residual variance (subtracted, not divided: gross errors in the validation rows are
/// not scaled down with it).
double comparable_validation(const ModelQuality& q) {
  const double ms = q.validation_rms_m * q.validation_rms_m -
                    q.validation_session_leverage * q.sigma_hat_m * q.sigma_hat_m;
  return std::sqrt(std::max(0.0, ms));
}

/// p of the F test that a model predicting the validation poses at `worse` (comparable RMS)
/// does so no worse than one at `better`: the ratio of the two mean squares, 3m dof each.
double validation_f_p(double worse, double better, size_t m) {
  const double m3 = 3.0 * static_cast<double>(m);
  const double ratio = (worse * worse) / (better * better);
  return std::isfinite(ratio) ? stats::f_sf(ratio, m3, m3) : 0.0;
}
}  // namespace

double Chain::step_validation(const Level& L,
                              const std::string& g,
                              std::vector<double>* errors) const {
  std::vector<std::string> eff = L.a.effects;
  eff.push_back(g);
  try {
    const Analysis a = analyse(*cx, eff, fixed);
    if (!a.quality.has_validation) return INFINITY;
    if (errors) *errors = a.quality.validation_error_m;
    return comparable_validation(a.quality);
  } catch (const NumericalError&) {
    return INFINITY;  // a member whose re-fit fails predicts nothing
  }
}

bool Chain::group_validates(const Level& L, double p_calibration) const {
  const double before = comparable_validation(L.a.quality);
  std::vector<double> errors;
  for (const auto& g : L.group)
    if (step_validation(L, g, &errors) < before &&
        (p_calibration >= 1 || confirmed(p_calibration, L.a.quality.validation_error_m, errors)))
      return true;
  return false;
}

bool Chain::confirmed(double p_calibration,
                      const std::vector<double>& before,
                      const std::vector<double>& after) const {
  // Fisher's combination of two independent p-values (calibration and validation sessions):
  // -2 (ln p1 + ln p2) ~ chi2(4) under the null, whose tail is k (1 - ln k), k = p1 p2.
  const double k = p_calibration * paired_fall_p(before, after);
  return k > 0 ? k * (1 - std::log(k)) < cx->opt->alpha : true;
}

std::string Chain::validation_separates(const Level& L,
                                        std::string* why,
                                        std::vector<double>* top_errors) const {
  top_errors->clear();
  if (!L.a.quality.has_validation || L.group.size() < 2) return "";
  std::vector<double> rms;
  for (const auto& g : L.group)
    rms.push_back(step_validation(L, g, rms.empty() ? top_errors : nullptr));
  const size_t best = static_cast<size_t>(std::min_element(rms.begin(), rms.end()) - rms.begin());
  if (!std::isfinite(rms[best]) || rms[best] <= 0) return "";
  std::string text;
  for (size_t k = 0; k < rms.size(); ++k) {
    if (k == best) continue;
    const double p = validation_f_p(rms[k], rms[best], cx->validation->rows.size());
    if (!(p < cx->opt->alpha)) return "";
    text += (text.empty() ? "" : ", ") + L.group[k] + " " + um(rms[k]) + " (p = " + num(p, 2) + ")";
  }
  *why = "the calibration poses cannot tell " + join(L.group, ", ") + " apart, but with " +
         L.group[best] + " the validation poses are predicted to " + um(rms[best]) +
         ", significantly better than with " + text;
  return L.group[best];
}

std::optional<OutsideTrend> Chain::outside_rival(size_t i) const {
  const Level& L = levels[i];
  if (L.pick >= L.bases.size()) return std::nullopt;
  const MatrixXd& ut = L.bases[L.pick];
  const double alpha = cx->opt->alpha, tol = cx->opt->rank_tolerance;
  // The effects the pick's chain adds after it (levels i + 1 ... built by explained_by) take up
  // their part of the residual in both tests: a second effect left in it (a drift beside a
  // link spring) would otherwise inflate the residual variance and let the mechanism explain
  // the pick away on its noise.
  MatrixXd others(L.a.r.size(), 0);
  for (size_t j = i + 1; j + 1 < levels.size(); ++j) {
    const std::string& e = levels[j].scores[levels[j].pick].effect;
    for (size_t k = 0; k < L.bases.size(); ++k)
      if (k != L.pick && L.scores[k].effect == e) {
        MatrixXd m(others.rows(), others.cols() + L.bases[k].cols());
        m << others, L.bases[k];
        others = std::move(m);
      }
  }
  // The pick must stand against the chain's other effects alone: else they, not the
  // mechanism, explain it away.
  if (others.cols() > 0 &&
      explains_away(L.a, ut, orthonormal_basis(others, tol, nullptr, nullptr, 1.0), alpha, tol))
    others.resize(L.a.r.size(), 0);
  auto with_others = [&](const MatrixXd& u) {
    if (others.cols() == 0) return u;
    MatrixXd m(u.rows(), u.cols() + others.cols());
    m << u, others;
    return orthonormal_basis(m, tol, nullptr, nullptr, 1.0);
  };
  for (OutsideTrend& o : outside_trends(*cx, L.a)) {
    const GroupScore g = score_group(L.a, o.z, VectorXd::Ones(o.z.cols()), 1e-6);
    if (g.df == 0 || !(std::exp(g.log_p) < alpha)) continue;
    if (!explains_away(L.a, ut, with_others(g.u), alpha, tol)) continue;
    // A flexible group contains much of the library's own laws (a compensator is a joint-2
    // compliance that varies with q2): it is a rival only when the candidate does not explain
    // it away in turn, i.e. when it takes up more than the candidate does.
    if (o.beyond_candidates && explains_away(L.a, g.u, with_others(ut), alpha, tol)) continue;
    return std::move(o);
  }
  return std::nullopt;
}

bool Chain::explained_by_chain(
    size_t i, int depth, std::string* why, std::string* top_why, bool* weak) {
  static constexpr size_t kAlternatives = 3;
  std::string first, alt_why;
  bool first_weak = false, top_validated = false, top_refuted = false;
  std::vector<double> top_step_errors;  // validation errors of the top's step, when not validated
  size_t best = SIZE_MAX, alt = SIZE_MAX;
  // A copy: levels grows (and may move) while the chains are built.
  const std::string top_effect = levels[i].scores.empty() ? "" : levels[i].scores[0].effect;
  double best_rms = INFINITY, top_rms = INFINITY;
  const size_t tries = std::min(kAlternatives, levels[i].scores.size());
  const auto& group = levels[i].group;
  for (size_t k = 0; k < tries; ++k) {
    if (!levels[i].scores[k].significant) break;
    // Candidates outside the top's ambiguity group explain another part of the residual:
    // tried only when nothing in the group explains it.
    const bool rival =
        k == 0 || std::find(group.begin(), group.end(), levels[i].scores[k].effect) != group.end();
    if (!rival && best != SIZE_MAX) break;
    levels.resize(i + 1);
    levels[i].pick = k;
    std::string w;
    bool wk = false;
    const bool explains = explained_by(i, depth, &w, &wk);
    if (k == 0) {
      top_validated = levels[i].validated;
      top_refuted = levels[i].refuted;
      if (!top_validated && levels.size() > i + 1)
        top_step_errors = levels[i + 1].a.quality.validation_error_m;
    }
    // A rival whose chain explains the data only once the top is added later is no evidence
    // for the rival: the top's own chain asked whether the rival is needed after the top, and
    // the data did not say so; the rival's first step only took up part of the top's signal.
    // When the top's own step did not lower the validation error, its chain never asked: the
    // rival then counts if the validation poses need it beside the top (their errors fall
    // from the top's step to the rival chain's end).
    const auto& chain_effects = levels.back().a.effects;
    const bool needs_top =
        std::find(chain_effects.begin(), chain_effects.end(), top_effect) != chain_effects.end();
    const bool needed_beside_top =
        !top_step_errors.empty() &&
        paired_fall_p(top_step_errors, levels.back().a.quality.validation_error_m) < cx->opt->alpha;
    if (explains && k > 0 && needs_top && !needed_beside_top) continue;
    // A rival whose step the validation poses confirm, with only marginal evidence beyond it:
    // the lead when the top's chain is refuted outright.
    if (!explains && k > 0 && wk && levels[i].validated && !needs_top && alt == SIZE_MAX) {
      alt = k;
      alt_why = w;
    }
    if (explains) {
      const ModelQuality& end = levels.back().a.quality;
      const double rms = end.has_validation ? comparable_validation(end) : 0.0;
      if (k == 0) top_rms = end.has_validation ? rms : INFINITY;
      if (rms < best_rms) {
        best_rms = rms;
        best = k;
      }
      if (!end.has_validation) break;
    } else if (k == 0) {
      first = w;
      first_weak = wk;
    }
  }
  levels.resize(i + 1);
  levels[i].rival.clear();
  if (best == SIZE_MAX) {
    const bool lead_alt = !first_weak && alt != SIZE_MAX;
    levels[i].pick = lead_alt ? alt : 0;
    levels[i].validated = lead_alt || top_validated;
    levels[i].refuted = !lead_alt && top_refuted;
    *why = lead_alt ? alt_why : first;
    if (top_why) *top_why = lead_alt ? first : "";
    if (weak) *weak = lead_alt || first_weak;
    return false;
  }
  // The top keeps its place unless a rival chain predicts the validation poses significantly
  // better (F test of the two validation mean squares, 3m dof each); a rival that is not
  // significantly better or worse leaves the data unable to choose (ambiguous).
  if (best != 0 && top_rms < INFINITY) {
    if (validation_f_p(top_rms, best_rms, cx->validation->rows.size()) >= cx->opt->alpha) {
      levels[i].rival = levels[i].scores[best].effect;
      best = 0;
    }
  }
  levels[i].pick = best;
  std::string w;
  bool wk = false;
  explained_by(i, depth, &w, &wk);  // rebuild the chosen chain's levels
  if (top_why)
    *top_why = best == 0
                   ? ""
                   : (first.empty() ? "predicts the validation poses significantly worse" : first);
  return true;
}

bool Chain::explained_by(size_t i, int depth, std::string* why, bool* weak) {
  const std::string added = levels[i].scores[levels[i].pick].effect;
  levels[i].validated = levels[i].refuted = false;
  *weak = false;
  const Level* n = next(i);
  if (!n) {
    *why = "the re-fit with " + added + " failed";
    return false;
  }
  const ModelQuality& q = levels[i].a.quality;
  const ModelQuality& nq = n->a.quality;
  if (q.has_validation && comparable_validation(nq) >= comparable_validation(q)) {
    *why = "adding " + added + " does not improve the validation error (" + um(q.validation_rms_m) +
           " -> " + um(nq.validation_rms_m) + ")";
    // Refuted only when the validation poses are predicted significantly worse (paired test
    // of the squared errors); otherwise the effect may be real but too small for this data to
    // pay for its parameters on new poses.
    *weak = !(paired_fall_p(nq.validation_error_m, q.validation_error_m) < cx->opt->alpha);
    levels[i].refuted = !*weak;
    return false;
  }
  levels[i].validated = q.has_validation;
  // Without a stated noise, a step after the first must earn its place on the new poses: the
  // score tests' scale is the model's own residual variance, which shrinks as the chain grows,
  // so a flexible candidate can be significant on structure of the calibration poses alone.
  // (Absolute data are judged on the cross-validated poses too, after the chain: rule 5.)
  if (q.has_validation && !cx->noise->known && i > 0 && !cx->absolute) {
    const double p = paired_fall_p(q.validation_error_m, nq.validation_error_m);
    if (!(p < cx->opt->alpha)) {
      *why = "adding " + added + " lowers the validation error by no more than chance (" +
             um(q.validation_rms_m) + " -> " + um(nq.validation_rms_m) + ", p = " + num(p, 2) + ")";
      *weak = true;
      return false;
    }
  }
  // Explained: the residual is at the floor and no candidate finds structure in it (the
  // partial F-tests do not depend on the stated noise, so they also catch a residual that
  // the noise allowance would let pass).
  std::string floor_why;
  bool floor_weak = false;
  const bool floor = at_floor(*n, &floor_why, &floor_weak);
  if (floor && !claims(*n)) return true;
  // At a stated floor a significant candidate defers the trend tests to the chain (at_floor);
  // when the chain then dismisses that candidate as noise taken up, the level is judged as one
  // with no candidate left: a strong trend still refutes it.
  // Only a trend of a mechanism outside the library counts here: a trend against the generic
  // covariates is what the candidates are for, and the dismissed candidate's evidence was
  // judged (a force-frame error in the calibration session only follows the load torques).
  auto dismissed = [&]() {
    if (!cx->noise->known) return true;
    const std::optional<CovariateTest> t = strong_trend(*cx, levels[i + 1], true);
    if (!t) return true;
    *why = "after adding " + added +
           ", the residual reaches the stated noise floor but still follows " + trend_text(*t) +
           ": structure remains that no candidate explains";
    *weak = false;
    return false;
  };
  // At the floor with a marginal candidate left (p_adj > alpha/10, the rule of decide()) that
  // does not validate: not structure.
  const bool marginal = n->scores[0].p_adjusted > cx->opt->alpha / 10;
  if (claims(*n) && n->separable && depth > 1) {
    std::string deeper;
    bool deeper_weak = false;
    if (explained_by_chain(i + 1, depth - 1, &deeper, nullptr, &deeper_weak)) return true;
    if (floor && levels[i + 1].scores[0].p_adjusted > cx->opt->alpha / 10) return dismissed();
    // At a stated noise floor, a candidate whose calibration gain the validation poses do not
    // confirm is calibration noise taken up, not structure.
    if (floor && cx->noise->known && nq.has_validation && !levels[i + 1].validated)
      return dismissed();
    // The candidate left predicts the new poses significantly worse: what it takes up on the
    // calibration poses does not carry over. That may be a few rows a jump decided on the
    // wrong side, or an effect outside the list that no candidate reproduces: neither a
    // confirmation nor a refutation of the chain so far, unless the floor test refutes it.
    if (levels[i + 1].refuted && (floor || floor_weak)) {
      *why = "after adding " + added + ", " + levels[i + 1].scores[0].effect +
             " takes up structure on the calibration poses that the validation poses refute (" +
             deeper + ")" + (floor ? "" : " and " + floor_why);
      *weak = true;
      return false;
    }
    *why = "after adding " + added + ": " + deeper;
    // What is left here is marginal evidence against the chain when it is at the floor, or
    // when the validation poses confirmed the next step: then this level's misfit is that
    // step's, and only the evidence beyond it, marginal, remains.
    *weak = deeper_weak && (floor || floor_weak || levels[i + 1].validated);
    return false;
  }
  // A group the calibration poses cannot separate (a soft reducer zone and a preloaded gap,
  // both at the torque reversal): the chain explains the data when a member's own chain
  // does. Which member, that level's own verdict says (ambiguous); this step stands.
  if (claims(*n) && !n->separable && depth > 1) {
    std::string deeper;
    bool deeper_weak = false;
    if (explained_by_chain(i + 1, depth - 1, &deeper, nullptr, &deeper_weak)) return true;
  }
  if (floor && marginal) return dismissed();
  n = &levels[i + 1];
  // A group that does not separate and whose members the validation poses do not confirm,
  // on a model that passes the floor test: what they take up on the calibration poses does
  // not carry over. At a stated floor that is noise taken up; without a statement, marginal.
  if (claims(*n) && !n->separable && (floor || floor_weak) && nq.has_validation &&
      !group_validates(*n)) {
    if (floor && cx->noise->known) return dismissed();
    *why = "after adding " + added + ", " + join(n->group, ", ") +
           " take up structure on the calibration poses that none of them carries over to the "
           "validation poses" +
           (floor ? "" : " and " + floor_why);
    *weak = true;
    return false;
  }
  if (floor)
    floor_why = "structure remains (" + n->scores[0].effect +
                " is significant, p_adj = " + num(n->scores[0].p_adjusted, 2) +
                (n->separable ? "" : ", not separable from " + join(n->group, ", ")) + ")";
  *weak = !floor && floor_weak && (!claims(*n) || marginal);
  *why = "after adding " + added + " " + floor_why +
         (depth > 1 ? " and no further candidate explains the rest" : "");
  return false;
}

std::string Chain::decide(size_t i, std::string* why) {
  levels[i].tentative = false;
  levels[i].outside_rival.clear();
  const Level& L = levels[i];
  const double alpha = cx->opt->alpha;
  const ModelQuality& q = L.a.quality;
  const bool known = cx->noise->known;
  const bool omnibus = known && q.floor_p < alpha;
  const std::string chi = "chi2 = " + num(q.chi2, 4) + " for " + std::to_string(q.dof) +
                          " dof, residual " + num(q.residual_to_floor, 3) +
                          " times the floor, p = " + num(q.floor_p, 2) + " allowing " +
                          num(100 * cx->opt->noise_uncertainty, 2) + " % noise uncertainty";
  auto nothing = [&](const std::string& extra, bool top_failed) {
    if (omnibus) {
      *why = "the residual is above the noise floor (" + chi + ") but no candidate effect " +
             "explains it" + extra;
      return std::string("unexplained");
    }
    // Without a stated noise the fit-versus-validation test is the absolute check: a model
    // that predicts new poses worse than it fits leaves structure that no candidate explains.
    if (!known && q.has_validation && q.validation_to_fit_p < alpha) {
      *why =
          "no candidate effect is significant, but the model predicts the validation poses "
          "worse than it fits (validation/fit = " +
          num(q.validation_to_fit, 3) + ", p = " + num(q.validation_to_fit_p, 2) +
          "): the missing effect is probably not in the candidate list" + extra;
      return std::string("unexplained");
    }
    // A strong trend left against a covariate is structure whatever the noise level says.
    if (const std::optional<CovariateTest> t = strong_trend(*cx, L)) {
      *why = "no candidate effect is significant, but the residual follows " + trend_text(*t) +
             ": the missing effect is probably not in the candidate list" + extra;
      return std::string("unexplained");
    }
    // Without a stated noise `adequate` has no absolute check: a candidate the calibration
    // found but whose chain did not explain the data, and a mechanism outside the library
    // whose trend the residual follows at alpha, are two pieces of evidence that the residual
    // is not noise, neither of them a library effect. No claim either way. (With a statement
    // the floor test is that check, and a small library effect the validation poses cannot yet
    // confirm stays `adequate`.)
    if (top_failed && !known)
      if (const std::optional<CovariateTest> t = strong_trend(*cx, L, true, alpha)) {
        *why = "no candidate effect explains the residual" + extra + ", and it follows " +
               trend_text(*t) + ": the missing effect is probably not in the candidate list";
        return std::string("unexplained");
      }
    *why = known
               ? "the residuals are at the noise floor (" + chi + ") and no candidate " +
                     "effect is significant" + extra
               : "no candidate effect is significant (the noise level is unknown: give "
                 "sigma_d or sigma_p, # tracker_sigma_m or replicated measurements for an absolute "
                 "check)" +
                     extra;
    return std::string("adequate");
  };
  if (!claims(L)) return nothing("", false);
  const CandidateScore& top = L.scores[0];
  // Marginal evidence (p_adj >= alpha/10) is a claim only with the validation poses' support:
  // the calibration's p and the paired test of the step's validation errors (section 2),
  // combined, must reach alpha. A flexible candidate can reach p_adj = 0.05 on a control's
  // noise and lower the validation error by chance; a group of look-alikes is no stronger.
  // A strong trend left in the residual (a mean offset beside a drift) is evidence of its own:
  // then the rules below judge the candidate as before. (Level i's residual: asked once.)
  std::optional<bool> trend_left;
  auto marginal = [&](double p) {
    if (!(p > alpha / 10 && q.has_validation)) return false;
    if (!trend_left) trend_left = strong_trend(*cx, L).has_value();
    return !*trend_left;
  };
  if (!L.separable && !omnibus && marginal(top.p_adjusted) && !group_validates(L, top.p_adjusted))
    return nothing(" (" + join(L.group, ", ") + " reached p_adj = " + num(top.p_adjusted, 2) +
                       " but the validation poses confirm none of them)",
                   true);
  if (!L.separable) {
    // The calibration poses cannot separate the group. When the validation poses single out
    // one member and its chain explains the data, that member is the claim; otherwise the
    // group stands (a member that does not explain the rest is no better evidence than the
    // group).
    std::string separated_why;
    std::vector<double> top_errors;
    const std::string member = validation_separates(L, &separated_why, &top_errors);
    if (!member.empty()) {
      // What decide() and the chains change on level i, to restore when the group stands.
      const std::vector<std::string> group = L.group;
      const std::string experiment = L.experiment;
      levels[i].separable = true;
      std::string w;
      const std::string v = decide(i, &w);
      if (v == "missing_effect" && levels[i].scores[levels[i].pick].effect == member) {
        *why = w + "; " + separated_why;
        return v;
      }
      levels.resize(i + 1);
      Level& back = levels[i];
      back.separable = back.validated = back.refuted = back.tentative = false;
      back.pick = 0;
      back.rival.clear();
      back.outside_rival.clear();
      back.group = group;
      back.experiment = experiment;
    }
    // The loop still takes the top's step when the validation poses confirm it (their errors
    // fall significantly): the group is the claim, the step a model that predicts better.
    levels[i].tentative = !top_errors.empty() && paired_fall_p(L.a.quality.validation_error_m,
                                                               top_errors) < cx->opt->alpha;
    *why =
        "these candidates explain the same part of the residual and this data cannot tell "
        "them apart: " +
        join(levels[i].group, ", ");
    return "ambiguous";
  }
  std::string reason, top_reason;
  bool weak = false;
  if (!explained_by_chain(i, cx->opt->max_steps, &reason, &top_reason, &weak)) {
    // A marginal candidate that does not validate on a model at the noise floor, or any
    // candidate the validation poses do not confirm on a model at a stated floor: no claim.
    if (!omnibus &&
        (top.p_adjusted > alpha / 10 || (known && q.has_validation && !levels[i].validated)))
      return nothing(
          " (" + top.effect + " reached p_adj = " + num(top.p_adjusted, 2) + " but " + reason + ")",
          true);
    // The lead: the top, or a rival whose confirmed step replaced a top the validation poses
    // refuted (explained_by_chain).
    const CandidateScore& lead = L.scores[L.pick];
    const std::string evidence =
        (L.pick > 0 ? top.effect + " does not validate (" + top_reason + "); " : "") + lead.effect +
        " explains part of the misfit (partial F = " + num(lead.statistic, 4) +
        ", p_adj = " + num(lead.p_adjusted, 2) + ") but " + reason;
    // Strong evidence for the lead in the calibration, and only marginal evidence against its
    // chain: neither confirmed nor refuted, so no claim either way.
    if (weak) {
      levels[i].tentative = levels[i].validated;
      levels[i].group = {lead.effect};
      levels[i].experiment = "more validation poses, to confirm or refute " + lead.effect +
                             " on new data (the model with and without it as the candidates); " +
                             experiment_for(*cx, levels[i].group);
      *why = evidence +
             (levels[i].validated
                  ? "; that evidence is marginal (p >= alpha/10, or a fit the validation poses "
                    "refute): this data cannot tell whether " +
                        lead.effect +
                        " is what is missing and the rest chance, or an effect outside the "
                        "candidate list is at work"
                  : ", though not significantly worse: " + lead.effect +
                        " may be real but too small for this data to pay for its parameters on "
                        "new poses, or stand in for an effect outside the candidate list");
      return "ambiguous";
    }
    *why = evidence + ": the missing effect is probably not in the candidate list";
    return "unexplained";
  }
  if (!L.rival.empty()) {
    levels[i].tentative = levels[i].validated;  // the top's chain explains: the loop follows it
    levels[i].group = {top.effect, L.rival};
    levels[i].experiment = experiment_for(*cx, levels[i].group);
    *why = top.effect + " and " + L.rival +
           " each explain the misfit and predict the validation poses equally well: this data "
           "cannot tell them apart";
    return "ambiguous";
  }
  const CandidateScore& pick = L.scores[L.pick];
  // Marginal evidence needs the validation poses' support (above). The chain just built level
  // i + 1 with the pick added: its validation errors are the step's.
  if (marginal(pick.p_adjusted) && levels.size() > i + 1 &&
      !confirmed(pick.p_adjusted, q.validation_error_m, levels[i + 1].a.quality.validation_error_m))
    return nothing(" (" + pick.effect + " reached p_adj = " + num(pick.p_adjusted, 2) +
                       " but the validation poses do not confirm it)",
                   true);
  // A mechanism outside the library that takes up the same part of the residual: the chain
  // explains the data, but so may an effect that no candidate has. No claim; the loop follows
  // the step the validation poses confirmed.
  if (const std::optional<OutsideTrend> o = outside_rival(i)) {
    levels[i].tentative = levels[i].validated;
    levels[i].group = {pick.effect};
    levels[i].outside_rival = o->name;
    levels[i].experiment = experiment_for(*cx, levels[i].group);
    *why = pick.effect + " explains the misfit (partial F = " + num(pick.statistic, 4) +
           ", p_adj = " + num(pick.p_adjusted, 2) + "), but so does " + o->description +
           ": it takes up the same part of the residual, and this data cannot tell them apart";
    return "ambiguous";
  }
  *why = pick.effect + " is missing (partial F = " + num(pick.statistic, 4) +
         ", Holm-adjusted p = " + num(pick.p_adjusted, 2) + ", expected RMS drop " +
         um(pick.expected_rms_drop_m) + ")";
  if (L.pick > 0)
    *why += "; " + top.effect + " fits the calibration data as well or better but " + top_reason;
  return "missing_effect";
}

}  // namespace stiff::diagnose_detail
