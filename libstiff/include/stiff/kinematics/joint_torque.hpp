/// \file joint_torque.hpp
/// The statics of a revolute joint, written once for every layer (model, identification,
/// planning): the lever arm of a point about a joint axis and the joint torque of an external
/// wrench,
///   w = z x (L - o),   tau = w . F + z . M,
/// for the unit axis z through the origin o, the force F [N] at the point L [m] and the moment
/// M [N*m] (base frame). w is also the translational column of the geometric Jacobian at L, so
/// tau = J(L)^T (F, M) row by row. Arguments are anything indexable by 0..2 (Eigen vectors,
/// plain arrays, ceres::Jet or SIMD-lane values), so the hot loops keep their data layout.
#pragma once

namespace stiff {

/// out = z x (p - o): the lever arm of p about the axis z through o [m].
template <typename Z, typename O, typename P, typename Out>
inline void lever_arm(const Z& z, const O& o, const P& p, Out& out) {
  const auto a0 = p[0] - o[0], a1 = p[1] - o[1], a2 = p[2] - o[2];
  out[0] = z[1] * a2 - z[2] * a1;
  out[1] = z[2] * a0 - z[0] * a2;
  out[2] = z[0] * a1 - z[1] * a0;
}

/// w . F: the joint torque [N*m] of a pure force F applied with lever arm w (the planner's
/// loads carry no moment).
template <typename W, typename F>
inline auto force_torque(const W& w, const F& f) {
  return w[0] * f[0] + w[1] * f[1] + w[2] * f[2];
}

/// tau = w . F + z . M: the joint torque [N*m] of the force F applied with lever arm w and the
/// moment M, about the axis z.
template <typename W, typename Z, typename F, typename M>
inline auto joint_torque(const W& w, const Z& z, const F& f, const M& m) {
  return force_torque(w, f) + (z[0] * m[0] + z[1] * m[1] + z[2] * m[2]);
}

/// One lane l of structure-of-arrays data v[k][l] (k = 0..2), indexable like a 3-vector: lets
/// the batched loops (SIMD lanes, Jet derivative parts) call the functions above.
template <int L>
struct Lane {
  const double (*v)[L];
  int l;
  double operator[](int k) const { return v[k][l]; }
};

}  // namespace stiff
