// Issue 12, items 4, 5, 6, 11 through the real program: where and under which names flankcam writes.
#include <doctest/doctest.h>

#include <fmt/format.h>
#include <signal.h>
#include <sys/resource.h>
#include <sys/wait.h>
#include <unistd.h>

#include <cstdint>
#include <filesystem>

#include "core/blade.h"
#include "tests/test_util.h"

using namespace flankcam;
namespace fs = std::filesystem;

namespace {
const std::string kSmallPatchApt = std::string(TEST_DATA) + "/golden/small-patch.apt";

int entries(const fs::path& dir) {
  int n = 0;
  for (const auto& e : fs::directory_iterator(dir)) (void)e, ++n;
  return n;
}

// A job that reads (one triangle; it is refused before any fit) with the given patch names.
std::string quick_job(const test::ScratchDir& dir, const std::vector<std::string>& names) {
  test::write_text(dir.file("s.obj"), "v 0 0 0\nv 10 0 0\nv 0 10 0\nf 1 2 3\n");
  std::string job = "surface: s.obj\nmachine: xyzac-trt\npatches:\n";
  for (const std::string& n : names) job += "  - name: " + n + "\n    init: line\n    line: [0, 0, 5, 0, 0, 15]\n";
  test::write_text(dir.file("job.yaml"), job);
  return dir.file("job.yaml");
}

// A small blade and a one-patch run job without tool files (so report.html is the largest file).
std::string blade_job(const test::ScratchDir& dir) {
  REQUIRE(test::run_flankcam("blade --grid-chord 40 --grid-span 20 --out " + dir.file("blade"), dir).code == 0);
  BladeOptions o;
  o.grid_chord = 40, o.grid_span = 20;
  const auto lines = blade_lines(make_blade(o), 1, 5, 6, 1);
  std::string job =
      "surface: blade/blade.obj\ntool: {shape: cone}\ntolerance: 0.015\nsampling: {s: 20, t: 60}\n"
      "machine: xyzac-trt\npost: {dialects: [linuxcnc], tool: false}\npatches:\n  - name: p1\n    init: lines\n    lines:\n";
  for (const auto& l : lines[0]) job += fmt::format("      - [{}]\n", fmt::join(l, ", "));
  test::write_text(dir.file("job.yaml"), job);
  return dir.file("job.yaml");
}

// flankcam with `args`, files limited to `max_bytes` (SIGXFSZ ignored: the write fails with EFBIG).
int run_with_file_limit(const std::vector<std::string>& args, rlim_t max_bytes, const std::string& err) {
  const pid_t pid = fork();
  if (pid == 0) {
    signal(SIGXFSZ, SIG_IGN);
    const rlimit lim{max_bytes, max_bytes};
    setrlimit(RLIMIT_FSIZE, &lim);
    if (!freopen(err.c_str(), "w", stderr) || !freopen("/dev/null", "w", stdout)) _exit(98);
    std::vector<char*> argv{const_cast<char*>(FLANKCAM_BINARY)};
    for (const std::string& a : args) argv.push_back(const_cast<char*>(a.c_str()));
    argv.push_back(nullptr);
    execv(FLANKCAM_BINARY, argv.data());
    _exit(99);
  }
  int status = 0;
  waitpid(pid, &status, 0);
  return WIFEXITED(status) ? WEXITSTATUS(status) : -1;
}
}  // namespace

TEST_CASE("--out that is a file, under /proc or over-long: one line, exit 2, before any fit") {
  test::ScratchDir dir("out-refused");
  const std::string job = quick_job(dir, {"p1"});
  test::write_text(dir.file("plain"), "x");
  const struct {
    std::string out, message;
  } cases[] = {
      {dir.file("plain"), "exists and is not a folder"},
      {dir.file("plain/sub"), "is not a folder"},
      {"/proc/flankcam-out", "is under /proc"},
      {dir.file(std::string(5000, 'x')), "the path is 50"},
      {dir.file(std::string(300, 'x')), "a folder name is 300 characters long, the limit is 255"},
  };
  for (const auto& c : cases)
    for (const char* command : {"run", "fit"}) {
      CAPTURE(command);
      CAPTURE(c.message);
      // Without --quiet: a fit would print progress; the error must be the only line.
      const auto r = test::run_flankcam(fmt::format("{} {} --out {}", command, job, c.out), dir);
      CHECK(r.code == 2);
      CHECK(r.err.rfind("flankcam: error: --out ", 0) == 0);
      CHECK(r.err.find(c.message) != std::string::npos);
      CHECK(std::count(r.err.begin(), r.err.end(), '\n') == 1);
    }
  const auto r = test::run_flankcam("post " + kSmallPatchApt + " --machine xyzac-trt --out /proc/flankcam-out", dir);
  CHECK(r.code == 2);
  CHECK(r.err.find("is under /proc") != std::string::npos);
  CHECK(test::read_text(dir.file("plain")) == "x");
}

TEST_CASE("output names that clash or leave --out are refused with exit 2 and nothing written") {
  test::ScratchDir dir("out-names");
  const auto refused = [&](const std::string& args, const std::string& message) {
    CAPTURE(args);
    const auto r = test::run_flankcam(args + " --out " + dir.file("out"), dir);
    CHECK(r.code == 2);
    CHECK(r.err.find(message) != std::string::npos);
    CHECK(std::count(r.err.begin(), r.err.end(), '\n') == 1);
    CHECK(!fs::exists(dir.file("out")));
    CHECK(!fs::exists(dir.file("x.ngc")));
  };
  // A patch named all-patches would lose its program to the program of all patches.
  refused("run " + quick_job(dir, {"p1", "all-patches"}),
          "output name clash: all-patches.ngc would be written for the NC program of patch all-patches and for the program "
          "of all patches in order");
  fs::create_directories(dir.file("a"));
  fs::create_directories(dir.file("b"));
  test::write_text(dir.file("a/x.apt"), test::read_text(kSmallPatchApt));
  test::write_text(dir.file("b/x.apt"), test::read_text(kSmallPatchApt));
  test::write_text(dir.file("all.apt"), test::read_text(kSmallPatchApt));
  refused("post " + dir.file("a/x.apt") + " " + dir.file("b/x.apt") + " --machine xyzac-trt",
          "output name clash: x.ngc would be written for the program of " + dir.file("a/x.apt") + " and for the program of " +
              dir.file("b/x.apt"));
  refused("post " + dir.file("all.apt") + " " + dir.file("a/x.apt") + " --machine xyzac-trt",
          "output name clash: all.ngc would be written for the program of " + dir.file("all.apt") +
              " and for the program of all files in order (--name)");
  refused("post " + dir.file("a/x.apt") + " " + kSmallPatchApt + " --machine xyzac-trt --name ../x", "--name: '../x' starts with '.'");
  refused("post " + dir.file("a/x.apt") + " " + kSmallPatchApt + " --machine xyzac-trt --name sub/x", "--name: 'sub/x' contains '/'");
  // A different --name resolves the clash.
  const auto r = test::run_flankcam("post " + dir.file("all.apt") + " " + dir.file("a/x.apt") +
                                        " --machine xyzac-trt --name both --out " + dir.file("out"),
                                    dir);
  CHECK(r.code == 0);
  CHECK(fs::exists(dir.file("out/all.ngc")));
  CHECK(fs::exists(dir.file("out/x.ngc")));
  CHECK(fs::exists(dir.file("out/both.ngc")));
}

TEST_CASE("a planted symlink in an existing --out is replaced, never written through") {
  test::ScratchDir dir("out-symlink");
  fs::create_directories(dir.file("out"));
  test::write_text(dir.file("victim.txt"), "precious");
  for (const char* name : {"small-patch.ngc", "small-patch-tool.stl"})
    fs::create_symlink(dir.file("victim.txt"), dir.file(std::string("out/") + name));
  test::write_text(dir.file("out/mine.txt"), "kept");
  const auto r = test::run_flankcam("post " + kSmallPatchApt + " --machine xyzac-trt --out " + dir.file("out"), dir);
  CHECK(r.code == 0);
  CHECK(test::read_text(dir.file("victim.txt")) == "precious");
  CHECK(!fs::is_symlink(dir.file("out/small-patch.ngc")));
  CHECK(test::read_text(dir.file("out/small-patch.ngc")).find("G") != std::string::npos);
  CHECK(test::read_text(dir.file("out/mine.txt")) == "kept");
  CHECK(entries(dir.file("out")) == 3);  // no temporary file or folder left
}

TEST_CASE("a write failure late in a run leaves nothing: no folder, no programs, no temporary files" * doctest::test_suite("heavy")) {
  test::ScratchDir dir("out-late-failure");
  const std::string job = blade_job(dir);
  REQUIRE(test::run_flankcam("run " + job + " --out " + dir.file("ok") + " --quiet", dir).code == 0);
  // The NC programs are written first; a file size limit just below the largest file (a mesh or a
  // report) fails there, after the programs were written.
  std::string last;
  std::uintmax_t html = 0;
  for (const auto& e : fs::directory_iterator(dir.file("ok")))
    if (fs::file_size(e.path()) > html) html = fs::file_size(e.path()), last = e.path().filename().string();
  INFO(last);
  REQUIRE(fs::file_size(dir.file("ok/p1.ngc")) < html);
  const int before = entries(dir.path);
  const int code = run_with_file_limit({"run", job, "--out", dir.file("new/out"), "--quiet"}, html - 1, dir.file("err.txt"));
  const std::string err = test::read_text(dir.file("err.txt"));
  INFO(err);
  CHECK(code == 2);
  CHECK(err.find(last + ": write failed (File too large)") != std::string::npos);
  CHECK(!fs::exists(dir.file("new")));            // not even the parent it created
  CHECK(entries(dir.path) == before + 1);         // only err.txt is new

  // Into an existing folder: its files stay as they were, nothing is added.
  const int in_ok = entries(dir.file("ok"));
  const std::string program = test::read_text(dir.file("ok/p1.ngc"));
  test::write_text(dir.file("ok/p1.ngc"), "old program");
  CHECK(run_with_file_limit({"run", job, "--out", dir.file("ok"), "--quiet"}, html - 1, dir.file("err.txt")) == 2);
  CHECK(entries(dir.file("ok")) == in_ok);
  CHECK(test::read_text(dir.file("ok/p1.ngc")) == "old program");
  CHECK(program.find("G93") != std::string::npos);
}

TEST_CASE("a run stopped by SIGTERM or SIGINT leaves neither its output folder nor the private one nor parents it made") {
  test::ScratchDir dir("out-interrupted");
  const std::string job = blade_job(dir);
  for (const int sig : {SIGTERM, SIGINT}) {
    CAPTURE(sig);
    const fs::path made = dir.file("new"), out = made / "deeper" / "out";
    const std::string err = dir.file("err.txt");
    const pid_t pid = fork();
    if (pid == 0) {
      signal(SIGINT, SIG_DFL);  // a shell may have started the tests with SIGINT ignored
      signal(SIGTERM, SIG_DFL);
      if (!freopen(err.c_str(), "w", stderr) || !freopen("/dev/null", "w", stdout)) _exit(98);
      execl(FLANKCAM_BINARY, FLANKCAM_BINARY, "run", job.c_str(), "--out", out.c_str(), static_cast<char*>(nullptr));
      _exit(99);
    }
    // Once the run has made its private folder beside the target (the fit follows), it is stopped.
    int status = 0;
    bool stopped_early = false;
    for (;;) {
      std::error_code ec;
      bool staging = false;
      for (const auto& e : fs::directory_iterator(made / "deeper", ec))
        staging |= e.path().filename().string().rfind(".out.flankcam-", 0) == 0;
      if (staging) break;
      if (waitpid(pid, &status, WNOHANG) == pid) {
        stopped_early = true;  // finished (or failed) before it could be stopped
        break;
      }
      usleep(1000);
    }
    REQUIRE_FALSE(stopped_early);
    REQUIRE(kill(pid, sig) == 0);
    REQUIRE(waitpid(pid, &status, 0) == pid);
    REQUIRE(WIFEXITED(status));
    CHECK(WEXITSTATUS(status) == 128 + sig);
    CHECK(test::read_text(err).find("flankcam: interrupted") != std::string::npos);
    CHECK_FALSE(fs::exists(made));  // the private folder, the parents `new` and `deeper` it created: gone
  }
}
