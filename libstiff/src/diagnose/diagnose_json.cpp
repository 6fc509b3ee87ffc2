// The diagnosis as JSON ("stiff-diagnosis", docs/diagnosis.md section 4).
#include <cmath>
#include <nlohmann/json.hpp>

#include "diagnose/text.hpp"
#include "stiff/diagnose/diagnose.hpp"

namespace stiff {

using diagnose_detail::join;

namespace {

nlohmann::json finite(double v) {
  return std::isfinite(v) ? nlohmann::json(v) : nlohmann::json(nullptr);
}

/// A text, or null when there is none.
nlohmann::json text_or_null(const std::string& s) {
  return s.empty() ? nlohmann::json(nullptr) : nlohmann::json(s);
}

nlohmann::json quality_json(const ModelQuality& q) {
  nlohmann::json j;
  j["model"] = q.model;
  j["measurements"] = q.measurements;
  j["used"] = q.used;
  j["uncertain_rows"] = q.uncertain_rows;
  j["parameters"] = q.parameters;
  j["rms_m"] = q.fit_rms_m;
  j["chi2"] = q.chi2;
  j["dof"] = q.dof;
  j["chi2_p"] = q.chi2_p;
  j["sigma_hat_m"] = q.sigma_hat_m;
  j["residual_to_floor"] = finite(q.residual_to_floor);
  j["floor_p"] = q.floor_p;
  j["validation_to_floor"] = finite(q.validation_to_floor);
  if (q.has_validation) {
    j["validation_rms_m"] = q.validation_rms_m;
    j["validation_floor_m"] = q.validation_floor_m;
    j["validation_leverage"] = q.validation_leverage;
    j["validation_error_m"] = q.validation_error_m;
    j["validation_to_fit"] = finite(q.validation_to_fit);
    j["validation_to_fit_p"] = q.validation_to_fit_p;
    j["validation_outliers"] = q.validation_outliers;
    j["validation_session_parameters"] = q.validation_session_parameters;
    j["validation_uncertain_rows"] = q.validation_uncertain_rows;
  }
  if (!q.cross_validation_error_m.empty()) {
    nlohmann::json cv = nlohmann::json::array();
    for (double e : q.cross_validation_error_m) cv.push_back(finite(e));  // null: row not used
    j["cross_validation_error_m"] = cv;
  }
  nlohmann::json p = nlohmann::json::object();
  for (size_t k = 0; k < q.parameter_names.size(); ++k)
    p[q.parameter_names[k]] = q.parameter_values[k];
  j["parameter_values"] = p;
  return j;
}

}  // namespace

std::string diagnosis_to_json(const Diagnosis& d) {
  using nlohmann::json;
  json j;
  j["format"] = "stiff-diagnosis";
  j["version"] = 1;
  j["robot"] = d.robot;
  j["model"] = join(d.model, "+");
  j["verdict"] = d.verdict;
  j["summary"] = d.summary;
  j["alpha"] = d.alpha;
  j["noise_floor_m"] = d.noise_floor_m;
  j["noise_source"] = d.noise_source;
  j["noise_force_error"] = d.noise_force_error;
  j["repeatability_m"] = d.repeatability_m > 0 ? json(d.repeatability_m) : json(nullptr);
  json fit = quality_json(d.fit);
  fit["omnibus_rejects"] = d.omnibus_rejects;
  j["fit"] = fit;
  if (d.fit.has_validation) {
    json v;
    v["rms_m"] = d.fit.validation_rms_m;
    v["floor_m"] = d.fit.validation_floor_m;
    v["error_m"] = d.fit.validation_error_m;
    if (d.after_valid) v["rms_after_m"] = d.after.validation_rms_m;
    j["validation"] = v;
  }
  j["suggested_model"] = text_or_null(d.suggested_model);
  j["suggested_command"] = text_or_null(d.suggested_command);
  if (d.after_valid) j["after"] = quality_json(d.after);
  j["ambiguous_group"] = d.ambiguous_group;
  j["outside_rival"] = text_or_null(d.outside_rival);
  j["experiment"] = text_or_null(d.experiment);
  j["unexplained_signature"] = text_or_null(d.unexplained_signature);
  json cands = json::array();
  for (const auto& c : d.candidates) {
    json x;
    x["effect"] = c.effect;
    x["rank"] = c.rank == 0 ? json(nullptr) : json(c.rank);
    x["testable"] = c.testable;
    x["reason"] = c.reason;
    x["parameters"] = c.parameters;
    x["df"] = c.df;
    x["identifiable"] = c.identifiable;
    x["unidentifiable_parameters"] = c.unidentifiable;
    x["test"] = "partial_F";
    x["statistic"] = c.testable ? finite(c.statistic) : json(nullptr);
    x["lm"] = c.testable ? finite(c.lm) : json(nullptr);
    x["log10_p"] = c.testable ? finite(c.log_p / std::log(10.0)) : json(nullptr);
    x["p_value"] = c.testable ? json(c.p_value) : json(nullptr);
    x["p_adjusted"] = c.testable ? json(c.p_adjusted) : json(nullptr);
    x["significant"] = c.significant;
    x["expected_rms_drop_m"] = c.testable ? json(c.expected_rms_drop_m) : json(nullptr);
    x["fit_rms_after_m"] = c.testable ? json(c.fit_rms_after_m) : json(nullptr);
    x["excess_explained"] = finite(c.excess_explained);
    x["surviving_fraction"] = c.surviving_fraction;
    x["max_correlation_with_top"] = c.max_correlation;
    x["group"] = c.group;
    x["command"] = c.command;
    if (!c.av_fitted_m.empty()) {
      x["added_variable"] = {{"fitted_m", c.av_fitted_m}, {"residual_m", c.av_residual_m}};
    }
    cands.push_back(x);
  }
  j["candidates"] = cands;
  json w;
  json worst = json::array(), res = json::array();
  auto pose = [](const PoseResidual& p) {
    return json{{"row", p.row},
                {"id", p.id},
                {"residual_m", {p.residual_m[0], p.residual_m[1], p.residual_m[2]}},
                {"predicted_m", {p.predicted_m[0], p.predicted_m[1], p.predicted_m[2]}},
                {"norm_m", p.norm_m},
                {"norm_sigma", finite(p.norm_sigma)},
                {"outlier", p.outlier}};
  };
  for (const auto& p : d.worst) worst.push_back(pose(p));
  for (const auto& p : d.residuals) res.push_back(pose(p));
  w["worst_poses"] = worst;
  json axes = json::array();
  const char* ax[3] = {"x", "y", "z"};
  for (int k = 0; k < 3; ++k)
    axes.push_back({{"axis", ax[k]}, {"rms_m", d.axis_rms_m[k]}, {"chi2_p", d.axis_chi2_p[k]}});
  w["axes"] = axes;
  json cov = json::array();
  for (const auto& c : d.covariates)
    cov.push_back({{"covariate", c.covariate},
                   {"description", c.description},
                   {"test", c.test},
                   {"statistic", c.statistic},
                   {"df", c.df},
                   {"p_value", c.p_value},
                   {"p_adjusted", c.p_adjusted},
                   {"significant", c.significant},
                   {"share", c.share},
                   {"structure", c.structure},
                   {"correlation", {c.correlation[0], c.correlation[1], c.correlation[2]}}});
  w["covariates"] = cov;
  w["outliers"] = json::array();
  for (const auto& p : d.residuals)
    if (p.outlier) w["outliers"].push_back(pose(p));
  j["where"] = w;
  j["residuals"] = res;
  json steps = json::array();
  for (const auto& s : d.steps) {
    json x = quality_json(s.quality);
    x["step"] = s.step;
    x["added"] = text_or_null(s.added);
    x["verdict"] = s.verdict;
    x["top"] = text_or_null(s.top);
    x["top_p_adjusted"] = s.top_p_adjusted;
    x["top_expected_rms_drop_m"] = s.top_expected_rms_drop_m;
    steps.push_back(x);
  }
  j["steps"] = steps;
  j["final_model"] = d.final_model;
  j["final_verdict"] = d.final_verdict;
  j["notes"] = d.notes;
  j["warnings"] = d.warnings;
  return j.dump(1);
}

}  // namespace stiff
