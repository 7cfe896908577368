#include "postproc/report_svg.h"

#include <doctest/doctest.h>

#include <fmt/format.h>

#include <map>
#include <regex>

using namespace flankcam;

namespace {
// A flat 10 x 10 vertex grid, 1 mm apart, in the xy-plane.
TriMesh grid() {
  TriMesh m;
  for (int j = 0; j < 10; ++j)
    for (int i = 0; i < 10; ++i) m.vertices.emplace_back(i, j, 0);
  for (int j = 0; j < 9; ++j)
    for (int i = 0; i < 9; ++i) {
      const int a = j * 10 + i;
      m.faces.push_back({a, a + 1, a + 11});
      m.faces.push_back({a, a + 11, a + 10});
    }
  return m;
}
std::string hex(const std::array<unsigned char, 3>& c) { return fmt::format("#{:02x}{:02x}{:02x}", c[0], c[1], c[2]); }
// The picture's raster (the crispEdges group): drawn area per fill colour, in px^2.
std::map<std::string, double> raster_area(const std::string& svg) {
  const size_t begin = svg.find(R"(<g shape-rendering="crispEdges">)"), end = svg.find("</g>", begin);
  REQUIRE(begin != std::string::npos);
  const std::string raster = svg.substr(begin, end - begin);
  const std::regex rect(R"re(<rect x="[-0-9.]+" y="[-0-9.]+" width="([0-9.]+)" height="([0-9.]+)" fill="(#[0-9a-f]{6})"/>)re");
  std::map<std::string, double> area;
  for (auto it = std::sregex_iterator(raster.begin(), raster.end(), rect); it != std::sregex_iterator(); ++it)
    area[(*it)[3]] += std::stod((*it)[1]) * std::stod((*it)[2]);
  return area;
}
}  // namespace

TEST_CASE("the patch picture colours each point by the patch machining its nearest vertex and marks the uncovered band") {
  const TriMesh m = grid();
  std::vector<int> owner(m.vertices.size());
  for (size_t k = 0; k < owner.size(); ++k) {
    const double x = m.vertices[k].x();
    owner[k] = x < 4.5 ? 0 : (x < 5.5 ? -1 : 1);
  }
  const std::string svg = patch_owner_svg(m, owner, {"auto-1", "auto-2"}, "owners", 180);
  const auto area = raster_area(svg);
  double total = 0;
  for (const auto& [colour, a] : area) total += a;
  REQUIRE(total > 0);
  // Nearest-vertex regions: x in [0, 4.5] patch 0, [4.5, 5.5] none, [5.5, 9] patch 1.
  CHECK(area.at(hex(patch_color(0))) / total == doctest::Approx(4.5 / 9).epsilon(0.03));
  CHECK(area.at(hex(patch_color(-1))) / total == doctest::Approx(1.0 / 9).epsilon(0.1));
  CHECK(area.at(hex(patch_color(1))) / total == doctest::Approx(3.5 / 9).epsilon(0.03));
  CHECK(area.size() == 3);
  CHECK(svg.find(">auto-2</text>") != std::string::npos);
  CHECK(svg.find(">machined by no patch</text>") != std::string::npos);
  CHECK(hex(patch_color(0)) != hex(patch_color(1)));
}

TEST_CASE("the deviation picture colours within, over and under the tolerance and names what no patch reached") {
  const TriMesh m = grid();
  std::vector<double> dev(m.vertices.size());
  for (size_t k = 0; k < dev.size(); ++k) {
    const double y = m.vertices[k].y();
    dev[k] = y < 2.5 ? std::nan("") : (y < 6.5 ? 0.001 : -0.05);  // uncut, within 0.01, overcut
  }
  const std::string svg = deviation_map_svg(m, dev, 0.01, {}, {}, "union", 180, {}, "machined by no patch");
  const auto area = raster_area(svg);
  CHECK(area.count(hex(deviation_color(0.001, 0.01))) == 1);
  CHECK(area.count(hex(deviation_color(-0.05, 0.01))) == 1);
  CHECK(area.count(hex(deviation_color(NAN, 0.01))) == 1);
  CHECK(area.count(hex(deviation_color(0.05, 0.01))) == 0);  // nothing undercut
  CHECK(svg.find(">machined by no patch</text>") != std::string::npos);
}
