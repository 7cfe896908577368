#include <doctest/doctest.h>

#include <omp.h>
#include <sys/wait.h>

#include <filesystem>
#include <nlohmann/json.hpp>
#include <stdexcept>

#include "pipeline/data_dir.h"
#include "pipeline/run.h"
#include "tests/test_util.h"

using namespace flankcam;
namespace fs = std::filesystem;

TEST_CASE("--threads reaches the OpenMP loops of the fit, and the previous count is restored after it") {
  test::ScratchDir dir("threads");
  test::write_text(dir.file("s.obj"), "v 0 0 0\nv 10 0 0\nv 0 10 0\nf 1 2 3\n");
  test::write_text(dir.file("job.yaml"), "surface: s.obj\npatches:\n  - name: p\n    init: line\n    line: [0, 0, 5, 0, 0, 15]\n");
  const int before = omp_get_max_threads();
  for (const int threads : {1, 3}) {
    CAPTURE(threads);
    pipeline::RunOptions o;
    o.threads = threads;
    int seen = 0;
    // The first progress line comes from inside the fit; stop there.
    o.progress = [&](const std::string&) {
      seen = omp_get_max_threads();
      throw std::runtime_error("stop");
    };
    CHECK_THROWS_WITH(pipeline::fit(pipeline::read_job(dir.file("job.yaml")), o), "stop");
    CHECK(seen == threads);
    CHECK(omp_get_max_threads() == before);
  }
  pipeline::RunOptions o;
  o.threads = 0;
  CHECK(o.validate() == "threads: 1 .. 256");
}

TEST_CASE("the shipped machines are found from the build tree") {
  const fs::path dir = pipeline::machines_dir();
  CHECK(fs::is_regular_file(dir / "xyzac-trt.yaml"));
  CHECK(pipeline::tools_dir() == dir / "tools");
}

TEST_CASE("cmake --install: the installed flankcam runs the bundled example from another folder") {
  test::ScratchDir dir("install");
  const std::string prefix = dir.file("prefix");
  const std::string install = std::string("\"") + CMAKE_COMMAND + "\" --install \"" + FLANKCAM_BUILD_DIR + "\" --prefix \"" +
                              prefix + "\" > " + dir.file("install.log") + " 2>&1";
  const int installed = std::system(install.c_str());
  INFO(test::read_text(dir.file("install.log")));
  REQUIRE(WIFEXITED(installed));
  REQUIRE(WEXITSTATUS(installed) == 0);
  REQUIRE(fs::is_regular_file(prefix + "/share/flankcam/machines/xyzac-trt.yaml"));
  // From an unrelated folder, the job by absolute path, the machine by its shipped name.
  fs::create_directories(dir.file("elsewhere"));
  const std::string run = "cd \"" + dir.file("elsewhere") + "\" && \"" + prefix + "/bin/flankcam\" run \"" + FLANKCAM_SOURCE_DIR +
                          "/examples/conical-tool/job.yaml\" --out out --quiet > run.log 2>&1";
  const int ran = std::system(run.c_str());
  INFO(test::read_text(dir.file("elsewhere/run.log")));
  REQUIRE(WIFEXITED(ran));
  CHECK(WEXITSTATUS(ran) == 0);
  const auto report = nlohmann::json::parse(test::read_text(dir.file("elsewhere/out/report.json")));
  // The machine came from the installed share/flankcam, not from the source tree.
  const std::string machine = report["machine"]["file"];
  CHECK(machine == fs::weakly_canonical(prefix + "/share/flankcam/machines/xyzac-trt.yaml").string());
  CHECK(fs::exists(dir.file("elsewhere/out/cone-3.ngc")));
}
