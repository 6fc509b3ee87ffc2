// Least-squares rigid motion between two point sets (rigid_fit.hpp).
#include "stiff/kinematics/rigid_fit.hpp"

#include <Eigen/LU>
#include <Eigen/SVD>
#include <algorithm>

namespace stiff {

bool fit_rigid_motion(const Eigen::Matrix3Xd& x,
                      const Eigen::Matrix3Xd& y,
                      Eigen::Matrix3d* r,
                      Eigen::Vector3d* t) {
  if (x.cols() != y.cols() || x.cols() < 3) return false;
  const Eigen::Vector3d cx = x.rowwise().mean(), cy = y.rowwise().mean();
  const Eigen::Matrix3d h = (x.colwise() - cx) * (y.colwise() - cy).transpose();
  Eigen::JacobiSVD<Eigen::Matrix3d> svd(h, Eigen::ComputeFullU | Eigen::ComputeFullV);
  const Eigen::Vector3d sv = svd.singularValues();
  if (!(sv(1) > 1e-8 * std::max(sv(0), 1e-300))) return false;
  Eigen::Matrix3d d = Eigen::Matrix3d::Identity();
  d(2, 2) = (svd.matrixV() * svd.matrixU().transpose()).determinant() < 0 ? -1.0 : 1.0;
  *r = svd.matrixV() * d * svd.matrixU().transpose();
  *t = cy - *r * cx;
  return true;
}

}  // namespace stiff
