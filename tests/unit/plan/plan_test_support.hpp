// Shared by the planning tests: the pool of the paper's set-up (q6 held at 0).
#pragma once

#include <limits>

#include "stiff/plan/plan.hpp"

namespace stiff::test {

inline PoolOptions paper_pool(int poses, int loads, uint64_t seed = 1) {
  const double free = std::numeric_limits<double>::quiet_NaN();
  PoolOptions o;
  o.pose_count = poses;
  o.load_count = loads;
  o.q_fixed = {free, free, free, free, free, 0.0};
  o.seed = seed;
  return o;
}

}  // namespace stiff::test
