// The library never prints (stiff.h), also when Ceres gives up: Ceres 2.1 logs through glog
// to stderr unconditionally in a few places ("Terminating: ..." when the trust-region minimizer
// fails, "Error in evaluating the ResidualBlock" for a non-finite residual), whatever
// logging_type says. These tests capture the process's stderr file descriptor (fd 2, where
// glog writes) around identifications made to fail in those ways.
#include <gtest/gtest.h>
#include <unistd.h>

#include <cstdio>
#include <string>

#include "stiff/error.hpp"
#include "stiff/identify/identify.hpp"
#include "stiff/sim/simulate.hpp"
#include "stiff/stiff.h"
#include "test_support.hpp"

namespace stiff {
namespace {

/// Redirects fd 2 (and fd 1) to temporary files for its lifetime; text() returns what was
/// written to fd 2.
class CaptureFds {
 public:
  CaptureFds() {
    std::fflush(nullptr);
    for (int i = 0; i < 2; ++i) {
      file_[i] = std::tmpfile();
      saved_[i] = dup(i + 1);
      dup2(fileno(file_[i]), i + 1);
    }
  }
  ~CaptureFds() { restore(); }
  /// Restore fd 1 and 2 and return what was written to stderr and stdout.
  std::string text() {
    restore();
    std::string all;
    for (int i = 1; i >= 0; --i) {
      std::rewind(file_[i]);
      char buf[4096];
      size_t n;
      while ((n = std::fread(buf, 1, sizeof buf, file_[i])) > 0) all.append(buf, n);
    }
    return all;
  }

 private:
  void restore() {
    if (restored_) return;
    std::fflush(nullptr);
    for (int i = 0; i < 2; ++i) {
      dup2(saved_[i], i + 1);
      close(saved_[i]);
    }
    restored_ = true;
  }
  std::FILE* file_[2] = {nullptr, nullptr};
  int saved_[2] = {-1, -1};
  bool restored_ = false;
};

TEST(QuietSolver, CaptureSeesWritesToFd2) {
  CaptureFds cap;
  const char msg[] = "written to fd 2\n";
  ASSERT_EQ(write(2, msg, sizeof msg - 1), static_cast<ssize_t>(sizeof msg - 1));
  EXPECT_EQ(cap.text(), msg);
}

Dataset simulated() {
  NoiseModel noise;
  noise.tracker_sigma_m = 10e-6;
  noise.seed = 11;
  return simulate(test::rokae(), joint_truth(test::paper_stiffness()), test::paper_design_a(),
                  noise);
}

/// identify() under capture: returns what was printed; `status` gets "ok" or the error.
std::string identify_quietly(const Dataset& data,
                             const std::vector<std::string>& model,
                             const IdentifyOptions& opt,
                             std::string* status) {
  CaptureFds cap;
  try {
    const FitResult f = identify(test::rokae(), data, model, opt);
    *status = "ok";
    for (const auto& w : f.warnings) *status += "; " + w;
  } catch (const Error& e) {
    *status = e.what();
  }
  return cap.text();
}

// One measurement 1e308 m off: the start's Jacobian is finite, its residual (divided by the
// noise) is not. Ceres printed "Error in evaluating the ResidualBlock ..." and "Terminating:
// Residual and Jacobian evaluation failed."
TEST(QuietSolver, NonFiniteResidualAtTheStartIsAnErrorAndPrintsNothing) {
  for (const char* loss : {"none", "huber"}) {
    Dataset d = simulated();
    d.rows[3].displacement.y() = -1e308;
    IdentifyOptions o;
    o.loss = loss;
    std::string status;
    EXPECT_EQ(identify_quietly(d, {"joint", "link"}, o, &status), "") << loss << ": " << status;
    EXPECT_NE(status.find("units"), std::string::npos) << status;
  }
}

// The minimizer stopped by the iteration limit or cancelled by the progress callback.
TEST(QuietSolver, SolverStoppedEarlyPrintsNothing) {
  const Dataset d = simulated();
  IdentifyOptions o;
  o.max_iterations = 1;
  std::string status;
  EXPECT_EQ(identify_quietly(d, {"joint", "link"}, o, &status), "") << status;
  o.max_iterations = 50;
  o.progress = [](int, double) { return false; };
  EXPECT_EQ(identify_quietly(d, {"joint", "link"}, o, &status), "") << status;
  EXPECT_NE(status.find("cancelled"), std::string::npos) << status;
}

// Absurd but finite data through the C ABI (the fuzz target's path), every loss.
TEST(QuietSolver, AbsurdDataThroughTheCApiPrintsNothing) {
  stiff_robot* robot = nullptr;
  ASSERT_EQ(stiff_robot_load(&robot, test::source_path("examples/robots/rokae.yaml").c_str()),
            STIFF_OK);
  const double q[18] = {0.4,  0.3,  0.2, 0.1, 0.5, 0.0, 0.0,  0.0, 0.0,
                        -0.5, -0.5, 0.5, 0.1, 0.8, 0.4, -0.3, 1.0, 0.2};
  const double f[9] = {40, 50, 50, 50, 50, 50, 50, 50, 50};
  for (double big : {1e308, 1e200, 1e150, 1e30}) {
    for (const char* loss : {"none", "huber", "cauchy", "soft_l1", "tukey"}) {
      const double m[9] = {5e-324, -0.4, -0.5, 0, 5, 5, 5, 4.9, 5};
      const double d[9] = {-1.6e-5, -big, 0, -1.4e-5, -9.2e-5, 1e-16, 1.3e-5, 2e-5, -3e-5};
      stiff_dataset* ds = nullptr;
      ASSERT_EQ(stiff_dataset_create(&ds, 3, 6, q, f, m, d, nullptr), STIFF_OK);
      stiff_identify_options o = STIFF_IDENTIFY_OPTIONS_INIT;
      o.model = "joint+link";
      o.loss = loss;
      o.max_iterations = 5;
      stiff_result* fit = nullptr;
      CaptureFds cap;
      const stiff_status s = stiff_identify(&fit, robot, ds, &o);
      const std::string printed = cap.text();
      EXPECT_EQ(printed, "") << big << " " << loss << ": " << stiff_status_name(s) << " "
                             << (s == STIFF_OK ? "" : stiff_last_error());
      stiff_result_destroy(fit);
      stiff_dataset_destroy(ds);
    }
  }
  stiff_robot_destroy(robot);
}

}  // namespace
}  // namespace stiff
