/// \file text_io.hpp
/// File helpers shared by every reader and writer: whole-file reads with clear errors, and
/// atomic writes (a temporary file in the same folder, renamed when complete, so that a
/// failure never leaves a half-written output or destroys an existing file).
#pragma once

#include <cstddef>
#include <string>

namespace stiff {

/// Whole file as text; throws IoError naming the path when it cannot be read.
std::string read_text_file(const std::string& path);

/// Write `size` bytes to `path`; throws IoError naming `path` (never the temporary file).
/// A regular file (new or existing) is replaced atomically: a temporary file next to it,
/// renamed over it when complete; a replaced file keeps its permissions, a new one gets
/// 0666 minus the umask. Symbolic links are followed and their target replaced. Character
/// devices (/dev/null) and named pipes are written through, `-` is standard output. A
/// read-only file, a directory, a block device or a socket is refused, never replaced.
void write_file_atomic(const std::string& path, const char* data, size_t size);

/// Refuse (ParseError naming file:line:column) an XML document whose elements nest deeper than
/// `max_depth`, before any parser sees it: the parsers recurse once per level and a deep
/// document would overflow the calling thread's stack (a host may call from a small one).
void check_xml_nesting(const std::string& text, const std::string& file, int max_depth = 64);

/// The same for YAML: block indentation levels, compact "- - -" sequences and flow brackets.
void check_yaml_nesting(const std::string& text, const std::string& file, int max_depth = 64);

/// write_file_atomic for text.
void write_text_file_atomic(const std::string& path, const std::string& content);

}  // namespace stiff
