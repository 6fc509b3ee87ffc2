/// \file identifiability.hpp
/// The numerical identifiability decision of every fit (docs/identifiability.md): which
/// parameters, or combinations of them, the data cannot determine.
#pragma once

#include <Eigen/Core>
#include <string>
#include <vector>

#include "io/number_text.hpp"
#include "stiff/model/model.hpp"

namespace stiff::detail {

/// "effect.parameter" of theta's k-th parameter.
std::string qualified(const DeflectionModel& model, int k);

/// J^T J of `j`, both triangles (a rank update of the lower one, then mirrored).
Eigen::MatrixXd gram_of(const Eigen::MatrixXd& j);

struct Identifiability {
  std::vector<bool> fixed;          ///< per parameter: held (not determined by the data)
  std::vector<std::string> reason;  ///< per held parameter: why, naming its partners
  std::vector<bool> statistical;    ///< per held parameter: held by the statistical test
  bool operator==(const Identifiability& o) const { return fixed == o.fixed; }
};

/// Which parameters the data cannot determine, from the Jacobian `j` of the weighted
/// residuals (rows in units of each row's noise sigma) with every column scaled by the
/// parameter's typical magnitude:
///  1. structural rank: columns in priority order (joint compliances first, then the effects
///     in model order) are accepted when their part orthogonal to the accepted ones has a
///     relative norm above `tolerance` (the rank decision of a QR of the scaled Jacobian,
///     Khalil & Dombre 2002); a rejected column is named with the accepted parameters it is
///     a combination of;
///  2. statistical: with `max_relative_se` > 0 and the parameter values `theta`, an accepted
///     parameter is not determined when its standard error (residual scale `residual_sigma`
///     times the root of the scaled inverse Gram diagonal) exceeds `max_relative_se` times
///     both its typical magnitude and a third of its distance from its null value (a
///     t-statistic below 3 against "effect off"): the last in priority order of the
///     such parameters is held, named with the parameter it is most correlated with, and the
///     test repeated until every free parameter passes. Only parameters marked in `fitted`
///     (those theta holds a fitted value of; all when null) can be held by this test: a value
///     held at its null so far is not evidence either way. With the weighted `residuals` at
///     theta (the rows of j; before a solve), the residual scale is that of the linear
///     least-squares step from theta over each round's free set, and a parameter is held
///     when its standard error alone exceeds `max_relative_se` times its typical magnitude.
/// `first` (optional, per parameter): parameters that come first in the priority order, e.g.
/// those a start fit identified.
/// `structure`: the structural decision (1.) already made on j, whose held set the statistical
/// test starts from (it is not made again). `gram`: J^T J of j (symmetric) when the caller has
/// it; else it is formed once here for both tests.
/// Throws NumericalError when j is not finite.
Identifiability check_identifiability(const DeflectionModel& model,
                                      const Eigen::MatrixXd& j,
                                      const Eigen::VectorXd& typical,
                                      double tolerance,
                                      double residual_sigma = 1.0,
                                      double max_relative_se = 0.0,
                                      const Eigen::VectorXd* theta = nullptr,
                                      const std::vector<bool>* fitted = nullptr,
                                      const Eigen::VectorXd* residuals = nullptr,
                                      const std::vector<bool>* first = nullptr,
                                      const Identifiability* structure = nullptr,
                                      const Eigen::MatrixXd* gram = nullptr);

}  // namespace stiff::detail
