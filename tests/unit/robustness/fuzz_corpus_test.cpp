// Replays every fuzz corpus file (seeds and crash regressions, tests/fuzz/corpus/<target>/)
// through the normal, non-fuzz build of the readers and the C ABI with the fuzzers' oracle
// (tests/fuzz/fuzz_targets.hpp): a regression fails `make test` without clang.
#include <gtest/gtest.h>

#include <filesystem>
#include <fstream>
#include <functional>
#include <map>
#include <sstream>

#include "../../fuzz/fuzz_targets.hpp"

namespace fs = std::filesystem;

namespace {

using Target = std::function<void(const uint8_t*, size_t)>;

const std::map<std::string, Target>& targets() {
  static const std::map<std::string, Target> t = {
      {"measurements_csv", stiff::fuzz::measurements_csv},
      {"robot_yaml", stiff::fuzz::robot_yaml},
      {"robot_urdf", stiff::fuzz::robot_urdf},
      {"fit_json", stiff::fuzz::fit_json},
      {"truth_yaml", stiff::fuzz::truth_yaml},
      {"noise_yaml", stiff::fuzz::noise_yaml},
      {"capi_arrays", stiff::fuzz::capi_arrays},
#ifdef STIFF_FUZZ_HAVE_PATH_IO
      {"path_csv", stiff::fuzz::path_csv},
      {"gcode", stiff::fuzz::gcode},
#endif
  };
  return t;
}

std::string slurp(const fs::path& p) {
  std::ifstream in(p, std::ios::binary);
  std::ostringstream s;
  s << in.rdbuf();
  return s.str();
}

class FuzzCorpus : public ::testing::TestWithParam<std::string> {};

TEST_P(FuzzCorpus, EveryInputGivesAResultOrAClearError) {
  const fs::path dir = fs::path(STIFF_SOURCE_DIR) / "tests/fuzz/corpus" / GetParam();
  ASSERT_TRUE(fs::is_directory(dir)) << dir;
  const Target& run = targets().at(GetParam());
  int files = 0;
  for (const auto& entry : fs::directory_iterator(dir)) {
    if (!entry.is_regular_file()) continue;
    SCOPED_TRACE(entry.path().string());
    const std::string bytes = slurp(entry.path());
    // The oracle aborts on a finding; gtest's death would name the file via the trace.
    run(reinterpret_cast<const uint8_t*>(bytes.data()), bytes.size());
    ++files;
  }
  EXPECT_GT(files, 0) << "empty corpus " << dir;
}

std::vector<std::string> names() {
  std::vector<std::string> n;
  for (const auto& [k, v] : targets()) n.push_back(k);
  return n;
}

INSTANTIATE_TEST_SUITE_P(AllTargets,
                         FuzzCorpus,
                         ::testing::ValuesIn(names()),
                         [](const ::testing::TestParamInfo<std::string>& p) { return p.param; });

// Every target built by tests/fuzz has a corpus here, and every corpus a target.
TEST(FuzzCorpusLayout, EveryCorpusDirectoryHasATarget) {
  for (const auto& entry : fs::directory_iterator(fs::path(STIFF_SOURCE_DIR) / "tests/fuzz/corpus"))
    EXPECT_TRUE(targets().count(entry.path().filename().string()))
        << "corpus without a replay target: " << entry.path();
}

}  // namespace
