// Helpers of the FMI glue (glue_common.cpp): resource URIs, message formatting.
#pragma once

#include <cstdarg>
#include <cstdio>
#include <string>

namespace stiff::fmu {

/// FMI 2 resourceLocation URI -> native folder path. Accepts file:///p, file:/p,
/// file://localhost/p (RFC 8089) and percent-encoding; "" for anything else (e.g. http:).
inline std::string uri_to_path(const char* uri) {
  if (!uri) return "";
  std::string s(uri);
  std::string rest;
  if (s.rfind("file://localhost/", 0) == 0)
    rest = s.substr(16);
  else if (s.rfind("file:///", 0) == 0)
    rest = s.substr(7);
  else if (s.rfind("file:/", 0) == 0)
    rest = s.substr(5);
  else
    return "";
  std::string out;
  for (size_t i = 0; i < rest.size(); ++i) {
    if (rest[i] == '%' && i + 2 < rest.size()) {
      auto hex = [](char c) -> int {
        if (c >= '0' && c <= '9') return c - '0';
        if (c >= 'a' && c <= 'f') return c - 'a' + 10;
        if (c >= 'A' && c <= 'F') return c - 'A' + 10;
        return -1;
      };
      const int hi = hex(rest[i + 1]), lo = hex(rest[i + 2]);
      if (hi >= 0 && lo >= 0) {
        out += static_cast<char>(hi * 16 + lo);
        i += 2;
        continue;
      }
    }
    out += rest[i];
  }
  return out;
}

/// printf into a std::string.
inline std::string format(const char* fmt, ...) __attribute__((format(printf, 1, 2)));
inline std::string format(const char* fmt, ...) {
  char buf[1024];
  va_list ap;
  va_start(ap, fmt);
  std::vsnprintf(buf, sizeof buf, fmt, ap);
  va_end(ap);
  return buf;
}

}  // namespace stiff::fmu
