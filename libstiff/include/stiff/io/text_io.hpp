/// \file text_io.hpp
/// File helpers shared by every reader and writer: whole-file reads with clear errors, and
/// atomic writes (a temporary file in the same folder, renamed when complete, so that a
/// failure never leaves a half-written output or destroys an existing file).
#pragma once

#include <string>

namespace stiff {

/// Whole file as text; throws IoError naming the path when it cannot be read.
std::string read_text_file(const std::string& path);

/// Write `content` to `path` atomically; throws IoError naming the path on failure.
void write_text_file_atomic(const std::string& path, const std::string& content);

}  // namespace stiff
