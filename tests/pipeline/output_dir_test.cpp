#include <doctest/doctest.h>

#include <unistd.h>

#include <filesystem>
#include <string>

#include "core/atomic_file.h"
#include "core/errors.h"
#include "pipeline/output_dir.h"
#include "tests/test_util.h"

using namespace flankcam;
namespace fs = std::filesystem;

namespace {
int entries(const fs::path& dir) {
  int n = 0;
  for (const auto& e : fs::directory_iterator(dir)) (void)e, ++n;
  return n;
}
void write(pipeline::OutputDir& out, const std::string& name, const std::string& text) {
  write_file_atomically(out.file(name), [&](std::ostream& o) { o << text; });
}
std::string error_of(const std::function<void()>& f) {
  try {
    f();
  } catch (const InputError& e) {
    return e.what();
  }
  return "(accepted)";
}
}  // namespace

TEST_CASE("OutputDir: a new folder appears complete at commit, and not at all without it") {
  test::ScratchDir dir("outdir-new");
  {
    pipeline::OutputDir out(dir.file("a/b/out"));
    write(out, "one.txt", "1");
    write(out, "two.txt", "2");
    CHECK(!fs::exists(dir.file("a/b/out")));  // nothing visible before the commit
    out.commit();
  }
  CHECK(test::read_text(dir.file("a/b/out/one.txt")) == "1");
  CHECK(test::read_text(dir.file("a/b/out/two.txt")) == "2");
  CHECK(entries(dir.file("a/b")) == 1);  // the private folder is gone
  CHECK(entries(dir.file("a/b/out")) == 2);
  const auto perms = fs::status(dir.file("a/b/out")).permissions();
  CHECK((perms & fs::perms::owner_all) == fs::perms::owner_all);
  CHECK((perms & fs::perms::others_read) != fs::perms::none);  // not mkdtemp's 0700

  // A failure after some files were written: the folder and the parents it created disappear.
  CHECK(error_of([&] {
          pipeline::OutputDir out(dir.file("c/d/out"));
          write(out, "one.txt", "1");
          throw InputError("late failure");
        }) == "late failure");
  CHECK(!fs::exists(dir.file("c")));
  CHECK(entries(dir.path) == 1);  // only a/
}

TEST_CASE("OutputDir: into an existing folder only at commit, other files kept, planted symlinks replaced not followed") {
  test::ScratchDir dir("outdir-existing");
  fs::create_directories(dir.file("out"));
  test::write_text(dir.file("out/keep.txt"), "mine");
  test::write_text(dir.file("victim.txt"), "precious");
  fs::create_symlink(dir.file("victim.txt"), dir.file("out/report.json"));  // planted at a name flankcam writes
  CHECK(error_of([&] {
          pipeline::OutputDir out(dir.file("out"));
          write(out, "report.json", "{}");
          throw InputError("late failure");
        }) == "late failure");
  CHECK(entries(dir.file("out")) == 2);  // keep.txt and the symlink, no private folder left
  CHECK(fs::is_symlink(dir.file("out/report.json")));
  {
    pipeline::OutputDir out(dir.file("out"));
    write(out, "report.json", "{}");
    out.commit();
  }
  CHECK(test::read_text(dir.file("victim.txt")) == "precious");
  CHECK(!fs::is_symlink(dir.file("out/report.json")));
  CHECK(test::read_text(dir.file("out/report.json")) == "{}");
  CHECK(test::read_text(dir.file("out/keep.txt")) == "mine");
  CHECK(entries(dir.file("out")) == 2);
}

TEST_CASE("OutputDir refuses a file, /proc, an over-long path and bad or repeated file names before writing") {
  test::ScratchDir dir("outdir-refuse");
  test::write_text(dir.file("plain"), "x");
  CHECK(error_of([&] { pipeline::OutputDir out(dir.file("plain")); }).find("exists and is not a folder") != std::string::npos);
  CHECK(error_of([&] { pipeline::OutputDir out(dir.file("plain/sub")); }).find("--out ") == 0);
  CHECK(error_of([] { pipeline::OutputDir out("/proc/self/flankcam"); }).find("is under /proc") != std::string::npos);
  CHECK(error_of([] { pipeline::OutputDir out("/proc"); }).find("is under /proc") != std::string::npos);
  const std::string long_path = dir.file(std::string(5000, 'x'));
  const std::string e = error_of([&] { pipeline::OutputDir out(long_path); });
  CHECK(e.find("the path is 50") != std::string::npos);
  CHECK(e.size() < 200);  // the message quotes only the start of the path
  CHECK(error_of([&] { pipeline::OutputDir out(dir.file(std::string(300, 'y'))); }).find("a folder name is 300 characters") !=
        std::string::npos);
  CHECK(entries(dir.path) == 1);

  pipeline::OutputDir out(dir.file("out"));
  for (const char* bad : {"../x", "a/b", ".hidden", "", ".."}) {
    CAPTURE(bad);
    CHECK(error_of([&] { (void)out.file(bad); }) != "(accepted)");
  }
  (void)out.file("x.ngc");
  CHECK(error_of([&] { (void)out.file("x.ngc"); }).find("output name clash: x.ngc would be written twice") == 0);
  pipeline::OutputPlan plan;
  plan.add("all-patches.ngc", "the NC program of patch all-patches");
  CHECK(error_of([&] { plan.add("all-patches.ngc", "the program of all patches in order"); }) ==
        "output name clash: all-patches.ngc would be written for the NC program of patch all-patches and for the program "
        "of all patches in order (rename one of them)");
}

TEST_CASE("temporary files are created exclusively: a planted symlink makes the write fail or is replaced, never followed") {
  test::ScratchDir dir("atomic-symlink");
  test::write_text(dir.file("victim.txt"), "precious");
  // The old predictable temporary name (.<stem>.tmp<PID><ext>) and the final name both planted.
  fs::create_symlink(dir.file("victim.txt"), dir.file(".report.tmp" + std::to_string(::getpid()) + ".json"));
  CHECK_THROWS_AS((void)create_exclusive(dir.file(".report.tmp" + std::to_string(::getpid()) + ".json")), InputError);
  fs::create_symlink(dir.file("victim.txt"), dir.file("dangling-free.json"));
  CHECK_THROWS_AS((void)create_exclusive(dir.file("dangling-free.json")), InputError);
  fs::create_symlink(dir.file("nowhere.txt"), dir.file("dangling.json"));
  CHECK_THROWS_AS((void)create_exclusive(dir.file("dangling.json")), InputError);
  CHECK(!fs::exists(dir.file("nowhere.txt")));  // O_NOFOLLOW: the dangling link's target was not created
  write_file_atomically(dir.file("report.json"), [](std::ostream& o) { o << "new"; });
  fs::create_symlink(dir.file("victim.txt"), dir.file("link.json"));
  write_file_atomically(dir.file("link.json"), [](std::ostream& o) { o << "new"; });
  CHECK(test::read_text(dir.file("victim.txt")) == "precious");
  CHECK(test::read_text(dir.file("report.json")) == "new");
  CHECK(!fs::is_symlink(dir.file("link.json")));
  // No temporary file is left next to them.
  CHECK(entries(dir.path) == 6);
}
