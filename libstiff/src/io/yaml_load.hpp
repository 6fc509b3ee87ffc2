// One way to load a YAML file for every reader: nesting depth bounded before parsing, one
// document only, and no key twice in a mapping (yaml-cpp keeps both and a reader would see
// the first or the last depending on how it looks): each an error naming file:line:column.
#pragma once

#include <yaml-cpp/yaml.h>

#include <set>
#include <string>
#include <vector>

#include "stiff/error.hpp"
#include "stiff/io/text_io.hpp"

namespace stiff::detail {

inline ParseError yaml_error_at(const std::string& file,
                                const YAML::Mark& m,
                                const std::string& reason) {
  return ParseError(file, m.is_null() ? 0 : m.line + 1, m.is_null() ? 0 : m.column + 1, reason);
}

inline void check_unique_keys(const YAML::Node& node, const std::string& file) {
  if (node.IsMap()) {
    std::set<std::string> seen;
    for (const auto& kv : node) {
      if (kv.first.IsScalar() && !seen.insert(kv.first.Scalar()).second)
        throw yaml_error_at(file, kv.first.Mark(),
                            "key '" + kv.first.Scalar() + "' appears twice in the same mapping");
      check_unique_keys(kv.second, file);
    }
  } else if (node.IsSequence()) {
    for (const auto& item : node) check_unique_keys(item, file);
  }
}

/// The document of a YAML file (an empty file gives a null node).
inline YAML::Node load_yaml_document(const std::string& text, const std::string& file) {
  check_yaml_nesting(text, file);
  std::vector<YAML::Node> docs;
  try {
    docs = YAML::LoadAll(text);
  } catch (const YAML::ParserException& e) {
    throw yaml_error_at(file, e.mark, e.msg);
  }
  if (docs.size() > 1)
    throw yaml_error_at(file, docs[1].Mark(),
                        "a second YAML document ('---'); the file must hold one");
  if (docs.empty()) return YAML::Node();
  check_unique_keys(docs[0], file);
  return docs[0];
}

}  // namespace stiff::detail
