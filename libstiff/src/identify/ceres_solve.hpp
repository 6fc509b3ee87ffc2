// The Ceres side of the identification: robust losses, the residual blocks over the cached
// evaluations, the iteration callbacks (progress, parameters pinned on a bound, held
// parameters becoming identifiable) and the bounded active-set solve (private to identify/).
#pragma once

#include <ceres/ceres.h>

#include <functional>
#include <string>
#include <vector>

#include "identify/evaluations.hpp"
#include "stiff/identify/identify.hpp"

namespace stiff::detail {

/// The robust losses `identify` accepts ("none" first).
const std::vector<std::string>& known_losses();

/// Loss on the squared norm s of one measurement's residual (sigma units), scale a; null for
/// "none".
ceres::LossFunction* make_loss(const std::string& name, double a);

struct SolveOutcome {
  int iterations = 0;
  bool converged = true;
  bool restart = false;  ///< stopped because a held parameter became identifiable
  std::string message;
};

/// True when a parameter held as unidentifiable has become identifiable at theta.
using Visible = std::function<bool(const Eigen::VectorXd& theta)>;

/// Minimise over the free parameters within their bounds; theta (full) is updated in place.
/// Parameters that settle on a bound are held there and the rest solved again; at the end a
/// held parameter whose cost derivative points into the feasible range is released (KKT), and
/// after a few rounds the plain bounded solve over every free parameter is the fallback.
SolveOutcome solve(const Setup& s,
                   const std::vector<int>& free,
                   Eigen::VectorXd& theta,
                   const IdentifyOptions& opt,
                   const Eigen::VectorXd& loss_scale,
                   const Visible* visible);

}  // namespace stiff::detail
