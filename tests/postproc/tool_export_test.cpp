#include "postproc/tool_export.h"

#include <doctest/doctest.h>

#include <Eigen/Geometry>
#include <map>
#include <sstream>

#include "core/tool_end.h"
#include "postproc/verify.h"
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

TEST_CASE("tool STL for simulators: a closed, outward solid with the frustum's volume") {
  // Cone tool r 6 -> 9 over 40 mm: V = pi h (r1^2 + r1 r2 + r2^2) / 3, times n sin(2 pi / n) / (2 pi) for n facets.
  std::vector<Eigen::Vector2d> profile;
  for (int k = 0; k <= 4; ++k) profile.emplace_back(10.0 * k, 6 + 0.75 * k);
  const int n = 180;
  const std::string text = tool_stl(profile, "cone");
  std::istringstream in(text);
  std::string word;
  std::vector<Eigen::Vector3d> v;
  while (in >> word)
    if (word == "vertex") {
      Eigen::Vector3d p;
      in >> p.x() >> p.y() >> p.z();
      v.push_back(p);
    }
  REQUIRE(v.size() % 3 == 0);
  CHECK(v.size() / 3 == size_t(n) * (2 * 4 + 2));
  double volume = 0;  // divergence theorem: sum of signed tetrahedra from the origin
  std::map<std::pair<std::array<long, 3>, std::array<long, 3>>, int> edges;
  const auto key = [](const Eigen::Vector3d& p) {
    return std::array<long, 3>{std::lround(p.x() * 1e5), std::lround(p.y() * 1e5), std::lround(p.z() * 1e5)};
  };
  for (size_t f = 0; f < v.size(); f += 3) {
    volume += v[f].dot(v[f + 1].cross(v[f + 2])) / 6;
    for (int e = 0; e < 3; ++e) ++edges[{key(v[f + size_t(e)]), key(v[f + size_t((e + 1) % 3)])}];
  }
  const double exact = M_PI * 40 * (36 + 54 + 81) / 3 * n * std::sin(2 * M_PI / n) / (2 * M_PI);
  CHECK(volume == doctest::Approx(exact).epsilon(1e-5));
  // Closed and consistently oriented: every directed edge once, its reverse once.
  int bad = 0;
  for (const auto& [e, count] : edges) bad += count != 1 || !edges.count({e.second, e.first});
  CHECK(bad == 0);
}

TEST_CASE("tool files with the end: the ball's DXF profile starts on the axis, the corner's runs through its arc, the STL stays closed") {
  std::vector<Eigen::Vector2d> side;
  for (int k = 0; k <= 40; ++k) side.emplace_back(0.5 * k, 5.0);  // cylinder r 5, 20 mm
  const EndProfile ball = end_profile(side, {EndKind::Ball, 0, 1}, 16), bull = end_profile(side, {EndKind::Corner, 2, 1}, 16);
  std::string version;
  const auto ball_lines = read_dxf_lines(tool_dxf(ball.profile, "ball"), &version);
  REQUIRE(ball_lines.size() == ball.profile.size() + 1);  // no tip face: the profile itself leaves the axis
  CHECK(ball_lines.front().p == Eigen::Vector2d(0, 0));
  for (size_t k = 0; k < 16; ++k) CHECK((ball_lines[k].q - Eigen::Vector2d(5, 0)).norm() == doctest::Approx(5).epsilon(1e-6));
  const auto bull_lines = read_dxf_lines(tool_dxf(bull.profile, "corner"), &version);
  REQUIRE(bull_lines.size() == bull.profile.size() + 2);
  CHECK(bull_lines.front().p == Eigen::Vector2d(0, 0));
  CHECK((bull_lines.front().q - Eigen::Vector2d(0, 3)).norm() < 1e-6);  // the tip face keeps r 5 - 2
  for (size_t k = 1; k <= 16; ++k) CHECK((bull_lines[k].q - Eigen::Vector2d(2, 3)).norm() == doctest::Approx(2).epsilon(1e-6));
  // The checks' cutter from a ball profile whose tip plane lies a little above z = 0 (a fitted
  // meridian's first point): one point on the axis at the tip, then the arc.
  std::vector<Eigen::Vector2d> lifted = ball.profile;
  for (Eigen::Vector2d& q : lifted) q.x() += 0.05;
  const ToolAssembly a = assembly_from_meridian(lifted, ToolAssembly{});
  CHECK(a.validate().empty());
  CHECK(a.cutter.front() == Eigen::Vector2d(0, 0));
  CHECK(a.cutter[1] == lifted[1]);
  const ToolDimensions d = tool_dimensions(ball.profile, ball.end_points);
  CHECK(d.diameter_min_mm == doctest::Approx(10));
  CHECK(d.cone_half_angle_deg == doctest::Approx(0).epsilon(1e-9));
  CHECK(d.length_mm == doctest::Approx(20));

  // STL of the ball-end tool: closed, and its volume the cylinder above the ball plus the half ball
  // (the 16-segment arc and 180 facets: within 1%).
  const std::string text = tool_stl(ball.profile, "ball");
  std::istringstream in(text);
  std::string word;
  std::vector<Eigen::Vector3d> v;
  while (in >> word)
    if (word == "vertex") {
      Eigen::Vector3d p;
      in >> p.x() >> p.y() >> p.z();
      v.push_back(p);
    }
  double volume = 0;
  std::map<std::pair<std::array<long, 3>, std::array<long, 3>>, int> edges;
  const auto key = [](const Eigen::Vector3d& p) {
    return std::array<long, 3>{std::lround(p.x() * 1e5), std::lround(p.y() * 1e5), std::lround(p.z() * 1e5)};
  };
  for (size_t f = 0; f < v.size(); f += 3) {
    volume += v[f].dot(v[f + 1].cross(v[f + 2])) / 6;
    for (int e = 0; e < 3; ++e) ++edges[{key(v[f + size_t(e)]), key(v[f + size_t((e + 1) % 3)])}];
  }
  CHECK(volume == doctest::Approx(M_PI * 25 * 15 + 2.0 / 3 * M_PI * 125).epsilon(1e-2));
  int bad = 0;
  for (const auto& [e, count] : edges) bad += count != 1 || !edges.count({e.second, e.first});
  CHECK(bad == 0);
}
