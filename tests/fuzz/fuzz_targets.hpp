// One function per fuzz target: feed bytes to a reader (or the C ABI) and abort on anything but
// a clean result or a clean error. Shared by the libFuzzer programs (tests/fuzz/*_fuzz.cpp) and
// the corpus replay gtest (tests/unit/robustness/fuzz_corpus_test.cpp), so that every corpus
// file, including crash regressions, is checked by `make test` without clang.
//
// The oracle: readers throw only stiff::Error (ParseError, InvalidArgument, ...) with a
// non-empty message; the C ABI returns STIFF_OK or a negative status other than
// STIFF_E_INTERNAL with a non-empty stiff_last_error(); a successful result holds no NaN.
// Anything else (another exception type, a sanitizer report, a NaN) is a finding.
#pragma once

#include <cmath>
#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <exception>
#include <string>
#include <vector>

#include "stiff/error.hpp"
#include "stiff/identify/fit.hpp"
#include "stiff/io/dataset.hpp"
#include "stiff/io/robot_io.hpp"
#include "stiff/sim/simulate.hpp"
#include "stiff/stiff.h"
#if __has_include(<glog/logging.h>)
#include <glog/logging.h>  // Ceres logs through glog: a log line is a finding (never print)
#define STIFF_FUZZ_HAVE_GLOG 1
#endif
#if __has_include("stiff/io/path_io.hpp")
#include "stiff/io/path_io.hpp"
#define STIFF_FUZZ_HAVE_PATH_IO 1
#endif

#ifndef STIFF_SOURCE_DIR
#error "STIFF_SOURCE_DIR must be defined (the repository root)"
#endif

namespace stiff::fuzz {

/// Report a finding and abort (libFuzzer then saves the input as crash-*).
[[noreturn]] inline void finding(const char* target, const std::string& what) {
  std::fprintf(stderr, "stiff fuzz finding in %s: %s\n", target, what.c_str());
  std::abort();
}

/// Run `body` on the text; stiff::Error is the expected failure, anything else a finding.
template <typename Body>
void expect_clean(const char* target, Body&& body) {
  try {
    body();
  } catch (const stiff::Error& e) {
    if (std::string(e.what()).empty()) finding(target, "stiff::Error with an empty message");
  } catch (const std::exception& e) {
    finding(target, std::string("non-stiff exception escaped: ") + e.what());
  } catch (...) {
    finding(target, "unknown exception escaped");
  }
}

/// Run `body`, which must not fail at all: any exception is a finding (e.g. a writer whose
/// output its own reader rejects loses data).
template <typename Body>
void must_succeed(const char* target, const char* what, Body&& body) {
  try {
    body();
  } catch (const std::exception& e) {
    finding(target, std::string(what) + ": " + e.what());
  } catch (...) {
    finding(target, std::string(what) + ": unknown exception");
  }
}

inline std::string text_of(const uint8_t* data, size_t size) {
  return std::string(reinterpret_cast<const char*>(data), size);
}

inline const RobotModel& rokae() {
  static const RobotModel robot =
      load_robot(std::string(STIFF_SOURCE_DIR) + "/examples/robots/rokae.yaml");
  return robot;
}

inline void measurements_csv(const uint8_t* data, size_t size) {
  const std::string text = text_of(data, size);
  for (int dof : {0, 6}) {
    Dataset d;
    bool ok = false;
    expect_clean("measurements_csv", [&] {
      d = parse_measurements_csv(text, "fuzz.csv", dof);
      ok = true;
    });
    if (!ok) continue;
    if (dof != 0 && d.dof != dof) finding("measurements_csv", "dof not honoured");
    // What was read must be written and read back whole (writers never lose data).
    must_succeed("measurements_csv", "round trip", [&] {
      const std::string out = format_measurements_csv(d);
      Dataset again = parse_measurements_csv(out, "roundtrip.csv", d.dof);
      if (again.size() != d.size()) finding("measurements_csv", "round trip changed row count");
      if (again.extra_columns != d.extra_columns || again.metadata.size() != d.metadata.size())
        finding("measurements_csv", "round trip lost columns or metadata");
    });
    expect_clean("measurements_csv", [&] { validate_dataset(d, d.dof, d.has_displacement); });
  }
}

inline void robot_yaml(const uint8_t* data, size_t size) {
  RobotModel r;
  bool ok = false;
  expect_clean("robot_yaml", [&] {
    r = parse_robot_yaml(text_of(data, size), "fuzz.yaml");
    ok = true;
  });
  if (!ok) return;
  must_succeed("robot_yaml", "round trip", [&] {
    RobotModel again = parse_robot_yaml(robot_to_yaml(r), "roundtrip.yaml");
    if (again.dof() != r.dof()) finding("robot_yaml", "round trip changed dof");
  });
  if (r.dof() > 0 && r.dof() <= stiff::kMaxJoints)
    must_succeed("robot_yaml", "kinematics", [&] {
      const Eigen::VectorXd q = Eigen::VectorXd::Zero(r.dof());
      (void)r.tool_pose(q);
      (void)r.jacobian(q);
    });
}

inline void robot_urdf(const uint8_t* data, size_t size) {
  expect_clean("robot_urdf", [&] {
    RobotModel r = parse_robot_urdf(text_of(data, size), "fuzz.urdf");
    (void)robot_to_yaml(r);
    if (r.dof() > 0 && r.dof() <= stiff::kMaxJoints)
      (void)r.tool_pose(Eigen::VectorXd::Zero(r.dof()));
  });
}

inline void fit_json(const uint8_t* data, size_t size) {
  FitResult f;
  bool ok = false;
  expect_clean("fit_json", [&] {
    f = fit_from_json(text_of(data, size), "fuzz.json");
    ok = true;
  });
  if (!ok) return;
  must_succeed("fit_json", "round trip", [&] {
    FitResult again = fit_from_json(fit_to_json(f), "roundtrip.json");
    if (again.parameters.size() != f.parameters.size())
      finding("fit_json", "round trip changed parameter count");
    (void)f.theta();
  });
}

inline void truth_yaml(const uint8_t* data, size_t size) {
  expect_clean("truth_yaml", [&] {
    Truth t = parse_truth_yaml(text_of(data, size), "fuzz_truth.yaml", rokae());
    if (!t.theta.allFinite()) finding("truth_yaml", "non-finite parameter accepted");
  });
}

inline void noise_yaml(const uint8_t* data, size_t size) {
  expect_clean("noise_yaml", [&] {
    NoiseModel n = parse_noise_yaml(text_of(data, size), "fuzz_noise.yaml");
    if (!std::isfinite(n.tracker_sigma_m) || !std::isfinite(n.outlier_rate))
      finding("noise_yaml", "non-finite noise accepted");
    (void)n.tracker_sigma_at(Eigen::Vector3d(0.5, 0.1, 0.3));
  });
}

#ifdef STIFF_FUZZ_HAVE_PATH_IO
inline void path_csv(const uint8_t* data, size_t size) {
  expect_clean("path_csv", [&] {
    ToolPath p = parse_path_csv(text_of(data, size), "fuzz_path.csv");
    for (const auto& pt : p.points)
      if (!pt.pose.allFinite() || !pt.wrench.allFinite())
        finding("path_csv", "non-finite pose or wrench accepted");
  });
}

inline void gcode(const uint8_t* data, size_t size) {
  PathOptions o;
  o.segment_m = 0.01;
  expect_clean("gcode", [&] {
    ToolPath p = parse_gcode(text_of(data, size), "fuzz.nc", o);
    for (const auto& pt : p.points)
      if (!pt.pose.allFinite()) finding("gcode", "non-finite pose accepted");
  });
}
#endif

// ------------------------------------------------------------------ C ABI with fuzzed arrays

#ifdef STIFF_FUZZ_HAVE_GLOG
/// Sees every glog line (Ceres's "Terminating: ..."); glog also writes it to stderr, where a
/// host application would see it.
class GlogWatch : public google::LogSink {
 public:
  GlogWatch() { google::AddLogSink(this); }
  using google::LogSink::send;
  void send(google::LogSeverity,
            const char*,
            const char* base_filename,
            int line,
            const google::LogMessageTime&,
            const char* message,
            size_t message_len) override {
    if (first.empty())
      first = std::string(base_filename) + ":" + std::to_string(line) + ": " +
              std::string(message, message_len);
  }
  std::string first;
};

/// Installed once and never removed (glog may be torn down before static destructors run).
inline GlogWatch& glog_watch() {
  static GlogWatch* watch = new GlogWatch;
  return *watch;
}
#endif

/// Fails if a dependency logged (glog) while `body` ran: the library never prints.
template <typename Body>
void must_not_log(const char* target, Body&& body) {
#ifdef STIFF_FUZZ_HAVE_GLOG
  GlogWatch& watch = glog_watch();
  watch.first.clear();
  body();
  if (!watch.first.empty()) finding(target, "a dependency printed: " + watch.first);
#else
  body();
#endif
}

/// Check a C ABI status: OK, or a documented negative code with a message.
inline bool capi_ok(stiff_status s, const char* call) {
  if (s == STIFF_OK) return true;
  if (s == STIFF_E_INTERNAL)
    finding("capi", std::string(call) + " returned STIFF_E_INTERNAL: " + stiff_last_error());
  if (s > 0 || s < STIFF_E_INTERNAL)
    finding("capi", std::string(call) + " returned an undocumented status");
  if (!*stiff_last_error()) finding("capi", std::string(call) + " failed without a message");
  return false;
}

/// Reads doubles from the fuzz input: each value is either a special (NaN, inf, huge, denormal,
/// zero) chosen by a tag byte or a plain value in a realistic range scaled by a chosen power.
class DoubleSource {
 public:
  DoubleSource(const uint8_t* data, size_t size) : data_(data), size_(size) {}
  uint8_t byte() { return pos_ < size_ ? data_[pos_++] : 0; }
  size_t left() const { return size_ - pos_; }
  double next(double scale) {
    const uint8_t tag = byte();
    switch (tag % 16) {
      case 0:
        return std::nan("");
      case 1:
        return tag & 0x80 ? HUGE_VAL : -HUGE_VAL;
      case 2:
        return tag & 0x80 ? 1e308 : -1e308;
      case 3:
        return 4.9e-324;  // smallest denormal
      case 4:
        return 2.2e-310;  // denormal
      case 5:
        return 0.0;
      case 6:
        return -0.0;
      case 7:
        return scale * 1e9;  // huge but finite
      case 8:
        return scale * 1e-12;  // tiny
      default: {
        uint16_t v = static_cast<uint16_t>(byte() | (byte() << 8));
        return scale * (static_cast<double>(v) / 32767.5 - 1.0);
      }
    }
  }

 private:
  const uint8_t* data_;
  size_t size_;
  size_t pos_ = 0;
};

struct CRobot {
  stiff_robot* robot = nullptr;
  CRobot() {
    const std::string path = std::string(STIFF_SOURCE_DIR) + "/examples/robots/rokae.yaml";
    if (stiff_robot_load(&robot, path.c_str()) != STIFF_OK)
      finding("capi", std::string("cannot load rokae: ") + stiff_last_error());
  }
  ~CRobot() { stiff_robot_destroy(robot); }
};

inline void capi_arrays(const uint8_t* data, size_t size) {
  static CRobot robot;
  DoubleSource src(data, size);
  const uint8_t shape = src.byte();
  const uint8_t flags = src.byte();
  const size_t rows = shape & 0x0f;                 // 0..15 (0 is invalid)
  const size_t dof = (shape >> 4) % 9;              // 0..8: wrong sizes on purpose
  const size_t n_claimed = flags & 0x40 ? dof : 6;  // the size the caller says it passes
  std::vector<double> q(rows * dof), force(rows * 3), moment(rows * 3), disp(rows * 3), sigma(rows);
  for (double& v : q) v = src.next(3.0);
  for (double& v : force) v = src.next(50.0);
  for (double& v : moment) v = src.next(5.0);
  for (double& v : disp) v = src.next(1e-4);
  for (double& v : sigma) v = std::fabs(src.next(1e-5));

  stiff_dataset* ds = nullptr;
  const stiff_status s = stiff_dataset_create(
      &ds, rows, dof, (rows * dof != 0) ? q.data() : nullptr, rows != 0 ? force.data() : nullptr,
      (flags & 1) != 0 ? moment.data() : nullptr, (flags & 2) != 0 ? disp.data() : nullptr,
      (flags & 4) != 0 ? sigma.data() : nullptr);
  if (!capi_ok(s, "stiff_dataset_create")) {
    if (ds) finding("capi", "stiff_dataset_create failed but set *out");
    return;
  }
  static const char* const models[] = {"joint", "joint+link", "nonsense", "joint+joint", ""};
  static const char* const losses[] = {nullptr, "huber", "bogus"};
  stiff_identify_options o = STIFF_IDENTIFY_OPTIONS_INIT;
  o.model = models[(flags >> 3) % 5];
  o.loss = losses[(flags >> 6) % 3];
  o.max_iterations = 5;
  o.method = (flags & 0x20) ? STIFF_METHOD_LINEAR : STIFF_METHOD_AUTO;
  stiff_result* fit = nullptr;
  stiff_status is = STIFF_OK;
  must_not_log("capi", [&] { is = stiff_identify(&fit, robot.robot, ds, &o); });
  if (capi_ok(is, "stiff_identify")) {
    size_t needed = 0;
    stiff_result_parameters(nullptr, nullptr, 0, &needed, fit);
    std::vector<double> theta(needed), se(needed);
    if (!capi_ok(stiff_result_parameters(theta.data(), se.data(), needed, &needed, fit),
                 "stiff_result_parameters"))
      finding("capi", "parameters not readable after a successful fit");
    for (size_t i = 0; i < theta.size(); ++i)
      if (!std::isfinite(theta[i]))
        finding("capi", "a successful fit has a non-finite parameter " + std::to_string(i) + " = " +
                            std::to_string(theta[i]));
    stiff_model* model = nullptr;
    if (capi_ok(stiff_model_create(&model, robot.robot, fit), "stiff_model_create")) {
      const size_t prow = 1 + src.byte() % 4;
      std::vector<double> pq(prow * n_claimed), pw(prow * 6), out(prow * 6, -1.0);
      for (double& v : pq) v = src.next(3.0);
      for (double& v : pw) v = src.next(100.0);
      const size_t capacity = src.byte() & 1 ? out.size() : out.size() / 2;
      const stiff_status ps = stiff_predict_batch(out.data(), capacity, &needed, model, pq.data(),
                                                  pw.data(), prow, n_claimed);
      if (capi_ok(ps, "stiff_predict_batch"))
        for (double v : out)
          if (!std::isfinite(v)) finding("capi", "stiff_predict_batch returned a non-finite value");
      stiff_model_destroy(model);
    }
    stiff_result_destroy(fit);
  } else if (fit) {
    finding("capi", "stiff_identify failed but set *out");
  }
  stiff_dataset_destroy(ds);
}

}  // namespace stiff::fuzz
