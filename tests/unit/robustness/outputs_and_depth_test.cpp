// Outputs never destroy what is at their path, and readers never recurse deeper than a small
// thread stack allows (docs/reliability.md, "Round two").
#include <fcntl.h>
#include <gtest/gtest.h>
#include <pthread.h>
#include <sys/stat.h>
#include <sys/syscall.h>
#include <sys/types.h>
#include <unistd.h>

#include <atomic>
#include <cstdio>
#include <cstdlib>
#include <fstream>
#include <functional>
#include <sstream>
#include <string>
#include <thread>
#include <vector>

#include "stiff/error.hpp"
#include "stiff/io/robot_io.hpp"
#include "stiff/sim/simulate.hpp"
#include "stiff/io/text_io.hpp"

// Every umask() call of this process (the library is linked statically into this test, so its
// calls resolve here), forwarded to the kernel.
static std::atomic<int> umask_calls{0};
extern "C" mode_t umask(mode_t mask) noexcept {
  ++umask_calls;
  return static_cast<mode_t>(::syscall(SYS_umask, mask));
}

namespace stiff {
namespace {

struct TempDir {
  std::string path;
  TempDir() {
    char t[] = "/tmp/stiff-outputs-XXXXXX";
    path = ::mkdtemp(t);
  }
  ~TempDir() { std::system(("rm -rf '" + path + "'").c_str()); }
  std::string operator/(const std::string& name) const { return path + "/" + name; }
};

std::string slurp(const std::string& p) {
  std::ifstream in(p, std::ios::binary);
  std::ostringstream s;
  s << in.rdbuf();
  return s.str();
}

void put(const std::string& p, const std::string& text) { std::ofstream(p) << text; }

std::vector<std::string> leftovers(const TempDir& d) {
  std::vector<std::string> out;
  const std::string cmd = "ls -A '" + d.path + "'";
  FILE* f = ::popen(cmd.c_str(), "r");
  char line[512];
  while (f && std::fgets(line, sizeof line, f))
    if (std::string(line).find(".tmp") != std::string::npos) out.push_back(line);
  if (f) ::pclose(f);
  return out;
}

std::string error_of(const std::function<void()>& f) {
  try {
    f();
  } catch (const Error& e) {
    return e.what();
  }
  return "";
}

TEST(AtomicWriter, ReplacesARegularFileAndKeepsItsMode) {
  TempDir d;
  put(d / "a.txt", "old");
  ::chmod((d / "a.txt").c_str(), 0640);
  write_text_file_atomic(d / "a.txt", "new");
  EXPECT_EQ(slurp(d / "a.txt"), "new");
  struct stat st {};
  ::stat((d / "a.txt").c_str(), &st);
  EXPECT_EQ(st.st_mode & 0777, 0640u);
  EXPECT_TRUE(leftovers(d).empty());
}

TEST(AtomicWriter, NewFilesGetTheUmaskWithoutTheUmaskBeingChanged) {
  TempDir d;
  const mode_t old = ::umask(027);
  umask_calls = 0;
  for (int i = 0; i < 20; ++i) write_text_file_atomic(d / ("f" + std::to_string(i)), "x");
  // The umask is process-wide: setting it, even for a moment, races with every other thread
  // creating a file (3 in 80,000 got mode 666).
  EXPECT_EQ(umask_calls.load(), 0);
  ::umask(old);
  struct stat st {};
  ::stat((d / "f0").c_str(), &st);
  EXPECT_EQ(st.st_mode & 0777, 0640u);
}

TEST(AtomicWriter, FollowsSymbolicLinksToTheirTarget) {
  TempDir d;
  put(d / "target.txt", "old");
  ASSERT_EQ(::symlink("target.txt", (d / "link.txt").c_str()), 0);
  write_text_file_atomic(d / "link.txt", "new");
  struct stat st {};
  ASSERT_EQ(::lstat((d / "link.txt").c_str(), &st), 0);
  EXPECT_TRUE(S_ISLNK(st.st_mode)) << "the link was replaced by a file";
  EXPECT_EQ(slurp(d / "target.txt"), "new");
  // A dangling link: its target is created.
  ASSERT_EQ(::symlink("later.txt", (d / "dangling.txt").c_str()), 0);
  write_text_file_atomic(d / "dangling.txt", "x");
  EXPECT_EQ(slurp(d / "later.txt"), "x");
}

TEST(AtomicWriter, WritesThroughCharacterDevicesAndPipes) {
  write_text_file_atomic("/dev/null", "discarded");
  struct stat st {};
  ASSERT_EQ(::stat("/dev/null", &st), 0);
  EXPECT_TRUE(S_ISCHR(st.st_mode));
  // /dev/full: the device's error, naming the path, and the device is still there.
  const std::string e = error_of([] { write_text_file_atomic("/dev/full", "x"); });
  EXPECT_NE(e.find("/dev/full: write failed (No space left on device)"), std::string::npos) << e;
  ASSERT_EQ(::stat("/dev/full", &st), 0);
  EXPECT_TRUE(S_ISCHR(st.st_mode));

  TempDir d;
  const std::string fifo = d / "pipe";
  ASSERT_EQ(::mkfifo(fifo.c_str(), 0600), 0);
  // No reader: an error, not a hang.
  const std::string e2 = error_of([&] { write_text_file_atomic(fifo, "x"); });
  EXPECT_NE(e2.find("no process is reading"), std::string::npos) << e2;
  std::string got;
  std::thread reader([&] {
    const int fd = ::open(fifo.c_str(), O_RDONLY);
    char buf[64];
    ssize_t n;
    while ((n = ::read(fd, buf, sizeof buf)) > 0) got.append(buf, static_cast<size_t>(n));
    ::close(fd);
  });
  // The reader may not have opened yet: retry until it has.
  for (int i = 0; i < 1000; ++i) {
    if (error_of([&] { write_text_file_atomic(fifo, "through the pipe"); }).empty()) break;
    ::usleep(1000);
  }
  reader.join();
  EXPECT_EQ(got, "through the pipe");
  ASSERT_EQ(::lstat(fifo.c_str(), &st), 0);
  EXPECT_TRUE(S_ISFIFO(st.st_mode));
}

TEST(AtomicWriter, RefusesReadOnlyFilesAndDirectoriesAndNeverNamesTheTemporaryFile) {
  TempDir d;
  put(d / "ro.txt", "keep");
  ::chmod((d / "ro.txt").c_str(), 0444);
  const std::string e = error_of([&] { write_text_file_atomic(d / "ro.txt", "x"); });
  EXPECT_NE(e.find("ro.txt: is read-only"), std::string::npos) << e;
  EXPECT_EQ(slurp(d / "ro.txt"), "keep");
  const std::string e2 = error_of([&] { write_text_file_atomic(d.path, "x"); });
  EXPECT_NE(e2.find("is a directory"), std::string::npos) << e2;
  const std::string e3 = error_of([&] { write_text_file_atomic(d / "no/such/x.json", "x"); });
  EXPECT_NE(e3.find("x.json: cannot create a temporary file"), std::string::npos) << e3;
  EXPECT_EQ(e3.find(".tmp"), std::string::npos) << e3;
  const std::string e4 =
      error_of([&] { write_text_file_atomic(d / (std::string(300, 'n') + ".json"), "x"); });
  EXPECT_NE(e4.find("too long"), std::string::npos) << e4;
  EXPECT_TRUE(leftovers(d).empty());
}

// ----------------------------------------------------------------------------- nesting depth

std::string nested_urdf(int depth) {
  std::string s = "<?xml version='1.0'?><robot name='deep'>";
  for (int i = 0; i < depth; ++i) s += "<link name='l'>";
  for (int i = 0; i < depth; ++i) s += "</link>";
  return s + "</robot>";
}

// Runs f on a thread with a stack of `bytes` (hosts call from small ones: a GUI callback, a
// co-simulation worker): what a reader does must fit there.
std::string on_small_stack(size_t bytes, const std::function<void()>& f) {
  struct Job {
    std::function<void()> f;
    std::string error;
  } job{f, ""};
  pthread_attr_t attr;
  pthread_attr_init(&attr);
  pthread_attr_setstacksize(&attr, bytes);
  pthread_t t;
  auto run = [](void* p) -> void* {
    auto* j = static_cast<Job*>(p);
    j->error = error_of(j->f);
    return nullptr;
  };
  EXPECT_EQ(pthread_create(&t, &attr, run, &job), 0);
  pthread_join(t, nullptr);
  pthread_attr_destroy(&attr);
  return job.error;
}

TEST(NestingDepth, DeepUrdfIsAParseErrorOnAOneMebibyteStack) {
  for (int depth : {5000, 50000}) {
    const std::string e =
        on_small_stack(1 << 20, [&] { parse_robot_urdf(nested_urdf(depth), "deep.urdf"); });
    EXPECT_NE(e.find("deep.urdf:1:"), std::string::npos) << e;
    EXPECT_NE(e.find("nested deeper than 64 levels"), std::string::npos) << e;
  }
}

TEST(NestingDepth, DeepYamlIsAParseErrorOnA128KibStack) {
  const size_t stack = 128 << 10;
  std::string flow = "name: " + std::string(400, '[') + std::string(400, ']') + "\n";
  std::string block = "name: x\njoints:\n";
  for (int i = 0; i < 400; ++i) block += std::string(static_cast<size_t>(2 * i + 2), ' ') + "a:\n";
  std::string compact = "joints:\n";
  for (int i = 0; i < 400; ++i) compact += "- ";
  compact += "x\n";
  for (const std::string& text : {flow, block, compact}) {
    const std::string e = on_small_stack(stack, [&] { parse_robot_yaml(text, "deep.yaml"); });
    EXPECT_NE(e.find("deep.yaml:"), std::string::npos) << e;
    EXPECT_NE(e.find("nested deeper than 64 levels"), std::string::npos) << e;
    const std::string e2 = on_small_stack(stack, [&] { parse_noise_yaml(text, "noise.yaml"); });
    EXPECT_NE(e2.find("nested deeper"), std::string::npos) << e2;
  }
}

TEST(NestingDepth, OrdinaryFilesAreNotTooDeep) {
  const std::string dir = STIFF_SOURCE_DIR "/examples/robots/";
  for (const char* f : {"rokae.yaml", "puma560.yaml", "ur5.urdf"}) {
    std::ifstream probe(dir + f);
    if (!probe) continue;
    EXPECT_NO_THROW(load_robot(dir + f)) << f;
  }
  EXPECT_NO_THROW(check_yaml_nesting("a: {b: [1, [2, {c: 3}]]}\nd:\n  - - e\n    - f\n", "x"));
  EXPECT_NO_THROW(check_xml_nesting("<a x='>'><!-- <b> --><![CDATA[<c>]]><d/></a>", "x"));
}

// ----------------------------------------------------------------------------- URDF loops

TEST(UrdfLoop, ALinkWithTwoParentJointsIsAParseError) {
  const std::string urdf =
      "<?xml version='1.0'?><robot name='loop'>"
      "<link name='base'/><link name='a'/><link name='b'/>"
      "<joint name='j1' type='revolute'><parent link='base'/><child link='a'/><axis xyz='0 0 1'/>"
      "<limit lower='-1' upper='1' effort='1' velocity='1'/></joint>"
      "<joint name='j2' type='revolute'><parent link='a'/><child link='b'/><axis xyz='0 0 1'/>"
      "<limit lower='-1' upper='1' effort='1' velocity='1'/></joint>"
      "<joint name='j3' type='revolute'><parent link='b'/><child link='a'/><axis xyz='0 0 1'/>"
      "<limit lower='-1' upper='1' effort='1' velocity='1'/></joint>"
      "</robot>";
  const std::string e = on_small_stack(1 << 20, [&] { parse_robot_urdf(urdf, "loop.urdf"); });
  EXPECT_NE(e.find("loop.urdf"), std::string::npos) << e;
  EXPECT_NE(e.find("loop"), std::string::npos) << e;
}

}  // namespace
}  // namespace stiff
