// XML text for the files stiff writes (URDF, the FMU's model description): one escaping rule
// (private to the core).
#pragma once

#include <string>

namespace stiff::detail {

/// An XML attribute value: the five markup characters as entities; tab, newline and carriage
/// return as character references (an attribute's literal ones are normalised to spaces on
/// reading); characters XML 1.0 cannot hold at all (other C0 controls) as '_'.
inline std::string xml_attribute(const std::string& s) {
  std::string o;
  for (const unsigned char c : s) {
    switch (c) {
      case '&':
        o += "&amp;";
        break;
      case '<':
        o += "&lt;";
        break;
      case '>':
        o += "&gt;";
        break;
      case '"':
        o += "&quot;";
        break;
      case '\'':
        o += "&apos;";
        break;
      case '\t':
        o += "&#9;";
        break;
      case '\n':
        o += "&#10;";
        break;
      case '\r':
        o += "&#13;";
        break;
      default:
        o += c < 0x20 ? '_' : static_cast<char>(c);
    }
  }
  return o;
}

}  // namespace stiff::detail
