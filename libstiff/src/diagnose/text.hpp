// Number and list formatting of the diagnosis's messages (private to diagnose/).
#pragma once

#include <string>
#include <vector>

#include "io/number_text.hpp"

namespace stiff::diagnose_detail {

using detail::num;
inline std::string um(double m) { return num(m * 1e6, 3) + " um"; }
inline std::string mm(double m) { return num(m * 1e3, 3) + " mm"; }

inline std::string join(const std::vector<std::string>& v, const std::string& sep) {
  std::string s;
  for (const auto& x : v) s += (s.empty() ? "" : sep) + x;
  return s;
}

}  // namespace stiff::diagnose_detail
