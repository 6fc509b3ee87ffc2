// Distribution tails for the diagnosis (diagnose.hpp, namespace stats): regularised incomplete
// gamma and beta functions by series and Lentz continued fractions (Numerical Recipes 6.2,
// 6.4; Abramowitz & Stegun 6.5, 26.5), with log forms that do not underflow in the far tail.
#include <algorithm>
#include <cmath>
#include <limits>
#include <numeric>
#include <utility>

#include "stiff/diagnose/diagnose.hpp"
#include "stiff/error.hpp"

namespace stiff::stats {
namespace {

constexpr int kMaxIter = 100000;
constexpr double kEps = 1e-15;
constexpr double kTiny = 1e-300;

/// Series of P(a, x) without its prefactor: sum_n x^n / (a (a+1) ... (a+n)).
double gamma_series(double a, double x) {
  double ap = a, del = 1.0 / a, sum = del;
  for (int n = 0; n < kMaxIter; ++n) {
    ap += 1.0;
    del *= x / ap;
    sum += del;
    if (std::abs(del) < std::abs(sum) * kEps) break;
  }
  return sum;
}

/// a_1 / (b_1 + a_2 / (b_2 + a_3 / (b_3 + ...))) by the modified Lentz method (Numerical
/// Recipes 5.2), term(i) = (a_i, b_i) for i = 1, 2, ...; stops when a term changes the value by
/// less than kEps relative.
template <typename Term>
double continued_fraction(Term term) {
  double f = kTiny, c = f, d = 0.0;
  for (int i = 1; i < 2 * kMaxIter; ++i) {
    const auto [a, b] = term(i);
    d = b + a * d;
    if (std::abs(d) < kTiny) d = kTiny;
    c = b + a / c;
    if (std::abs(c) < kTiny) c = kTiny;
    d = 1.0 / d;
    const double del = c * d;
    f *= del;
    if (std::abs(del - 1.0) < kEps) break;
  }
  return f;
}

/// Continued fraction of Q(a, x) without its prefactor (A&S 6.5.31):
/// 1 / (x+1-a - 1(1-a) / (x+3-a - 2(2-a) / (x+5-a - ...))).
double gamma_cf(double a, double x) {
  return continued_fraction([&](int i) {
    const double k = i - 1;
    return std::pair<double, double>{i == 1 ? 1.0 : -k * (k - a), x + 2.0 * k + 1.0 - a};
  });
}

/// log of x^a e^-x / Gamma(a).
double gamma_log_prefactor(double a, double x) { return -x + a * std::log(x) - std::lgamma(a); }

void check_gamma(double a, double x) {
  if (!(a > 0) || !(x >= 0) || std::isnan(x))
    throw InvalidArgument("incomplete gamma: needs a > 0 and x >= 0");
}

/// Continued fraction of I_x(a, b) (A&S 26.5.8): 1 / (1 + d_1 / (1 + d_2 / (1 + ...))) with
/// d_2m = m (b-m) x / ((a+2m-1)(a+2m)), d_2m+1 = -(a+m)(a+b+m) x / ((a+2m)(a+2m+1)).
double beta_cf(double a, double b, double x) {
  return continued_fraction([&](int i) {
    if (i == 1) return std::pair<double, double>{1.0, 1.0};
    const int k = i - 1, m = k / 2;
    const double dk = (k % 2 == 0) ? m * (b - m) * x / ((a + 2 * m - 1) * (a + 2 * m))
                                   : -(a + m) * (a + b + m) * x / ((a + 2 * m) * (a + 2 * m + 1));
    return std::pair<double, double>{dk, 1.0};
  });
}

/// log of x^a (1-x)^b / B(a, b).
double beta_log_prefactor(double a, double b, double x) {
  return std::lgamma(a + b) - std::lgamma(a) - std::lgamma(b) + a * std::log(x) +
         b * std::log1p(-x);
}

void check_beta(double a, double b, double x) {
  if (!(a > 0) || !(b > 0) || !(x >= 0 && x <= 1))
    throw InvalidArgument("incomplete beta: needs a, b > 0 and 0 <= x <= 1");
}

}  // namespace

double gamma_p(double a, double x) {
  check_gamma(a, x);
  if (x == 0) return 0.0;
  if (x < a + 1.0) return std::exp(gamma_log_prefactor(a, x)) * gamma_series(a, x);
  return 1.0 - std::exp(gamma_log_prefactor(a, x)) * gamma_cf(a, x);
}

double gamma_q(double a, double x) {
  check_gamma(a, x);
  if (x == 0) return 1.0;
  if (x < a + 1.0) return 1.0 - std::exp(gamma_log_prefactor(a, x)) * gamma_series(a, x);
  return std::exp(gamma_log_prefactor(a, x)) * gamma_cf(a, x);
}

double log_gamma_q(double a, double x) {
  check_gamma(a, x);
  if (x == 0) return 0.0;
  if (std::isinf(x)) return -std::numeric_limits<double>::infinity();
  if (x < a + 1.0) return std::log1p(-std::exp(gamma_log_prefactor(a, x)) * gamma_series(a, x));
  return gamma_log_prefactor(a, x) + std::log(gamma_cf(a, x));
}

double beta_i(double a, double b, double x) {
  check_beta(a, b, x);
  if (x == 0 || x == 1) return x;
  const double bt = std::exp(beta_log_prefactor(a, b, x));
  if (x < (a + 1.0) / (a + b + 2.0)) return bt * beta_cf(a, b, x) / a;
  return 1.0 - bt * beta_cf(b, a, 1.0 - x) / b;
}

double log_beta_i(double a, double b, double x) {
  check_beta(a, b, x);
  if (x == 0) return -std::numeric_limits<double>::infinity();
  if (x == 1) return 0.0;
  if (x < (a + 1.0) / (a + b + 2.0))
    return beta_log_prefactor(a, b, x) + std::log(beta_cf(a, b, x) / a);
  return std::log1p(-std::exp(beta_log_prefactor(a, b, x)) * beta_cf(b, a, 1.0 - x) / b);
}

double chi2_sf(double x, double k) {
  if (!(k > 0)) throw InvalidArgument("chi2: degrees of freedom must be > 0");
  return x <= 0 ? 1.0 : gamma_q(0.5 * k, 0.5 * x);
}

double log_chi2_sf(double x, double k) {
  if (!(k > 0)) throw InvalidArgument("chi2: degrees of freedom must be > 0");
  return x <= 0 ? 0.0 : log_gamma_q(0.5 * k, 0.5 * x);
}

double f_sf(double f, double d1, double d2) {
  if (!(d1 > 0 && d2 > 0)) throw InvalidArgument("F: degrees of freedom must be > 0");
  if (!(f > 0)) return 1.0;
  if (std::isinf(f)) return 0.0;
  return beta_i(0.5 * d2, 0.5 * d1, d2 / (d2 + d1 * f));
}

double log_f_sf(double f, double d1, double d2) {
  if (!(d1 > 0 && d2 > 0)) throw InvalidArgument("F: degrees of freedom must be > 0");
  if (!(f > 0)) return 0.0;
  if (std::isinf(f)) return -std::numeric_limits<double>::infinity();
  return log_beta_i(0.5 * d2, 0.5 * d1, d2 / (d2 + d1 * f));
}

std::vector<double> holm_adjust(const std::vector<double>& log_p) {
  const size_t m = log_p.size();
  std::vector<size_t> order(m);
  std::iota(order.begin(), order.end(), size_t{0});
  std::stable_sort(order.begin(), order.end(),
                   [&](size_t a, size_t b) { return log_p[a] < log_p[b]; });
  std::vector<double> out(m, 1.0);
  double running = -std::numeric_limits<double>::infinity();
  for (size_t i = 0; i < m; ++i) {
    const double adj = std::min(0.0, std::log(static_cast<double>(m - i)) + log_p[order[i]]);
    running = std::max(running, adj);
    out[order[i]] = std::exp(running);
  }
  return out;
}

}  // namespace stiff::stats
