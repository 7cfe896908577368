#include "pipeline/faces.h"

#include <Eigen/Geometry>
#include <fmt/format.h>

#include <algorithm>
#include <cmath>
#include <filesystem>
#include <numeric>
#include <sstream>

#include "core/atomic_file.h"
#include "core/number_format.h"
#include "postproc/markup.h"

namespace flankcam::pipeline {

namespace {
std::string neighbour_text(const std::vector<int>& n) {
  std::string s;
  for (size_t i = 0; i < n.size(); ++i) s += (i ? " " : "") + std::to_string(n[i]);
  return s.empty() ? "-" : s;
}

std::vector<std::string> table_lines(const CadFaces& faces) {
  std::vector<std::string> lines;
  lines.push_back(fmt::format("{:>5}  {:<10} {:>12}  {:>21}  {:>21}  {:>21}  {}", "face", "surface", "area mm2", "x min .. max mm",
                              "y min .. max mm", "z min .. max mm", "neighbours"));
  for (const FaceInfo& f : faces.faces) {
    const auto range = [&](int k) { return fmt::format("{:>9} .. {:>9}", fixed(f.box.min[k], 3), fixed(f.box.max[k], 3)); };
    lines.push_back(fmt::format("{:>5}  {:<10} {:>12}  {}  {}  {}  {}", f.number, f.surface, fixed(f.area_mm2, 3), range(0),
                                range(1), range(2), neighbour_text(f.neighbours)));
  }
  return lines;
}

// Face colour: hues spread by the golden angle so neighbours differ; `shade` in [0, 1].
std::string face_colour(int number, double shade) {
  const double h = std::fmod(number * 137.508, 360.0) / 60.0, s = 0.55, v = 0.35 + 0.6 * shade;
  const double c = v * s, x = c * (1 - std::fabs(std::fmod(h, 2.0) - 1)), m = v - c;
  double r = 0, g = 0, b = 0;
  if (h < 1) r = c, g = x;
  else if (h < 2) r = x, g = c;
  else if (h < 3) g = c, b = x;
  else if (h < 4) g = x, b = c;
  else if (h < 5) r = x, b = c;
  else r = c, b = x;
  const auto byte = [](double t) { return int(std::lround(255 * std::clamp(t, 0.0, 1.0))); };
  return fmt::format("#{:02x}{:02x}{:02x}", byte(r + m), byte(g + m), byte(b + m));
}

// One view: parallel projection towards -toward (toward points at the viewer), +z up on the page,
// triangles painted back to front, shaded by their facing; back sides grey. Returns an SVG <g>.
std::string view_svg(const CadMesh& mesh, const CadFaces& faces, const Eigen::Vector3d& toward, double x0, double size,
                     const std::string& title) {
  const Eigen::Vector3d w = toward.normalized();
  const Eigen::Vector3d right = Eigen::Vector3d::UnitZ().cross(w).normalized(), up = w.cross(right);
  const auto& m = mesh.loaded.mesh;
  double umin = 1e300, umax = -1e300, vmin = 1e300, vmax = -1e300;
  for (const auto& p : m.vertices) {
    umin = std::min(umin, p.dot(right)), umax = std::max(umax, p.dot(right));
    vmin = std::min(vmin, p.dot(up)), vmax = std::max(vmax, p.dot(up));
  }
  const double margin = 20, scale = (size - 2 * margin) / std::max({umax - umin, vmax - vmin, 1e-9});
  const double ox = x0 + margin + 0.5 * (size - 2 * margin - scale * (umax - umin)), oy = 40 + margin;
  const auto sx = [&](const Eigen::Vector3d& p) { return ox + scale * (p.dot(right) - umin); };
  const auto sy = [&](const Eigen::Vector3d& p) { return oy + scale * (vmax - p.dot(up)) + 0.5 * (size - 2 * margin - scale * (vmax - vmin)); };

  std::vector<int> order(m.faces.size());
  std::iota(order.begin(), order.end(), 0);
  std::vector<double> depth(m.faces.size());
  for (size_t t = 0; t < m.faces.size(); ++t)
    depth[t] = (m.vertices[size_t(m.faces[t][0])] + m.vertices[size_t(m.faces[t][1])] + m.vertices[size_t(m.faces[t][2])]).dot(w);
  std::stable_sort(order.begin(), order.end(), [&](int a, int b) { return depth[size_t(a)] < depth[size_t(b)]; });

  std::ostringstream s;
  s << "<g>\n<text x=\"" << fixed(x0 + size / 2, 1) << "\" y=\"24\" text-anchor=\"middle\" font-size=\"15\">"
    << markup_escape(title) << "</text>\n";
  for (int t : order) {
    const auto& f = m.faces[size_t(t)];
    const double facing = face_normal(m, t).dot(w);
    const int number = mesh.triangle_face.empty() ? 0 : mesh.triangle_face[size_t(t)];
    const std::string fill = facing >= 0 ? face_colour(number, facing) : "#b0b0b0";
    s << "<polygon points=\"";
    for (int k = 0; k < 3; ++k) {
      const Eigen::Vector3d& p = m.vertices[size_t(f[k])];
      s << fixed(sx(p), 2) << ',' << fixed(sy(p), 2) << (k < 2 ? " " : "");
    }
    s << "\" fill=\"" << fill << "\" stroke=\"" << fill << "\" stroke-width=\"0.3\"/>\n";
  }
  for (const FaceInfo& f : faces.faces) {
    const double x = sx(f.centroid_mm), y = sy(f.centroid_mm);
    s << "<text x=\"" << fixed(x, 1) << "\" y=\"" << fixed(y, 1)
      << "\" text-anchor=\"middle\" dominant-baseline=\"central\" font-size=\"13\" font-weight=\"bold\" fill=\"#000\" "
         "stroke=\"#fff\" stroke-width=\"3\" paint-order=\"stroke\">"
      << f.number << "</text>\n";
  }
  s << "</g>\n";
  return s.str();
}

std::string overview_svg(const std::string& model, const CadMesh& mesh, const CadFaces& faces) {
  const double size = 520;
  std::ostringstream s;
  s << "<svg xmlns=\"http://www.w3.org/2000/svg\" width=\"" << 2 * size << "\" height=\"" << size + 60 << "\" viewBox=\"0 0 "
    << 2 * size << ' ' << size + 60 << "\" font-family=\"sans-serif\">\n"
    << "<rect width=\"100%\" height=\"100%\" fill=\"#fff\"/>\n";
  // Two opposite views so that every face is seen from its front in one of them.
  s << view_svg(mesh, faces, {1, 2, 1.4}, 0, size, "from +x +y +z");
  s << view_svg(mesh, faces, {-1, -2, 1.4}, size, size, "from -x -y +z");
  s << "<text x=\"10\" y=\"" << size + 50 << "\" font-size=\"12\" fill=\"#444\">" << markup_escape(model)
    << ": faces numbered at their centroids (grey: seen from behind)</text>\n</svg>\n";
  return s.str();
}

}  // namespace

FacesOverview faces_overview(const std::string& model, double sewing_mm, bool with_picture) {
  FacesOverview o;
  o.model = model;
  o.faces = list_faces(model, sewing_mm);
  o.table = table_lines(o.faces);
  o.head = fmt::format("{}: {} faces{}", model, o.faces.faces.size(), o.faces.note.empty() ? ", mm" : ", " + o.faces.note);
  if (with_picture) {
    // A coarse tessellation is enough for a picture: 1/300 of the model's size.
    BoundingBox all{o.faces.faces[0].box.min, o.faces.faces[0].box.max};
    for (const FaceInfo& f : o.faces.faces) all.min = all.min.cwiseMin(f.box.min), all.max = all.max.cwiseMax(f.box.max);
    CadOptions c;
    c.chordal_deflection_mm = std::max(all.diagonal() / 300, 1e-3);
    c.angular_deflection_rad = 0.3;
    c.sewing_tolerance_mm = sewing_mm;
    o.mesh = load_cad(model, c);
  }
  return o;
}

void write_faces(const FacesOverview& o, OutputDir& out) {
  const std::string svg = overview_svg(o.model, *o.mesh, o.faces);
  write_file_atomically(out.file("faces.svg"), [&](std::ostream& s) { s << svg; });
  write_file_atomically(out.file("faces.html"), [&](std::ostream& s) {
    s << "<!DOCTYPE html>\n<html><head><meta charset=\"utf-8\"><title>" << markup_escape(o.model)
      << " faces</title></head>\n<body style=\"font-family:sans-serif\">\n<h1>" << markup_escape(o.head) << "</h1>\n"
      << svg << "<pre>\n";
    for (const auto& l : o.table) s << markup_escape(l) << '\n';
    s << "</pre>\n<p>Pick the flank in a job: <code>surface: {file: "
      << markup_escape(std::filesystem::path(o.model).filename().string()) << ", faces: [N, ...]}</code>.</p>\n</body></html>\n";
  });
  out.commit();
}

}  // namespace flankcam::pipeline
