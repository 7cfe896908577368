#include "postproc/report_svg.h"

#include <Eigen/Eigenvalues>
#include <Eigen/Geometry>
#include <fmt/format.h>

#include <algorithm>
#include <cmath>
#include <limits>

#include "core/number_format.h"
#include "postproc/markup.h"

namespace flankcam {

std::array<unsigned char, 3> deviation_color(double d, double tol) {
  const std::array<double, 3> green{60, 170, 80}, red{215, 40, 40}, blue{40, 80, 215};
  if (!std::isfinite(d)) return {170, 170, 170};
  if (std::abs(d) <= tol) return {60, 170, 80};
  const double u = std::clamp((std::abs(d) - tol) / (3 * tol), 0.0, 1.0);
  const std::array<double, 3>& q = d > 0 ? red : blue;
  std::array<unsigned char, 3> c{};
  for (size_t k = 0; k < 3; ++k) c[k] = static_cast<unsigned char>(std::lround(green[k] + u * (q[k] - green[k])));
  return c;
}

namespace {

std::string num(double x) { return fixed(x, 2); }
std::string hex(const std::array<unsigned char, 3>& c) { return fmt::format("#{:02x}{:02x}{:02x}", c[0], c[1], c[2]); }
std::string header(double w, double h) {
  return fmt::format(R"(<svg xmlns="http://www.w3.org/2000/svg" width="{0}" height="{1}" viewBox="0 0 {0} {1}" )"
                     R"(font-family="sans-serif" font-size="12">)"
                     "\n",
                     num(w), num(h));
}
std::string text(double x, double y, const std::string& s, const std::string& extra = "") {
  return fmt::format(R"(<text x="{}" y="{}"{}>{}</text>)"
                     "\n",
                     num(x), num(y), extra.empty() ? "" : " " + extra, markup_escape(s));
}
std::string line(double x0, double y0, double x1, double y1, const std::string& style) {
  return fmt::format(R"(<line x1="{}" y1="{}" x2="{}" y2="{}" {}/>)"
                     "\n",
                     num(x0), num(y0), num(x1), num(y1), style);
}
// A nice step for about `n` ticks over `span`.
double tick_step(double span, int n) {
  const double raw = span / n, p = std::pow(10.0, std::floor(std::log10(raw)));
  for (double m : {1.0, 2.0, 5.0, 10.0})
    if (m * p >= raw) return m * p;
  return 10 * p;
}

}  // namespace

namespace {

// The surface seen along the area-weighted mean normal v of the faces whose three vertices are
// `defined` (all faces if none or no such face); picture x along the surface's longest extent u.
struct SurfaceView {
  Eigen::Vector3d mean, u, v, w;
  [[nodiscard]] Eigen::Vector2d project(const Eigen::Vector3d& p) const { return {(p - mean).dot(u), (p - mean).dot(w)}; }
};

SurfaceView view_along_mean_normal(const TriMesh& mesh, const std::vector<bool>& defined) {
  Eigen::Vector3d normal = Eigen::Vector3d::Zero();
  for (int pass = 0; pass < 2 && normal.norm() < 1e-12; ++pass)
    for (const auto& f : mesh.faces) {
      if (pass == 0 && !(defined[size_t(f[0])] && defined[size_t(f[1])] && defined[size_t(f[2])])) continue;
      const Eigen::Vector3d &a = mesh.vertices[size_t(f[0])], &b = mesh.vertices[size_t(f[1])], &c = mesh.vertices[size_t(f[2])];
      normal += (b - a).cross(c - a);
    }
  SurfaceView view;
  view.v = normal.norm() > 1e-12 ? normal.normalized() : Eigen::Vector3d::UnitZ();
  view.mean = Eigen::Vector3d::Zero();
  for (const auto& p : mesh.vertices) view.mean += p;
  view.mean /= double(std::max<size_t>(1, mesh.vertices.size()));
  Eigen::Matrix3d cov = Eigen::Matrix3d::Zero();
  const Eigen::Matrix3d flat = Eigen::Matrix3d::Identity() - view.v * view.v.transpose();
  for (const auto& p : mesh.vertices) {
    const Eigen::Vector3d q = flat * (p - view.mean);
    cov += q * q.transpose();
  }
  view.u = Eigen::SelfAdjointEigenSolver<Eigen::Matrix3d>(cov).eigenvectors().col(2);
  if (view.u.dot(Eigen::Vector3d(1, 1, 1)) < 0) view.u = -view.u;  // a fixed sign: same input, same picture
  view.w = view.v.cross(view.u);
  return view;
}

// The surface rasterised in the view: per cell the front-most face covering its centre, the
// per-vertex `values` interpolated there and the face's vertex nearest the centre.
struct Raster {
  Eigen::Vector2d lo, hi;  // picture bounds, mm
  double cell = 1;         // mm
  int nx = 1, ny = 1;
  std::vector<bool> covered;
  std::vector<double> value;
  std::vector<int> vertex;
};

Raster rasterise(const TriMesh& mesh, const SurfaceView& view, const std::vector<double>& values, int columns,
                 const std::vector<Eigen::Vector2d>& also_in_view) {
  Raster r;
  r.lo = Eigen::Vector2d(1e300, 1e300), r.hi = Eigen::Vector2d(-1e300, -1e300);
  for (const auto& p : mesh.vertices) r.lo = r.lo.cwiseMin(view.project(p)), r.hi = r.hi.cwiseMax(view.project(p));
  for (const auto& q : also_in_view) r.lo = r.lo.cwiseMin(q), r.hi = r.hi.cwiseMax(q);
  r.cell = std::max(r.hi.x() - r.lo.x(), (r.hi.y() - r.lo.y()) * 0.75) / columns;
  if (!(r.cell > 0)) r.cell = 1;
  r.nx = std::max(1, int(std::ceil((r.hi.x() - r.lo.x()) / r.cell)));
  r.ny = std::max(1, int(std::ceil((r.hi.y() - r.lo.y()) / r.cell)));
  const size_t cells = size_t(r.nx) * size_t(r.ny);
  std::vector<double> depth(cells, -std::numeric_limits<double>::infinity());
  r.covered.assign(cells, false);
  r.value.assign(cells, std::numeric_limits<double>::quiet_NaN());
  r.vertex.assign(cells, -1);
  for (const auto& f : mesh.faces) {
    const Eigen::Vector2d a = view.project(mesh.vertices[size_t(f[0])]), b = view.project(mesh.vertices[size_t(f[1])]),
                          c = view.project(mesh.vertices[size_t(f[2])]);
    const double area = (b - a).x() * (c - a).y() - (b - a).y() * (c - a).x();
    if (std::abs(area) < 1e-300) continue;
    const int x0 = std::max(0, int((std::min({a.x(), b.x(), c.x()}) - r.lo.x()) / r.cell - 0.5));
    const int x1 = std::min(r.nx - 1, int((std::max({a.x(), b.x(), c.x()}) - r.lo.x()) / r.cell + 0.5));
    const int y0 = std::max(0, int((std::min({a.y(), b.y(), c.y()}) - r.lo.y()) / r.cell - 0.5));
    const int y1 = std::min(r.ny - 1, int((std::max({a.y(), b.y(), c.y()}) - r.lo.y()) / r.cell + 0.5));
    for (int iy = y0; iy <= y1; ++iy)
      for (int ix = x0; ix <= x1; ++ix) {
        const Eigen::Vector2d p = r.lo + r.cell * Eigen::Vector2d(ix + 0.5, iy + 0.5);
        const double l1 = ((b - p).x() * (c - p).y() - (b - p).y() * (c - p).x()) / area;
        const double l2 = ((c - p).x() * (a - p).y() - (c - p).y() * (a - p).x()) / area;
        const double l3 = 1 - l1 - l2;
        if (l1 < -1e-9 || l2 < -1e-9 || l3 < -1e-9) continue;
        const double d = l1 * mesh.vertices[size_t(f[0])].dot(view.v) + l2 * mesh.vertices[size_t(f[1])].dot(view.v) +
                         l3 * mesh.vertices[size_t(f[2])].dot(view.v);
        const size_t k = size_t(iy) * size_t(r.nx) + size_t(ix);
        if (d <= depth[k]) continue;
        depth[k] = d;
        r.covered[k] = true;
        if (!values.empty())
          r.value[k] = l1 * values[size_t(f[0])] + l2 * values[size_t(f[1])] + l3 * values[size_t(f[2])];
        r.vertex[k] = f[l1 >= l2 && l1 >= l3 ? 0 : (l2 >= l3 ? 1 : 2)];
      }
  }
  return r;
}

// The picture's frame: 640 px across the raster, a title above and a legend band below.
struct Canvas {
  double scale = 1, margin = 20, top = 36, legend = 60, width = 0, height = 0;
  Eigen::Vector2d lo, hi;
  Canvas(const Raster& r, double legend_height) : scale(640.0 / (r.nx * r.cell)), legend(legend_height), lo(r.lo), hi(r.hi) {
    width = 640 + 2 * margin;
    height = top + r.ny * r.cell * scale + legend + margin;
  }
  [[nodiscard]] double sx(double x) const { return margin + (x - lo.x()) * scale; }
  [[nodiscard]] double sy(double y) const { return top + (hi.y() - y) * scale; }
};

// The covered cells, one rect per run of equal colour in a row.
template <class Colour>
std::string cells_svg(const Raster& r, const Canvas& cv, const Colour& colour_of) {
  std::string s = R"(<g shape-rendering="crispEdges">)"
                  "\n";
  for (int iy = 0; iy < r.ny; ++iy)
    for (int ix = 0; ix < r.nx;) {
      const size_t k = size_t(iy) * size_t(r.nx) + size_t(ix);
      if (!r.covered[k]) {
        ++ix;
        continue;
      }
      const std::string colour = colour_of(k);
      int run = 1;
      while (ix + run < r.nx && r.covered[k + size_t(run)] && colour_of(k + size_t(run)) == colour) ++run;
      s += fmt::format(R"(<rect x="{}" y="{}" width="{}" height="{}" fill="{}"/>)"
                       "\n",
                       num(cv.sx(r.lo.x() + ix * r.cell)), num(cv.sy(r.lo.y() + (iy + 1) * r.cell)),
                       num(run * r.cell * cv.scale + 0.3), num(r.cell * cv.scale + 0.3), colour);
      ix += run;
    }
  return s + "</g>\n";
}

std::string swatch(double x, double y, const std::string& colour) {
  return fmt::format(R"(<rect x="{}" y="{}" width="14" height="14" fill="{}"/>)"
                     "\n",
                     num(x), num(y), colour);
}

}  // namespace

std::string deviation_map_svg(const TriMesh& mesh, const std::vector<double>& dev, double tol,
                              const std::vector<ToolPose>& poses, const std::vector<Eigen::Vector2d>& profile,
                              const std::string& title, int columns, const std::vector<SvgHitMarker>& hits,
                              const std::string& uncut_label) {
  std::vector<bool> defined(dev.size());
  for (size_t i = 0; i < dev.size(); ++i) defined[i] = std::isfinite(dev[i]);
  const SurfaceView view = view_along_mean_normal(mesh, defined);
  const Eigen::Vector3d &u = view.u, &w = view.w;
  const auto project = [&](const Eigen::Vector3d& p) { return view.project(p); };

  // The tool at a few poses: its silhouette seen along v (outline, then the axis from tip to end).
  std::vector<std::vector<Eigen::Vector2d>> outlines;
  std::vector<std::array<Eigen::Vector2d, 2>> axes;
  std::vector<Eigen::Vector2d> outline_points;
  const size_t shown = std::min<size_t>(5, poses.size());
  for (size_t i = 0; i < shown && profile.size() >= 2; ++i) {
    const ToolPose& p = poses[shown == 1 ? 0 : i * (poses.size() - 1) / (shown - 1)];
    const Eigen::Vector2d a2(p.axis.dot(u), p.axis.dot(w));
    if (a2.norm() < 1e-6) continue;  // looking down the axis
    const Eigen::Vector2d side = Eigen::Vector2d(-a2.y(), a2.x()).normalized();
    std::vector<Eigen::Vector2d> outline;
    for (size_t k = 0; k < profile.size(); ++k) outline.push_back(project(p.tip + profile[k].x() * p.axis) + profile[k].y() * side);
    for (size_t k = profile.size(); k-- > 0;) outline.push_back(project(p.tip + profile[k].x() * p.axis) - profile[k].y() * side);
    outline_points.insert(outline_points.end(), outline.begin(), outline.end());
    outlines.push_back(outline);
    axes.push_back({project(p.tip), project(p.tip + profile.back().x() * p.axis)});
  }
  const Raster r = rasterise(mesh, view, dev, columns, outline_points);
  const Canvas cv(r, 60);
  std::string s = header(cv.width, cv.height);
  s += text(cv.margin, 22, title, R"(font-size="14" font-weight="bold")");
  s += cells_svg(r, cv, [&](size_t k) { return hex(deviation_color(r.value[k], tol)); });
  for (size_t i = 0; i < outlines.size(); ++i) {
    std::string pts;
    for (const auto& q : outlines[i]) pts += num(cv.sx(q.x())) + "," + num(cv.sy(q.y())) + " ";
    pts.pop_back();
    s += fmt::format(R"(<polygon points="{}" fill="#000000" fill-opacity="0.06" stroke="#222222" stroke-width="1"/>)"
                     "\n",
                     pts);
    s += line(cv.sx(axes[i][0].x()), cv.sy(axes[i][0].y()), cv.sx(axes[i][1].x()), cv.sy(axes[i][1].y()),
              R"(stroke="#222222" stroke-dasharray="6 3")");
  }
  // Collisions and gouges: a ring with a cross, labelled (at most 12 labels, the rest unlabelled).
  for (size_t i = 0; i < hits.size(); ++i) {
    const Eigen::Vector2d q = project(hits[i].point);
    const double x = cv.sx(q.x()), y = cv.sy(q.y());
    const std::string colour = hits[i].gouge ? "#ff8c00" : "#d000d0";
    s += fmt::format(R"(<circle cx="{}" cy="{}" r="7" fill="none" stroke="{}" stroke-width="2.5"/>)"
                     "\n",
                     num(x), num(y), colour);
    s += line(x - 5, y - 5, x + 5, y + 5, fmt::format(R"(stroke="{}" stroke-width="2")", colour));
    s += line(x - 5, y + 5, x + 5, y - 5, fmt::format(R"(stroke="{}" stroke-width="2")", colour));
    if (i < 12) s += text(x + 9, y - 6, hits[i].label, fmt::format(R"(font-size="10" fill="{}")", colour));
  }
  // Legend: -4 tol .. +4 tol.
  const double ly = cv.height - cv.legend + 10, lw = 300, margin = cv.margin;
  for (int k = 0; k < 64; ++k) {
    const double d = (-4 + 8 * (k + 0.5) / 64) * tol;
    s += fmt::format(R"(<rect x="{}" y="{}" width="{}" height="14" fill="{}"/>)"
                     "\n",
                     num(margin + k * lw / 64), num(ly), num(lw / 64 + 0.3), hex(deviation_color(d, tol)));
  }
  for (int k : {-4, -1, 1, 4}) {
    const double x = margin + (k + 4) * lw / 8;
    s += line(x, ly + 14, x, ly + 18, R"(stroke="#000000")");
    s += text(x, ly + 30, fixed(k * tol, 4), R"(text-anchor="middle" font-size="10")");
  }
  s += text(margin + lw + 40, ly + 11, "signed deviation, mm: blue overcut,");
  s += text(margin + lw + 40, ly + 25, "green within tolerance, red undercut");
  s += swatch(margin + lw + 40, ly + 32, hex(deviation_color(NAN, tol)));
  s += text(margin + lw + 60, ly + 44, uncut_label);
  return s + "</svg>\n";
}

std::array<unsigned char, 3> patch_color(int patch) {
  // Qualitative palette (Okabe-Ito, then Tableau), distinct from the deviation greys.
  static const std::array<std::array<unsigned char, 3>, 12> palette{{{0, 114, 178},
                                                                     {230, 159, 0},
                                                                     {0, 158, 115},
                                                                     {204, 121, 167},
                                                                     {86, 180, 233},
                                                                     {213, 94, 0},
                                                                     {240, 228, 66},
                                                                     {140, 86, 75},
                                                                     {148, 103, 189},
                                                                     {188, 189, 34},
                                                                     {23, 190, 207},
                                                                     {127, 60, 141}}};
  if (patch < 0) return {170, 170, 170};
  return palette[size_t(patch) % palette.size()];
}

std::string patch_owner_svg(const TriMesh& mesh, const std::vector<int>& owner, const std::vector<std::string>& names,
                            const std::string& title, int columns) {
  std::vector<bool> defined(owner.size());
  for (size_t i = 0; i < owner.size(); ++i) defined[i] = owner[i] >= 0;
  const SurfaceView view = view_along_mean_normal(mesh, defined);
  const Raster r = rasterise(mesh, view, {}, columns, {});
  const double rows = double((names.size() + 1 + 3) / 4);  // legend: 4 entries a row, "uncovered" last
  const Canvas cv(r, 12 + 20 * rows);
  std::string s = header(cv.width, cv.height);
  s += text(cv.margin, 22, title, R"(font-size="14" font-weight="bold")");
  s += cells_svg(r, cv, [&](size_t k) {
    const int v = r.vertex[k];
    return hex(patch_color(v >= 0 && size_t(v) < owner.size() ? owner[size_t(v)] : -1));
  });
  const double ly = cv.height - cv.legend + 6;
  for (size_t i = 0; i <= names.size(); ++i) {
    const double x = cv.margin + double(i % 4) * 160, y = ly + double(i / 4) * 20;
    const bool uncovered = i == names.size();
    s += swatch(x, y, hex(patch_color(uncovered ? -1 : int(i))));
    s += text(x + 20, y + 12, uncovered ? "machined by no patch" : names[i]);
  }
  return s + "</svg>\n";
}

std::string tool_profile_svg(const std::vector<Eigen::Vector2d>& profile, const std::string& title) {
  const ToolDimensions dim = tool_dimensions(profile);
  double r_max = 0;
  for (const auto& q : profile) r_max = std::max(r_max, q.y());
  const double len = std::max(dim.length_mm, 1e-9), z0 = profile.empty() ? 0 : profile.front().x();
  const double draw_h = 360, scale = std::min(draw_h / len, 200 / std::max(r_max, 1e-9));
  const double cx = 170, base = 40 + len * scale + 10;  // tip at the bottom
  const auto px = [&](double r) { return cx + r * scale; };
  const auto py = [&](double z) { return base - (z - z0) * scale; };
  const double width = 460, height = base + 60;
  std::string s = header(width, height);
  s += text(10, 22, title, R"(font-size="14" font-weight="bold")");
  std::string pts;
  for (const auto& q : profile) pts += num(px(q.y())) + "," + num(py(q.x())) + " ";
  for (size_t k = profile.size(); k-- > 0;) pts += num(px(-profile[k].y())) + "," + num(py(profile[k].x())) + " ";
  if (!pts.empty()) pts.pop_back();
  s += fmt::format(R"(<polygon points="{}" fill="#b8c4d6" stroke="#1f3b63" stroke-width="1.5"/>)"
                   "\n",
                   pts);
  s += line(cx, py(z0) + 12, cx, py(z0 + len) - 12, R"(stroke="#555555" stroke-dasharray="10 3 2 3")");
  const std::string dimension = R"(stroke="#000000" stroke-width="0.8")";
  // Length at the right.
  const double xr = px(r_max) + 30;
  s += line(xr, py(z0), xr, py(z0 + len), dimension);
  s += line(xr - 5, py(z0), xr + 5, py(z0), dimension) + line(xr - 5, py(z0 + len), xr + 5, py(z0 + len), dimension);
  s += text(xr + 8, (py(z0) + py(z0 + len)) / 2, "L " + fixed(dim.length_mm, 3) + " mm");
  // End diameters.
  if (!profile.empty()) {
    const double rt = profile.front().y(), re = profile.back().y();
    s += line(px(-rt), py(z0) + 18, px(rt), py(z0) + 18, dimension);
    s += text(cx, py(z0) + 34, "D " + fixed(2 * rt, 3) + " mm at the tip", R"(text-anchor="middle")");
    s += line(px(-re), py(z0 + len) - 10, px(re), py(z0 + len) - 10, dimension);
    s += text(cx, py(z0 + len) - 16, "D " + fixed(2 * re, 3) + " mm", R"(text-anchor="middle")");
  }
  s += text(xr + 8, py(z0 + len) + 16, "D min " + fixed(dim.diameter_min_mm, 3) + ", max " + fixed(dim.diameter_max_mm, 3));
  if (dim.cone_half_angle_deg != 0)
    s += text(xr + 8, py(z0 + len) + 32, "cone half-angle " + fixed(dim.cone_half_angle_deg, 3) + " deg");
  return s + "</svg>\n";
}

std::string angle_chart_svg(const std::array<AngleSeries, 2>& series, const std::string& title) {
  const double width = 680, height = 310, left = 60, right = 20, top = 56, bottom = 40;
  double lo = 1e300, hi = -1e300;
  size_t n = 0;
  for (const auto& a : series) {
    for (double d : a.deg) lo = std::min(lo, d), hi = std::max(hi, d);
    n = std::max(n, a.deg.size());
  }
  if (n == 0) lo = 0, hi = 1;
  const double pad = std::max(1.0, 0.08 * (hi - lo));
  lo -= pad, hi += pad;
  const auto px = [&](double i) { return left + (width - left - right) * (n > 1 ? i / double(n - 1) : 0.5); };
  const auto py = [&](double d) { return top + (height - top - bottom) * (hi - d) / (hi - lo); };
  std::string s = header(width, height);
  s += text(10, 22, title, R"(font-size="14" font-weight="bold")");
  const double step = tick_step(hi - lo, 6);
  for (double t = std::ceil(lo / step) * step; t <= hi; t += step) {
    s += line(left, py(t), width - right, py(t), R"(stroke="#dddddd")");
    s += text(left - 6, py(t) + 4, fixed(t, step < 1 ? 1 : 0), R"(text-anchor="end" font-size="10")");
  }
  s += line(left, top, left, height - bottom, R"(stroke="#000000")");
  s += line(left, height - bottom, width - right, height - bottom, R"(stroke="#000000")");
  s += text((left + width - right) / 2, height - 10, "block of the program", R"(text-anchor="middle")");
  s += text(14, (top + height - bottom) / 2, "deg", R"(text-anchor="middle")");
  const std::array<std::string, 2> colour{"#c0392b", "#1f6fb2"};
  for (size_t k = 0; k < 2; ++k) {
    const AngleSeries& a = series[k];
    std::string pts;
    for (size_t i = 0; i < a.deg.size(); ++i) pts += num(px(double(i))) + "," + num(py(a.deg[i])) + " ";
    if (!pts.empty()) pts.pop_back();
    s += fmt::format(R"(<polyline points="{}" fill="none" stroke="{}" stroke-width="1.5"/>)"
                     "\n",
                     pts, colour[k]);
    if (!a.continuous)
      for (double limit : {a.min_deg, a.max_deg})
        if (limit > lo && limit < hi) {
          s += line(left, py(limit), width - right, py(limit), "stroke=\"" + colour[k] + R"(" stroke-dasharray="5 4")");
          s += text(width - right - 4, py(limit) - 4, a.name + " limit " + fixed(limit, 1), R"(text-anchor="end" font-size="10")");
        }
    double mn = 1e300, mx = -1e300;
    for (double d : a.deg) mn = std::min(mn, d), mx = std::max(mx, d);
    s += fmt::format(R"(<rect x="{}" y="{}" width="14" height="4" fill="{}"/>)"
                     "\n",
                     num(left + 10 + 250 * double(k)), num(top - 22), colour[k]);
    s += text(left + 30 + 250 * double(k), top - 17,
              a.deg.empty() ? a.name : fmt::format("{}: {} .. {} deg", a.name, fixed(mn, 2), fixed(mx, 2)));
  }
  return s + "</svg>\n";
}

}  // namespace flankcam
