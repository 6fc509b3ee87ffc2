// One way to load a YAML file for every reader: nesting depth bounded before parsing, one
// document only, and no key twice in a mapping (yaml-cpp keeps both and a reader would see
// the first or the last depending on how it looks): each an error naming file:line:column.
#pragma once

#include <yaml-cpp/eventhandler.h>
#include <yaml-cpp/yaml.h>

#include <set>
#include <sstream>
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

/// Where each document of a stream starts; nothing else is kept.
class DocumentStarts final : public YAML::EventHandler {
 public:
  std::vector<YAML::Mark> starts;
  void OnDocumentStart(const YAML::Mark& mark) override { starts.push_back(mark); }
  void OnDocumentEnd() override {}
  void OnNull(const YAML::Mark&, YAML::anchor_t) override {}
  void OnAlias(const YAML::Mark&, YAML::anchor_t) override {}
  void OnScalar(const YAML::Mark&,
                const std::string&,
                YAML::anchor_t,
                const std::string&) override {}
  void OnSequenceStart(const YAML::Mark&,
                       const std::string&,
                       YAML::anchor_t,
                       YAML::EmitterStyle::value) override {}
  void OnSequenceEnd() override {}
  void OnMapStart(const YAML::Mark&,
                  const std::string&,
                  YAML::anchor_t,
                  YAML::EmitterStyle::value) override {}
  void OnMapEnd() override {}
};

/// The document of a YAML file (an empty file gives a null node).
inline YAML::Node load_yaml_document(const std::string& text, const std::string& file) {
  check_yaml_nesting(text, file);
  try {
    // Documents are counted with a bound, never collected with YAML::LoadAll: yaml-cpp 0.7
    // returns an endless stream of empty documents for a stray ',' at the top level.
    std::istringstream in(text);
    YAML::Parser parser(in);
    DocumentStarts counter;
    for (int n = 0; n < 2 && parser.HandleNextDocument(counter); ++n) {
    }
    if (counter.starts.size() > 1)
      throw yaml_error_at(file, counter.starts[1],
                          "a second YAML document ('---', or text after the end of the first); "
                          "the file must hold one");
    if (counter.starts.empty()) return YAML::Node();
    YAML::Node doc = YAML::Load(text);
    check_unique_keys(doc, file);
    return doc;
  } catch (const YAML::ParserException& e) {
    throw yaml_error_at(file, e.mark, e.msg);
  }
}

}  // namespace stiff::detail
