#include <doctest/doctest.h>

#include <cstdlib>
#include <fstream>
#include <nlohmann/json.hpp>

#include "core/closest_point.h"
#include "tests/test_util.h"

using namespace flankcam;

namespace {
int run(const std::string& args) {
  const std::string cmd = std::string(FLANKCAM_BINARY) + " " + args + " > /dev/null 2>&1";
  const int status = std::system(cmd.c_str());
  return WIFEXITED(status) ? WEXITSTATUS(status) : -1;
}
}  // namespace

TEST_CASE("flankcam envelope writes a mesh whose truth axis lies at distance d(s) from it") {
  test::ScratchDir dir("cli-envelope");
  for (const char* profile : {"cylinder", "cone", "barrel", "spline"}) {
    CAPTURE(profile);
    const std::string out = dir.file(profile);
    REQUIRE(run(std::string("envelope --profile ") + profile + " --motion s-curve --grid-s 31 --grid-t 121 --out " + out) == 0);
    const nlohmann::json truth = nlohmann::json::parse(std::ifstream(out + "/truth.json"));
    const SurfaceIndex index(load_mesh(out + "/envelope.obj").mesh);
    const auto& axis = truth["axis"];
    const auto& radius = truth["radius"];
    REQUIRE(axis.size() == 121);
    REQUIRE(radius.size() == 31);
    CHECK(truth["folded_triangles"] == 0);
    const double L = truth["length"];
    double worst = 0;
    for (size_t i = 6; i + 6 < axis.size(); i += 5) {
      const Eigen::Vector3d a(axis[i][0], axis[i][1], axis[i][2]), b(axis[i][3], axis[i][4], axis[i][5]);
      CHECK((b - a).norm() == doctest::Approx(L));
      for (size_t j = 0; j < radius.size(); j += 3) {
        const double s = double(j) / (radius.size() - 1);
        worst = std::max(worst, std::abs(index.closest((1 - s) * a + s * b).distance - double(radius[j])));
      }
    }
    CHECK(worst < 0.05);  // tessellation of a 1.3 mm x 1.0 mm grid on radii >= 5 mm
  }
}

TEST_CASE("flankcam envelope rejects bad options with a non-zero exit and writes nothing") {
  test::ScratchDir dir("cli-envelope-bad");
  CHECK(run("envelope --profile hyperboloid --out " + dir.file("a")) == 2);
  CHECK(run("envelope --motion loop --out " + dir.file("b")) == 2);
  CHECK(run("envelope --profile cone --radius-end 60 --out " + dir.file("c")) == 2);  // no characteristic
  CHECK(run("envelope --length -3 --out " + dir.file("d")) == 2);
  CHECK(run("envelope --grid-s 1 --out " + dir.file("e")) == 2);
  // Usage errors (CLI11's own exit codes are 105-109) end like any other bad input.
  CHECK(run("envelope --no-such-option 3 --out " + dir.file("f")) == 2);
  CHECK(run("envelope --grid-s abc --out " + dir.file("g")) == 2);
  CHECK(run("run --job x.yaml --out " + dir.file("h")) == 2);
  CHECK(run("envelope --help") == 0);
  for (const char* d : {"a", "b", "c", "d", "e", "f", "g", "h"}) CHECK_FALSE(std::filesystem::exists(dir.file(d) + "/envelope.obj"));
}
