#include <doctest/doctest.h>

#include <string>

#include "core/errors.h"
#include "pipeline/job.h"
#include "tests/pipeline/job_error.h"
#include "tests/test_util.h"

using namespace flankcam;

namespace {
const char* patch = "patches:\n  - name: p\n    init: line\n    line: [0, 0, 0, 0, 0, 10]\n";

// The InputError message read_job gives for a job whose first line is `first`.
std::string error_of(const test::ScratchDir& dir, const std::string& first) {
  test::write_text(dir.file("s.obj"), "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n");
  test::write_text(dir.file("job.yaml"), first + "\nsurface: s.obj\n" + patch);
  return test::job_error(dir.file("job.yaml"));
}
}  // namespace

TEST_CASE("read_job bounds every value and names the file, line and key with the bound") {
  test::ScratchDir dir("job-ranges");
  const struct {
    const char* yaml;
    const char* message;
  } cases[] = {
      {"feed: 1e-300", "job.yaml:1: feed: must be in 0.01 .. 100000 mm/min, got 1e-300"},
      {"spindle: 1e300", "job.yaml:1: spindle: must be in 1 .. 200000 rpm, got 1e300"},
      {"lead_in: 1e300", "job.yaml:1: lead_in: must be in 0 .. 100000 mm"},
      {"retract: 1e-9", "job.yaml:1: retract: must be in 0.001 .. 100000 mm"},
      {"tolerance: 1e-300", "job.yaml:1: tolerance: must be in 1e-05 .. 100 mm"},
      {"clearance: 1e-9", "job.yaml:1: clearance: must be in 0.01 .. 1000 mm"},
      {"sampling: {s: 6, t: 100000}", "job.yaml:1: sampling.t: expected a whole number in 8..2000"},
      {"sampling: {s: 1000}", "job.yaml:1: sampling.s: expected a whole number in 4..200"},
      {"sampling: {s: 200, t: 2000}", "job.yaml:1: sampling: s x t = 400000 samples, at most 60000"},
      {"holder: {length: 1e9, diameter: 10}", "job.yaml:1: holder.length: must be in 0 .. 100000 mm"},
      {"holder: {shank_length: 10, shank_diameter: -1}", "job.yaml:1: holder.shank_diameter: must be in 0 .. 100000 mm"},
      {"post: {tolerance: 1e-300}", "job.yaml:1: post.tolerance: must be in 1e-05 .. 10 mm"},
      {"post: {angle_tolerance: 90}", "job.yaml:1: post.angle_tolerance: must be in 0.0001 .. 10 deg"},
      {"post: {safe_height: 1e300}", "job.yaml:1: post.safe_height: must be in 0 .. 100000 mm"},
      {"post: {tool_length: 1e300}", "job.yaml:1: post.tool_length: must be in 0.001 .. 100000 mm"},
      {"post: {setup: {rotate: [0, 0, 1e9]}}", "job.yaml:1: post.setup.rotate[2]: must be in -360 .. 360 deg"},
      {"post: {setup: {translate: [1e300, 0, 0]}}", "job.yaml:1: post.setup.translate[0]: must be in -1000000 .. 1000000 mm"},
      {"weights: {plane: 1e300}", "job.yaml:1: weights.plane: must be in 0 .. 1000000, got 1e300"},
      {"weights: {plane: 0, point: 0}", "job.yaml:1: weights: plane or point must be > 0"},
      {"fit: {robust: 1e300}", "job.yaml:1: fit.robust: must be in 0 .. 100000 mm"},
  };
  for (const auto& c : cases) {
    CAPTURE(c.yaml);
    const std::string message = error_of(dir, c.yaml);
    CAPTURE(message);
    CHECK(message.find(c.message) != std::string::npos);
    CHECK(message.find('\n') == std::string::npos);
  }
  // The defaults and the paper's values stay accepted.
  CHECK(error_of(dir, "sampling: {s: 30, t: 100}") == "(accepted)");
  CHECK(error_of(dir, "feed: 600") == "(accepted)");
}

TEST_CASE("read_job: a file name the system refuses (too long, control characters) is 'file not found' on its key") {
  // std::filesystem's throwing overloads aborted the program on such names (found by .ci/fuzz).
  test::ScratchDir dir("job-names");
  test::write_text(dir.file("s.obj"), "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n");
  const std::string long_name(5000, 'a');
  const struct {
    std::string yaml;
    const char* message;
  } cases[] = {
      {"surface: " + long_name + ".obj\n", "job.yaml:1: surface: file not found: "},
      {"surface: s.obj\npart: {file: " + long_name + "}\n", "job.yaml:2: part.file: file not found: "},
      {"surface: \"s\\x01\\n.obj\"\n", "job.yaml:1: surface: file not found: "},
  };
  for (const auto& c : cases) {
    test::write_text(dir.file("job.yaml"), c.yaml + patch);
    const std::string message = test::job_error(dir.file("job.yaml"));
    CAPTURE(message);
    CHECK(message.find(c.message) != std::string::npos);
    CHECK(message.find('\n') == std::string::npos);
    CHECK(message.size() < 400);  // the name is quoted, not copied whole
  }
  CHECK(test::job_error(dir.file(long_name + ".yaml")).find(": job file not found") != std::string::npos);
  // A job file that exists under such a name: its own errors quote the name escaped and cut too.
  const std::string odd = dir.file(std::string(230, 'j') + "\n\x01.yaml");
  CHECK(test::job_error(odd).find("job file not found") != std::string::npos);  // before it is written
  for (const std::string& yaml : {std::string("feed: 1e-300\nsurface: s.obj\n") + patch, std::string("- a list\n"),
                                   std::string("surface: s.obj\n"), std::string("feed: [1,\n")}) {
    CAPTURE(yaml);
    test::write_text(odd, yaml);
    const std::string message = test::job_error(odd);
    CAPTURE(message);
    CHECK(message.find('\n') == std::string::npos);
    CHECK(message.find('\x01') == std::string::npos);
    CHECK(message.size() < 400);
  }
}

TEST_CASE("rail and meridian control points: errors name the job's key and line, not FitOptions fields") {
  test::ScratchDir dir("job-control-points");
  const struct {
    const char* yaml;
    const char* message;
  } cases[] = {
      {"fit: {rail_control_points: 60}", "job.yaml:1: fit.rail_control_points: 60 is more than half of sampling.t = 100"},
      {"sampling: {t: 20}", "job.yaml:1: sampling.t: 20 is less than twice fit.rail_control_points = 16"},
      {"tool: {control_points: 50}", "job.yaml:1: tool.control_points: 50 is more than sampling.s = 30"},
      {"sampling: {s: 6}", "job.yaml:1: sampling.s: 6 is less than tool.control_points = 10"},
  };
  for (const auto& c : cases) {
    CAPTURE(c.yaml);
    const std::string message = error_of(dir, c.yaml);
    CAPTURE(message);
    CHECK(message.find(c.message) != std::string::npos);
    CHECK(message.find("meridian_control_points") == std::string::npos);
  }
  CHECK(error_of(dir, "fit: {rail_control_points: 8}\nsampling: {t: 16}") == "(accepted)");
}

TEST_CASE("read_job: patches auto with cover options, and surface given as a mapping") {
  test::ScratchDir dir("job-auto");
  test::write_text(dir.file("s.obj"), "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n");
  test::write_text(dir.file("job.yaml"), "surface: {file: s.obj}\ncover: {coverage: 0.8, max_patches: 3, exchanges: 0, regions: 0}\npatches: auto\n");
  const pipeline::Job job = pipeline::read_job(dir.file("job.yaml"));
  CHECK(job.surface.filename() == "s.obj");
  CHECK(job.patches.empty());
  REQUIRE(job.cover.has_value());
  CHECK(job.cover->coverage == 0.8);
  CHECK(job.cover->max_patches == 3);
  CHECK(job.cover->exchanges == 0);
  CHECK(job.cover->regions == 0);
  test::write_text(dir.file("job2.yaml"), "surface: s.obj\npatches: auto\n");
  const pipeline::Job defaults = pipeline::read_job(dir.file("job2.yaml"));
  REQUIRE(defaults.cover.has_value());
  CHECK(defaults.cover->coverage == 0.95);
  CHECK(defaults.cover->max_patches == 8);
  CHECK(defaults.cover->exchanges == 3);
  CHECK(defaults.cover->regions == 2);
  test::write_text(dir.file("job3.yaml"), "surface: s.obj\npatches: auto\ncover: {exchanges: 17}\n");
  CHECK(test::job_error(dir.file("job3.yaml")).find(dir.file("job3.yaml") + ":3: cover.exchanges") == 0);
  test::write_text(dir.file("job5.yaml"), "surface: s.obj\npatches: auto\ncover: {regions: -1}\n");
  CHECK(test::job_error(dir.file("job5.yaml")).find(dir.file("job5.yaml") + ":3: cover.regions") == 0);
  test::write_text(dir.file("job4.yaml"), "surface: s.obj\npatches: auto\ncover: 0.9\n");
  CHECK(test::job_error(dir.file("job4.yaml")) ==
        dir.file("job4.yaml") + ":3: cover: expected {coverage: 0.95, max_patches: 8, exchanges: 3, regions: 2}");
  CHECK(error_of(dir, "cover: {max_patches: 3}") == dir.file("job.yaml") + ":1: cover: only with patches: auto");
}
