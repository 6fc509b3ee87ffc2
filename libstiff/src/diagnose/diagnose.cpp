// Model diagnosis, the entry point: checks the options, runs the loop of levels (chain.cpp) on
// the analysis of the given model (analysis.cpp, scoring.cpp) and fills the report with the
// verdict, where the model fails (where.cpp) and the steps of the loop (docs/diagnosis.md).
#include "stiff/diagnose/diagnose.hpp"

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <optional>
#include <set>

#include "diagnose/analysis.hpp"
#include "diagnose/text.hpp"
#include "stiff/error.hpp"
#include "stiff/model/model.hpp"

namespace stiff {

using diagnose_detail::analyse;
using diagnose_detail::Chain;
using diagnose_detail::claims;
using diagnose_detail::Context;
using diagnose_detail::cross_validation_errors;
using diagnose_detail::join;
using diagnose_detail::Level;
using diagnose_detail::mm;
using diagnose_detail::Noise;
using diagnose_detail::noise_of;
using diagnose_detail::num;
using diagnose_detail::score_level;
using diagnose_detail::signature_of;
using diagnose_detail::split_validation;
using diagnose_detail::um;
using diagnose_detail::ValidationSplit;
using diagnose_detail::where;
using diagnose_detail::with_explicit_time;

Diagnosis diagnose(const RobotModel& robot,
                   const Dataset& calibration,
                   const Dataset* validation,
                   const std::vector<std::string>& model,
                   const DiagnosisOptions& options) {
  if (!(options.alpha > 0 && options.alpha < 1))
    throw InvalidArgument("diagnose: alpha must be in (0, 1)");
  if (!(options.ambiguity_correlation > 0 && options.ambiguity_correlation <= 1))
    throw InvalidArgument("diagnose: ambiguity_correlation must be in (0, 1]");
  if (!(options.rank_tolerance > 0 && options.rank_tolerance < 0.1))
    throw InvalidArgument("diagnose: rank_tolerance must be in (0, 0.1)");
  if (!(options.outlier_alpha >= 0 && options.outlier_alpha < 1))
    throw InvalidArgument("diagnose: outlier_alpha must be in [0, 1)");
  if (!(options.noise_uncertainty >= 0 && options.noise_uncertainty < 1))
    throw InvalidArgument("diagnose: noise_uncertainty must be in [0, 1)");
  if (!(options.validation_registration_fraction > 0 &&
        options.validation_registration_fraction < 1))
    throw InvalidArgument("diagnose: validation_registration_fraction must be in (0, 1)");
  if (!(options.repeatability_m >= 0 && std::isfinite(options.repeatability_m)))
    throw InvalidArgument("diagnose: repeatability_m must be finite and >= 0 (0: not stated)");
  if (options.cross_validation_folds < 0 || options.cross_validation_folds == 1 ||
      options.cross_validation_folds > 20)
    throw InvalidArgument("diagnose: cross_validation_folds must be 0 (none) or in [2, 20]");
  if (options.max_steps < 0 || options.max_steps > 20)
    throw InvalidArgument("diagnose: max_steps must be in [0, 20]");
  if (model.empty()) throw InvalidArgument("diagnose: the model has no effect (e.g. 'joint')");
  validate_dataset(calibration, robot.dof(), true);
  if (calibration.rows.size() < 4)
    throw InvalidArgument("diagnose: needs at least 4 calibration measurements");
  if (validation) {
    validate_dataset(*validation, robot.dof(), true);
    if (validation->rows.empty()) throw InvalidArgument("diagnose: the validation data is empty");
  }
  { const DeflectionModel check(robot, model, &calibration); }  // names, requirements
  std::vector<std::string> candidates = options.candidates;
  const auto all = effect_names();
  if (candidates.empty()) {
    for (const auto& e : all)
      if (std::find(model.begin(), model.end(), e) == model.end()) candidates.push_back(e);
  } else {
    std::set<std::string> seen;
    std::vector<std::string> keep;
    for (const auto& c : candidates) {
      if (std::find(all.begin(), all.end(), c) == all.end())
        throw InvalidArgument("diagnose: unknown candidate effect '" + c +
                              "'; known effects: " + join(all, " "));
      if (!seen.insert(c).second) continue;
      if (std::find(model.begin(), model.end(), c) == model.end()) keep.push_back(c);
    }
    candidates = keep;
  }

  Dataset calib = with_explicit_time(calibration);
  const Noise noise = noise_of(calibration);
  // A validation set-up the calibration has not seen is registered from part of its rows.
  ValidationSplit split;
  if (validation)
    split =
        split_validation(calibration, *validation, model, options.validation_registration_fraction);
  const Dataset* scored = validation ? &split.scored : nullptr;
  const Noise vnoise = validation ? noise_of(split.scored) : Noise{};
  Context cx{&robot, &calib, scored, &noise, &vnoise, &options, calibration.has_time, &split};
  cx.absolute = std::any_of(calibration.rows.begin(), calibration.rows.end(),
                            [](const Measurement& m) { return m.absolute; });

  Diagnosis d;
  d.notes = split.notes;
  d.robot = robot.name;
  d.model = model;
  d.alpha = options.alpha;
  d.noise_floor_m = noise.floor_m;
  d.noise_source = noise.source;
  d.noise_force_error = noise.force_error_stated();
  d.repeatability_m = options.repeatability_m;
  if (!noise.known)
    d.warnings.push_back(
        "the noise level is unknown (no sigma_d or sigma_p, no # tracker_sigma_m, no replicated "
        "measurements): tests use the residual variance; the absolute (chi2) check is skipped");

  Chain chain{&cx, candidates, {}, {}};
  // decide() holds references into `levels` while the chain grows it: never reallocate (the
  // loop's last step looks max_steps further).
  chain.levels.reserve(2 * static_cast<size_t>(options.max_steps) + 2);
  chain.levels.push_back(score_level(cx, analyse(cx, model, nullptr, candidates), candidates));
  std::string why;
  d.verdict = chain.decide(0, &why);
  // Outliers are judged under the best explanation found: rows the given model calls outliers
  // only because an effect is missing are not outliers. Redo the chain with the last level's
  // flags, shared by every level (so that the steps compare like with like).
  std::vector<bool> final_flags = chain.levels.back().a.outlier;
  if (final_flags != chain.levels[0].a.outlier || chain.levels.size() > 1) {
    chain.levels.clear();
    chain.fixed = &final_flags;
    chain.levels.push_back(score_level(cx, analyse(cx, model, &final_flags), candidates));
    d.verdict = chain.decide(0, &why);
  }
  // Held-out evidence on absolute data: the validation rows and the calibration's own poses,
  // cross-validated (docs/diagnosis.md, section 3, rule 5).
  auto held_out = [&](Level& L) {
    ModelQuality& q = L.a.quality;
    if (cx.absolute && options.cross_validation_folds >= 2 && !L.cross_validated) {
      L.cross_validated = true;
      q.cross_validation_error_m = cross_validation_errors(cx, L.a, options.cross_validation_folds);
    }
    std::vector<double> h = q.validation_error_m;
    h.insert(h.end(), q.cross_validation_error_m.begin(), q.cross_validation_error_m.end());
    return h;
  };
  // A model whose held-out mean error is within the robot's stated repeatability predicts the
  // robot within its own scatter: nothing beyond it can be shown on single measurements.
  auto at_repeatability = [&](Level& L, std::string* reason) {
    if (!cx.absolute || !(options.repeatability_m > 0)) return false;
    double sum = 0;
    int n = 0;
    for (double e : held_out(L))
      if (std::isfinite(e)) {
        sum += e;
        ++n;
      }
    if (n < 3 || sum / n > options.repeatability_m) return false;
    const size_t v = L.a.quality.validation_error_m.size();
    *reason = "the held-out mean position error, " + mm(sum / n) + " over " + std::to_string(n) +
              " poses (" + std::to_string(v) + " validation, " + std::to_string(n - v) +
              " cross-validated), is within the robot's repeatability of " +
              mm(options.repeatability_m) + " (ISO 9283 RP): what remains is at the repeatability";
    return true;
  };
  const bool repeats = at_repeatability(chain.levels[0], &why);
  if (repeats) {
    d.verdict = "adequate";
    d.notes.push_back("step 0: " + why);
  }
  const Level* next = repeats ? nullptr : chain.next(0);
  const Level& L0 = chain.levels[0];
  d.fit = L0.a.quality;
  d.omnibus_rejects = noise.known && d.fit.floor_p < options.alpha;
  d.candidates = L0.scores;
  d.warnings.insert(d.warnings.end(), L0.a.warnings.begin(), L0.a.warnings.end());
  where(cx, L0, d);
  if (next) {
    d.after = next->a.quality;
    d.after_valid = true;
  }
  if (claims(L0) && !repeats) {
    d.suggested_model = join(model, "+") + "+" + L0.scores[L0.pick].effect;
    d.suggested_command = L0.scores[L0.pick].command;
  }
  if (d.verdict == "ambiguous") {
    d.ambiguous_group = L0.group;
    d.outside_rival = L0.outside_rival;
    d.experiment = L0.experiment;
  }
  if (d.verdict == "unexplained") d.unexplained_signature = signature_of(d);
  int outliers = 0;
  for (bool o : L0.a.outlier) outliers += o;
  d.summary = "model " + d.fit.model + ": fit RMS " + um(d.fit.fit_rms_m) +
              (noise.known ? " vs noise floor " + um(noise.floor_m) + " (" +
                                 num(d.fit.residual_to_floor, 3) + " times the floor)"
                           : "") +
              (d.fit.has_validation ? ", validation RMS " + um(d.fit.validation_rms_m) : "") +
              (outliers ? ", " + std::to_string(outliers) + " outlier(s) excluded" : "") +
              ". Verdict: " + d.verdict + " - " + why + ".";
  if (d.verdict == "ambiguous") d.summary += " Discriminating experiment: " + d.experiment + ".";
  if (d.verdict == "unexplained") d.summary += " Signature: " + d.unexplained_signature + ".";

  // Step 0 and the loop.
  auto step_of = [&](size_t i, const std::string& added, const std::string& verdict) {
    if (options.auto_loop) held_out(chain.levels[i]);  // the steps show the held-out errors
    const Level& L = chain.levels[i];
    DiagnosisStep s;
    s.step = static_cast<int>(i);
    s.added = added;
    s.quality = L.a.quality;
    s.verdict = verdict;
    if (claims(L)) {
      s.top = L.scores[L.pick].effect;
      s.top_p_adjusted = L.scores[L.pick].p_adjusted;
      s.top_expected_rms_drop_m = L.scores[L.pick].expected_rms_drop_m;
    }
    return s;
  };
  d.steps.push_back(step_of(0, "", d.verdict));
  d.final_model = d.fit.model;
  d.final_verdict = d.verdict;
  if (options.auto_loop) {
    // On absolute data the loop is also a calibration: a residual that no candidate explains
    // completely (unexplained), or that two candidates explain equally well (ambiguous, e.g. a
    // joint offset and a tilt of the same axis), still gets a candidate when the held-out poses
    // confirm it. Which one, the held-out poses decide (the calibration's own ranking favours
    // terms that fit its poses, e.g. harmonics, which may not carry over); the model grows
    // while the evidence holds, and the last step says what is left. Displacement data stop at
    // rule 4: their verdicts name a physical effect, not an accuracy.
    //
    // Do the held-out errors b fall against a (paired_fall_p: t test of the lengths, at alpha)? The
    // pairs are the common prefix: the validation rows, then the cross-validated calibration
    // rows when both levels have them (NaN: a row that is not used).
    auto falls = [&](const std::vector<double>& a, const std::vector<double>& b) {
      return diagnose_detail::paired_fall_p(a, b) < options.alpha;
    };
    auto mean_square = [](const std::vector<double>& e) {
      double s2 = 0;
      int n = 0;
      for (double x : e)
        if (std::isfinite(x)) {
          s2 += x * x;
          ++n;
        }
      return n ? s2 / n : INFINITY;
    };
    // Level i's pick becomes the candidate the held-out poses support best, its level i + 1
    // built; false (pick unchanged) when none is confirmed. Confirmed: the held-out errors fall
    // against level i. Of those, a candidate that the validation rows alone show to predict
    // worse than another is refuted (they are the poses the user asked about: another region,
    // another set-up); the rest are ranked by the mean square over all held-out poses (the
    // validation rows resolve a small difference only when there are many).
    auto choose_by_held_out = [&](size_t i) {
      if (!claims(chain.levels[i])) return false;
      const std::vector<double> base = held_out(chain.levels[i]);
      struct Option {
        size_t k;
        std::optional<Level> level;
        std::vector<double> h;
      };
      const size_t v = chain.levels[i].a.quality.validation_error_m.size();
      auto validation_part = [&](const std::vector<double>& h) {
        return std::vector<double>(h.begin(), h.begin() + v);
      };
      std::vector<Option> confirmed;
      for (size_t k = 0; k < chain.levels[i].scores.size(); ++k) {
        if (!chain.levels[i].scores[k].significant) continue;
        chain.levels.resize(i + 1);
        chain.levels[i].pick = k;
        if (!chain.next(i)) continue;
        // ... and the validation error itself falls: each step must show it to the user
        // (checked first: it needs no cross-validation refits).
        if (v > 0 && !(mean_square(chain.levels[i + 1].a.quality.validation_error_m) <
                       mean_square(validation_part(base))))
          continue;
        std::vector<double> h = held_out(chain.levels[i + 1]);
        if (!falls(base, h)) continue;
        confirmed.push_back({k, std::move(chain.levels[i + 1]), std::move(h)});
      }
      chain.levels.resize(i + 1);
      if (confirmed.empty()) return false;
      size_t best_v = 0;
      for (size_t c = 1; c < confirmed.size(); ++c)
        if (mean_square(validation_part(confirmed[c].h)) <
            mean_square(validation_part(confirmed[best_v].h)))
          best_v = c;
      std::optional<size_t> best;
      for (size_t c = 0; c < confirmed.size(); ++c) {
        if (c != best_v &&
            falls(validation_part(confirmed[c].h), validation_part(confirmed[best_v].h)))
          continue;
        if (!best || mean_square(confirmed[c].h) < mean_square(confirmed[*best].h)) best = c;
      }
      chain.levels[i].pick = confirmed[*best].k;
      chain.levels.push_back(std::move(*confirmed[*best].level));
      return true;
    };
    std::string verdict = d.verdict;
    for (size_t i = 0; static_cast<int>(i) < options.max_steps; ++i) {
      const bool go = verdict == "missing_effect" ||
                      (!cx.absolute && verdict == "ambiguous" && chain.levels[i].tentative) ||
                      (cx.absolute && (verdict == "unexplained" || verdict == "ambiguous") &&
                       choose_by_held_out(i));
      if (!go || !chain.next(i)) break;
      const std::string added = chain.levels[i].scores[chain.levels[i].pick].effect;
      std::string w2;
      verdict = chain.decide(i + 1, &w2);
      if (at_repeatability(chain.levels[i + 1], &w2)) {
        verdict = "adequate";
        d.notes.push_back("step " + std::to_string(i + 1) + ": " + w2);
      }
      d.steps.push_back(step_of(i + 1, added, verdict));
      d.final_model = chain.levels[i + 1].a.quality.model;
      d.final_verdict = verdict;
    }
  }
  d.warnings.insert(d.warnings.end(), chain.warnings.begin(), chain.warnings.end());
  return d;
}

}  // namespace stiff
