// Keeps Ceres from printing. Ceres 2.1 logs through glog to stderr in a few places whatever
// Solver::Options::logging_type says: "Terminating: ..." (LOG(ERROR)) when the trust-region
// minimizer fails (start not evaluable, too many consecutive invalid steps, Jacobian not
// evaluable at an accepted point) and "Error in evaluating the ResidualBlock" (LOG(WARNING))
// when a cost function returns true with a non-finite value. The library must never print
// (stiff.h), and glog's switches (minloglevel) are process-wide and belong to the host
// application (changing them around a solve would also race with other threads), so these
// failures are avoided before Ceres reaches its log line: cost functions return false for
// non-finite values, the start is evaluated before ceres::Solve, and this guard stops the
// minimizer one invalid step before Ceres's own limit.
#pragma once

#include <ceres/ceres.h>

#include <string>

#include "stiff/error.hpp"

namespace stiff::ceres_quiet {

/// Stops the minimizer (SOLVER_ABORT, which Ceres does not log) after kLimit consecutive
/// invalid steps; Ceres's own limit, one more, would log "Terminating: ...".
class InvalidStepGuard final : public ceres::IterationCallback {
 public:
  static constexpr int kLimit = 5;
  ceres::CallbackReturnType operator()(const ceres::IterationSummary& s) override {
    run_ = s.step_is_valid ? 0 : run_ + 1;
    return run_ >= kLimit ? ceres::SOLVER_ABORT : ceres::SOLVER_CONTINUE;
  }
  bool tripped() const { return run_ >= kLimit; }

 private:
  int run_ = 0;
};

/// Installs the guard into the solver options.
inline void install(ceres::Solver::Options& so, InvalidStepGuard& guard) {
  so.max_num_consecutive_invalid_steps = InvalidStepGuard::kLimit + 1;
  so.callbacks.push_back(&guard);
}

/// After ceres::Solve: the guard's stop is a numerical failure, in the library's words.
inline void check(const InvalidStepGuard& guard, const std::string& what) {
  if (guard.tripped())
    throw NumericalError(what + ": the solver failed: " + std::to_string(InvalidStepGuard::kLimit) +
                         " consecutive invalid steps (values too large for double precision?): "
                         "check the units and sizes of the loads and displacements (N, N*m, m)");
}

}  // namespace stiff::ceres_quiet
