#include "stiff/io/text_io.hpp"

#include <fcntl.h>
#include <sys/stat.h>
#include <unistd.h>

#include <atomic>
#include <cerrno>
#include <chrono>
#include <cstdio>
#include <cstring>
#include <fstream>
#include <sstream>
#include <vector>

#include "stiff/error.hpp"

namespace stiff {

std::string read_text_file(const std::string& path) {
  std::ifstream in(path, std::ios::binary);
  if (!in) throw IoError(path + ": cannot open for reading (" + std::strerror(errno) + ")");
  std::ostringstream ss;
  ss << in.rdbuf();
  if (in.bad()) throw IoError(path + ": read error");
  return ss.str();
}

namespace {

[[noreturn]] void too_deep(
    const std::string& file, const std::string& text, size_t at, int max_depth, const char* what) {
  int line = 1, column = 1;
  for (size_t i = 0; i < at && i < text.size(); ++i) {
    if (text[i] == '\n') {
      ++line;
      column = 1;
    } else {
      ++column;
    }
  }
  throw ParseError(file, line, column,
                   std::string(what) + " nested deeper than " + std::to_string(max_depth) +
                       " levels; no robot, fit or noise file needs that many");
}

}  // namespace

void check_xml_nesting(const std::string& text, const std::string& file, int max_depth) {
  int depth = 0;
  const size_t n = text.size();
  auto skip_to = [&](size_t from, const char* end) {
    const size_t e = text.find(end, from);
    return e == std::string::npos ? n : e + std::strlen(end);
  };
  for (size_t i = 0; i < n;) {
    if (text[i] != '<') {
      ++i;
      continue;
    }
    if (text.compare(i, 4, "<!--") == 0) {
      i = skip_to(i + 4, "-->");
    } else if (text.compare(i, 9, "<![CDATA[") == 0) {
      i = skip_to(i + 9, "]]>");
    } else if (text.compare(i, 2, "<?") == 0) {
      i = skip_to(i + 2, "?>");
    } else if (text.compare(i, 2, "<!") == 0) {
      i = skip_to(i + 2, ">");
    } else if (text.compare(i, 2, "</") == 0) {
      if (depth > 0) --depth;
      i = skip_to(i + 2, ">");
    } else {
      // A start tag; quoted attribute values may hold '>'.
      const size_t start = i;
      char quote = 0;
      size_t j = i + 1;
      for (; j < n; ++j) {
        const char c = text[j];
        if (quote) {
          if (c == quote) quote = 0;
        } else if (c == '"' || c == '\'') {
          quote = c;
        } else if (c == '>') {
          break;
        }
      }
      const bool empty_element = j < n && j > i + 1 && text[j - 1] == '/';
      if (!empty_element && ++depth > max_depth)
        too_deep(file, text, start, max_depth, "XML elements");
      i = j < n ? j + 1 : n;
    }
  }
}

void check_yaml_nesting(const std::string& text, const std::string& file, int max_depth) {
  std::vector<size_t> indents;  // block levels open at the current line
  int flow = 0;                 // [ and { open (flow collections span lines)
  size_t pos = 0;
  while (pos < text.size()) {
    size_t end = text.find('\n', pos);
    if (end == std::string::npos) end = text.size();
    size_t i = pos;
    while (i < end && text[i] == ' ') ++i;
    const bool blank = i == end || text[i] == '#' || text[i] == '\r';
    if (!blank && flow == 0) {
      const size_t indent = i - pos;
      while (!indents.empty() && indents.back() >= indent) indents.pop_back();
      indents.push_back(indent);
      // compact nesting on one line: "- - - x", "- a: - b"
      int compact = 0;
      for (size_t k = i; k + 1 < end && text[k] == '-' && text[k + 1] == ' ';) {
        ++compact;
        k += 2;
        while (k < end && text[k] == ' ') ++k;
      }
      if (static_cast<int>(indents.size()) + compact > max_depth)
        too_deep(file, text, i, max_depth, "YAML collections");
    }
    char quote = 0;
    for (size_t k = i; k < end; ++k) {
      const char c = text[k];
      if (quote) {
        if (c == quote) quote = 0;
        continue;
      }
      if (c == '#' && (k == pos || text[k - 1] == ' ' || text[k - 1] == '\t')) break;
      if (c == '"' || c == '\'') {
        if (k == pos || std::strchr(" \t[{,:-", text[k - 1])) quote = c;
      } else if (c == '[' || c == '{') {
        if (++flow + static_cast<int>(indents.size()) > max_depth)
          too_deep(file, text, k, max_depth, "YAML collections");
      } else if ((c == ']' || c == '}') && flow > 0) {
        --flow;
      }
    }
    pos = end + 1;
  }
}

namespace {

std::string why(int err) { return std::strerror(err); }

std::string parent_of(const std::string& p) {
  const size_t slash = p.rfind('/');
  if (slash == std::string::npos) return ".";
  if (slash == 0) return "/";
  return p.substr(0, slash);
}

// Writes every byte to fd; on failure throws IoError naming `shown` (the user's path).
void write_all(int fd, const char* data, size_t size, const std::string& shown) {
  size_t done = 0;
  while (done < size) {
    const ssize_t w = ::write(fd, data + done, size - done);
    if (w < 0) {
      if (errno == EINTR) continue;
      throw IoError(shown + ": write failed (" + why(errno) + ")");
    }
    done += static_cast<size_t>(w);
  }
}

// The file a path finally names: symbolic links are followed (also dangling ones, whose target
// is then created), so that writing replaces the target and keeps the link.
std::string resolve_links(const std::string& path) {
  std::string p = path;
  for (int hops = 0; hops < 40; ++hops) {
    struct stat st {};
    if (::lstat(p.c_str(), &st) != 0 || !S_ISLNK(st.st_mode)) return p;
    std::string target(static_cast<size_t>(st.st_size > 0 ? st.st_size : 4096) + 1, '\0');
    const ssize_t n = ::readlink(p.c_str(), target.data(), target.size());
    if (n < 0) throw IoError(path + ": cannot read the symbolic link (" + why(errno) + ")");
    target.resize(static_cast<size_t>(n));
    p = (!target.empty() && target[0] == '/') ? target : parent_of(p) + "/" + target;
  }
  throw IoError(path + ": too many levels of symbolic links");
}

// Character devices (/dev/null, a terminal) and named pipes are written through, never replaced.
void write_through(
    const std::string& target, const std::string& shown, const char* data, size_t size, bool fifo) {
  // O_NONBLOCK on a pipe fails with ENXIO instead of waiting forever for a reader.
  const int fd = ::open(target.c_str(), O_WRONLY | O_NOCTTY | O_CLOEXEC | (fifo ? O_NONBLOCK : 0));
  if (fd < 0) {
    const int e = errno;
    if (fifo && e == ENXIO) throw IoError(shown + ": no process is reading from this named pipe");
    throw IoError(shown + ": cannot open for writing (" + why(e) + ")");
  }
  if (fifo) ::fcntl(fd, F_SETFL, ::fcntl(fd, F_GETFL) & ~O_NONBLOCK);
  try {
    write_all(fd, data, size, shown);
  } catch (...) {
    ::close(fd);
    throw;
  }
  if (::close(fd) != 0) throw IoError(shown + ": write failed (" + why(errno) + ")");
}

// A new file next to `target`, created with mode 0666 so that the kernel applies the umask
// (reading the umask would mean setting it, which is process-wide and races with other threads).
int create_temporary(const std::string& target, const std::string& shown, std::string& tmp) {
  static std::atomic<unsigned> counter{0};
  const std::string dir = parent_of(target);
  const size_t slash = target.rfind('/');
  const std::string base = slash == std::string::npos ? target : target.substr(slash + 1);
  for (int attempt = 0; attempt < 100; ++attempt) {
    const auto t = static_cast<unsigned long long>(
        std::chrono::steady_clock::now().time_since_epoch().count());
    char suffix[64];
    std::snprintf(suffix, sizeof suffix, ".%d.%llx.%u.tmp", static_cast<int>(::getpid()),
                  t & 0xffffffffULL, counter++);
    tmp = (dir == "." && slash == std::string::npos ? std::string() : dir + "/") + "." + base +
          suffix;
    const int fd = ::open(tmp.c_str(), O_WRONLY | O_CREAT | O_EXCL | O_CLOEXEC, 0666);
    if (fd >= 0) return fd;
    if (errno == EEXIST) continue;
    if (errno == ENAMETOOLONG)
      throw IoError(shown + ": the file name is too long for this file system");
    throw IoError(shown + ": cannot create a temporary file next to it in '" + dir + "' (" +
                  why(errno) + ")");
  }
  throw IoError(shown + ": cannot create a temporary file next to it in '" + dir + "'");
}

}  // namespace

void write_file_atomic(const std::string& path, const char* data, size_t size) {
  if (path.empty()) throw IoError("output path is empty");
  if (path.find('\0') != std::string::npos) throw IoError("output path contains a NUL byte");
  if (path == "-") {
    write_all(STDOUT_FILENO, data, size, "standard output");
    return;
  }
  const std::string target = resolve_links(path);
  struct stat st {};
  const bool exists = ::stat(target.c_str(), &st) == 0;
  if (exists) {
    if (S_ISCHR(st.st_mode) || S_ISFIFO(st.st_mode))
      return write_through(target, path, data, size, S_ISFIFO(st.st_mode));
    if (S_ISDIR(st.st_mode)) throw IoError(path + ": is a directory");
    if (!S_ISREG(st.st_mode))
      throw IoError(path + ": is not a regular file (a device or socket); not replacing it");
    // Read-only is refused even for root, who could replace it: the mode says "keep".
    if ((st.st_mode & 0222) == 0 || ::access(target.c_str(), W_OK) != 0)
      throw IoError(path +
                    ": is read-only; not replacing it (make it writable or choose "
                    "another output)");
  }
  std::string tmp;
  const int fd = create_temporary(target, path, tmp);
  try {
    // A replaced file keeps its permissions.
    if (exists) ::fchmod(fd, st.st_mode & 07777);
    write_all(fd, data, size, path);
    if (::fsync(fd) != 0) throw IoError(path + ": write failed (" + why(errno) + ")");
  } catch (...) {
    ::close(fd);
    ::unlink(tmp.c_str());
    throw;
  }
  if (::close(fd) != 0) {
    const int e = errno;
    ::unlink(tmp.c_str());
    throw IoError(path + ": write failed (" + why(e) + ")");
  }
  if (::rename(tmp.c_str(), target.c_str()) != 0) {
    const int e = errno;
    ::unlink(tmp.c_str());
    throw IoError(path + ": cannot put the finished file in place (" + why(e) + ")");
  }
}

void write_text_file_atomic(const std::string& path, const std::string& content) {
  write_file_atomic(path, content.data(), content.size());
}

}  // namespace stiff
