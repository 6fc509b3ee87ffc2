/// \file error.hpp
/// Error model of the core: bad input from a caller throws a subclass of
/// stiff::Error carrying a Status whose values equal the C ABI's stiff_status; numerical
/// outcomes are values, never exceptions.
#pragma once

#include <stdexcept>
#include <string>

namespace stiff {

/// Status codes; the values are pinned and equal the C enum stiff_status (checked in capi/).
enum class Status : int {
  ok = 0,
  invalid_argument = -1,  ///< NULL, NaN, wrong size, out of range, unknown name
  invalid_state = -2,     ///< call out of order
  parse = -3,             ///< bad input file; message is "path:line:col: reason"
  io = -4,                ///< file cannot be opened, read or written
  buffer_too_small = -5,  ///< caller's buffer too small
  numerical = -6,         ///< singular, non-finite or unidentifiable problem
  cancelled = -7,         ///< a user callback asked to stop
  no_memory = -8,
  internal = -99  ///< a bug
};

/// Base of every exception the core throws on bad input.
class Error : public std::runtime_error {
 public:
  Error(Status status, const std::string& what) : std::runtime_error(what), status_(status) {}
  Status status() const noexcept { return status_; }

 private:
  Status status_;
};

/// Invalid argument: sizes, non-finite values, unknown names.
class InvalidArgument : public Error {
 public:
  explicit InvalidArgument(const std::string& what) : Error(Status::invalid_argument, what) {}
};

/// A problem the data cannot answer: singular, rank deficient, non-finite.
class NumericalError : public Error {
 public:
  explicit NumericalError(const std::string& what) : Error(Status::numerical, what) {}
};

/// A file that cannot be opened, read or written.
class IoError : public Error {
 public:
  explicit IoError(const std::string& what) : Error(Status::io, what) {}
};

/// The user asked to stop (progress callback returned non-zero or Ctrl-C).
class Cancelled : public Error {
 public:
  explicit Cancelled(const std::string& what) : Error(Status::cancelled, what) {}
};

/// A malformed input file. what() is "path:line:column: reason" (line and column 1-based;
/// 0 where not applicable, then omitted).
class ParseError : public Error {
 public:
  ParseError(std::string path, int line, int column, const std::string& reason)
      : Error(Status::parse, format(path, line, column, reason)),
        path_(std::move(path)),
        line_(line),
        column_(column) {}
  const std::string& path() const noexcept { return path_; }
  int line() const noexcept { return line_; }
  int column() const noexcept { return column_; }

 private:
  static std::string format(const std::string& path,
                            int line,
                            int column,
                            const std::string& reason) {
    std::string s = path;
    if (line > 0) s += ":" + std::to_string(line);
    if (line > 0 && column > 0) s += ":" + std::to_string(column);
    return s + ": " + reason;
  }
  std::string path_;
  int line_;
  int column_;
};

}  // namespace stiff
