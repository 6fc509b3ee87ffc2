// The glibc floor of the FMU binaries (docs/fmu.md, "Portability"). FMI importers load the
// binary on whatever Linux runs the simulation tool, often years older than the build host, so
// the binary must not bind to a symbol version newer than it needs. Built on glibc 2.36, the
// statically linked libstdc++ and our own code bind these newer versions, each replaced here
// by a call that older glibc releases export, with the same behaviour:
//   arc4random (2.36), getentropy (2.25)  <- libstdc++'s std::random_device (which the FMU never
//                                            calls; it comes with libstdc++'s string code):
//                                            the getrandom system call
//   hypot (2.35)                          <- hypot@GLIBC_2.2.5, the same correctly computed
//                                            function behind the SVID error wrapper
//   exp (2.29)                            <- exp@GLIBC_2.2.5, the same function behind the
//                                            SVID error wrapper (the derivative of erf calls it)
//   pthread_once (2.34)                   <- pthread_once@GLIBC_2.2.5, the same function
//   stat, lstat, fstat64 (2.33)           <- __xstat, __lxstat, __fxstat64 (version 1), which
//                                            the 2.33 functions call
//   __libc_single_threaded (2.32)         <- a private flag that says "maybe multi-threaded",
//                                            so libstdc++ always uses atomic reference counts
// The linker is told to route the references here (-Wl,--wrap=<symbol>, fmu/CMakeLists.txt).
// The unwinder's _dl_find_object (2.35) is avoided by linking libgcc dynamically.
#include <sys/stat.h>
#include <sys/syscall.h>
#include <unistd.h>

#include <cerrno>
#include <cstddef>
#include <cstdint>
#include <cstdlib>

extern "C" {

double stiff_glibc_hypot(double x, double y);
__asm__(".symver stiff_glibc_hypot,hypot@GLIBC_2.2.5");
double stiff_glibc_exp(double x);
__asm__(".symver stiff_glibc_exp,exp@GLIBC_2.2.5");
int stiff_glibc_pthread_once(void* once, void (*init)(void));
__asm__(".symver stiff_glibc_pthread_once,pthread_once@GLIBC_2.2.5");
int __xstat(int version, const char* path, struct stat* buf);
int __lxstat(int version, const char* path, struct stat* buf);
int __fxstat64(int version, int fd, struct stat64* buf);

double __wrap_hypot(double x, double y) { return stiff_glibc_hypot(x, y); }
double __wrap_exp(double x) { return stiff_glibc_exp(x); }

int __wrap_pthread_once(void* once, void (*init)(void)) {
  return stiff_glibc_pthread_once(once, init);
}

// _STAT_VER_LINUX: the struct stat layout of x86-64, the one <sys/stat.h> declares.
int __wrap_stat(const char* path, struct stat* buf) { return __xstat(1, path, buf); }
int __wrap_lstat(const char* path, struct stat* buf) { return __lxstat(1, path, buf); }
int __wrap_fstat64(int fd, struct stat64* buf) { return __fxstat64(1, fd, buf); }

// getentropy: at most 256 bytes, all or an error (EIO for a short read), as in glibc.
int __wrap_getentropy(void* buffer, size_t length) {
  if (length > 256) {
    errno = EIO;
    return -1;
  }
  auto* p = static_cast<unsigned char*>(buffer);
  while (length > 0) {
    const long got = syscall(SYS_getrandom, p, length, 0);
    if (got < 0) {
      if (errno == EINTR) continue;
      return -1;
    }
    p += got;
    length -= static_cast<size_t>(got);
  }
  return 0;
}

// arc4random cannot fail; glibc aborts when the kernel gives no randomness, so does this.
uint32_t __wrap_arc4random(void) {
  uint32_t v = 0;
  if (__wrap_getentropy(&v, sizeof v) != 0) std::abort();
  return v;
}

// Read by libstdc++ to skip atomic operations in a single-threaded process; 0 is always
// correct (the atomic path), only a little slower.
char __libc_single_threaded = 0;

}  // extern "C"
