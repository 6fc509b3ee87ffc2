// libFuzzer entry point; STIFF_FUZZ_TARGET names the function of fuzz_targets.hpp to call
// (tests/fuzz/CMakeLists.txt builds one program per target).
#include "fuzz_targets.hpp"

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  stiff::fuzz::STIFF_FUZZ_TARGET(data, size);
  return 0;
}
