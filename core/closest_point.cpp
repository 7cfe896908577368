#include "core/closest_point.h"

#include <Eigen/Eigenvalues>
#include <Eigen/Geometry>
#include <algorithm>
#include <cmath>
#include <limits>
#include <numeric>

namespace flankcam {

TrianglePoint closest_on_triangle(const Eigen::Vector3d& p, const Eigen::Vector3d& a, const Eigen::Vector3d& b,
                                  const Eigen::Vector3d& c) {
  const Eigen::Vector3d ab = b - a, ac = c - a, ap = p - a;
  const double d1 = ab.dot(ap), d2 = ac.dot(ap);
  if (d1 <= 0 && d2 <= 0) return {a, {1, 0, 0}};
  const Eigen::Vector3d bp = p - b;
  const double d3 = ab.dot(bp), d4 = ac.dot(bp);
  if (d3 >= 0 && d4 <= d3) return {b, {0, 1, 0}};
  const double vc = d1 * d4 - d3 * d2;
  if (vc <= 0 && d1 >= 0 && d3 <= 0) {
    const double v = d1 / (d1 - d3);
    return {a + v * ab, {1 - v, v, 0}};
  }
  const Eigen::Vector3d cp = p - c;
  const double d5 = ab.dot(cp), d6 = ac.dot(cp);
  if (d6 >= 0 && d5 <= d6) return {c, {0, 0, 1}};
  const double vb = d5 * d2 - d1 * d6;
  if (vb <= 0 && d2 >= 0 && d6 <= 0) {
    const double w = d2 / (d2 - d6);
    return {a + w * ac, {1 - w, 0, w}};
  }
  const double va = d3 * d6 - d5 * d4;
  if (va <= 0 && (d4 - d3) >= 0 && (d5 - d6) >= 0) {
    const double w = (d4 - d3) / ((d4 - d3) + (d5 - d6));
    return {b + w * (c - b), {0, 1 - w, w}};
  }
  const double denom = 1.0 / (va + vb + vc);
  const double v = vb * denom, w = vc * denom;
  return {a + ab * v + ac * w, {1 - v - w, v, w}};
}

namespace {

// Largest distance from a point of the triangle to its nearest corner: the
// circumradius for non-obtuse triangles, half the longest edge otherwise.
double covering_radius_of(const Eigen::Vector3d& a, const Eigen::Vector3d& b, const Eigen::Vector3d& c) {
  const double A = (b - c).squaredNorm(), B = (c - a).squaredNorm(), C = (a - b).squaredNorm();
  const double longest = std::max({A, B, C});
  if (2 * longest >= A + B + C) return 0.5 * std::sqrt(longest);  // right or obtuse
  const double area2 = (b - a).cross(c - a).norm();                // twice the area
  return std::sqrt(A * B * C) / (2 * area2);
}


// Oriented bounding box of a node: local = R (p - c), |local_k| <= e_k. R's rows are the
// principal axes of the node's vertices, so on a smooth surface the box is thin along the
// normal and the lower bound stays tight at any query distance (an axis-aligned box is as thick
// as the patch is tilted, and the number of boxes it cannot prune grows like √n at one tool
// radius off the surface).
struct Node {
  float R[9];      // rows: the principal axes, rounded to float (the extents are measured in this frame)
  float m[3];      // centre of the box in that frame
  float e[3];      // half extents, rounded up
  int first = 0;   // leaf: first slot in Impl::tri; inner: index of the left child (right = first + 1)
  int count = 0;   // leaf: number of faces; 0 for inner nodes

  // Squared distance from p to the box (0 inside), in the box's frame. The float axes are unit and
  // orthogonal to 1e-7, so this exceeds the true distance by at most a factor 1 + kFrameError.
  double distance2(double x, double y, double z) const {
    const double o0 = std::max(0.0, std::abs(double(R[0]) * x + double(R[1]) * y + double(R[2]) * z - double(m[0])) - double(e[0]));
    const double o1 = std::max(0.0, std::abs(double(R[3]) * x + double(R[4]) * y + double(R[5]) * z - double(m[1])) - double(e[1]));
    const double o2 = std::max(0.0, std::abs(double(R[6]) * x + double(R[7]) * y + double(R[8]) * z - double(m[2])) - double(e[2]));
    return o0 * o0 + o1 * o1 + o2 * o2;
  }
  // Signed depth of p in the box: the largest |local| - e (negative inside). Orders two children
  // that both contain p: the one p is deeper in is more likely to hold its footpoint.
  double depth(double x, double y, double z) const {
    const double o0 = std::abs(double(R[0]) * x + double(R[1]) * y + double(R[2]) * z - double(m[0])) - double(e[0]);
    const double o1 = std::abs(double(R[3]) * x + double(R[4]) * y + double(R[5]) * z - double(m[1])) - double(e[1]);
    const double o2 = std::abs(double(R[6]) * x + double(R[7]) * y + double(R[8]) * z - double(m[2])) - double(e[2]);
    return std::max({o0, o1, o2});
  }
};
constexpr double kFrameError = 1e-6;

// A face in leaf order: corners, unit normal and plane offset (the plane distance bounds the face
// distance from below and skips most faces of a leaf cheaply).
struct LeafFace {
  Eigen::Vector3d a, b, c, n;
  double offset;
  int face;
};

constexpr int kLeafFaces = 4;

// The order both searches pick by: smaller squared distance, then the lower face index; a NaN
// distance (a degenerate triangle) counts as infinite. Updates (best2, face) and says whether f won.
inline bool closer(double d2, int f, double& best2, int& face) {
  if (std::isnan(d2)) d2 = std::numeric_limits<double>::infinity();
  if (face >= 0 && !(d2 < best2 || (d2 == best2 && f < face))) return false;
  best2 = d2;
  face = f;
  return true;
}

// The answer for a query that is not finite: no face, infinite distance, NaN point, and marked
// as beyond the boundary so that callers which skip samples off Φ's rim skip it too.
Footpoint no_footpoint() {
  Footpoint f;
  f.point = f.normal = f.barycentric = Eigen::Vector3d::Constant(std::numeric_limits<double>::quiet_NaN());
  f.distance = std::numeric_limits<double>::infinity();
  f.face = -1;
  f.on_boundary = true;
  return f;
}

}  // namespace

struct SurfaceIndex::Impl {
  TriMesh mesh;
  std::vector<Eigen::Vector3d> normals;
  MeshTopology topology;
  double cover = 0;
  std::vector<Node> nodes;                  // nodes[0] is the root
  std::vector<LeafFace> tri;                // the faces in leaf order
  double slack = 0;                         // absolute rounding allowance of the box bounds

  double face_distance2(int f, const Eigen::Vector3d& p) const {
    const auto& F = mesh.faces[f];
    return (closest_on_triangle(p, mesh.vertices[F[0]], mesh.vertices[F[1]], mesh.vertices[F[2]]).point - p)
        .squaredNorm();
  }

  void build();
  int search(const Eigen::Vector3d& p) const;

  Footpoint make_footpoint(const Eigen::Vector3d& p, int f) const {
    const auto& F = mesh.faces[f];
    const TrianglePoint tp = closest_on_triangle(p, mesh.vertices[F[0]], mesh.vertices[F[1]], mesh.vertices[F[2]]);
    Footpoint fp;
    fp.point = tp.point;
    fp.barycentric = tp.barycentric;
    fp.distance = (p - tp.point).norm();
    fp.face = f;
    Eigen::Vector3d n = Eigen::Vector3d::Zero();
    for (int k = 0; k < 3; ++k) n += tp.barycentric[k] * normals[F[k]];
    fp.normal = n.norm() > 1e-12 ? Eigen::Vector3d(n.normalized()) : face_normal(mesh, f);
    // On the boundary: on a boundary edge (the opposite corner's weight is 0) or at a boundary vertex.
    for (int k = 0; k < 3; ++k) {
      const int opposite = (k + 2) % 3;
      if (tp.barycentric[opposite] == 0 && topology.boundary_edge[f][k]) fp.on_boundary = true;
      if (tp.barycentric[k] == 1 && topology.boundary_vertex[F[k]]) fp.on_boundary = true;
    }
    return fp;
  }
};

// Top-down: each node's axes are the principal axes of its faces' corners (of at most 64 faces),
// split at the median centroid along the axis of largest spread. Nodes of up to kExactFaces faces measure their extents on the corners; bigger ones enclose their children's
// boxes (8 corners each, bottom-up), which is looser but costs O(1) per node. Deterministic: the
// median is found on (projection, face index) pairs.
void SurfaceIndex::Impl::build() {
  constexpr int kExactFaces = 4096;
  const int nf = int(mesh.faces.size());
  std::vector<std::pair<double, int>> order(static_cast<size_t>(nf));
  std::vector<Eigen::Vector3d> centroid(static_cast<size_t>(nf));
  double scale = 0;
  for (const auto& v : mesh.vertices) scale = std::max(scale, v.cwiseAbs().maxCoeff());
  for (int f = 0; f < nf; ++f) {
    const auto& F = mesh.faces[size_t(f)];
    centroid[size_t(f)] = (mesh.vertices[size_t(F[0])] + mesh.vertices[size_t(F[1])] + mesh.vertices[size_t(F[2])]) / 3;
    order[size_t(f)] = {0.0, f};
  }
  // A few thousand ulps of the largest coordinate: covers the rounding of the box bounds and of
  // the triangle distances, so a box never prunes a face brute force would pick.
  slack = 1e-12 * scale + std::numeric_limits<double>::min();
  nodes.reserve(size_t(2 * (nf / kLeafFaces + 1)));
  tri.reserve(size_t(nf));
  std::vector<char> merge;  // per node: extents from the children

  // Stores the frame R (rounded to float) and the extents of `points` in it, widened for rounding.
  const auto set_box = [&](Node& node, const Eigen::Matrix3d& R, const auto& for_each_point) {
    Eigen::Matrix3d Rf;
    for (int i = 0; i < 9; ++i) node.R[i] = float(R(i / 3, i % 3)), Rf(i / 3, i % 3) = double(node.R[i]);
    Eigen::Vector3d lo = Eigen::Vector3d::Constant(INFINITY), hi = -lo;
    for_each_point([&](const Eigen::Vector3d& x) {
      const Eigen::Vector3d l = Rf * x;
      lo = lo.cwiseMin(l);
      hi = hi.cwiseMax(l);
    });
    for (int k = 0; k < 3; ++k) {
      node.m[k] = float(0.5 * (lo[k] + hi[k]));
      const double half = std::max(hi[k] - double(node.m[k]), double(node.m[k]) - lo[k]);
      const double wide = half + 4 * slack + 1e-12 * std::abs(double(node.m[k]));
      node.e[k] = float(wide);
      if (double(node.e[k]) < wide) node.e[k] = std::nextafter(node.e[k], INFINITY);
    }
  };

  struct Range {
    int node, begin, end;
  };
  std::vector<Range> todo;
  nodes.emplace_back();
  merge.push_back(0);
  todo.push_back({0, 0, nf});
  while (!todo.empty()) {
    const Range r = todo.back();
    todo.pop_back();
    const int count = r.end - r.begin;
    const int stride = std::max(1, count / 64);
    Eigen::Vector3d mean = Eigen::Vector3d::Zero();
    int used = 0;
    for (int k = r.begin; k < r.end; k += stride, ++used) mean += centroid[size_t(order[size_t(k)].second)];
    mean /= double(used);
    // Principal axes of the corners (of every stride-th face: at most 64 faces per node).
    Eigen::Matrix3d cov = Eigen::Matrix3d::Zero();
    for (int k = r.begin; k < r.end; k += stride)
      for (int v : mesh.faces[size_t(order[size_t(k)].second)]) {
        const Eigen::Vector3d d = mesh.vertices[size_t(v)] - mean;
        cov += d * d.transpose();
      }
    Eigen::Matrix3d R = Eigen::Matrix3d::Identity();  // rows: axes, the first of largest spread
    if (cov.allFinite() && cov.norm() > 0) {
      Eigen::SelfAdjointEigenSolver<Eigen::Matrix3d> eig;
      eig.computeDirect(cov);
      const Eigen::Matrix3d Q = eig.eigenvectors();  // columns, ascending eigenvalues
      Eigen::Matrix3d Rn;
      Rn.row(0) = Q.col(2).normalized().transpose();
      Rn.row(1) = Q.col(1).normalized().transpose();
      Rn.row(2) = Rn.row(0).cross(Rn.row(1)).normalized();
      Rn.row(1) = Rn.row(2).cross(Rn.row(0)).normalized();
      if (Rn.allFinite()) R = Rn;
    }
    const auto corners = [&](const auto& f) {
      for (int k = r.begin; k < r.end; ++k)
        for (int v : mesh.faces[size_t(order[size_t(k)].second)]) f(mesh.vertices[size_t(v)]);
    };
    if (count <= kExactFaces) {
      set_box(nodes[size_t(r.node)], R, corners);
    } else {
      for (int i = 0; i < 9; ++i) nodes[size_t(r.node)].R[i] = float(R(i / 3, i % 3));
      merge[size_t(r.node)] = 1;
    }
    if (count <= kLeafFaces) {
      Node& node = nodes[size_t(r.node)];
      node.first = int(tri.size());
      node.count = count;
      std::sort(order.begin() + r.begin, order.begin() + r.end,
                [](const auto& x, const auto& y) { return x.second < y.second; });
      for (int k = r.begin; k < r.end; ++k) {
        const auto& F = mesh.faces[size_t(order[size_t(k)].second)];
        LeafFace t;
        t.a = mesh.vertices[size_t(F[0])], t.b = mesh.vertices[size_t(F[1])], t.c = mesh.vertices[size_t(F[2])];
        const Eigen::Vector3d n = (t.b - t.a).cross(t.c - t.a);
        const double len = n.norm();
        t.n = len > 0 && std::isfinite(len) ? Eigen::Vector3d(n / len) : Eigen::Vector3d::Zero();
        t.offset = t.n.dot(t.a);
        t.face = order[size_t(k)].second;
        tri.push_back(t);
      }
      continue;
    }
    // Split at the median along the box's longest axis (the axis of largest variance on big nodes).
    int axis = 0;
    if (count <= kExactFaces) Eigen::Vector3f(nodes[size_t(r.node)].e[0], nodes[size_t(r.node)].e[1], nodes[size_t(r.node)].e[2]).maxCoeff(&axis);
    const Eigen::RowVector3d dir = R.row(axis);
    for (int k = r.begin; k < r.end; ++k) order[size_t(k)].first = dir.dot(centroid[size_t(order[size_t(k)].second)]);
    const int mid = r.begin + count / 2;
    std::nth_element(order.begin() + r.begin, order.begin() + mid, order.begin() + r.end);
    const int left = int(nodes.size());
    nodes[size_t(r.node)].first = left;
    nodes.emplace_back();
    nodes.emplace_back();
    merge.push_back(0);
    merge.push_back(0);
    todo.push_back({left + 1, mid, r.end});
    todo.push_back({left, r.begin, mid});
  }
  // Children have higher indices than their parent: enclose the children's corners bottom-up.
  for (int i = int(nodes.size()) - 1; i >= 0; --i) {
    if (!merge[size_t(i)]) continue;
    Eigen::Matrix3d R;
    for (int k = 0; k < 9; ++k) R(k / 3, k % 3) = double(nodes[size_t(i)].R[k]);
    const int l = nodes[size_t(i)].first;
    set_box(nodes[size_t(i)], R, [&](const auto& f) {
      for (int c : {l, l + 1}) {
        const Node& ch = nodes[size_t(c)];
        Eigen::Matrix3d Rc;
        for (int k = 0; k < 9; ++k) Rc(k / 3, k % 3) = double(ch.R[k]);
        // The child's box is {x : |Rc x - m| <= e}; Rc is orthonormal to 1e-7, so its corners
        // are Rc^-1 (m ± e), enlarged by the frame error.
        const Eigen::Matrix3d Ri = Rc.inverse();
        for (int corner = 0; corner < 8; ++corner) {
          Eigen::Vector3d l3;
          for (int k = 0; k < 3; ++k)
            l3[k] = double(ch.m[k]) + ((corner >> k) & 1 ? 1.0 : -1.0) * double(ch.e[k]) * (1 + kFrameError);
          f(Eigen::Vector3d(Ri * l3));
        }
      }
    });
  }
}

// Ordered depth-first search: the nearer child first, a node is skipped when its box is farther
// than the best face so far. Among faces at the same distance the lowest index wins, as in
// closest_brute_force, so the answer is the same face whatever the tree's shape.
int SurfaceIndex::Impl::search(const Eigen::Vector3d& p) const {
  struct Entry {
    int node;
    double d2;
  };
  Entry stack[128];
  int top = 0;
  double best2 = std::numeric_limits<double>::infinity();
  int face = -1;
  // A box is pruned only when it is farther than the best face by more than the rounding slack.
  const auto bound = [&](double b2) {
    const double b = std::sqrt(b2) + slack;
    return b * b * (1 + 1e-12) * (1 + kFrameError);
  };
  double prune2 = std::numeric_limits<double>::infinity();
  const double px = p.x(), py = p.y(), pz = p.z();
  stack[top++] = {0, 0.0};
  while (top > 0) {
    const Entry en = stack[--top];
    if (en.d2 > prune2) continue;
    int n = en.node;
    for (;;) {
      const Node& node = nodes[size_t(n)];
      if (node.count > 0) {
        for (int k = node.first; k < node.first + node.count; ++k) {
          const LeafFace& T = tri[size_t(k)];
          const double plane = T.n.dot(p) - T.offset;
          if (plane * plane > prune2) continue;  // (prune2 already allows for rounding)
          const double d2 = (closest_on_triangle(p, T.a, T.b, T.c).point - p).squaredNorm();
          if (closer(d2, T.face, best2, face)) prune2 = bound(best2);
        }
        break;
      }
      const int l = node.first;
      const double dl = nodes[size_t(l)].distance2(px, py, pz), dr = nodes[size_t(l) + 1].distance2(px, py, pz);
      const bool left_first = dl == dr && dl == 0
                                  ? !(nodes[size_t(l) + 1].depth(px, py, pz) < nodes[size_t(l)].depth(px, py, pz))
                                  : !(dr < dl);
      const int near = left_first ? l : l + 1, far = left_first ? l + 1 : l;
      const double dn = left_first ? dl : dr, dfar = left_first ? dr : dl;
      if (dfar <= prune2) stack[top++] = {far, dfar};
      if (!(dn <= prune2)) break;
      n = near;
    }
  }
  return face;
}

SurfaceIndex::SurfaceIndex(TriMesh mesh) : impl_(std::make_unique<Impl>()) {
  Impl& s = *impl_;
  s.mesh = std::move(mesh);
  s.normals = vertex_normals(s.mesh);
  s.topology = mesh_topology(s.mesh);
  for (const auto& F : s.mesh.faces)
    s.cover = std::max(s.cover, covering_radius_of(s.mesh.vertices[size_t(F[0])], s.mesh.vertices[size_t(F[1])],
                                                   s.mesh.vertices[size_t(F[2])]));
  if (!s.mesh.faces.empty()) s.build();
}

SurfaceIndex::~SurfaceIndex() = default;
SurfaceIndex::SurfaceIndex(SurfaceIndex&&) noexcept = default;
SurfaceIndex& SurfaceIndex::operator=(SurfaceIndex&&) noexcept = default;

Footpoint SurfaceIndex::closest(const Eigen::Vector3d& p) const {
  const int face = p.allFinite() ? impl_->search(p) : -1;
  if (face < 0) return no_footpoint();
  return impl_->make_footpoint(p, face);
}

std::vector<Footpoint> SurfaceIndex::closest(const std::vector<Eigen::Vector3d>& points) const {
  std::vector<Footpoint> out(points.size());
  const long n = long(points.size());
#pragma omp parallel for schedule(static) if (n > 256)
  for (long i = 0; i < n; ++i) out[i] = closest(points[i]);
  return out;
}

Footpoint SurfaceIndex::closest_brute_force(const Eigen::Vector3d& p) const {
  if (!p.allFinite()) return no_footpoint();
  double best2 = std::numeric_limits<double>::infinity();
  int face = -1;
  for (int f = 0; f < int(impl_->mesh.faces.size()); ++f)
    closer(impl_->face_distance2(f, p), f, best2, face);
  if (face < 0) return no_footpoint();
  return impl_->make_footpoint(p, face);
}

const TriMesh& SurfaceIndex::mesh() const { return impl_->mesh; }
const std::vector<Eigen::Vector3d>& SurfaceIndex::normals() const { return impl_->normals; }
const MeshTopology& SurfaceIndex::topology() const { return impl_->topology; }
double SurfaceIndex::covering_radius() const { return impl_->cover; }

}  // namespace flankcam
