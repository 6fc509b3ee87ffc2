// The C boundary: every extern "C" function is
//   return stiff::capi::guarded(__func__, [&] { ...; return STIFF_OK; });
// so that no exception crosses it; failures store "function: reason" in a thread-local
// message that stiff_last_error() returns.
#pragma once

#include <cmath>
#include <cstring>
#include <exception>
#include <new>
#include <string>

#include "stiff/error.hpp"
#include "stiff/stiff.h"

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

/// Read an option struct of the caller's size into the library's current layout: a smaller
/// struct_size leaves later fields at their defaults (zero); a larger one is accepted only if
/// the unknown trailing bytes are zero.
template <typename Options>
Options read_options(const Options* in) {
  Options out{};
  if (!in) return out;
  const size_t size = in->struct_size;
  if (size < sizeof(uint32_t)) throw InvalidArgument("options: struct_size is too small");
  const unsigned char* bytes = reinterpret_cast<const unsigned char*>(in);
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

}  // namespace stiff::capi
