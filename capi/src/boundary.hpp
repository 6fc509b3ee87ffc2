// The C boundary: every extern "C" function is
//   return stiff::capi::guarded(__func__, [&] { ...; return STIFF_OK; });
// so that no exception crosses it; failures store "function: reason" in a thread-local
// message that stiff_last_error() returns.
#pragma once

#include <Eigen/Core>
#include <Eigen/LU>
#include <cmath>
#include <cstring>
#include <exception>
#include <new>
#include <string>

#include "stiff/error.hpp"
#include "stiff/stiff.h"
#include "struct_fields.hpp"

namespace stiff::capi {

static_assert(static_cast<int>(Status::invalid_argument) == STIFF_E_INVALID_ARGUMENT);
static_assert(static_cast<int>(Status::invalid_state) == STIFF_E_INVALID_STATE);
static_assert(static_cast<int>(Status::parse) == STIFF_E_PARSE);
static_assert(static_cast<int>(Status::io) == STIFF_E_IO);
static_assert(static_cast<int>(Status::buffer_too_small) == STIFF_E_BUFFER_TOO_SMALL);
static_assert(static_cast<int>(Status::numerical) == STIFF_E_NUMERICAL);
static_assert(static_cast<int>(Status::cancelled) == STIFF_E_CANCELLED);
static_assert(static_cast<int>(Status::no_memory) == STIFF_E_NO_MEMORY);
static_assert(static_cast<int>(Status::internal) == STIFF_E_INTERNAL);

/// Record the failure of `function` and return `status`.
stiff_status fail(const char* function, stiff_status status, const std::string& what) noexcept;

inline stiff_status to_c(Status s) { return static_cast<stiff_status>(static_cast<int>(s)); }

/// The integer a C caller passed for an enum parameter. C allows any int there; in C++ loading
/// an enum object outside its enumerators' range is undefined, so read its bytes instead.
template <typename Enum>
int enum_value(const Enum& e) {
  static_assert(sizeof(Enum) == sizeof(int), "C enums are int-sized on supported platforms");
  int v;
  std::memcpy(&v, &e, sizeof v);
  return v;
}

template <typename Body>
stiff_status guarded(const char* function, Body&& body) noexcept {
  try {
    return body();
  } catch (const stiff::Error& e) {
    return fail(function, to_c(e.status()), e.what());
  } catch (const std::bad_alloc&) {
    return fail(function, STIFF_E_NO_MEMORY, "out of memory");
  } catch (const std::exception& e) {
    return fail(function, STIFF_E_INTERNAL, e.what());
  } catch (...) {
    return fail(function, STIFF_E_INTERNAL, "unknown exception");
  }
}

/// Throw InvalidArgument naming `what` if p is NULL.
template <typename T>
void require(const T* p, const char* what) {
  if (!p) throw InvalidArgument(std::string(what) + " is NULL");
}
inline void require_string(const char* s, const char* what) {
  if (!s) throw InvalidArgument(std::string(what) + " is NULL");
  if (!*s) throw InvalidArgument(std::string(what) + " is empty");
}
/// Throw InvalidArgument if any of n values is not finite.
inline void require_finite(const double* v, size_t n, const char* what) {
  for (size_t i = 0; i < n; ++i)
    if (!std::isfinite(v[i]))
      throw InvalidArgument(std::string(what) + "[" + std::to_string(i) + "] is not finite");
}

/// rows x width values; a product that wraps around size_t (a huge row count) is refused
/// instead of passing a capacity check it should fail.
inline size_t values_of(size_t rows, size_t width, const char* what) {
  if (width != 0 && rows > static_cast<size_t>(-1) / width)
    throw InvalidArgument(std::string(what) + ": " + std::to_string(rows) + " rows of " +
                          std::to_string(width) + " values are more than memory can hold");
  return rows * width;
}

/// Throw the buffer-too-small error (caught by guarded(), which names the C function).
[[noreturn]] inline void too_small(size_t capacity, size_t n, const char* unit) {
  throw Error(Status::buffer_too_small, "buffer holds " + std::to_string(capacity) + " " + unit +
                                            ", " + std::to_string(n) + " needed");
}

/// Capacity/needed check of an output buffer of n values.
inline void require_capacity(size_t n, const void* dst, size_t capacity, size_t* needed) {
  if (needed) *needed = n;
  if (capacity < n || (!dst && n > 0)) too_small(capacity, n, "values");
}

/// Copy `n` values into a caller buffer with capacity/needed semantics.
inline stiff_status copy_out(
    const double* src, size_t n, double* dst, size_t capacity, size_t* needed) {
  if (needed) *needed = n;
  if (capacity < n || (!dst && n > 0)) too_small(capacity, n, "values");
  for (size_t i = 0; i < n; ++i) dst[i] = src[i];
  return STIFF_OK;
}

/// Copy a string (with its NUL) into a caller buffer with capacity/needed semantics (bytes).
inline stiff_status copy_string(const std::string& s, char* dst, size_t capacity, size_t* needed) {
  if (needed) *needed = s.size() + 1;
  if (capacity < s.size() + 1 || !dst) too_small(capacity, s.size() + 1, "bytes");
  s.copy(dst, s.size());
  dst[s.size()] = '\0';
  return STIFF_OK;
}

/// Read a struct of the caller's version into the library's current layout. A struct_size
/// must be where some version of the struct ends (a field boundary, see struct_fields.hpp): a
/// smaller one leaves later fields at their defaults (zero). A larger one (a newer stiff.h) is
/// accepted for input structs only if the unknown trailing bytes are zero; for output structs
/// (`output`: the library writes the caller's part, never beyond) whatever they hold.
template <typename Options>
Options read_options(const Options* in, bool output = false) {
  Options out{};
  if (!in) return out;
  const size_t size = in->struct_size;
  const char* what = output ? "output struct" : "options";
  if (size < sizeof(uint32_t))
    throw InvalidArgument(std::string(what) + ": struct_size " + std::to_string(size) +
                          " is too small (set it to sizeof the struct)");
  if (size < sizeof(Options) && !is_version_size<Options>(size))
    throw InvalidArgument(std::string(what) + ": struct_size " + std::to_string(size) + " ends " +
                          field_cut_by<Options>(size) +
                          ", so it is no version of the struct (set it to sizeof the struct)");
  const unsigned char* bytes = reinterpret_cast<const unsigned char*>(in);
  if (!output)
    for (size_t i = sizeof(Options); i < size; ++i)
      if (bytes[i] != 0)
        throw InvalidArgument(
            "options: struct_size is larger than this library knows and the "
            "unknown fields are not zero (built against a newer stiff.h?)");
  const size_t n = size < sizeof(Options) ? size : sizeof(Options);
  std::memcpy(&out, in, n);
  out.struct_size = static_cast<uint32_t>(sizeof(Options));
  return out;
}

/// A default string of a core option struct as a C string with static storage (option structs
/// hold borrowed pointers, so the one *_options_init writes must outlive every call):
/// `static_string([] { return IdentifyOptions{}.loss; })`. Each lambda is its own type, so each
/// call site keeps its own copy. An empty default gives NULL (the library then decides).
template <typename Make>
const char* static_string(Make make) {
  static const std::string s = make();
  return s.empty() ? nullptr : s.c_str();
}

/// The body of every stiff_*_options_init (libgit2's options_init convention): write `defaults`
/// (built from the core's option structs, never restated numbers) into the caller's struct.
/// `struct_size` is sizeof the struct as the caller compiled it: at least `first_size` (the
/// first released version) and, when smaller than this library's struct, the end of one of
/// its versions. Bytes beyond min(struct_size, sizeof(Options)) are not touched; struct_size
/// is set to the bytes written.
template <typename Options>
stiff_status init_options(Options* options,
                          size_t struct_size,
                          size_t first_size,
                          const char* type_name,
                          Options defaults) {
  require(options, "options");
  if (struct_size < first_size)
    throw InvalidArgument("struct_size " + std::to_string(struct_size) +
                          " is smaller than the first released " + type_name + " (" +
                          std::to_string(first_size) + " bytes; pass sizeof the struct)");
  if (struct_size < sizeof(Options) && !is_version_size<Options>(struct_size))
    throw InvalidArgument("struct_size " + std::to_string(struct_size) + " ends " +
                          field_cut_by<Options>(struct_size) + ", so it is no version of " +
                          type_name + " (pass sizeof the struct)");
  const size_t n = struct_size < sizeof(Options) ? struct_size : sizeof(Options);
  defaults.struct_size = static_cast<uint32_t>(n);
  std::memcpy(options, &defaults, n);
  return STIFF_OK;
}

/// A 4 x 4 row-major pose read from the caller's 16 doubles: finite, with an orthonormal
/// right-handed rotation and last row 0 0 0 1, else InvalidArgument naming `what`.
inline Eigen::Matrix4d rigid_pose_at(const double* p, const char* what) {
  require_finite(p, 16, what);
  Eigen::Matrix4d t;
  for (int r = 0; r < 4; ++r)
    for (int c = 0; c < 4; ++c) t(r, c) = p[4 * r + c];
  const Eigen::Matrix3d rot = t.block<3, 3>(0, 0);
  if ((rot.transpose() * rot - Eigen::Matrix3d::Identity()).norm() > 1e-6 ||
      rot.determinant() < 0 || t.row(3) != Eigen::RowVector4d(0, 0, 0, 1))
    throw InvalidArgument(std::string(what) +
                          " is not a rigid transform (rotation part not orthonormal or last row "
                          "not 0 0 0 1)");
  return t;
}

}  // namespace stiff::capi
