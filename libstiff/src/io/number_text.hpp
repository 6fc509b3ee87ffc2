/// \file number_text.hpp
/// Numbers as text, one way for the whole library: short ones in messages, exact ones in files.
#pragma once

#include <cmath>
#include <cstdio>
#include <string>

namespace stiff::detail {

/// `v` with `digits` significant digits (printf %g): messages and reports; "nan" for any NaN.
inline std::string num(double v, int digits = 3) {
  if (std::isnan(v)) return "nan";
  char b[64];
  std::snprintf(b, sizeof b, "%.*g", digits, v);
  return b;
}

/// `v` with 17 significant digits, which read back to the same double: values written to files.
inline std::string exact(double v) { return num(v, 17); }

}  // namespace stiff::detail
