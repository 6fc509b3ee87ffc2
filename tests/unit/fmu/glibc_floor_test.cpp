// The FMU's glibc shims (fmu/src/glibc_floor.cpp) behave like the glibc functions they stand in
// for. This test is linked with the same --wrap options as the FMU binaries, so every call
// below of hypot, stat, lstat, fstat64, pthread_once, getentropy and arc4random goes through a
// shim; the references are the functions glibc exports under their current versions, found with
// dlsym, or the system calls behind them.
#include <dlfcn.h>
#include <fcntl.h>
#include <gtest/gtest.h>
#include <pthread.h>
#include <sys/random.h>
#include <sys/stat.h>
#include <unistd.h>

#include <cerrno>
#include <cmath>
#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <fstream>
#include <random>
#include <set>
#include <string>

extern "C" uint32_t arc4random(void);

namespace {

#ifndef STIFF_GLIBC_FLOOR
#define SKIP_WITHOUT_SHIMS() GTEST_SKIP() << "built without the FMU (no glibc shims to test)"
#else
#define SKIP_WITHOUT_SHIMS() (void)0
#endif

template <typename F>
F current(const char* lib, const char* name) {
  void* h = dlopen(lib, RTLD_NOW | RTLD_NOLOAD);
  if (!h) h = dlopen(lib, RTLD_NOW);
  return h ? reinterpret_cast<F>(dlsym(h, name)) : nullptr;
}

TEST(GlibcFloor, HypotIsBitForBitTheCurrentOne) {
  SKIP_WITHOUT_SHIMS();
  using Hypot = double (*)(double, double);
  const Hypot now = current<Hypot>("libm.so.6", "hypot");
  ASSERT_NE(now, nullptr);
  std::mt19937_64 rng(7);
  std::uniform_real_distribution<double> metre(-3.0, 3.0);
  std::uniform_int_distribution<uint64_t> bits;
  for (int i = 0; i < 200000; ++i) {
    double a = metre(rng), b = metre(rng);
    if (i % 2) {  // any finite double, subnormals and huge values included
      const uint64_t x = bits(rng), y = bits(rng);
      std::memcpy(&a, &x, 8);
      std::memcpy(&b, &y, 8);
      if (!std::isfinite(a) || !std::isfinite(b)) continue;
    }
    const double h = std::hypot(a, b), r = now(a, b);
    ASSERT_EQ(std::memcmp(&h, &r, 8), 0) << a << ' ' << b;
  }
}

TEST(GlibcFloor, StatFamilyTellsWhatTheKernelTells) {
  SKIP_WITHOUT_SHIMS();
  char dir[] = "/tmp/stiff_glibc_floor_XXXXXX";
  ASSERT_NE(mkdtemp(dir), nullptr);
  const std::string file = std::string(dir) + "/f.txt", link = std::string(dir) + "/l";
  std::ofstream(file) << "twelve bytes";
  ASSERT_EQ(symlink(file.c_str(), link.c_str()), 0);
  struct stat a, b;
  ASSERT_EQ(stat(link.c_str(), &a), 0);  // follows the link
  ASSERT_EQ(fstatat(AT_FDCWD, file.c_str(), &b, 0), 0);
  EXPECT_EQ(a.st_ino, b.st_ino);
  EXPECT_EQ(a.st_size, 12);
  EXPECT_TRUE(S_ISREG(a.st_mode));
  EXPECT_EQ(a.st_mtim.tv_nsec, b.st_mtim.tv_nsec);
  ASSERT_EQ(lstat(link.c_str(), &a), 0);  // the link itself
  EXPECT_TRUE(S_ISLNK(a.st_mode));
  const int fd = open(file.c_str(), O_RDONLY);
  ASSERT_GE(fd, 0);
  struct stat64 c;
  ASSERT_EQ(fstat64(fd, &c), 0);
  EXPECT_EQ(c.st_ino, b.st_ino);
  EXPECT_EQ(c.st_size, 12);
  close(fd);
  errno = 0;
  EXPECT_EQ(stat((std::string(dir) + "/none").c_str(), &a), -1);
  EXPECT_EQ(errno, ENOENT);
  std::remove(link.c_str());
  std::remove(file.c_str());
  rmdir(dir);
}

pthread_once_t once = PTHREAD_ONCE_INIT;
int initialised = 0;
void init_once() { ++initialised; }

TEST(GlibcFloor, PthreadOnceRunsOnce) {
  SKIP_WITHOUT_SHIMS();
  for (int i = 0; i < 3; ++i) ASSERT_EQ(pthread_once(&once, init_once), 0);
  EXPECT_EQ(initialised, 1);
}

TEST(GlibcFloor, RandomBytesAreRandomAndBounded) {
  SKIP_WITHOUT_SHIMS();
  unsigned char a[256] = {}, b[256] = {};
  ASSERT_EQ(getentropy(a, sizeof a), 0);
  ASSERT_EQ(getentropy(b, sizeof b), 0);
  EXPECT_NE(std::memcmp(a, b, sizeof a), 0);
  unsigned char big[257];
  errno = 0;
  EXPECT_EQ(getentropy(big, sizeof big), -1);  // glibc's limit: 256 bytes
  EXPECT_EQ(errno, EIO);
  std::set<uint32_t> seen;
  for (int i = 0; i < 64; ++i) seen.insert(arc4random());
  EXPECT_GT(seen.size(), 60u);  // 64 draws of 2^32 values: a repeat has probability 5e-7
  std::random_device device;    // libstdc++'s, which is what needs these in the FMU
  std::set<unsigned> drawn;
  for (int i = 0; i < 8; ++i) drawn.insert(device());
  EXPECT_GE(drawn.size(), 7u);
}

}  // namespace
