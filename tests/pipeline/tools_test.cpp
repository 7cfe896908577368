// Tools in jobs (issue 15): constraints enforced in the fit, the catalogue, one shared tool,
// allowance and overtravel, the grinding sheet. Exact envelopes are the ground truth.
#include <doctest/doctest.h>

#include <fmt/format.h>

#include <cmath>
#include <map>
#include <sstream>
#include <string>

#include "core/errors.h"
#include "core/machined_surface.h"
#include "pipeline/data_dir.h"
#include "pipeline/run.h"
#include "pipeline/tool_catalogue.h"
#include "postproc/tool_export.h"
#include "tests/test_util.h"

using namespace flankcam;

namespace {
// The exact envelope of `profile` (mm) under the analytic `motion` of axis length `length_mm`,
// written as DIR/surface.obj, and a job that fits it from lines through the true axis at `ts`.
struct EnvelopeJob {
  LineMotion motion;
  TriMesh mesh;  // mm
  double diagonal_mm = 0;
};
EnvelopeJob envelope_job(const test::ScratchDir& dir, const char* motion, const RadiusProfile& profile, double length_mm) {
  AnalyticMotionOptions o;
  o.kind = motion;
  o.length = length_mm;
  EnvelopeJob e;
  e.motion = analytic_motion(o);
  e.mesh = envelope_grid(e.motion, profile, 66, 200, 1).mesh;
  e.diagonal_mm = bounding_box(e.mesh.vertices).diagonal();
  write_obj(dir.file("surface.obj"), e.mesh);
  return e;
}
std::string patch_yaml(const EnvelopeJob& e, const std::string& name, const std::vector<double>& ts) {
  std::string y = fmt::format("  - name: {}\n    init: lines\n    lines:\n", name);
  for (double t : ts) {
    const Eigen::Vector3d a = e.motion.a(t), b = e.motion.b(t);
    y += fmt::format("      - [{}, {}, {}, {}, {}, {}]\n", a.x(), a.y(), a.z(), b.x(), b.y(), b.z());
  }
  return y;
}
pipeline::FitRun fit_job_file(const test::ScratchDir& dir, const std::string& yaml) {
  test::write_text(dir.file("job.yaml"), yaml);
  return pipeline::fit(pipeline::read_job(dir.file("job.yaml")), {});
}
std::string error_of(const test::ScratchDir& dir, const std::string& yaml) {
  test::write_text(dir.file("job.yaml"), yaml);
  try {
    (void)pipeline::read_job(dir.file("job.yaml"));
  } catch (const InputError& e) {
    return e.what();
  }
  return "(accepted)";
}
}  // namespace

TEST_CASE("the shipped tool catalogue reads: five families, standard sizes, flanks off the axis") {
  const std::vector<pipeline::CatalogueTool> all = pipeline::read_catalogue(pipeline::tools_dir());
  std::map<std::string, int> per_family;
  for (const pipeline::CatalogueTool& t : all) {
    CAPTURE(t.name);
    ++per_family[t.family];
    const std::vector<Eigen::Vector2d> zr = t.meridian_mm();
    CHECK(zr.front().x() == 0);
    CHECK(zr.back().x() == doctest::Approx(t.length_mm));
    double rmax = 0;
    for (const auto& p : zr) {
      CHECK(p.y() > 0);
      rmax = std::max(rmax, p.y());
    }
    if (t.family != "taper") CHECK(2 * rmax == doctest::Approx(t.diameter_mm).epsilon(1e-3));
    else CHECK(2 * zr.front().y() == doctest::Approx(t.tip_diameter_mm));
  }
  for (const char* f : {"cylinder", "taper", "barrel", "lens", "oval"}) {
    CAPTURE(f);
    CHECK(per_family[f] >= 4);
  }
}

TEST_CASE("tool catalogue errors name the file, the line and the key") {
  test::ScratchDir dir("catalogue-errors");
  const struct {
    const char* yaml;
    const char* expect;
  } cases[] = {
      {"family: cylinder\ntools:\n  - {name: a, diameter: 6, length: 20, flutes: 4}\n", ":3: tools[0].flutes: unknown key"},
      {"family: cylinder\ntools:\n  - {name: a, length: 20}\n", ":3: tools[0].diameter: missing"},
      {"family: drill\ntools:\n  - {name: a}\n", ":1: family: unknown family 'drill'"},
      {"family: barrel\ntools:\n  - {name: a, diameter: 12, profile_radius: 10, length: 30}\n",
       ":3: tools[0].profile_radius: 10 mm is too small"},
      {"family: taper\ntools:\n  - {name: a, tip_diameter: 6, half_angle: 60, length: 30}\n",
       ":3: tools[0].half_angle: must be in 0..45 deg"},
      {"family: oval\ntools:\n  - {name: a, diameter: 4, profile_radius: 8, widest_at: 5, length: 12}\n",
       ":3: tools[0]: the flank reaches the axis"},
      {"family: cylinder\ntools:\n  - {name: a, diameter: 6, length: 20}\n  - {name: a, diameter: 8, length: 20}\n",
       ":4: name: tool 'a' is also defined at"},
  };
  for (const auto& c : cases) {
    CAPTURE(c.yaml);
    test::write_text(dir.file("t.yaml"), c.yaml);
    std::string msg = "(accepted)";
    try {
      (void)pipeline::read_catalogue(dir.path);
    } catch (const InputError& e) {
      msg = e.what();
    }
    CAPTURE(msg);
    CHECK(msg.find(dir.file("t.yaml") + c.expect) != std::string::npos);
  }
}

TEST_CASE("tool keys in a job: limits, catalogue and shared are checked with file, line and key") {
  test::ScratchDir dir("tool-keys");
  test::write_text(dir.file("s.obj"), "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n");
  const std::string rest = "surface: s.obj\npatches:\n  - name: p\n    init: line\n    line: [0, 0, 0, 0, 0, 10]\n";
  const struct {
    const char* tool;
    const char* expect;
  } cases[] = {
      {"tool: {min_diameter: 12, max_diameter: 10}", ":1: tool.min_diameter: 12 mm is larger than tool.max_diameter"},
      {"tool: {max_cone_angle: 95}", ":1: tool.max_cone_angle: must be in 0 .. 90 deg"},
      {"tool: {catalogue: no-such-tool}", ":1: tool.catalogue: no tool 'no-such-tool' in the catalogue"},
      {"tool: {catalogue: cyl-d6-l20, shape: cone}", ":1: tool.shape: not with tool.catalogue"},
      {"tool: {catalogue: cyl-d6-l20, max_diameter: 8}", ":1: tool.max_diameter: not with tool.catalogue"},
      {"tool: {shared: 3}", ":1: tool.shared: expected true or false"},
      {"tool: {convex: yes, diameter: 3}", ":1: tool.diameter: unknown key"},
      {"allowance: -0.1", ":1: allowance: must be in 0 .. 100 mm"},
      {"overtravel: x", ":1: overtravel: expected a number"},
  };
  for (const auto& c : cases) {
    CAPTURE(c.tool);
    const std::string msg = error_of(dir, std::string(c.tool) + "\n" + rest);
    CAPTURE(msg);
    CHECK(msg.find(dir.file("job.yaml") + c.expect) != std::string::npos);
  }
  const pipeline::Job ok = [&] {
    test::write_text(dir.file("job.yaml"), "tool: {catalogue: barrel-d16-r150-l40, shared: true}\nallowance: 0.3\n" + rest);
    return pipeline::read_job(dir.file("job.yaml"));
  }();
  REQUIRE(ok.tool.catalogue);
  CHECK(ok.tool.catalogue->family == "barrel");
  CHECK(ok.tool.catalogue->profile_radius_mm == 150);
  CHECK(ok.tool.shared);
  CHECK(ok.allowance_mm == 0.3);
}
