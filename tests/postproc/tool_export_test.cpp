#include "postproc/tool_export.h"

#include <doctest/doctest.h>

#include <map>
#include <sstream>

#include "tests/test_util.h"

using namespace flankcam;

namespace {
struct DxfLine {
  std::string layer;
  Eigen::Vector2d p, q;
};
// A small DXF reader: group code / value pairs, LINE entities of the ENTITIES section.
std::vector<DxfLine> read_dxf_lines(const std::string& text, std::string* version) {
  std::istringstream in(text);
  std::vector<std::pair<int, std::string>> groups;
  std::string code, value;
  while (std::getline(in, code) && std::getline(in, value)) groups.emplace_back(std::stoi(code), value);
  std::vector<DxfLine> lines;
  for (size_t k = 0; k < groups.size(); ++k) {
    if (groups[k].first == 9 && groups[k].second == "$ACADVER") *version = groups[k + 1].second;
    if (groups[k].first != 0 || groups[k].second != "LINE") continue;
    DxfLine l;
    std::map<int, double> v;
    for (size_t j = k + 1; j < groups.size() && groups[j].first != 0; ++j) {
      if (groups[j].first == 8)
        l.layer = groups[j].second;
      else
        v[groups[j].first] = std::stod(groups[j].second);
    }
    l.p = {v[10], v[20]};
    l.q = {v[11], v[21]};
    lines.push_back(l);
  }
  return lines;
}
}  // namespace

TEST_CASE("tool DXF (R12): the profile read back within 1 µm, connected, closed over the axis") {
  std::vector<Eigen::Vector2d> profile;
  for (int k = 0; k <= 60; ++k) {
    const double z = -0.3 + 40.3 * k / 60;
    profile.emplace_back(z, 6 + 3 * z / 40 + 0.8 * std::sin(z / 40 * M_PI) + 1e-7 * k);  // a barrel, odd digits
  }
  test::ScratchDir dir("dxf");
  write_tool_dxf(dir.file("tool.dxf"), profile, "patch p, general tool");
  std::string version;
  const auto lines = read_dxf_lines(test::read_text(dir.file("tool.dxf")), &version);
  CHECK(version == "AC1009");
  REQUIRE(lines.size() == profile.size() + 2);
  for (size_t k = 1; k + 1 < lines.size(); ++k) CHECK((lines[k].q - lines[k + 1].p).norm() == 0);  // connected
  CHECK((lines.back().q - lines.front().p).norm() == 0);                                              // closed
  CHECK(lines.back().layer == "AXIS");
  CHECK(lines.front().p.y() == 0);
  double worst = 0;
  for (size_t k = 0; k < profile.size(); ++k) worst = std::max(worst, (lines[k].q - profile[k]).norm());
  CHECK(worst < 1e-6);
  const ToolDimensions d = tool_dimensions(profile);
  CHECK(d.length_mm == doctest::Approx(40.3));
  CHECK(d.diameter_max_mm > d.diameter_min_mm);
  CHECK(d.diameter_min_mm == doctest::Approx(2 * profile.front().y()));
}
