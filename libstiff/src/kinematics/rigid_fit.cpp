// Least-squares rigid motion between two point sets (rigid_fit.hpp).
#include "stiff/kinematics/rigid_fit.hpp"

#include <Eigen/LU>
#include <Eigen/SVD>
#include <algorithm>

namespace stiff {

Eigen::Matrix3d nearest_rotation(const Eigen::Matrix3d& m) {
  Eigen::JacobiSVD<Eigen::Matrix3d> svd(m, Eigen::ComputeFullU | Eigen::ComputeFullV);
  Eigen::Matrix3d d = Eigen::Matrix3d::Identity();
  d(2, 2) = (svd.matrixU() * svd.matrixV().transpose()).determinant() < 0 ? -1.0 : 1.0;
  return svd.matrixU() * d * svd.matrixV().transpose();
}

bool fit_rigid_motion(const Eigen::Matrix3Xd& x,
                      const Eigen::Matrix3Xd& y,
                      Eigen::Matrix3d* r,
                      Eigen::Vector3d* t) {
  if (x.cols() != y.cols() || x.cols() < 3) return false;
  const Eigen::Vector3d cx = x.rowwise().mean(), cy = y.rowwise().mean();
  const Eigen::Matrix3d h = (x.colwise() - cx) * (y.colwise() - cy).transpose();
  const Eigen::Vector3d sv = Eigen::JacobiSVD<Eigen::Matrix3d>(h).singularValues();
  if (!(sv(1) > 1e-8 * std::max(sv(0), 1e-300))) return false;
  // max tr(R h) = max tr(R^T h^T).
  *r = nearest_rotation(h.transpose());
  *t = cy - *r * cx;
  return true;
}

}  // namespace stiff
