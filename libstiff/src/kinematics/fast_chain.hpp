// Forward kinematics specialised once per robot, for the per-measurement loops of the
// identification (observation rows, measurement contexts). Equal to RobotModel::chain up to
// round-off. Internal header of libstiff.
#pragma once

#include <Eigen/Geometry>
#include <cmath>
#include <cstdint>
#include <cstring>
#include <vector>

#include "stiff/kinematics/robot_model.hpp"

namespace stiff::detail {

/// sin and cos of x for |x| < 1e5: reduction by pi/2 in three parts (exact there) and
/// minimax polynomials on [-pi/4, pi/4] (Cephes), within about one ulp. Branch-free, so that
/// a loop over many angles vectorises (libm's sincos is a call with branches).
inline void sincos_reduced(double x, double* s, double* c) {
  constexpr double kTwoOverPi = 6.36619772367581382433e-01;
  constexpr double kPio2_1 = 1.57079632673412561417e+00;  // pi/2 in parts of <= 33 bits
  constexpr double kPio2_2 = 6.07710050630396597660e-11;
  constexpr double kPio2_3 = 2.02226624871116645580e-21;
  constexpr double kRound = 6755399441055744.0;  // 1.5 * 2^52: adding it rounds to an integer
  const double t = x * kTwoOverPi + kRound;
  const double k = t - kRound;
  std::int64_t bits;  // k mod 4 in the low bits of t's mantissa
  std::memcpy(&bits, &t, sizeof bits);
  const std::int64_t q = bits & 3;
  const double r = ((x - k * kPio2_1) - k * kPio2_2) - k * kPio2_3;
  const double z = r * r;
  const double ps = ((((1.58962301576546568060e-10 * z - 2.50507477628578072866e-8) * z +
                       2.75573136213857245213e-6) *
                          z -
                      1.98412698295895385996e-4) *
                         z +
                     8.33333333332211858878e-3) *
                        z -
                    1.66666666666666307295e-1;
  const double pc = ((((-1.13585365213876817300e-11 * z + 2.08757008419747316778e-9) * z -
                       2.75573141792967388112e-7) *
                          z +
                      2.48015872888517045348e-5) *
                         z -
                     1.38888888888730564116e-3) *
                        z +
                    4.16666666666665929218e-2;
  const double sr = r + r * z * ps;
  const double cr = (1.0 - 0.5 * z) + z * z * pc;
  const double sv = (q & 1) ? cr : sr, cv = (q & 1) ? sr : cr;
  *s = (q & 2) ? -sv : sv;
  *c = ((q + 1) & 2) ? -cv : cv;
}

/// sincos_reduced of n angles (|x| < 1e5), a loop the compiler vectorises.
inline void sincos_lanes(const double* __restrict x,
                         double* __restrict s,
                         double* __restrict c,
                         int n) {
  for (int l = 0; l < n; ++l) sincos_reduced(x[l], &s[l], &c[l]);
}

/// sin and cos of any x (libm beyond 1e5).
inline void sincos_fast(double x, double* s, double* c) {
  if (std::abs(x) < 1e5) {
    sincos_reduced(x, s, c);
  } else {
    *s = std::sin(x);
    *c = std::cos(x);
  }
}

/// The joints' constant transforms as rotation + translation with identity / zero parts
/// skipped and unit joint axes applied as plane rotations; modified-DH joints as two plane
/// rotations and one translation.
class FastChain {
 public:
  static constexpr int kLanes = 8;  ///< configurations per batch()

  explicit FastChain(const RobotModel& robot) {
    for (const auto& j : robot.joints) {
      Step s;
      s.pre = rigid(j.pre);
      s.post = rigid(j.post);
      s.axis = j.axis;
      s.unit = -1;
      for (int k = 0; k < 3; ++k) {
        Eigen::Vector3d e = Eigen::Vector3d::Zero();
        e(k) = 1.0;
        if (j.axis == e) s.unit = k, s.sign = 1.0;
        if (j.axis == -e) s.unit = k, s.sign = -1.0;
      }
      // A modified-DH joint (Craig: RotX(alpha) TransX(a) TransZ(d) RotZ(offset + q)) is applied
      // as two plane rotations and one translation; cos/sin of alpha snapped to 0 / +-1 when
      // they are round-off of a multiple of 90 degrees.
      const Joint dh = modified_dh_joint(j.dh[0], j.dh[1], j.dh[2], j.dh[3]);
      if (j.axis == Eigen::Vector3d::UnitZ() && s.post.r_identity && s.post.p_zero &&
          dh.pre == j.pre) {
        s.dh = true;
        s.ca = std::cos(j.dh[0]);
        s.sa = std::sin(j.dh[0]);
        if (std::abs(s.ca) < 1e-15) s.ca = 0.0, s.sa = s.sa > 0 ? 1.0 : -1.0;
        if (std::abs(s.sa) < 1e-15) s.sa = 0.0, s.ca = s.ca > 0 ? 1.0 : -1.0;
        s.a = j.dh[1];
        s.d = j.dh[2];
        s.offset = j.dh[3];
      }
      all_dh_ = all_dh_ && s.dh;
      steps_.push_back(s);
    }
  }

  /// Every joint is a modified-DH joint (batch() applies).
  bool all_dh() const { return all_dh_; }
  /// Angle offset of DH joint j (the rotation is about q_j + offset).
  double offset(int j) const { return steps_[j].offset; }

  /// z (3 x n) axes, o (3 x n) points on them, flange rotation and position; with `links`,
  /// the pose of every link frame (rotation and position, n entries).
  void operator()(const Eigen::VectorXd& q,
                  Eigen::Matrix3Xd& z,
                  Eigen::Matrix3Xd& o,
                  Eigen::Matrix3d& r,
                  Eigen::Vector3d& p,
                  Eigen::Matrix4d* links = nullptr) const {
    r.setIdentity();
    p.setZero();
    for (size_t i = 0; i < steps_.size(); ++i) {
      const Step& s = steps_[i];
      if (s.dh) {
        // r <- r RotX(alpha)
        if (s.sa != 0.0 || s.ca != 1.0) {
          const Eigen::Vector3d c1 = r.col(1), c2 = r.col(2);
          if (s.ca == 0.0) {
            r.col(1) = c2 * s.sa;
            r.col(2) = c1 * -s.sa;
          } else {
            r.col(1) = c1 * s.ca + c2 * s.sa;
            r.col(2) = c2 * s.ca - c1 * s.sa;
          }
        }
        if (s.a != 0.0) p += r.col(0) * s.a;
        if (s.d != 0.0) p += r.col(2) * s.d;
        o.col(i) = p;
        z.col(i) = r.col(2);
        rotate(r, 2, s.offset == 0.0 ? q(i) : q(i) + s.offset, 1.0);
      } else {
        apply(s.pre, r, p);
        o.col(i) = p;
        if (s.unit >= 0) {
          z.col(i) = s.sign * r.col(s.unit);
          rotate(r, s.unit, q(i), s.sign);
        } else {
          z.col(i) = r * s.axis;
          const Eigen::Matrix3d rot = Eigen::AngleAxisd(q(i), s.axis).toRotationMatrix();
          r = (r * rot).eval();
        }
        apply(s.post, r, p);
      }
      if (links) {
        links[i].setIdentity();
        links[i].topLeftCorner<3, 3>() = r;
        links[i].topRightCorner<3, 1>() = p;
      }
    }
  }

  /// Forward kinematics of kLanes configurations of an all-DH chain at once, one lane each,
  /// from c[j][lane], s[j][lane] = cos, sin of q_j + offset(j): axes z[j][k][lane], points
  /// o[j][k][lane], flange rotation r[row][col][lane] and position p[k][lane]. The loops over
  /// the lanes vectorise.
  void batch(const double (*c)[kLanes],
             const double (*s)[kLanes],
             double (*z)[3][kLanes],
             double (*o)[3][kLanes],
             double (*r)[3][kLanes],
             double (*p)[kLanes]) const {
    for (int a = 0; a < 3; ++a)
      for (int b = 0; b < 3; ++b)
        for (int l = 0; l < kLanes; ++l) r[a][b][l] = a == b ? 1.0 : 0.0;
    for (int a = 0; a < 3; ++a)
      for (int l = 0; l < kLanes; ++l) p[a][l] = 0.0;
    for (size_t i = 0; i < steps_.size(); ++i) {
      const Step& st = steps_[i];
      for (int a = 0; a < 3; ++a) {
        double* r1 = r[a][1];
        double* r2 = r[a][2];
        if (st.sa != 0.0 || st.ca != 1.0) {
          if (st.ca == 0.0) {
            for (int l = 0; l < kLanes; ++l) {
              const double c1 = r1[l], c2 = r2[l];
              r1[l] = c2 * st.sa;
              r2[l] = c1 * -st.sa;
            }
          } else {
            for (int l = 0; l < kLanes; ++l) {
              const double c1 = r1[l], c2 = r2[l];
              r1[l] = c1 * st.ca + c2 * st.sa;
              r2[l] = c2 * st.ca - c1 * st.sa;
            }
          }
        }
        if (st.a != 0.0)
          for (int l = 0; l < kLanes; ++l) p[a][l] += r[a][0][l] * st.a;
        if (st.d != 0.0)
          for (int l = 0; l < kLanes; ++l) p[a][l] += r[a][2][l] * st.d;
        for (int l = 0; l < kLanes; ++l) {
          o[i][a][l] = p[a][l];
          z[i][a][l] = r[a][2][l];
        }
        // r <- r RotZ(q + offset)
        double* r0 = r[a][0];
        for (int l = 0; l < kLanes; ++l) {
          const double c0 = r0[l], c1 = r1[l];
          r0[l] = c0 * c[i][l] + c1 * s[i][l];
          r1[l] = c1 * c[i][l] - c0 * s[i][l];
        }
      }
    }
  }

 private:
  struct Rigid {
    Eigen::Matrix3d r;
    Eigen::Vector3d p;
    bool r_identity;
    bool p_zero;
  };
  struct Step {
    Rigid pre, post;
    Eigen::Vector3d axis;
    int unit;  ///< axis = sign * e_unit, or -1 for a general axis
    double sign = 1.0;
    bool dh = false;  ///< modified DH joint: the fields below
    double ca = 1, sa = 0, a = 0, d = 0, offset = 0;
  };
  /// r <- r Rot(sign e_unit, angle)
  static void rotate(Eigen::Matrix3d& r, int unit, double angle, double sign) {
    double c, sn;
    sincos_fast(angle, &sn, &c);
    sn *= sign;
    const int a = (unit + 1) % 3, b = (unit + 2) % 3;
    const Eigen::Vector3d ca = r.col(a), cb = r.col(b);
    r.col(a) = ca * c + cb * sn;
    r.col(b) = cb * c - ca * sn;
  }
  static Rigid rigid(const Eigen::Matrix4d& t) {
    Rigid g;
    g.r = t.block<3, 3>(0, 0);
    g.p = t.block<3, 1>(0, 3);
    g.r_identity = g.r == Eigen::Matrix3d::Identity();
    g.p_zero = g.p.isZero(0.0);
    return g;
  }
  /// (r, p) <- (r, p) * g
  static void apply(const Rigid& g, Eigen::Matrix3d& r, Eigen::Vector3d& p) {
    if (!g.p_zero) {
      Eigen::Vector3d dp = Eigen::Vector3d::Zero();
      for (int k = 0; k < 3; ++k)
        if (g.p(k) != 0.0) dp += r.col(k) * g.p(k);
      p += dp;
    }
    if (!g.r_identity) r = (r * g.r).eval();
  }
  std::vector<Step> steps_;
  bool all_dh_ = true;
};

}  // namespace stiff::detail
