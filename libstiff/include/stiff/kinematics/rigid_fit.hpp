/// \file rigid_fit.hpp
/// The rigid motion that best maps one set of points onto another (least squares), the step
/// that registers an instrument's frame to a robot's base.
#pragma once

#include <Eigen/Core>

namespace stiff {

/// Rotation `r` and translation `t` minimising sum_i |r x_i + t - y_i|^2 over the columns of
/// `x` and `y` (3 x n each), by the SVD of the centred cross-covariance with the reflection
/// excluded (Arun, Huang & Blostein, IEEE PAMI 9(5), 1987; Umeyama 1991). Returns false, with
/// `r` and `t` untouched, when the points are (nearly) collinear or fewer than 3: the rotation
/// about their line is then not determined.
/// The rotation nearest to `m` (Frobenius norm; the maximiser of tr(R^T m)), reflection
/// excluded: U diag(1, 1, det(U V^T)) V^T of the SVD m = U S V^T. Fits a rotation to sums of
/// rotations (their chordal mean) and point clouds (fit_rigid_motion).
Eigen::Matrix3d nearest_rotation(const Eigen::Matrix3d& m);

bool fit_rigid_motion(const Eigen::Matrix3Xd& x,
                      const Eigen::Matrix3Xd& y,
                      Eigen::Matrix3d* r,
                      Eigen::Vector3d* t);

}  // namespace stiff
