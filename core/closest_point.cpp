#include "core/closest_point.h"

#include <Eigen/Geometry>
#include <flann/flann.hpp>

#include <algorithm>
#include <cmath>
#include <limits>

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

using KdTree = flann::KDTreeSingleIndex<flann::L2_Simple<double>>;

// Largest distance from a point of the triangle to its nearest corner: the
// circumradius for non-obtuse triangles, half the longest edge otherwise.
double covering_radius_of(const Eigen::Vector3d& a, const Eigen::Vector3d& b, const Eigen::Vector3d& c) {
  const double A = (b - c).squaredNorm(), B = (c - a).squaredNorm(), C = (a - b).squaredNorm();
  const double longest = std::max({A, B, C});
  if (2 * longest >= A + B + C) return 0.5 * std::sqrt(longest);  // right or obtuse
  const double area2 = (b - a).cross(c - a).norm();                // twice the area
  return std::sqrt(A * B * C) / (2 * area2);
}

}  // namespace

struct SurfaceIndex::Impl {
  TriMesh mesh;
  std::vector<Eigen::Vector3d> normals;
  MeshTopology topology;
  std::vector<int> vf_start, vf_faces;  // vertex -> incident faces (CSR)
  std::vector<double> reach;            // per vertex: farthest point of an incident face
  double cover = 0;
  std::unique_ptr<KdTree> tree;

  double face_distance2(int f, const Eigen::Vector3d& p) const {
    const auto& F = mesh.faces[f];
    return (closest_on_triangle(p, mesh.vertices[F[0]], mesh.vertices[F[1]], mesh.vertices[F[2]]).point - p)
        .squaredNorm();
  }

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

namespace {

// A FLANN result set that never stores anything: each vertex the kd-tree reports
// has its incident faces tested at once, and the search radius shrinks with the
// best distance found (radius = best + covering radius, squared for FLANN's L2).
class NearestFaceVisitor final : public flann::ResultSet<double> {
 public:
  NearestFaceVisitor(const SurfaceIndex::Impl& s, const Eigen::Vector3d& p) : s_(s), p_(p) { seen_.fill(-1); }
  bool full() const override { return true; }
  double worstDist() const override { return radius2_; }
  void addPoint(double dist2, size_t vertex) override {
    if (dist2 >= radius2_) return;
    const double dv = std::sqrt(dist2);
    if (dv - s_.reach[vertex] > best_) return;  // no incident face can come closer
    for (int i = s_.vf_start[vertex]; i < s_.vf_start[vertex + 1]; ++i) {
      const int f = s_.vf_faces[i];
      if (!first_visit(f)) continue;
      const double d2 = s_.face_distance2(f, p_);
      if (d2 < best2_ || (d2 == best2_ && f < face_)) {
        best2_ = d2;
        face_ = f;
        best_ = std::sqrt(d2);
        const double r = best_ + s_.cover;
        radius2_ = r * r * (1 + 1e-12) + 1e-300;
      }
    }
  }
  int face() const { return face_; }

 private:
  // Small open-addressing set of tested faces; when it is full, faces are simply
  // retested (costs time, never changes the answer).
  bool first_visit(int f) {
    unsigned h = (unsigned(f) * 2654435761u) & (kSlots - 1);
    for (int probe = 0; probe < 16; ++probe, h = (h + 1) & (kSlots - 1)) {
      if (seen_[h] == f) return false;
      if (seen_[h] < 0) {
        seen_[h] = f;
        return true;
      }
    }
    return true;
  }
  static constexpr unsigned kSlots = 256;
  const SurfaceIndex::Impl& s_;
  Eigen::Vector3d p_;
  std::array<int, kSlots> seen_;
  double best_ = std::numeric_limits<double>::infinity();
  double best2_ = std::numeric_limits<double>::infinity();
  double radius2_ = std::numeric_limits<double>::max();
  int face_ = -1;
};

}  // namespace

SurfaceIndex::SurfaceIndex(TriMesh mesh) : impl_(std::make_unique<Impl>()) {
  Impl& s = *impl_;
  s.mesh = std::move(mesh);
  s.normals = vertex_normals(s.mesh);
  s.topology = mesh_topology(s.mesh);
  const int nv = int(s.mesh.vertices.size());
  s.vf_start.assign(nv + 1, 0);
  for (const auto& f : s.mesh.faces)
    for (int v : f) ++s.vf_start[v + 1];
  for (int v = 0; v < nv; ++v) s.vf_start[v + 1] += s.vf_start[v];
  s.vf_faces.resize(s.vf_start[nv]);
  std::vector<int> fill(s.vf_start.begin(), s.vf_start.end() - 1);
  s.reach.assign(nv, 0.0);
  for (int f = 0; f < int(s.mesh.faces.size()); ++f) {
    const auto& F = s.mesh.faces[f];
    const auto &a = s.mesh.vertices[F[0]], &b = s.mesh.vertices[F[1]], &c = s.mesh.vertices[F[2]];
    s.cover = std::max(s.cover, covering_radius_of(a, b, c));
    for (int k = 0; k < 3; ++k) {
      s.vf_faces[fill[F[k]]++] = f;
      for (int j = 0; j < 3; ++j)
        s.reach[F[k]] = std::max(s.reach[F[k]], (s.mesh.vertices[F[j]] - s.mesh.vertices[F[k]]).norm());
    }
  }
  s.cover *= 1 + 1e-9;  // rounding of the covering radius must never shrink the search
  flann::Matrix<double> data(const_cast<double*>(s.mesh.vertices[0].data()), size_t(nv), 3);
  s.tree = std::make_unique<KdTree>(data, flann::KDTreeSingleIndexParams(16, true));
  s.tree->buildIndex();
}

SurfaceIndex::~SurfaceIndex() = default;
SurfaceIndex::SurfaceIndex(SurfaceIndex&&) noexcept = default;
SurfaceIndex& SurfaceIndex::operator=(SurfaceIndex&&) noexcept = default;

Footpoint SurfaceIndex::closest(const Eigen::Vector3d& p) const {
  NearestFaceVisitor visitor(*impl_, p);
  impl_->tree->findNeighbors(visitor, p.data(), flann::SearchParams(flann::FLANN_CHECKS_UNLIMITED, 0.0f));
  return impl_->make_footpoint(p, visitor.face());
}

std::vector<Footpoint> SurfaceIndex::closest(const std::vector<Eigen::Vector3d>& points) const {
  std::vector<Footpoint> out(points.size());
  const long n = long(points.size());
#pragma omp parallel for schedule(static) if (n > 256)
  for (long i = 0; i < n; ++i) out[i] = closest(points[i]);
  return out;
}

Footpoint SurfaceIndex::closest_brute_force(const Eigen::Vector3d& p) const {
  double best = std::numeric_limits<double>::infinity();
  int face = -1;
  for (int f = 0; f < int(impl_->mesh.faces.size()); ++f) {
    const double d2 = impl_->face_distance2(f, p);
    if (d2 < best) {
      best = d2;
      face = f;
    }
  }
  return impl_->make_footpoint(p, face);
}

const TriMesh& SurfaceIndex::mesh() const { return impl_->mesh; }
const std::vector<Eigen::Vector3d>& SurfaceIndex::normals() const { return impl_->normals; }
const MeshTopology& SurfaceIndex::topology() const { return impl_->topology; }
double SurfaceIndex::covering_radius() const { return impl_->cover; }

}  // namespace flankcam
