#include "core/detect.h"

#include <Eigen/Dense>
#include <fmt/format.h>
#include <algorithm>
#include <cmath>
#include <iterator>
#include <limits>
#include <map>
#include <numeric>
#include <optional>
#include <queue>
#include <tuple>
#include <array>

#include "core/errors.h"
#include "core/movability.h"

namespace flankcam {

std::string CoverOptions::validate() const {
  if (!(coverage > 0 && coverage <= 1)) return "cover.coverage: must be in (0, 1]";
  if (max_patches < 1) return "cover.max_patches: at least 1";
  if (seed_points < 1) return "cover.seed_points: at least 1";
  if (directions < 1) return "cover.directions: at least 1";
  if (radii.empty()) return "cover.radii: at least one candidate radius";
  if (!(floor_tip >= 0) || !std::isfinite(floor_tip)) return "cover.floor_tip_diameter: must be >= 0";
  for (double r : radii)
    if (!(r > 0) || !std::isfinite(r)) return "cover.radii: must be positive";
  if (explored_seeds < 1) return "cover.explored_seeds: at least 1";
  if (refined_seeds < explored_seeds) return "cover.refined_seeds: at least explored_seeds";
  if (sweep_steps < 2) return "cover.sweep_steps: at least 2";
  if (!(sweep_step > 0 && sweep_step < 0.1)) return "cover.sweep_step: must be in (0, 0.1)";
  if (refine_evaluations < 0) return "cover.refine_evaluations: must be >= 0";
  if (explored_unrefined < 0) return "cover.explored_unrefined: must be >= 0";
  if (oriented_lines < 0) return "cover.oriented_lines: must be >= 0";
  if (fitted_seeds < 1 || fitted_seeds > explored_seeds + explored_unrefined)
    return "cover.fitted_seeds: 1 .. explored_seeds + explored_unrefined";
  if (oriented_refined < 0) return "cover.oriented_refined: must be >= 0";
  if (!(orient_below >= 0 && orient_below <= 1)) return "cover.orient_below: must be in [0, 1]";
  if (oriented_explored < 0 || (oriented_explored > 0 && oriented_refined < oriented_explored))
    return "cover.oriented_explored: 0 .. oriented_refined";
  if (oriented_fitted < 0 || oriented_fitted > 2 * oriented_explored) return "cover.oriented_fitted: 0 .. 2 oriented_explored";
  if (oriented_explored > 0 && oriented_lines < 1) return "cover.oriented_lines: at least 1 when oriented seeds are explored";
  if (!(band >= 0) || !std::isfinite(band)) return "cover.band: must be >= 0";
  if (lines < 2) return "cover.lines: at least 2";
  if (spares < 0) return "cover.spares: must be >= 0";
  if (exchanges < 0) return "cover.exchanges: must be >= 0";
  if (finish_sweeps < 0) return "cover.finish_sweeps: must be >= 0";
  if (regions < 0) return "cover.regions: must be >= 0";
  if (!(region_min > 0 && region_min <= 1)) return "cover.region_min: must be in (0, 1]";
  if (!(region_below >= 0 && region_below <= 1)) return "cover.region_below: must be in [0, 1]";
  if (patch.fit.fixed_tool && !(tool_length > 0 && std::isfinite(tool_length)))
    return "tool_length: must be positive with a fixed tool";
  if (up && !(up->norm() > 0 && up->allFinite())) return "up: must be a nonzero direction";
  if (!(patch.tolerance > 0)) return "tolerance: must be positive";
  if (auto e = patch.fit.validate(); !e.empty()) return e;
  if (auto e = patch.exploration.validate(); !e.empty()) return "exploration." + e;
  if (auto e = patch.propagation.validate(); !e.empty()) return "propagation." + e;
  if (auto e = patch.machined.validate(); !e.empty()) return e;
  return {};
}

const char* to_string(CoverStop s) {
  switch (s) {
    case CoverStop::Coverage: return "coverage reached";
    case CoverStop::MaxPatches: return "max_patches reached";
    case CoverStop::NoProgress: return "no further patch adds coverage";
  }
  return "?";
}

std::vector<Region> uncovered_regions(const std::vector<std::vector<int>>& ring, const std::vector<char>& covered,
                                      const std::vector<double>& area) {
  std::vector<Region> regions;
  std::vector<char> seen(covered.size(), 0);
  for (size_t v0 = 0; v0 < covered.size(); ++v0) {
    if (covered[v0] || seen[v0]) continue;
    Region r;
    r.vertices = {int(v0)};
    seen[v0] = 1;
    for (size_t k = 0; k < r.vertices.size(); ++k)
      for (int w : ring[size_t(r.vertices[k])])
        if (!covered[size_t(w)] && !seen[size_t(w)]) seen[size_t(w)] = 1, r.vertices.push_back(w);
    std::sort(r.vertices.begin(), r.vertices.end());
    for (int v : r.vertices) r.area += area[size_t(v)];
    regions.push_back(std::move(r));
  }
  std::stable_sort(regions.begin(), regions.end(), [](const Region& x, const Region& y) { return x.area > y.area; });
  return regions;
}

SubSurface sub_surface(const TriMesh& m, const std::vector<std::vector<int>>& ring, const std::vector<int>& region, double band) {
  std::vector<double> dist(m.vertices.size(), INFINITY);
  using Item = std::pair<double, int>;
  std::priority_queue<Item, std::vector<Item>, std::greater<>> queue;
  for (int v : region) dist[size_t(v)] = 0, queue.push({0.0, v});
  while (!queue.empty()) {
    const auto [d, v] = queue.top();
    queue.pop();
    if (d > dist[size_t(v)]) continue;
    for (int w : ring[size_t(v)]) {
      const double dw = d + (m.vertices[size_t(w)] - m.vertices[size_t(v)]).norm();
      if (dw <= band && dw < dist[size_t(w)]) dist[size_t(w)] = dw, queue.push({dw, w});
    }
  }
  SubSurface sub;
  std::vector<int> index(m.vertices.size(), -1);
  for (const auto& f : m.faces) {
    if (!(std::isfinite(dist[size_t(f[0])]) && std::isfinite(dist[size_t(f[1])]) && std::isfinite(dist[size_t(f[2])]))) continue;
    std::array<int, 3> g;
    for (int c = 0; c < 3; ++c) {
      int& k = index[size_t(f[size_t(c)])];
      if (k < 0) k = int(sub.whole.size()), sub.whole.push_back(f[size_t(c)]), sub.mesh.vertices.push_back(m.vertices[size_t(f[size_t(c)])]);
      g[size_t(c)] = k;
    }
    sub.mesh.faces.push_back(g);
  }
  return sub;
}

std::vector<AxisLine> lines_of(const Rails& rails, int count) {
  std::vector<AxisLine> out;
  for (int k = 0; k < count; ++k) {
    const double t = double(k) / (count - 1);
    out.push_back({rails.a.point(t), rails.b.point(t)});
  }
  return out;
}

UnionDeviation union_deviation(const std::vector<const MachinedSurface*>& machined, size_t vertices) {
  UnionDeviation u;
  u.owner.assign(vertices, -1);
  u.deviation.assign(vertices, std::numeric_limits<double>::quiet_NaN());
  // The tools remove material one after the other: what is left is the deepest cut (smallest signed
  // deviation, undercut > 0), and the patch that made it machines the vertex.
  for (size_t p = 0; p < machined.size(); ++p)
    for (size_t v = 0; v < vertices; ++v) {
      const double d = machined[p]->design_deviation[v];
      if (!std::isfinite(d)) continue;
      if (u.owner[v] < 0 || d < u.deviation[v]) {
        u.deviation[v] = d;
        u.owner[v] = int(p);
      }
    }
  return u;
}

namespace {

constexpr double kMovableF = 1e-8;

std::vector<double> vertex_areas(const TriMesh& m) {
  std::vector<double> area(m.vertices.size(), 0.0);
  for (int f = 0; f < int(m.faces.size()); ++f)
    for (int v : m.faces[size_t(f)]) area[size_t(v)] += face_area(m, f) / 3;
  const double total = std::accumulate(area.begin(), area.end(), 0.0);
  for (double& a : area) a /= total > 0 ? total : 1;
  return area;
}

// The corner of the footpoint's face nearest to it.
int nearest_corner(const TriMesh& m, const Footpoint& f) {
  Eigen::Index k;
  f.barycentric.maxCoeff(&k);
  return m.faces[size_t(f.face)][size_t(k)];
}

struct Seed {
  AxisLine line;
  double F = std::numeric_limits<double>::infinity();
  double rank = std::numeric_limits<double>::infinity();
  int vertex = -1;
  int side = 0;  // +1: the line lies on the side Φ's normals point to
  double spread = std::numeric_limits<double>::infinity();  // sweep_spread of the refined line
  bool oriented = false;  // turned to its least F_l (orient_line)
  void take(const struct SeedLine& l);
};

// A candidate line at a seed point: turned about `pivot` by orient_seeds.
struct SeedLine {
  AxisLine line;
  Eigen::Vector3d pivot;
  double F, rank;
};

void Seed::take(const SeedLine& l) {
  if (l.rank < rank) {
    rank = l.rank;
    F = l.F;
    line = l.line;
  }
}

// Per seed point: best[0], best[1] the most movable line as seeded on side -1, +1 of Φ; best[2],
// best[3] the oriented ones (orient_seeds); top: per side the best-ranked lines, to be oriented.
struct PointSeeds {
  std::array<Seed, 4> best;
  std::array<std::vector<SeedLine>, 2> top;
};

// Principal directions from the change of the vertex normals over the two-ring (dn = W dx in the
// tangent plane, least squares). The least-curvature direction is where a flank tool's axis lies on
// an envelope; the largest curvature 1/r, towards its centre, suggests the tool radius and side.
struct Principal {
  Eigen::Vector3d least = Eigen::Vector3d::Zero();
  double radius = 0;  // 1 / |largest curvature|; 0: flat or unknown
  int side = 1;       // the centre of curvature lies at p + side * radius * n
  bool valid = false;
};

Principal principal_at(const SurfaceIndex& surface, const std::vector<std::vector<int>>& ring, int v,
                       const Eigen::Vector3d& t1, const Eigen::Vector3d& t2) {
  const auto& P = surface.mesh().vertices;
  const auto& N = surface.normals();
  std::vector<int> near = ring[size_t(v)];
  for (int w : ring[size_t(v)]) near.insert(near.end(), ring[size_t(w)].begin(), ring[size_t(w)].end());
  std::sort(near.begin(), near.end());
  near.erase(std::unique(near.begin(), near.end()), near.end());
  Principal out;
  Eigen::Matrix2d XtX = Eigen::Matrix2d::Zero(), XtY = Eigen::Matrix2d::Zero();
  int used = 0;
  for (int w : near) {
    if (w == v) continue;
    const Eigen::Vector3d dx = P[size_t(w)] - P[size_t(v)], dn = N[size_t(w)] - N[size_t(v)];
    const Eigen::Vector2d x(dx.dot(t1), dx.dot(t2)), y(dn.dot(t1), dn.dot(t2));
    XtX += x * x.transpose();
    XtY += x * y.transpose();
    ++used;
  }
  if (used < 5 || XtX.determinant() <= 1e-18) return out;
  Eigen::Matrix2d W = XtX.ldlt().solve(XtY);
  W = 0.5 * (W + W.transpose()).eval();
  Eigen::SelfAdjointEigenSolver<Eigen::Matrix2d> es(W);
  const int lo = std::abs(es.eigenvalues()[0]) <= std::abs(es.eigenvalues()[1]) ? 0 : 1;
  out.least = (es.eigenvectors()(0, lo) * t1 + es.eigenvectors()(1, lo) * t2).normalized();
  const double k_max = es.eigenvalues()[1 - lo];
  if (std::abs(k_max) > 1e-9) {
    out.radius = 1 / std::abs(k_max);
    out.side = k_max > 0 ? -1 : 1;  // n(q) = (q - c)/R on a sphere: dn = +dx/R with the centre behind
  }
  out.valid = true;
  return out;
}

// Sec. 4.1 over the whole surface: at a seed point, lines around the least-curvature direction,
// offset along the normal by the candidate radii (and by the radius of curvature towards its
// centre), each as long as the surface reaches along it; the most movable one on each side of Φ.
// `width`: the direction of Φ's middle extent (principal axes of its vertices), across the flank.
PointSeeds best_lines_at(const SurfaceIndex& surface, const std::vector<std::vector<int>>& ring, int v,
                         const Eigen::Vector3d& width, const CoverOptions& o) {
  const Eigen::Vector3d p = surface.mesh().vertices[size_t(v)], n = surface.normals()[size_t(v)];
  Eigen::Index k;
  n.cwiseAbs().minCoeff(&k);
  Eigen::Vector3d t1 = n.cross(Eigen::Vector3d::Unit(k)).normalized(), t2 = n.cross(t1);
  Principal pc = principal_at(surface, ring, v, t1, t2);
  // Where Φ is flat (no curvature radius below 50 diagonals: the normal turns by less than a degree
  // over the whole surface) its least-curvature direction is noise: on the HECC diffuser's vane (a
  // near-plane but for its leading edge) it pointed anywhere, along the chord too, and the first
  // patch brought 31% instead of 79%. There a tool's axis is laid across Φ's width, so that one tool
  // spans the flank.
  if (pc.valid && (o.across || !(pc.radius > 0 && pc.radius < 50))) {
    const Eigen::Vector3d w = width - width.dot(n) * n;
    if (w.norm() > 0.3) pc.least = w.normalized();
  }
  std::vector<std::pair<double, int>> offsets;  // radius, side
  for (double r : o.radii) offsets.emplace_back(r, 1), offsets.emplace_back(r, -1);
  if (pc.valid && pc.radius > 0.005 && pc.radius < 0.3) offsets.emplace_back(pc.radius, pc.side);
  // Around the least-curvature direction (±30 degrees); without it, evenly over the half circle.
  // `across`: how much of a line's length counts as reach across Φ where F_l is at its floor. A line
  // turned by φ from the least-curvature direction is 1/cos φ longer over the same strip, and on a
  // developable flank (F_l at the floor for every turn) it ranked first for that alone: on the HECC
  // diffuser's 15 mm high, 124 mm long vane the 30° line won, its cylinder fitted 0.011 mm off with
  // its flat end 1.2 mm short of the hub (79% of the vane; the ruling line: 95%). Its reach is the
  // length times cos φ, and a turn costs a little (10% of 1 - cos φ) so that ties go to the principal
  // direction.
  std::vector<Eigen::Vector3d> dirs;
  std::vector<double> across;
  if (pc.valid) {
    t1 = pc.least;
    t2 = n.cross(t1);
    for (int dk = 0; dk < o.directions; ++dk) {
      const double phi = o.directions == 1 ? 0.0 : (-30.0 + 60.0 * dk / (o.directions - 1)) * M_PI / 180;
      dirs.push_back(std::cos(phi) * t1 + std::sin(phi) * t2);
      across.push_back(std::cos(phi) / (1 + 0.1 * (1 - std::cos(phi))));
    }
  } else {
    for (int dk = 0; dk < o.directions; ++dk) {
      const double phi = M_PI * dk / o.directions;
      dirs.push_back(std::cos(phi) * t1 + std::sin(phi) * t2);
      across.push_back(1.0);
    }
  }
  std::array<std::vector<SeedLine>, 2> lines;  // per side: -1, +1
  constexpr int reach_samples = 121;  // 0.0125 apart: a line as short as 0.05 of the diagonal is seen
  constexpr double reach = 0.75;  // half-length of the probe line (unit frame)
  const auto u_of = [&](int i) { return -reach + 2 * reach * i / (reach_samples - 1); };
  for (size_t dk = 0; dk < dirs.size(); ++dk)
    for (const auto& [r, side] : offsets) {
      const Eigen::Vector3d& d = dirs[dk];
      {
        const Eigen::Vector3d c = p + side * r * n;
        const auto inside = [&](double u) { return !surface.closest(Eigen::Vector3d(c + u * d)).on_boundary; };
        std::vector<char> in(reach_samples);
        for (int i = 0; i < reach_samples; ++i) in[size_t(i)] = inside(u_of(i));
        const int mid = reach_samples / 2;
        if (!in[size_t(mid)]) continue;
        int lo = mid, hi = mid;
        while (lo > 0 && in[size_t(lo - 1)]) --lo;
        while (hi + 1 < reach_samples && in[size_t(hi + 1)]) ++hi;
        if (hi - lo < 4) continue;
        // The line reaches as far as Φ does along it (bisection to the boundary, 1% overhang): a tool
        // shorter than Φ's width leaves strips at its ends.
        const auto edge = [&](double u_in, double u_out) {
          for (int it = 0; it < 8; ++it) {
            const double u = 0.5 * (u_in + u_out);
            (inside(u) ? u_in : u_out) = u;
          }
          return u_in;
        };
        double u0 = lo > 0 ? edge(u_of(lo), u_of(lo - 1)) : u_of(lo);
        double u1 = hi + 1 < reach_samples ? edge(u_of(hi), u_of(hi + 1)) : u_of(hi);
        const double overhang = 0.01 * (u1 - u0);
        u0 -= overhang;
        u1 += overhang;
        const AxisLine line{c + u0 * d, c + u1 * d};
        const Movability m = line_movability(surface, line.a, line.b, o.patch.exploration.movability);
        if (!m.movable || m.used_samples * 5 < 4 * o.patch.exploration.movability.samples) continue;
        // Below ~1e-8 (angles ~1e-4 rad) F_l is tessellation noise: among such lines the one that
        // reaches furthest across Φ wins, so the rank is F_l floored there, per unit of reach.
        lines[side > 0 ? 1 : 0].push_back(
            SeedLine{line, c, m.F, std::max(m.F, kMovableF) / ((u1 - u0) * (m.F <= kMovableF ? across[dk] : 1.0))});
      }
  }
  PointSeeds out;
  for (int k = 0; k < 4; ++k) {
    out.best[size_t(k)].vertex = v;
    out.best[size_t(k)].side = k % 2 == 0 ? -1 : 1;
    out.best[size_t(k)].oriented = k >= 2;
  }
  for (int s = 0; s < 2; ++s) {
    auto& ls = lines[size_t(s)];
    std::stable_sort(ls.begin(), ls.end(), [](const SeedLine& x, const SeedLine& y) { return x.rank < y.rank; });
    if (!ls.empty()) out.best[size_t(s)].take(ls.front());
    ls.resize(std::min(ls.size(), size_t(o.oriented_lines)));
    out.top[size_t(s)] = std::move(ls);
  }
  return out;
}

// The best `oriented_lines` of each side turned about their seed point to their least F_l
// (orient_line) and the most movable of them kept as the point's oriented seeds: a general tool's
// axis leaves the tangent plane and is no principal direction; lines in the tangent plane miss it
// by its slope r'(s) and rank behind lines that are no axis.
void orient_seeds(const SurfaceIndex& surface, PointSeeds& ps, const CoverOptions& o) {
  OrientationOptions orientation;
  orientation.movability = o.patch.exploration.movability;
  for (int s = 0; s < 2; ++s)
    for (SeedLine l : ps.top[size_t(s)]) {
      if (l.F > kMovableF) {
        const OrientedLine ol = orient_line(surface, l.line.a, l.line.b, l.pivot, orientation);
        l.line = {ol.a, ol.b};
        l.rank *= std::max(ol.movability.F, kMovableF) / std::max(l.F, kMovableF);
        l.F = ol.movability.F;
      }
      ps.best[size_t(2 + s)].take(l);
    }
}

// How far a line is from a tool axis: the line is swept a short way in both directions along its best
// tangential field (Sec. 4.3), and each point along it should keep its distance to Φ (a tool's radius,
// eq. 8). The RMS over the points of the spread (max - min) of that distance is the score; F_l alone
// cannot tell offsets apart (on nearly developable envelopes lines at any offset, on either side,
// have F_l at the tessellation's noise level), the change of the distances over a sweep can.
// Infinite when the sweep is too short or too few points stay over Φ.
double sweep_spread(const SurfaceIndex& surface, const AxisLine& l, const CoverOptions& o) {
  PropagationOptions pr = o.patch.propagation;
  pr.max_steps = o.sweep_steps;
  pr.step = o.sweep_step;
  pr.keep_radii = false;  // the corrector keeps the distances by construction: it would hide the spread
  const LineTrajectory tr = propagate_line(surface, l.a, l.b, pr);
  const int positions = int(tr.a.size());
  constexpr double inf = std::numeric_limits<double>::infinity();
  if (positions < o.sweep_steps) return inf;
  constexpr int points = 14;
  std::vector<Eigen::Vector3d> x;
  x.reserve(size_t(positions * points));
  for (int k = 0; k < positions; ++k)
    for (int j = 1; j <= points; ++j) {
      const double s = double(j) / (points + 1);
      x.push_back((1 - s) * tr.a[size_t(k)] + s * tr.b[size_t(k)]);
    }
  const std::vector<Footpoint> f = surface.closest(x);
  double sum = 0;
  int used = 0;
  for (int j = 0; j < points; ++j) {
    double lo = inf, hi = -inf;
    bool inside = true;
    for (int k = 0; k < positions && inside; ++k) {
      const Footpoint& fp = f[size_t(k * points + j)];
      inside = !fp.on_boundary;
      const double d = smooth_distance(surface, fp, x[size_t(k * points + j)]);
      lo = std::min(lo, d);
      hi = std::max(hi, d);
    }
    if (inside) sum += (hi - lo) * (hi - lo), ++used;
  }
  return used * 2 >= points ? std::sqrt(sum / used) : inf;
}

// The seed line moved to the nearest tool axis it can find: the points at 20% and 80% of it are
// moved along their footpoint normals and across (4 unknowns: offset, tilt and turn of the line),
// a pattern search on sweep_spread. Seeds place the line at a few candidate radii along the
// least-curvature direction; the axis of a cone, barrel or spline tool is tilted out of the tangent
// plane and its radius is none of them, and exploration (Sec. 4.2) reaches only about 0.02.
Seed refine_seed(const SurfaceIndex& surface, Seed seed, const CoverOptions& o) {
  const AxisLine l0 = seed.line;
  const double L = (l0.b - l0.a).norm();
  const Eigen::Vector3d qa = 0.8 * l0.a + 0.2 * l0.b, qb = 0.2 * l0.a + 0.8 * l0.b;
  const Footpoint fa = surface.closest(qa), fb = surface.closest(qb);
  const Eigen::Vector3d e = (l0.b - l0.a) / L;
  const auto frame = [&](const Footpoint& f) {
    Eigen::Vector3d n = f.normal - f.normal.dot(e) * e;
    n = n.norm() > 1e-9 ? Eigen::Vector3d(n.normalized()) : Eigen::Vector3d(e.unitOrthogonal());
    return std::make_pair(n, Eigen::Vector3d(e.cross(n)));
  };
  // Plain variables, not structured bindings: C++17 lambdas cannot capture bindings (clang rejects).
  const std::pair<Eigen::Vector3d, Eigen::Vector3d> frame_a = frame(fa), frame_b = frame(fb);
  const Eigen::Vector3d na = frame_a.first, ta = frame_a.second, nb = frame_b.first, tb = frame_b.second;
  using X = Eigen::Vector4d;  // normal offset at 20%, at 80%, across at 20%, at 80%
  const auto line_of = [&](const X& x) {
    const Eigen::Vector3d pa = qa + x[0] * na + x[2] * ta, pb = qb + x[1] * nb + x[3] * tb;
    const Eigen::Vector3d mid = 0.5 * (pa + pb), d = (pb - pa).normalized();
    return AxisLine{mid - 0.5 * L * d, mid + 0.5 * L * d};
  };
  // A spread below 1% of the tolerance is no worse than none: below it the search would chase the
  // tessellation's noise and turn the line at will (on the HECC diffuser's exactly ruled vane, lines
  // seeded along the rulings ended 20-40° off them and their cylinders 0.011 mm off the vane).
  const double noise = 0.01 * o.patch.tolerance;
  const auto spread_of = [&](const AxisLine& l) { return std::max(sweep_spread(surface, l, o), noise); };
  X best = X::Zero();
  double best_score = spread_of(l0);
  // Common offset first (the radius is the least known), coarse, then the pattern search.
  for (int k = -4; k <= 4; ++k) {
    if (k == 0) continue;
    const X x(0.01 * k, 0.01 * k, 0, 0);
    const double sc = spread_of(line_of(x));
    if (sc < best_score) best_score = sc, best = x;
  }
  double h = 0.005;
  for (int evals = 0; h >= 0.0005 && evals < o.refine_evaluations;) {
    X step_best = best;
    double step_score = best_score;
    for (int i = 0; i < 4; ++i)
      for (int sign : {-1, 1}) {
        X x = best;
        x[i] += sign * h;
        const double sc = spread_of(line_of(x));
        ++evals;
        if (sc < step_score) step_score = sc, step_best = x;
      }
    if (step_score < best_score) {
      best = step_best;
      best_score = step_score;
    } else {
      h *= 0.5;
    }
  }
  seed.line = line_of(best);
  seed.spread = best_score;
  return seed;
}

// Seed points: per cell of a grid whose spacing follows Φ's area, the lowest-index vertex that is
// uncovered and not on the boundary.
std::vector<int> seed_points(const SurfaceIndex& surface, const std::vector<char>& covered, const CoverOptions& o) {
  const TriMesh& m = surface.mesh();
  const double h = std::sqrt(surface_area(m) / o.seed_points);
  const auto& boundary = surface.topology().boundary_vertex;
  std::map<std::tuple<long, long, long>, int> cells;
  for (int v = 0; v < int(m.vertices.size()); ++v) {
    if (covered[size_t(v)] || boundary[size_t(v)]) continue;
    const Eigen::Vector3d& x = m.vertices[size_t(v)];
    cells.emplace(std::make_tuple(long(std::floor(x.x() / h)), long(std::floor(x.y() / h)), long(std::floor(x.z() / h))), v);
  }
  std::vector<int> out;
  for (const auto& [cell, v] : cells) out.push_back(v);
  std::sort(out.begin(), out.end());
  return out;
}

// Positions [from, to) of a trajectory (F_l with them; the stop reasons are not carried over).
LineTrajectory slice(const LineTrajectory& tr, size_t from, size_t to) {
  LineTrajectory p;
  p.a.assign(tr.a.begin() + long(from), tr.a.begin() + long(to));
  p.b.assign(tr.b.begin() + long(from), tr.b.begin() + long(to));
  p.F.assign(tr.F.begin() + long(from), tr.F.begin() + long(to));
  return p;
}

// The trajectory's position nearest to where its line was seeded (a end).
int seed_position(const LineTrajectory& tr, const Eigen::Vector3d& seed_a) {
  int start = 0;
  double best = std::numeric_limits<double>::infinity();
  for (size_t i = 0; i < tr.a.size(); ++i)
    if ((tr.a[i] - seed_a).norm() < best) best = (tr.a[i] - seed_a).norm(), start = int(i);
  return start;
}

// A propagated line as the tool it starts: at most `max_length` long (custom tools), and with a part
// slid along its axis out of it. A seed line reaches across Φ, which may be wider than any allowed tool
// (the HECC impeller's inlet: 67 mm, tools up to 50 mm), and a line of constant length propagated
// over a flank whose width shrinks (the impeller's outlet: 17 mm) hangs far beyond it, into the hub;
// the fit would shorten it at an arbitrary end and the part trim away most of its motion. So per
// position, from the stretch of the axis over Φ [f0, f1] and the stretch where a sphere of the
// local tool radius (the distance to Φ) keeps out of the part [c0, c1], two placements of one
// length w = min(L, max_length): the tip end low (at f0, or lifted to c0 less a radius, where a flat
// end stands on the hub) and the tip end high (its far end at f1, or lowered to c1). They are
// candidates of their own (the tier at the hub and the one above it); one when they agree. A line no
// longer than max_length is only slid as far as the part needs (not at all without a part). A fixed
// tool beside a part is placed the same way with its own length w, its tip end turned away from `up`
// (the part's floor side; held_tool_start keeps it): centred on the line, the catalogue's Ø8 25 mm
// cylinder stood 5 mm into the HECC diffuser's hub beside its 15 mm vane and the first patch covered
// 0.9%. Without a part or `up` held_tool_start centres it on the line.
std::vector<LineTrajectory> placed_lines(const SurfaceIndex& surface, const LineTrajectory& given, const CoverOptions& o) {
  const CheckSurface& check = o.patch.fit.check;
  const bool fixed = o.patch.fit.fixed_tool.has_value();
  if (given.a.empty() || (fixed && !(check.part && o.up))) return {given};
  LineTrajectory tr = given;
  if (fixed && (tr.b.front() - tr.a.front()).dot(*o.up) < 0) std::swap(tr.a, tr.b);
  const double L = (tr.b.front() - tr.a.front()).norm();
  const double w = fixed ? o.tool_length : std::min(L, o.patch.fit.constraints.max_length);
  if (!check.part && w >= L) return {tr};
  const size_t n = tr.a.size();
  // Samples along the axis, from w below its a end to w beyond its b end.
  const int per = 48;
  const double h = w / per;
  const int count = int(std::ceil((L + 2 * w) / h)) + 1;
  std::vector<Eigen::Vector3d> x(n * size_t(count));
  for (size_t i = 0; i < n; ++i) {
    const Eigen::Vector3d e = (tr.b[i] - tr.a[i]).normalized();
    for (int k = 0; k < count; ++k) x[i * size_t(count) + size_t(k)] = tr.a[i] + (-w + k * h) * e;
  }
  const std::vector<Footpoint> f = surface.closest(x);
  const std::vector<double> part = cutter_clearances(check, x);
  constexpr double nan = std::numeric_limits<double>::quiet_NaN();
  std::vector<double> low(n, nan), high(n, nan);
  const double overhang = 0.01 * L;
  for (size_t i = 0; i < n; ++i) {
    const auto at = [&](int k) { return i * size_t(count) + size_t(k); };
    int k0 = -1, k1 = -1;  // the axis over Φ
    for (int k = 0; k < count; ++k)
      if (!f[at(k)].on_boundary) k1 = k, k0 = k0 < 0 ? k : k0;
    if (k0 < 0) continue;
    const auto u = [&](int k) { return -w + k * h; };
    // The tool radius along the axis: the distance to Φ over it, the nearest such beyond it.
    const auto radius = [&](int k) { return f[at(std::clamp(k, k0, k1))].distance; };
    const auto clear = [&](int k) { return part[at(k)] >= radius(k) - check.tolerance; };
    // The clear stretch around the middle of the axis over Φ (none there: the part says nothing here).
    const int mid = (k0 + k1) / 2;
    int c0 = 0, c1 = count - 1;
    if (clear(mid)) {
      c0 = c1 = mid;
      while (c0 > 0 && clear(c0 - 1)) --c0;
      while (c1 + 1 < count && clear(c1 + 1)) ++c1;
    }
    // Where the tip may stand: not below the part's side at the tip, not so high that the far end
    // enters the part (both: the tip's side wins, the trim judges the rest).
    const double tip_min = c0 > 0 ? u(c0) - radius(c0) : -INFINITY;
    const double tip_max = c1 + 1 < count ? u(c1) + radius(c1) - w : INFINITY;
    if (w < L) {
      low[i] = std::max(std::min(u(k0) - overhang, tip_max), tip_min);
      high[i] = std::max(std::min(u(k1) + overhang - w, tip_max), tip_min);
    } else {
      low[i] = high[i] = std::max(std::min(0.0, tip_max), tip_min);  // slid only as far as the part needs
    }
  }
  // Positions with no axis over Φ take their neighbour's placement.
  const auto fill = [&](std::vector<double>& s) {
    for (size_t i = 1; i < n; ++i)
      if (std::isnan(s[i])) s[i] = s[i - 1];
    for (size_t i = n - 1; i-- > 0;)
      if (std::isnan(s[i])) s[i] = s[i + 1];
    for (double& v : s)
      if (std::isnan(v)) v = 0;
  };
  fill(low);
  fill(high);
  const auto moved = [&](const std::vector<double>& s) {
    LineTrajectory p = tr;
    for (size_t i = 0; i < n; ++i) {
      const Eigen::Vector3d e = (tr.b[i] - tr.a[i]).normalized();
      p.a[i] = tr.a[i] + s[i] * e;
      p.b[i] = p.a[i] + w * e;
    }
    return p;
  };
  double apart = 0, slid = 0;
  for (size_t i = 0; i < n; ++i) apart = std::max(apart, std::abs(low[i] - high[i])), slid = std::max(slid, std::abs(low[i]));
  if (w >= L && slid == 0 && !fixed) return {tr};
  if (apart < 0.02 * w) return {moved(low)};
  return {moved(low), moved(high)};
}

struct Candidate {
  LineTrajectory trajectory;
  double uncovered_swept = 0;  // share of Φ's area, uncovered, under the kept trajectory
  int seed_vertex = -1;        // the seed point it came from
};

// Keeps the run of the trajectory that sweeps uncovered surface around the seed position, plus
// `band` of arc length into covered surface on each side (the overlap with the neighbours).
Candidate keep_uncovered(const SurfaceIndex& surface, const LineTrajectory& tr, int start,
                         const std::vector<char>& covered, const std::vector<double>& area, const CoverOptions& o) {
  const TriMesh& m = surface.mesh();
  const int n = int(tr.a.size());
  constexpr int per_line = 9;
  std::vector<Eigen::Vector3d> pts;
  for (int i = 0; i < n; ++i)
    for (int j = 0; j < per_line; ++j) {
      const double s = (j + 0.5) / per_line;
      pts.push_back((1 - s) * tr.a[size_t(i)] + s * tr.b[size_t(i)]);
    }
  const auto fps = surface.closest(pts);
  std::vector<char> pos_covered(size_t(n), 0);
  for (int i = 0; i < n; ++i) {
    int inside = 0, cov = 0;
    for (int j = 0; j < per_line; ++j) {
      const Footpoint& f = fps[size_t(i * per_line + j)];
      if (f.on_boundary) continue;
      ++inside;
      cov += covered[size_t(nearest_corner(m, f))];
    }
    pos_covered[size_t(i)] = inside == 0 || cov * 5 >= inside * 4;
  }
  int lo = start, hi = start;
  while (lo > 0 && !pos_covered[size_t(lo - 1)]) --lo;
  while (hi + 1 < n && !pos_covered[size_t(hi + 1)]) ++hi;
  const auto mid = [&](int i) { return Eigen::Vector3d(0.5 * (tr.a[size_t(i)] + tr.b[size_t(i)])); };
  for (double run = 0; lo > 0 && run < o.band; --lo) run += (mid(lo) - mid(lo - 1)).norm();
  for (double run = 0; hi + 1 < n && run < o.band; ++hi) run += (mid(hi + 1) - mid(hi)).norm();
  Candidate c;
  c.trajectory = slice(tr, size_t(lo), size_t(hi + 1));
  c.trajectory.stop_backward = tr.stop_backward;
  c.trajectory.stop_forward = tr.stop_forward;
  std::vector<char> swept(m.vertices.size(), 0);
  for (int i = lo; i <= hi; ++i)
    for (int j = 0; j < per_line; ++j) {
      const Footpoint& f = fps[size_t(i * per_line + j)];
      if (!f.on_boundary) swept[size_t(nearest_corner(m, f))] = 1;
    }
  for (size_t v = 0; v < swept.size(); ++v)
    if (swept[v] && !covered[v]) c.uncovered_swept += area[v];
  return c;
}

struct Fitted {
  PatchFit fit;
  double gain = 0;
  bool ok = false;
  // Its tool is the fitted one cut shorter at its tip; whole_gain: what the whole tool brought.
  bool cut = false;
  double whole_gain = 0;
  bool from_region = false;  // found by searching an uncovered region on its own
};

// A held tool's start (fixed or shared tool): the candidate's rails with the tool's axis length,
// centred on the candidate's line (which reaches across Φ), its holder end along `up` (or, without
// one, the way round whose initial error is lower: a tool's ends are not interchangeable).
Rails held_tool_start(const SurfaceIndex& surface, const Rails& r, const CoverOptions& o) {
  const double L = o.tool_length;
  Rails c = r;
  c.length = L;
  for (Eigen::Index k = 0; k < r.a.ctrl.rows(); ++k) {
    const Eigen::RowVector3d a = r.a.ctrl.row(k), b = r.b.ctrl.row(k);
    const Eigen::RowVector3d mid = 0.5 * (a + b), e = (b - a).normalized();
    c.a.ctrl.row(k) = mid - 0.5 * L * e;
    c.b.ctrl.row(k) = mid + 0.5 * L * e;
  }
  Rails turned = c;
  std::swap(turned.a, turned.b);
  if (o.up) return mean_axis(c).dot(*o.up) >= 0 ? c : turned;
  const auto error = [&](const Rails& x) {
    try {
      return sample_error(surface, x, *o.patch.fit.fixed_tool, o.patch.fit).max;
    } catch (const InputError&) {
      return std::numeric_limits<double>::infinity();
    }
  };
  return error(turned) < error(c) ? turned : c;
}

// Marks in `into` the vertices a fit brings within tolerance.
void mark_covered(const PatchFit& f, double tol, std::vector<char>& into) {
  for (size_t v = 0; v < into.size(); ++v) {
    const double d = f.machined.design_deviation[v];
    into[v] |= std::isfinite(d) && std::abs(d) <= tol;
  }
}

// The share of Φ's area a fit brings within tolerance that is not covered yet.
double gain_of(const PatchFit& f, const std::vector<char>& covered, const std::vector<double>& area, double tol) {
  double g = 0;
  for (size_t v = 0; v < area.size(); ++v) {
    const double d = f.machined.design_deviation[v];
    if (!covered[v] && std::isfinite(d) && std::abs(d) <= tol) g += area[v];
  }
  return g;
}

// One candidate fitted, machined and trimmed where it gouges; its gain is the uncovered area it
// brings within tolerance. From the trajectory, or from `start` (rails of an earlier fit).
PatchOptions candidate_options(const CoverOptions& o) {
  PatchOptions po = o.patch;
  po.trim_gouges = true;  // neighbours must not overcut each other's region
  // A held tool keeps its tip at the a end: the part must not turn it round (that would be the
  // mirrored tool), the start has its holder end along `up` already.
  if (po.fit.fixed_tool) po.orient_by_part = false;
  po.fit.check.floor_reach = 0;  // the floor pass pulls the tip of each round's best only
  return po;
}

// The a end (the tip) of each axis line tilted towards Φ, square to the axis, to within `radius`
// of it: a start tool narrowing to its tip. A seed's or a fitted wide tool's axis lies at its
// radius from Φ; the fit, started from that tool held narrow at its tip, stayed 0.5 mm off a plane.
Rails tip_tilted(const SurfaceIndex& surface, Rails start, double radius) {
  for (Eigen::Index i = 0; i < start.a.ctrl.rows(); ++i) {
    const Eigen::Vector3d a = start.a.ctrl.row(i).transpose(), b = start.b.ctrl.row(i).transpose();
    const Eigen::Vector3d e = (b - a).normalized();
    Eigen::Vector3d v = a - surface.closest(a).point;
    v -= v.dot(e) * e;
    if (const double r = v.norm(); r > radius) start.a.ctrl.row(i) = (a - (1 - radius / r) * v).transpose();
  }
  return start;
}

// A tip narrower than the tool (ToolConstraints::max_tip_radius) is held at the tip alone: the tool
// widens towards its holder. Held at both ends (either_end: detection turns a tool after its fit) it
// made lenses, narrow at both ends, that fitted nothing (the HECC impeller with max_tip_diameter 4:
// no patch). So the tip end is chosen on the start motion, as it is after the fit: by the part
// (holder_up with the start's own tool), without one by `up` (the spindle's side); the start is
// turned so that its tip is the a end, and the fit holds the tip's limits there with that choice kept.
bool tip_chosen_first(const CoverOptions& o) {
  const PatchOptions& p = o.patch;
  return !p.fit.fixed_tool && std::isfinite(p.fit.constraints.max_tip_radius) &&
         (p.fit.check.part ? p.orient_by_part : o.up.has_value());
}

// The options that keep a motion's tip at its a end (a start turned by tip_first, or a fit of one):
// the part does not turn it, the tip's limits hold there alone.
void tip_held_at_a(PatchOptions& po, const Rails& rails) {
  po.orient_by_part = false;
  po.fit.check.up = mean_axis(rails);
  po.fit.constraints.either_end = false;
}

Rails tip_first(const SurfaceIndex& surface, Rails start, const CoverOptions& o, PatchOptions& po) {
  const Eigen::Vector3d axis = mean_axis(start);
  Eigen::Vector3d up = o.up.value_or(axis);
  if (po.fit.check.part)
    up = holder_up(start, initial_tool(surface, start, po.fit), po.fit.check, 2 * po.fit.samples_t,
                   po.fit.check.up.value_or(up));
  if (axis.dot(up) < 0) std::swap(start.a, start.b);
  start = tip_tilted(surface, std::move(start), 0.9 * po.fit.constraints.max_tip_radius);
  tip_held_at_a(po, start);
  return start;
}

// A fitted motion machined over Φ and trimmed where it gouges; with a check surface kept out of the
// part (with_check), rejected when no stretch keeps clear. Nothing when its tool cannot carry the
// job's end (a ball wider than the tool, InputError from the machined surface): not a candidate.
std::optional<PatchFit> judged(const SurfaceIndex& surface, PatchFit f, const PatchOptions& po) {
  try {
    return po.fit.check.part ? with_check(surface, std::move(f), po) : machine_and_trim(surface, std::move(f), po);
  } catch (const InputError&) {
    return std::nullopt;
  }
}

Fitted fit_candidate(const SurfaceIndex& surface, const LineTrajectory& tr, const std::vector<char>& covered,
                     const std::vector<double>& area, const CoverOptions& o, const Rails* start = nullptr) {
  Fitted out;
  PatchOptions po = candidate_options(o);
  if (!start && tr.a.size() < size_t(po.fit.rail_control_points)) return out;
  try {
    out.fit.trajectory = tr;
    out.fit.initial = start ? *start : rails_from_trajectory(tr, po.fit);
    if (tip_chosen_first(o)) out.fit.initial = tip_first(surface, std::move(out.fit.initial), o, po);
    if (po.fit.fixed_tool) out.fit.initial = held_tool_start(surface, out.fit.initial, o);
    out.fit.fit = optimize_motion(surface, out.fit.initial, po.fit);
  } catch (const InputError&) {
    return out;  // the motion left the surface: not a patch
  }
  const FitResult fitted = out.fit.fit;  // untrimmed, its tip at the a end unless the part turned it
  std::optional<PatchFit> j = judged(surface, std::move(out.fit), po);
  if (!j) return Fitted{};
  out.fit = std::move(*j);
  if (machinable(out.fit)) out.gain = gain_of(out.fit, covered, area, po.tolerance), out.ok = true;
  out.whole_gain = out.gain;
  // Trimmed to less than 90% of its motion for gouging Φ, or gouging all along (not for the part,
  // whose own tip cut with_check has tried): a tool as long as the flank is high fits part of a
  // twisted flank and gouges the rest (the HECC impeller's inducer is 67 mm high, tools up to 50 mm:
  // on its upper half alone 8 patches bring 67% within 0.02 mm, 88% with this). The axis cut a
  // quarter or half shorter at the tool's tip, tool and motion fitted again over what it still
  // reaches and judged as above; whichever brings most uncovered area is the candidate. The tip: the
  // a end where the part has turned the tool (with_check), else the end away from `up`; with no
  // `up`, either end is tried.
  if (!po.fit.fixed_tool && !out.fit.check_trim && (out.fit.gouges || out.fit.t_to - out.fit.t_from < 0.9)) {
    const std::optional<Eigen::Vector3d> up = po.fit.check.part ? po.fit.check.up : o.up;
    std::vector<bool> tip_ends;  // tip at the a end of `fitted`
    if (po.fit.check.part && po.orient_by_part)
      tip_ends = {mean_axis(out.fit.fit.rails).dot(mean_axis(fitted.rails)) > 0};
    else if (up)
      tip_ends = {mean_axis(fitted.rails).dot(*up) >= 0};
    else
      tip_ends = {true, false};
    for (const bool tip_at_a : tip_ends)
      for (const double c : {0.25, 0.5}) {
        const ToolCut cut = tip_at_a ? cut_tool(fitted.rails, fitted.tool, c, 1) : cut_tool(fitted.rails, fitted.tool, 0, 1 - c);
        PatchFit p;
        p.trajectory = out.fit.trajectory;
        // What stays of a tool widening towards its holder is wide at its new tip: tilted as a start.
        p.initial = tip_chosen_first(o) ? tip_tilted(surface, cut.rails, 0.9 * po.fit.constraints.max_tip_radius) : cut.rails;
        try {
          p.fit = optimize_motion(surface, p.initial, po.fit);
        } catch (const InputError&) {
          continue;  // what stays of the axis left Φ
        }
        std::optional<PatchFit> jp = judged(surface, std::move(p), po);
        if (!jp || !machinable(*jp)) continue;
        p = std::move(*jp);
        const double g = gain_of(p, covered, area, po.tolerance);
        if (!out.ok || g > out.gain) out.fit = std::move(p), out.gain = g, out.ok = true, out.cut = true;
      }
  }
  return out;
}

// Whether a row (t index `row`, all of its s) or a column (s index `column`, all of its t; row < 0) of
// the machined surface's Ω still lies over Φ: a deviation of it is finite.
bool omega_over_phi(const MachinedSurface& ms, int row, int column) {
  const size_t n_s = size_t(ms.omega.n_s);
  const int n = row >= 0 ? ms.omega.n_s : ms.omega.n_t;
  for (int k = 0; k < n; ++k)
    if (std::isfinite(ms.omega_deviation[row >= 0 ? size_t(row) * n_s + size_t(k) : size_t(k) * n_s + size_t(column)]))
      return true;
  return false;
}

// A patch's motion continued past an end whose last row of Ω still lies over Φ. Propagation stops a
// motion where its line reaches Φ's boundary; a contact curve slanted to that boundary reaches it at
// one end of the tool first and leaves a wedge of the boundary strip unmachined (rotor 37's trailing
// edge: 2-10 of 241 columns along the hub half, fitted within 0.003 mm up to where the motion ends).
// The motion is continued straight by steps of 5% of its length, at most 40% an end, and fitted
// again with its tool held (what of the line still lies over Φ holds it there). Each step offers that
// fit and the fit anchored (the stretch machined so far kept as it was, the fit only past the ends:
// a refit that moves the rest leaves what it machined or gouges there); each is judged as a
// candidate (trimmed where it gouges Φ or meets the part) and the one bringing most of what is
// uncovered is kept while it brings more. Both ends step together; when that brings nothing, each
// end alone (one end gouging trimmed the joint step back), and an end that brings nothing alone
// stops. The kept stretch's t_from / t_to then lie beyond [0, 1] of the first optimised motion.
Fitted continued(const SurfaceIndex& surface, Fitted f, const std::vector<char>& covered, const std::vector<double>& area,
                 const CoverOptions& o) {
  PatchOptions po = candidate_options(o);
  po.solid_cutter_on_phi = true;
  // The holder at the b end: with_check has turned the fit so that its tip is the a end.
  if (po.fit.check.part) po.fit.check.up = mean_axis(f.fit.fit.rails);
  FitOptions held = po.fit;
  held.fixed_tool = f.fit.fit.tool;
  const auto over_phi = [](const MachinedSurface& ms, int row) { return omega_over_phi(ms, row, -1); };
  const PatchFit original = f.fit;
  const double t_from = original.t_from, w = original.t_to - original.t_from;
  constexpr double step = 0.05;
  constexpr int most_steps = 8;  // 40% of the motion an end
  // Whether a fit's end (0: t = 0, 1: t = 1) may be continued: not trimmed (where the motion gouged Φ
  // or met the part) and its last row of Ω still over Φ.
  const auto open_at = [&](const PatchFit& p, int end) {
    return end == 0 ? p.t_from == 0 && over_phi(p.machined, 0) : p.t_to == 1 && over_phi(p.machined, p.machined.omega.n_t - 1);
  };
  bool ends[2] = {open_at(original, 0), open_at(original, 1)};
  // The motion continued by kb / ka steps, its best candidate (none when none is machinable), its
  // gain, and open_at of that candidate's ends.
  struct Step {
    std::optional<PatchFit> fit;
    double gain = 0;
    bool open[2] = {false, false};
  };
  const auto try_step = [&](int kb, int ka) {
    Step out;
    const double b = step * kb, a = step * ka;
    PatchFit p = original;
    try {
      p.fit = optimize_motion(surface, continued(original.fit.rails, b, a), held);
    } catch (const InputError&) {
      return out;  // the continued motion left Φ
    }
    p.fit.eps_ini = original.fit.eps_ini;
    p.fit.iterations += original.fit.iterations;
    PatchFit anchor = p;
    anchor.fit.rails = anchored(original.fit.rails, p.fit.rails, b, a, step);
    for (PatchFit* c : {&p, &anchor}) {
      try {
        // ε of the anchored motion itself (eq. 13), not of the refit it was made from.
        if (c == &anchor) c->fit.eps_opt = sample_error(surface, c->fit.rails, c->fit.tool, held);
        PatchFit j = machine_and_trim(surface, std::move(*c), po);
        if (!machinable(j)) continue;
        const double g = gain_of(j, covered, area, po.tolerance);
        if (out.fit && !(g > out.gain)) continue;
        out.open[0] = open_at(j, 0), out.open[1] = open_at(j, 1);
        // The kept stretch in the first motion's t.
        std::tie(j.t_from, j.t_to) = kept_within(t_from - w * b, t_from + w * (1 + a), j.t_from, j.t_to);
        out.fit = std::move(j), out.gain = g;
      } catch (const InputError&) {
      }
    }
    return out;
  };
  int before = 0, after = 0;  // steps the kept motion reaches past each end
  // The step taken: an end stepped stays open while the kept stretch still reaches it over Φ (an end
  // trimmed back, by a gouge or the part, or beyond Φ is not continued further); an end not stepped
  // keeps what it had.
  const auto take = [&](Step& s, int kb, int ka) {
    f.fit = std::move(*s.fit);
    f.gain = s.gain;
    if (kb > before) ends[0] = ends[0] && s.open[0];
    if (ka > after) ends[1] = ends[1] && s.open[1];
    before = kb, after = ka;
  };
  const auto gains = [&](const Step& s) { return s.fit && s.gain > f.gain + 1e-4; };
  while ((ends[0] || ends[1]) && std::max(before, after) < most_steps) {
    if (ends[0] && ends[1]) {
      if (Step s = try_step(before + 1, after + 1); gains(s)) {
        take(s, before + 1, after + 1);
        continue;
      }
    }
    Step alone[2];
    int best = -1;  // the end that brings most alone (the a end on a tie)
    for (int e = 0; e < 2; ++e)
      if (ends[e]) {
        alone[e] = try_step(before + (e == 0), after + (e == 1));
        if (!gains(alone[e]))
          ends[e] = false;
        else if (best < 0 || alone[e].gain > alone[best].gain)
          best = e;
      }
    if (best < 0) break;
    take(alone[best], before + (best == 0), after + (best == 1));
  }
  return f;
}

// The floor pass (CoverOptions::end) on a patch: the options its variants are judged with (the
// tool's end swept unless `end_swept` is false; with_check has turned the fit so that its tip is the
// a end: kept so, the tip's limits held there).
PatchOptions floor_options(const CoverOptions& o, const Rails& r, bool end_swept = true) {
  PatchOptions po = candidate_options(o);
  if (end_swept) po.machined.end = o.end;
  tip_held_at_a(po, r);
  return po;
}

// The floor pass's variants of a patch, each judged and machinable, in the order offered: the patch
// as it is, fitted again from its motion with the tip pulled onto the part's floor (its tool free),
// and with CoverOptions::floor_tip with a narrow tip, pulled so. They depend on the patch alone, not
// on what the others cover. A held tool (catalogue or shared) is never passed here.
std::vector<PatchFit> floor_variants(const SurfaceIndex& surface, const PatchFit& f, const CoverOptions& o) {
  const PatchOptions po = floor_options(o, f.fit.rails);
  std::vector<PatchFit> variants;
  const auto offer = [&](PatchFit p) {
    std::optional<PatchFit> j = judged(surface, std::move(p), po);
    if (j && machinable(*j)) variants.push_back(std::move(*j));
  };
  // `p` fitted again from `start` with `fit` (its iterations counted on f's) and offered; a motion
  // that leaves Φ is no variant.
  const auto refit = [&](PatchFit p, const Rails& start, const FitOptions& fit) {
    try {
      p.fit = optimize_motion(surface, start, fit);
    } catch (const InputError&) {
      return;
    }
    p.fit.eps_ini = f.fit.eps_ini;
    p.fit.iterations += f.fit.iterations;
    offer(std::move(p));
  };
  offer(f);
  PatchOptions pull = po;
  pull.fit.check.floor_reach = o.patch.fit.check.floor_reach;
  refit(f, f.fit.rails, pull.fit);
  const double narrow = o.floor_tip;
  if (narrow > 0 && narrow < pull.fit.constraints.max_tip_radius && narrow >= pull.fit.constraints.min_tip_radius) {
    PatchFit thin = f;
    thin.clear_part_adjustments();  // a tool of its own, fitted on the axis as it stands
    const Rails start = tip_tilted(surface, f.fit.rails, 0.9 * narrow);
    thin.initial = start;
    FitOptions held = pull.fit;
    held.constraints.max_tip_radius = narrow;
    // The floor's pull reaches as far as it did for the wide tip: the narrow tip starts where the wide
    // one stood, its lowest point (the wide rim's dip) up to that tip's radius above the floor, beyond
    // the narrow tip's own reach, and floated there.
    held.check.floor_reach *= std::max(1.0, f.fit.tool.d(0) / narrow);
    // Judged with the tool's own limits (po): where the part has the tip ground shorter it widens.
    refit(std::move(thin), start, held);
  }
  return variants;
}

// A variant's cutter made longer at its tip (lengthened_at_tip) by 5%, 10% and 20% of its length, each
// judged (with `po`, the floor options of the patch it is a variant of) and machinable: a tip that
// stops short of the floor (rotor 37's hub rows, 1-3 mm of flank left under tips that kept clear)
// reaches down to it, and with_check grinds back what would meet the part.
std::vector<PatchFit> tip_lengthenings(const SurfaceIndex& surface, const PatchFit& v, const PatchOptions& po) {
  std::vector<PatchFit> out;
  for (const double g : {0.05, 0.1, 0.2})
    if (std::optional<PatchFit> l = lengthened_at_tip(v, po, g * v.fit.rails.length))
      if (std::optional<PatchFit> j = judged(surface, std::move(*l), po); j && machinable(*j)) out.push_back(std::move(*j));
  return out;
}

// floor_variants, each also offered longer at its tip (tip_lengthenings), not only the one that brings
// most: the last pass's, which depend on the patch alone.
std::vector<PatchFit> floor_variants_lengthened(const SurfaceIndex& surface, const PatchFit& f, const CoverOptions& o) {
  std::vector<PatchFit> variants = floor_variants(surface, f, o);
  const PatchOptions po = floor_options(o, f.fit.rails);
  for (size_t i = 0, as_fitted = variants.size(); i < as_fitted; ++i) {
    std::vector<PatchFit> longer = tip_lengthenings(surface, variants[i], po);
    variants.insert(variants.end(), std::make_move_iterator(longer.begin()), std::make_move_iterator(longer.end()));
  }
  return variants;
}

// The first of some variants that brings most uncovered area: its index and that area.
struct MostGaining {
  size_t index = 0;
  double gain = 0;
};
std::optional<MostGaining> most_gaining(const std::vector<PatchFit>& variants, const std::vector<char>& covered,
                                        const std::vector<double>& area, double tol) {
  std::optional<MostGaining> best;
  for (size_t i = 0; i < variants.size(); ++i)
    if (const double g = gain_of(variants[i], covered, area, tol); !best || g > best->gain) best = MostGaining{i, g};
  return best;
}

// `f` replaced by `variant`, the floor pass's choice, bringing `gain`.
Fitted floor_chosen(const Fitted& f, PatchFit variant, double gain) {
  Fitted best;
  best.fit = std::move(variant);
  best.gain = gain;
  best.ok = true;
  best.cut = f.cut;
  best.whole_gain = f.cut ? f.whole_gain : gain;
  best.from_region = f.from_region;
  return best;
}

// The floor pass on a round's best: of its floor_variants the one that brings most uncovered area,
// then offered longer at its tip (tip_lengthenings); `f` itself when no variant is machinable.
Fitted floor_finished(const SurfaceIndex& surface, Fitted f, const std::vector<char>& covered, const std::vector<double>& area,
                      const CoverOptions& o) {
  const double tol = o.patch.tolerance;
  std::vector<PatchFit> variants = floor_variants(surface, f.fit, o);
  const std::optional<MostGaining> first = most_gaining(variants, covered, area, tol);
  if (!first) return f;
  std::vector<PatchFit> longer = tip_lengthenings(surface, variants[first->index], floor_options(o, f.fit.fit.rails));
  variants.insert(variants.end(), std::make_move_iterator(longer.begin()), std::make_move_iterator(longer.end()));
  const MostGaining best = *most_gaining(variants, covered, area, tol);
  return floor_chosen(f, std::move(variants[best.index]), best.gain);
}

// A patch of the cover with its cutter made longer at its holder end (lengthened_to_reach) by 10%, 25%
// and 50% of its length and to the tool's max_length, where that end's column of Ω still lies over
// Φ; with a part (its tip stays on the floor; the holder end is b, as with_check turned it). A
// patch's tool is as long as the lines it started from; where the flank grows taller along the
// motion (the HECC impeller's blade: 18 mm at its trailing edge, 66 mm at its leading edge) the
// cutter's holder end stops inside Φ, and the strip above it was reached by no patch (1.7% of the
// blade along its shroud edge, 4-13 mm beyond the holder ends of the patches beside it). Each is
// judged as a candidate (trimmed where it gouges Φ, shank and holder checked against the part where
// they now stand); the one bringing most uncovered area is kept when it brings more. `end_swept`:
// judged with the tool's end swept, as the floor pass judged `f`. Not without a part: there either
// end may lengthen, and the exact envelopes' cones then gained a rim beyond Φ's boundary whose
// written-out lines (init: lines) fitted radii that fold back where no Φ holds them.
Fitted reaching_further(const SurfaceIndex& surface, Fitted f, const std::vector<char>& covered, const std::vector<double>& area,
                        const CoverOptions& o, bool end_swept) {
  const PatchOptions po = floor_options(o, f.fit.fit.rails, end_swept);
  if (!omega_over_phi(f.fit.machined, -1, f.fit.machined.omega.n_s - 1)) return f;
  const double length = f.fit.fit.rails.length, room = po.fit.constraints.max_length - length;
  Fitted best = f;
  for (const double e : {0.1 * length, 0.25 * length, 0.5 * length, room}) {
    if (!(e > 0) || !std::isfinite(e) || e > room) continue;
    std::optional<PatchFit> l = lengthened_to_reach(f.fit, po, e, true);
    if (!l) continue;
    std::optional<PatchFit> j = judged(surface, std::move(*l), po);
    if (!j || !machinable(*j)) continue;
    // What is kept, in the first motion's t as before (a continued motion reaches beyond [0, 1]).
    std::tie(j->t_from, j->t_to) = kept_within(f.fit.t_from, f.fit.t_to, j->t_from, j->t_to);
    const double g = gain_of(*j, covered, area, po.tolerance);
    if (g > best.gain + 1e-4) best.fit = std::move(*j), best.gain = g;
  }
  return best;
}

// A patch of the cover with its motion continued past its ends (continued), against what the others
// cover, then judged with the part as the floor pass judges (`end_swept`). A round continues its best
// before the floor pass refits it and judges it against the patches of the rounds before; here it is
// judged against the whole cover (HECC impeller: two of its 8 patches continued, 13.1% -> 13.6% and
// 32.4% -> 35.3% of the blade, the union 94.57% -> 94.62%; the wedge along the trailing edge, 4-7 of
// 241 columns reached by no patch, stays: its patch was not continued there).
Fitted continued_in_cover(const SurfaceIndex& surface, const Fitted& f, const std::vector<char>& covered,
                          const std::vector<double>& area, const CoverOptions& o, bool end_swept) {
  Fitted start = f;
  start.fit.t_from = 0, start.fit.t_to = 1;  // its ends as they stand: `continued` continues an end not trimmed
  Fitted c = continued(surface, std::move(start), covered, area, o);
  if (c.fit.t_from == 0 && c.fit.t_to == 1) return f;  // no step brought more
  const PatchOptions po = floor_options(o, f.fit.fit.rails, end_swept);
  const double from = c.fit.t_from, to = c.fit.t_to;  // the continued rails in f's t
  std::optional<PatchFit> j = judged(surface, std::move(c.fit), po);
  if (!j || !machinable(*j)) return f;
  // What is kept, in f's t, then in the first motion's t as before.
  std::tie(j->t_from, j->t_to) = kept_within(from, to, j->t_from, j->t_to);
  std::tie(j->t_from, j->t_to) = kept_within(f.fit.t_from, f.fit.t_to, j->t_from, j->t_to);
  Fitted out = f;
  out.fit = std::move(*j);
  out.gain = gain_of(out.fit, covered, area, o.patch.tolerance);
  return out;
}

// The principal axes of Φ's vertices, by increasing extent (columns).
Eigen::Matrix3d extent_axes(const TriMesh& m) {
  Eigen::Vector3d centre = Eigen::Vector3d::Zero();
  for (const auto& x : m.vertices) centre += x / double(m.vertices.size());
  Eigen::Matrix3d C = Eigen::Matrix3d::Zero();
  for (const auto& x : m.vertices) C += (x - centre) * (x - centre).transpose();
  return Eigen::SelfAdjointEigenSolver<Eigen::Matrix3d>(C).eigenvectors();
}

// Each round's best goes through the floor pass (floor_finished), judged there with the tool's end swept.
bool floor_pass_on(const CoverOptions& o) {
  return o.end && o.floor_pass && o.patch.fit.check.part && o.patch.fit.check.floor_reach > 0 && !o.patch.fit.fixed_tool;
}

}  // namespace

std::vector<size_t> finish_cover(const SurfaceIndex& surface, std::vector<PatchFit>& cover, const CoverOptions& o,
                                 const std::function<void(size_t, double)>& on_patch) {
  std::vector<size_t> replaced;
  if (!o.patch.fit.check.part || o.patch.fit.fixed_tool || o.shared_tool) return replaced;
  const bool floor = floor_pass_on(o), further = o.reach_further;
  if (!floor && !further && !o.continue_ends) return replaced;
  const TriMesh& m = surface.mesh();
  const size_t nv = m.vertices.size();
  const std::vector<double> area = vertex_areas(m);
  const double tol = o.patch.tolerance;
  // The union's coverage with patch k machined as `instead` (k beyond the cover: as it is).
  const auto union_coverage = [&](size_t k, const PatchFit* instead) {
    std::vector<const MachinedSurface*> ms;
    for (size_t j = 0; j < cover.size(); ++j) ms.push_back(j == k ? &instead->machined : &cover[j].machined);
    return coverage(m, union_deviation(ms, nv).deviation, tol);
  };
  double now = union_coverage(cover.size(), nullptr);
  // A patch is judged again once another has been replaced since it was last judged (patches replaced
  // after it change what it is judged against): sweeps over the cover until none is (finish_sweeps).
  const size_t n = cover.size();
  std::vector<char> stale(n, 1);  // not judged since the last patch replaced
  // Each patch's floor_variants_lengthened: they depend on the patch alone, so they are kept until it
  // is replaced, and a sweep judging it again only chooses among them anew.
  std::vector<std::optional<std::vector<PatchFit>>> variants(n);
  for (int sweep = 0; sweep < o.finish_sweeps; ++sweep) {
    bool any = false;
    for (size_t k = 0; k < n; ++k) {
      if (!stale[k]) continue;
      stale[k] = 0;
      any = true;
      if (on_patch) on_patch(k, now);
      std::vector<char> others(nv, 0);
      for (size_t j = 0; j < n; ++j)
        if (j != k) mark_covered(cover[j], tol, others);
      Fitted f;
      f.fit = cover[k];
      f.gain = gain_of(f.fit, others, area, tol);
      std::optional<Fitted> best;  // a variant under which the union grows most
      double best_coverage = now;
      const auto consider = [&](Fitted g) {
        if (const double c = union_coverage(k, &g.fit); c > best_coverage) best_coverage = c, best = std::move(g);
      };
      if (floor) {
        if (!variants[k]) variants[k] = floor_variants_lengthened(surface, f.fit, o);
        if (const std::optional<MostGaining> c = most_gaining(*variants[k], others, area, tol))
          consider(floor_chosen(f, (*variants[k])[c->index], c->gain));
      }
      if (further) {
        const Fitted& base = best ? *best : f;
        Fitted longer = reaching_further(surface, base, others, area, o, floor);
        if (longer.fit.reach_lengthened > base.fit.reach_lengthened) consider(std::move(longer));
      }
      if (o.continue_ends) consider(continued_in_cover(surface, best ? *best : f, others, area, o, floor));
      if (best) {
        cover[k] = std::move(best->fit);
        now = best_coverage;
        replaced.push_back(k);
        for (size_t j = 0; j < n; ++j) stale[j] = j != k;
        variants[k].reset();
      }
    }
    if (!any) break;
  }
  return replaced;
}

Detection detect_patches(const SurfaceIndex& surface, const CoverOptions& options,
                         const std::function<void(const CoverProgress&)>& on_progress) {
  if (auto err = options.validate(); !err.empty()) throw InputError(err);
  // The options of the search; a shared tool is held in them once the first two patches have chosen it.
  CoverOptions o = options;
  const bool sharing = o.shared_tool && !o.patch.fit.fixed_tool;  // a fixed tool is one tool already
  const TriMesh& m = surface.mesh();
  const size_t nv = m.vertices.size();
  const std::vector<double> area = vertex_areas(m);
  const Eigen::Matrix3d extents = extent_axes(m);
  const Eigen::Vector3d width = o.width.value_or(Eigen::Vector3d(extents.col(1)));
  const double tol = o.patch.tolerance;
  const bool floor_pass = floor_pass_on(o);
  Detection out;
  // The patches of the cover, in the order found.
  struct Chosen {
    PatchFit fit;
    double gain = 0;           // what it brings first, in this order
    bool stays = false;        // set aside against this union and returned
    bool from_region = false;  // found by searching an uncovered region on its own
  };
  std::vector<Chosen> chosen;
  const std::vector<std::vector<int>> ring = vertex_rings(m);
  std::vector<char> covered(nv, 0);
  std::vector<char> tried(nv, 0);  // seed vertices already used
  std::vector<std::vector<int>> searched_regions;  // uncovered regions searched on their own
  CoverProgress progress;
  const auto report = [&](const std::string& stage) {
    progress.stage = stage;
    progress.patches = int(chosen.size());
    progress.coverage = out.coverage;
    if (on_progress) on_progress(progress);
  };
  const auto update_union = [&]() {
    std::vector<const MachinedSurface*> ms;
    for (const Chosen& c : chosen) ms.push_back(&c.fit.machined);
    UnionDeviation u = union_deviation(ms, nv);
    out.owner = std::move(u.owner);
    out.deviation = std::move(u.deviation);
    out.coverage = coverage(m, out.deviation, tol);
    for (size_t v = 0; v < nv; ++v) covered[v] = std::isfinite(out.deviation[v]) && std::abs(out.deviation[v]) <= tol;
  };
  update_union();
  // What each patch brings first, in the order they were found (after patches were exchanged or refitted).
  const auto recount_gains = [&]() {
    std::fill(covered.begin(), covered.end(), 0);
    for (Chosen& c : chosen) {
      c.gain = gain_of(c.fit, covered, area, tol);
      mark_covered(c.fit, tol, covered);
    }
  };
  out.stop = CoverStop::NoProgress;
  out.shared_tool = o.shared_tool || o.patch.fit.fixed_tool.has_value();
  int failures = 0;
  bool stuck = false;  // no further patch found: exchange rounds only
  // Fitted candidates not chosen (spares), and, right after a shared tool has been fixed, those
  // fitted with their own tools, to be refitted with it (restarts).
  std::vector<Fitted> pool, restarts;
  int exchanges = 0;
  std::optional<Fitted> aside;  // the patch set aside in an exchange round, and its place in `chosen`
  size_t aside_at = 0;
  while (true) {
    if (out.coverage >= o.coverage) {
      out.stop = CoverStop::Coverage;
      break;
    }
    if (int(chosen.size()) >= o.max_patches || stuck) {
      out.stop = stuck ? CoverStop::NoProgress : CoverStop::MaxPatches;
      if (sharing || exchanges >= o.exchanges) break;
      // An exchange round: of the patches not yet set aside against this union, the one whose own
      // share (what no other patch covers) is least is set aside.
      size_t weakest = chosen.size();
      double least = INFINITY;
      for (size_t k = 0; k < chosen.size(); ++k) {
        if (chosen[k].stays) continue;
        std::vector<const MachinedSurface*> others;
        for (size_t j = 0; j < chosen.size(); ++j)
          if (j != k) others.push_back(&chosen[j].fit.machined);
        const double own = out.coverage - coverage(m, union_deviation(others, nv).deviation, tol);
        if (own < least) least = own, weakest = k;
      }
      if (weakest == chosen.size()) break;
      ++exchanges;
      aside = Fitted{chosen[weakest].fit, least, true};
      aside->from_region = chosen[weakest].from_region;
      aside_at = weakest;
      pool.push_back(*aside);  // a spare from now on, should another patch take its place
      chosen.erase(chosen.begin() + std::ptrdiff_t(weakest));
      update_union();
      report(fmt::format("exchange {} of {}: a patch bringing {:.1f}% of its own set aside", exchanges, o.exchanges,
                         100 * least));
    }
    Fitted best;
    double whole_best = 0;  // the best gain of a whole (not cut) tool this round
    // Fits made in earlier rounds first: their gain on what is still uncovered. The best spare is
    // this round's first candidate; when it reaches the target, no search is needed.
    const auto offer = [&](Fitted f) {
      if (!f.ok) return;
      whole_best = std::max(whole_best, f.cut ? std::min(f.whole_gain, f.gain) : f.gain);
      if (f.gain > best.gain) std::swap(f, best);
      if (f.ok) pool.push_back(std::move(f));
    };
    {
      std::vector<Fitted> earlier = std::move(pool);
      pool.clear();
      for (Fitted& f : earlier) {
        f.gain = gain_of(f.fit, covered, area, tol);
        offer(std::move(f));
      }
      // A shared tool just fixed: the best of the other first-round fits refitted with it (motion only,
      // from their fitted motions).
      for (Fitted& f : restarts) f.gain = gain_of(f.fit, covered, area, tol);
      std::stable_sort(restarts.begin(), restarts.end(), [](const Fitted& x, const Fitted& y) { return x.gain > y.gain; });
      for (size_t r = 0; r < restarts.size() && int(r) < o.fitted_seeds; ++r) {
        if (restarts[r].gain < 0.005) break;
        report("refitting spare " + std::to_string(r + 1) + " with the shared tool");
        const Rails start = restarts[r].fit.fit.rails;
        offer(fit_candidate(surface, restarts[r].fit.trajectory.value_or(LineTrajectory{}), covered, area, o, &start));
        ++out.seeds_tried;
      }
      restarts.clear();
    }
    const bool enough = best.ok && out.coverage + best.gain >= o.coverage;
    std::vector<char> blocked = covered;
    for (size_t v = 0; v < nv; ++v) blocked[v] |= tried[v];
    const std::vector<int> points = enough ? std::vector<int>{} : seed_points(surface, blocked, o);
    progress.seeds = int(points.size());
    progress.seed = 0;
    report("seeding");
    std::vector<PointSeeds> at_point(points.size());
#pragma omp parallel for schedule(dynamic, 1)
    for (int k = 0; k < int(points.size()); ++k)
      at_point[size_t(k)] = best_lines_at(surface, ring, points[size_t(k)], width, o);
    bool any_seed = false;
    for (const auto& ps : at_point)
      for (const Seed& sd : ps.best) any_seed |= std::isfinite(sd.F);
    // Candidate trajectories from one pool of seeds: the lines as seeded, or the oriented ones.
    const auto candidates_of = [&](bool oriented) {
      const int refined_count = oriented ? o.oriented_refined : o.refined_seeds;
      const int explored_count = oriented ? o.oriented_explored : o.explored_seeds;
      const int unrefined_count = oriented ? o.oriented_explored : o.explored_unrefined;
      std::vector<Candidate> candidates;
      // The best-ranked lines of each side of Φ (which side the tool is on is not known here) are moved
      // to the nearest axis (refine_seed) and ranked again by how well they keep their distances.
      std::vector<Seed> seeds;
      for (int side : {1, -1}) {
        std::vector<Seed> one;
        for (const auto& ps : at_point)
          for (const Seed& sd : ps.best)
            if (sd.oriented == oriented && sd.side == side && std::isfinite(sd.F)) one.push_back(sd);
        std::stable_sort(one.begin(), one.end(), [](const Seed& x, const Seed& y) { return x.rank < y.rank; });
        one.resize(std::min(one.size(), size_t((refined_count + 1) / 2)));
        seeds.insert(seeds.end(), one.begin(), one.end());
      }
      progress.seeds = int(seeds.size());
      report(oriented ? "refining oriented seed lines" : "refining seed lines");
#pragma omp parallel for schedule(dynamic, 1)
      for (int k = 0; k < int(seeds.size()); ++k) seeds[size_t(k)] = refine_seed(surface, seeds[size_t(k)], o);
      // A longer line reaches further across Φ: the score is the spread per unit length.
      const auto score = [](const Seed& sd) { return sd.spread / (sd.line.b - sd.line.a).norm(); };
      std::vector<size_t> by_spread(seeds.size());
      std::iota(by_spread.begin(), by_spread.end(), size_t(0));
      std::stable_sort(by_spread.begin(), by_spread.end(), [&](size_t x, size_t y) { return score(seeds[x]) < score(seeds[y]); });
      // Where the motion is close to a screw (helices) the spread cannot tell lines apart either; the
      // most movable unrefined lines, explored as in Sec. 4.2, are candidates too. Refined and
      // unrefined lines take turns.
      std::vector<Seed> unrefined;
      for (const auto& ps : at_point)
        for (const Seed& sd : ps.best)
          if (sd.oriented == oriented && std::isfinite(sd.F)) unrefined.push_back(sd);
      std::stable_sort(unrefined.begin(), unrefined.end(), [](const Seed& x, const Seed& y) { return x.rank < y.rank; });
      std::vector<Seed> turns;
      for (size_t r = 0; r < std::max(by_spread.size(), unrefined.size()); ++r) {
        if (r < by_spread.size() && int(r) < explored_count && std::isfinite(seeds[by_spread[r]].spread))
          turns.push_back(seeds[by_spread[r]]);
        if (r < unrefined.size() && int(r) < unrefined_count) turns.push_back(unrefined[r]);
      }
      for (size_t r = 0; r < turns.size(); ++r) {
        const Seed& s = turns[r];
        progress.seed = int(r) + 1;
        progress.seeds = int(turns.size());
        report(oriented ? "exploring and propagating oriented seeds" : "exploring and propagating");
        // Refined lines are explored too: the refinement does not look at F_l, exploration does.
        const ExploredLine ex = explore_line(surface, s.line.a, s.line.b, o.patch.exploration);
        const LineTrajectory tr = propagate_line(surface, ex.a, ex.b, o.patch.propagation);
        const int start = seed_position(tr, ex.a);
        for (const LineTrajectory& placed : placed_lines(surface, tr, o)) {
          Candidate c = keep_uncovered(surface, placed, start, covered, area, o);
          c.seed_vertex = s.vertex;
          // A seed is used up when its candidate is fitted or cannot be; one explored but not fitted
          // (others swept more uncovered area, on another flank perhaps) is seeded again next round.
          if (c.trajectory.a.size() < size_t(o.patch.fit.rail_control_points)) {
            tried[size_t(s.vertex)] = 1;
            continue;
          }
          candidates.push_back(std::move(c));
        }
      }
      // The candidates sweeping the most uncovered area first.
      std::stable_sort(candidates.begin(), candidates.end(),
                       [](const Candidate& x, const Candidate& y) { return x.uncovered_swept > y.uncovered_swept; });
      return candidates;
    };
    const auto fit_best = [&](const std::vector<Candidate>& candidates, int count) {
      for (size_t r = 0; r < candidates.size() && int(r) < count; ++r) {
        // Enough already.
        if (best.ok && out.coverage + best.gain >= o.coverage) break;
        report("fitting candidate " + std::to_string(r + 1));
        const LineTrajectory& tr = candidates[r].trajectory;
        tried[size_t(candidates[r].seed_vertex)] = 1;
        Fitted f = fit_candidate(surface, tr, covered, area, o);
        ++out.seeds_tried;
        // A sweep too long for one envelope within tolerance (it gouges all along, or brings little):
        // its halves are fitted instead (shorter motions bend less).
        const size_t half = tr.a.size() / 2;
        if ((!f.ok || f.gain < 0.02) && half >= size_t(2 * o.patch.fit.rail_control_points))
          for (int piece = 0; piece < 2; ++piece) {
            const size_t from = piece == 0 ? 0 : half, to = piece == 0 ? half + half / 10 : tr.a.size();
            const size_t lo = piece == 0 ? from : from - half / 10;  // a small overlap between the halves
            const LineTrajectory part = slice(tr, lo, to);
            report("fitting candidate " + std::to_string(r + 1) + ", half " + std::to_string(piece + 1));
            Fitted h = fit_candidate(surface, part, covered, area, o);
            ++out.seeds_tried;
            if (h.ok && (!f.ok || h.gain > f.gain)) f = std::move(h);
          }
        // With a part: a motion trimmed where its tool would enter the part keeps one clear stretch;
        // the sweep's stretches before and after it are fitted on their own (a shorter motion turns
        // less, and its tool can stand otherwise there).
        std::vector<LineTrajectory> rest;
        if (f.ok && o.patch.fit.check.part && f.fit.check_trim && f.fit.trajectory) {
          const LineTrajectory& ft = *f.fit.trajectory;
          const size_t n = ft.a.size(), min_poses = size_t(2 * o.patch.fit.rail_control_points);
          // The kept stretch's positions by the rails' parameter.
          const std::vector<double> ts = trajectory_parameters(ft);
          const size_t i0 = size_t(std::lower_bound(ts.begin(), ts.end(), f.fit.t_from) - ts.begin());
          const size_t i1 = size_t(std::upper_bound(ts.begin(), ts.end(), f.fit.t_to) - ts.begin());  // first beyond
          if (i0 >= min_poses) rest.push_back(slice(ft, 0, i0));
          if (n > i1 && n - i1 >= min_poses) rest.push_back(slice(ft, i1, n));
        }
        offer(std::move(f));
        for (size_t k = 0; k < rest.size(); ++k) {
          report("fitting candidate " + std::to_string(r + 1) + ", beyond its trim " + std::to_string(k + 1));
          offer(fit_candidate(surface, rest[k], covered, area, o));
          ++out.seeds_tried;
        }
      }
    };
    fit_best(candidates_of(false), o.fitted_seeds);
    // When the seeded lines' best patch brings less than `orient_below` of the uncovered area, they
    // have likely missed the tool axis's direction (general tools) and the oriented ones are tried as
    // well, judged by whole tools (a tool cut short at its tip can bring more from a line off the
    // axis). Not always: a larger first patch is not a better cover (greedy), and the seeded lines
    // serve conical and cylindrical tools well.
    if (!enough && o.oriented_explored > 0 && !(best.ok && whole_best >= o.orient_below * (1 - out.coverage))) {
      report("orienting seed lines");
#pragma omp parallel for schedule(dynamic, 1)
      for (int k = 0; k < int(at_point.size()); ++k) orient_seeds(surface, at_point[size_t(k)], o);
      fit_best(candidates_of(true), o.oriented_fitted);
    }
    // Uncovered regions this round's candidates bring little of, searched on their own (see
    // CoverOptions::regions); a region searched once is not searched again.
    if (!enough && o.regions > 0 && !chosen.empty()) {
      // One patch on the region alone: no exchanges, spares or regions within it.
      CoverOptions so = o;
      so.coverage = 1;
      so.max_patches = 1;
      so.exchanges = 0;
      so.spares = 0;
      so.regions = 0;
      so.continue_ends = false;
      so.reach_further = false;
      so.floor_pass = false;
      so.width = width;
      int searched = 0;
      for (const Region& uncovered : uncovered_regions(ring, covered, area)) {
        // Named, not a structured binding: lambdas may not capture those before C++20 (clang refuses).
        const std::vector<int>& region = uncovered.vertices;
        const double size = uncovered.area;
        if (searched >= o.regions) break;
        if (size < o.region_min) break;
        // Searched before: a region of (nearly) the same vertices.
        const auto same = [&](const std::vector<int>& r) {
          std::vector<int> both;
          std::set_intersection(r.begin(), r.end(), region.begin(), region.end(), std::back_inserter(both));
          return 10 * both.size() >= 9 * std::max(r.size(), region.size());
        };
        if ((best.ok && best.gain >= o.region_below * size) || std::any_of(searched_regions.begin(), searched_regions.end(), same))
          continue;
        ++searched;
        ++out.regions_searched;
        searched_regions.push_back(region);
        SubSurface sub = sub_surface(m, ring, region, o.band);
        std::optional<SurfaceIndex> index;
        try {
          index.emplace(std::move(sub.mesh));
        } catch (const InputError&) {
          continue;  // too small a piece of surface to fit on
        }
        for (const bool across : {false, true}) {
          so.across = across;
          const std::string name = fmt::format("uncovered region of {:.1f}%{}", 100 * size, across ? ", across Φ" : "");
          const auto forward = [&](const CoverProgress& p) {
            progress.seed = p.seed, progress.seeds = p.seeds;
            report(name + ": " + p.stage);
          };
          Detection d;
          try {
            d = detect_patches(*index, so, forward);
          } catch (const InputError&) {
            continue;  // too small a piece of surface to fit on
          }
          out.seeds_tried += d.seeds_tried;
          if (d.patches.empty()) continue;
          const PatchFit& found = d.patches.front().fit;
          // As fitted on the region, and refitted on Φ from its motion.
          Fitted as_is;
          PatchOptions as_found = candidate_options(o);
          if (tip_chosen_first(o)) tip_held_at_a(as_found, found.fit.rails);  // its narrow tip at a, where it was fitted
          std::optional<PatchFit> j = judged(surface, found, as_found);
          if (j) as_is.fit = std::move(*j);
          if (j && machinable(as_is.fit)) as_is.ok = true, as_is.gain = as_is.whole_gain = gain_of(as_is.fit, covered, area, tol);
          report(name + ": refitting its patch on the whole surface");
          Fitted refit = fit_candidate(surface, found.trajectory.value_or(LineTrajectory{}), covered, area, o, &found.fit.rails);
          ++out.seeds_tried;
          as_is.from_region = refit.from_region = true;
          offer(std::move(as_is));
          offer(std::move(refit));
        }
      }
    }
    if (best.ok && o.continue_ends) {
      report("continuing the best patch's motion past its ends");
      best = continued(surface, std::move(best), covered, area, o);
    }
    if (best.ok && floor_pass) {
      report("fitting the best patch again with its tip on the part's floor");
      best = floor_finished(surface, std::move(best), covered, area, o);
    }
    // An exchange round whose best brings no more than the patch set aside (and does not reach the
    // target): that one returns to its place and stays; the next round sets aside the next weakest.
    if (aside) {
      const bool better = best.ok && (best.gain > aside->gain + 1e-4 || out.coverage + best.gain >= o.coverage);
      if (!better) {
        chosen.insert(chosen.begin() + std::ptrdiff_t(aside_at), Chosen{std::move(aside->fit), aside->gain, true, aside->from_region});
        aside.reset();
        update_union();
        report("exchange: no better patch, the one set aside kept");
        continue;
      }
      aside.reset();
      for (Chosen& c : chosen) c.stays = false;  // a new union: each may be the weakest again
      ++out.exchanged;
    } else if (!best.ok || best.gain < 0.005) {  // a patch must bring a real share of the surface (0.5%)
      // Nothing from these seeds: the next round takes the next-best ones (these are marked tried).
      if (++failures >= 3 || !any_seed) {
        // Short of max_patches with no patch left to add: the exchange rounds as at max_patches (the
        // greedy's order can leave a patch that another, found once it is set aside, beats; rotor 37
        // stopped at 7 patches, 93.1%, where the 8th brought less than 0.5%).
        if (stuck || sharing || exchanges >= o.exchanges || chosen.empty()) break;
        stuck = true;
      }
      continue;
    }
    failures = 0;
    chosen.push_back(Chosen{std::move(best.fit), best.gain, false, best.from_region});
    update_union();
    report("patch accepted");
    // The most promising spares only (a machined surface each).
    for (Fitted& f : pool) f.gain = gain_of(f.fit, covered, area, tol);
    std::stable_sort(pool.begin(), pool.end(), [](const Fitted& x, const Fitted& y) { return x.gain > y.gain; });
    while (!pool.empty() && (int(pool.size()) > o.spares || pool.back().gain < 0.005)) pool.pop_back();
    if (sharing && !o.patch.fit.fixed_tool && chosen.size() == 2) {
      // The shared tool: each of the first two patches' own tools (turned to stand with its holder
      // end along `up`; with a check surface the part has chosen that end already) is held for the
      // other patch, refitted from its motion; the pair that covers more is kept and its tool held
      // from now on: the seeds are placed at its radii, the spares refitted with it. The first patch
      // alone is fitted to its own stretch of Φ: a tool that machines it within tolerance need not
      // be the one that machines the rest (two flanks of one barrel tool: the first patch's tool held
      // covered 91.3% of both in 3 patches, the second's 97.9% in 3).
      std::vector<char> none(nv, 0);
      double pick_coverage = -1;
      std::vector<Chosen> pick;
      for (size_t i = 0; i < 2; ++i) {
        Chosen own = chosen[i];
        if (o.up && !o.patch.fit.check.part && mean_axis(own.fit.fit.rails).dot(*o.up) < 0) own.fit = reversed(std::move(own.fit));
        CoverOptions held = o;
        held.patch.fit.fixed_tool = own.fit.fit.tool;
        held.tool_length = own.fit.fit.rails.length;
        std::vector<char> by_own(nv, 0);
        mark_covered(own.fit, tol, by_own);
        own.gain = gain_of(own.fit, none, area, tol);
        report("choosing the shared tool: patch " + std::to_string(i + 1) + "'s tool held for the other");
        const Chosen& other = chosen[1 - i];
        const Rails start = other.fit.fit.rails;
        Fitted f = fit_candidate(surface, other.fit.trajectory.value_or(LineTrajectory{}), by_own, area, held, &start);
        ++out.seeds_tried;
        std::vector<Chosen> pair{own};
        if (f.ok && f.gain >= 0.005) pair.push_back(Chosen{std::move(f.fit), f.gain, false, other.from_region});
        const double c = own.gain + (pair.size() > 1 ? pair[1].gain : 0);
        if (c > pick_coverage + 1e-9) pick_coverage = c, pick = std::move(pair);
      }
      chosen = std::move(pick);
      update_union();
      report("shared tool chosen");
      const PatchFit& first = chosen.front().fit;
      o.patch.fit.fixed_tool = first.fit.tool;
      o.tool_length = first.fit.rails.length;
      o.radii.clear();
      for (double s : {0.25, 0.5, 0.75}) o.radii.push_back(first.fit.tool.d(s));
      std::sort(o.radii.begin(), o.radii.end());
      o.radii.erase(std::unique(o.radii.begin(), o.radii.end(), [](double x, double y) { return std::abs(x - y) < 1e-3; }),
                    o.radii.end());
      for (Fitted& f : pool) f.gain = gain_of(f.fit, covered, area, tol);
      restarts = std::move(pool);
      pool.clear();
    }
  }
  if (exchanges > 0) recount_gains();
  out.from_regions = int(std::count_if(chosen.begin(), chosen.end(), [](const Chosen& c) { return c.from_region; }));
  out.coverage_held_tool = out.coverage;
  if (sharing && chosen.size() > 1) {
    // One joint refit of every patch with one tool (eq. 12 summed over the patches, the radii free
    // again, from the held tool and the fitted motions), kept when the union's coverage does not
    // drop and no patch gouges after trimming.
    report("refitting all patches jointly with one tool");
    PatchOptions po = o.patch;
    po.fit.fixed_tool.reset();
    po.trim_gouges = true;
    po.solid_cutter_on_phi = true;  // motions continued past Φ's ends among them
    po.orient_by_part = false;
    if (tip_chosen_first(o)) po.fit.constraints.either_end = false;  // held tools stand with their tip at a
    std::vector<FitResult> joint;
    for (const Chosen& c : chosen) joint.push_back(c.fit.fit);
    std::vector<PatchFit> refit;
    try {
      joint = fit_shared_tool(std::vector<const SurfaceIndex*>(chosen.size(), &surface), std::move(joint), o.tool_length, po.fit);
      for (size_t k = 0; k < chosen.size(); ++k) {
        PatchFit f = chosen[k].fit;
        f.fit = std::move(joint[k]);
        f.clear_part_adjustments();
        f = po.fit.check.part ? with_check(surface, std::move(f), po) : machine_and_trim(surface, std::move(f), po);
        if (!machinable(f)) break;
        // What is kept, in the first motion's t as before (a continued motion reaches beyond [0, 1]).
        std::tie(f.t_from, f.t_to) = kept_within(chosen[k].fit.t_from, chosen[k].fit.t_to, f.t_from, f.t_to);
        refit.push_back(std::move(f));
      }
    } catch (const InputError&) {
      refit.clear();  // a motion left the surface: the held tool's patches stay
    }
    if (refit.size() == chosen.size()) {
      std::vector<const MachinedSurface*> ms;
      for (const PatchFit& f : refit) ms.push_back(&f.machined);
      const UnionDeviation u = union_deviation(ms, nv);
      if (coverage(m, u.deviation, tol) >= out.coverage) {
        for (size_t k = 0; k < chosen.size(); ++k) chosen[k].fit = std::move(refit[k]);
        update_union();
        out.joint_refit = true;
        recount_gains();
      }
    }
    report(out.joint_refit ? "joint refit kept" : "joint refit not kept (the held tool covers more)");
  }

  // Once the cover is chosen, each patch against what the others cover (finish_cover): the floor pass
  // again and its cutter made longer at its holder end, kept when the union's coverage grows. Offered
  // to each round's best instead, the longer cutters won their rounds and the later rounds found less
  // (the HECC impeller: 35.3% against 31.4% after the first round, 84.7% against 90.4% after the
  // eighth), so they only add to the cover the rounds chose. Not for a held (catalogue or shared) tool.
  if (!sharing) {
    std::vector<PatchFit> cover;
    for (Chosen& c : chosen) cover.push_back(std::move(c.fit));
    const std::vector<size_t> replaced =
        finish_cover(surface, cover, o, [&](size_t k, double now) {
          out.coverage = now;
          report("finishing patch " + std::to_string(k + 1) + " against the others");
        });
    for (size_t k = 0; k < chosen.size(); ++k) chosen[k].fit = std::move(cover[k]);
    if (!replaced.empty()) {
      update_union();
      recount_gains();
    }
  }

  // Machining order: along Φ's longest extent (principal axis of the vertices).
  Eigen::Vector3d axis = extents.col(2);
  if (axis.sum() < 0) axis = -axis;  // deterministic sign
  std::vector<double> key(chosen.size(), 0.0), weight(chosen.size(), 0.0);
  for (size_t v = 0; v < nv; ++v)
    if (out.owner[v] >= 0) {
      key[size_t(out.owner[v])] += area[v] * m.vertices[v].dot(axis);
      weight[size_t(out.owner[v])] += area[v];
    }
  for (size_t p = 0; p < chosen.size(); ++p)
    key[p] = weight[p] > 0 ? key[p] / weight[p] : chosen[p].fit.fit.rails.point(0.5, 0.5).dot(axis);
  std::vector<size_t> order(chosen.size());
  std::iota(order.begin(), order.end(), size_t(0));
  std::stable_sort(order.begin(), order.end(), [&](size_t x, size_t y) { return key[x] < key[y]; });
  std::vector<int> new_index(chosen.size());
  for (size_t k = 0; k < order.size(); ++k) {
    const size_t p = order[k];
    new_index[p] = int(k);
    DetectedPatch d;
    d.spec.name = "auto-" + std::to_string(k + 1);
    d.spec.init = PatchInit::Lines;
    d.spec.lines = lines_of(chosen[p].fit.fit.rails, o.lines);
    d.spec.rail = 0;
    d.spec.length = chosen[p].fit.fit.rails.length;
    d.fit = std::move(chosen[p].fit);
    d.new_area = chosen[p].gain;
    out.patches.push_back(std::move(d));
  }
  for (int& w : out.owner)
    if (w >= 0) w = new_index[size_t(w)];
  out.overcut = 0;
  for (double d : out.deviation)
    if (std::isfinite(d)) out.overcut = std::max(out.overcut, -d);
  return out;
}

}  // namespace flankcam
