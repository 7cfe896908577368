#include "postproc/tool_export.h"

#include <Eigen/Geometry>
#include <fmt/format.h>

#include <cmath>

#include "core/atomic_file.h"
#include "core/errors.h"
#include "core/number_format.h"
#include "core/tool_end.h"

namespace flankcam {

ToolDimensions tool_dimensions(const std::vector<Eigen::Vector2d>& p, int end_points) {
  if (p.size() < 2) throw InputError("tool profile: at least two points");
  if (end_points < 0 || size_t(end_points) + 2 > p.size()) throw InputError("tool profile: the end leaves no side");
  ToolDimensions d;
  d.length_mm = p.back().x() - std::min(0.0, p.front().x());
  d.diameter_min_mm = INFINITY;
  for (size_t k = size_t(end_points); k < p.size(); ++k) {
    d.diameter_min_mm = std::min(d.diameter_min_mm, 2 * p[k].y());
    d.diameter_max_mm = std::max(d.diameter_max_mm, 2 * p[k].y());
  }
  // The taper over the side's middle half: a tool that is the union of its spheres rounds off at its
  // ends (within d sin(half angle) of them), so its end diameters understate a cone's angle.
  const double z0 = p[size_t(end_points)].x(), z1 = p.back().x();
  const double za = z0 + 0.25 * (z1 - z0), zb = z0 + 0.75 * (z1 - z0);
  d.cone_half_angle_deg = std::atan2(profile_radius(p, zb) - profile_radius(p, za), zb - za) * 180 / M_PI + 0.0;
  return d;
}

namespace {
void line(fmt::memory_buffer& b, const char* layer, const Eigen::Vector2d& p, const Eigen::Vector2d& q) {
  fmt::format_to(std::back_inserter(b), "0\nLINE\n8\n{}\n10\n{}\n20\n{}\n30\n0.0\n11\n{}\n21\n{}\n31\n0.0\n", layer, fixed(p.x(), 6),
                 fixed(p.y(), 6), fixed(q.x(), 6), fixed(q.y(), 6));
}
}  // namespace

std::string tool_dxf(const std::vector<Eigen::Vector2d>& p, const std::string& title) {
  if (p.size() < 2) throw InputError("tool profile: at least two points");
  fmt::memory_buffer b;
  auto o = std::back_inserter(b);
  fmt::format_to(o, "999\nflankcam tool profile, mm, axis along X, tip at the origin: {}\n", title);
  fmt::format_to(o, "0\nSECTION\n2\nHEADER\n9\n$ACADVER\n1\nAC1009\n9\n$MEASUREMENT\n70\n1\n0\nENDSEC\n");
  fmt::format_to(o, "0\nSECTION\n2\nENTITIES\n");
  const Eigen::Vector2d start(p.front().x(), 0), end(p.back().x(), 0);
  if (p.front().y() > 0) line(b, "PROFILE", start, p.front());  // the tip face (a ball's profile starts on the axis)
  for (size_t k = 1; k < p.size(); ++k) line(b, "PROFILE", p[k - 1], p[k]);
  line(b, "PROFILE", p.back(), end);
  line(b, "AXIS", end, start);
  fmt::format_to(o, "0\nENDSEC\n0\nEOF\n");
  return {b.data(), b.size()};
}

void write_tool_dxf(const std::string& path, const std::vector<Eigen::Vector2d>& p, const std::string& title) {
  const std::string text = tool_dxf(p, title);
  write_file_atomically(path, [&](std::ostream& out) { out << text; });
}

std::string tool_stl(const std::vector<Eigen::Vector2d>& p, const std::string& title, int segments) {
  if (p.size() < 2) throw InputError("tool profile: at least two points needed");
  if (segments < 3) throw InputError("tool_stl: at least 3 segments");
  const auto at = [&](const Eigen::Vector2d& zr, int k) {
    const double a = 2 * M_PI * (k % segments) / segments;
    return Eigen::Vector3d(zr.y() * std::cos(a), zr.y() * std::sin(a), zr.x());
  };
  std::string out = "solid " + title + "\n";
  const auto facet = [&](const Eigen::Vector3d& a, const Eigen::Vector3d& b, const Eigen::Vector3d& c) {
    const Eigen::Vector3d n = (b - a).cross(c - a);
    if (n.norm() < 1e-12) return;  // a sliver where the profile touches the axis
    const Eigen::Vector3d u = n.normalized();
    out += "facet normal " + fixed(u.x(), 6) + " " + fixed(u.y(), 6) + " " + fixed(u.z(), 6) + "\n outer loop\n";
    for (const Eigen::Vector3d* v : {&a, &b, &c})
      out += "  vertex " + fixed(v->x(), 6) + " " + fixed(v->y(), 6) + " " + fixed(v->z(), 6) + "\n";
    out += " endloop\nendfacet\n";
  };
  for (int k = 0; k < segments; ++k) {
    // Side: outward normals (counter-clockwise seen from outside).
    for (size_t i = 0; i + 1 < p.size(); ++i) {
      facet(at(p[i], k), at(p[i], k + 1), at(p[i + 1], k + 1));
      facet(at(p[i], k), at(p[i + 1], k + 1), at(p[i + 1], k));
    }
    // End faces: the tip face looks down, the far face up.
    const Eigen::Vector3d tip_centre(0, 0, p.front().x()), far_centre(0, 0, p.back().x());
    facet(tip_centre, at(p.front(), k + 1), at(p.front(), k));
    facet(far_centre, at(p.back(), k), at(p.back(), k + 1));
  }
  return out + "endsolid " + title + "\n";
}

void write_tool_stl(const std::string& path, const std::vector<Eigen::Vector2d>& p, const std::string& title) {
  const std::string text = tool_stl(p, title);
  write_file_atomically(path, [&](std::ostream& out) { out << text; });
}

}  // namespace flankcam
