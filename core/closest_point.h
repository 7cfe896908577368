// Exact closest points on a triangle mesh. FLANN's exact kd-tree over the vertices
// drives the search; candidate triangles are those with a vertex within
// (best distance so far + largest covering radius of a triangle), which provably
// contains the triangle of the true closest point, so the answer equals brute force.
#pragma once
#include <Eigen/Core>
#include <array>
#include <memory>
#include <vector>

#include "core/mesh.h"

namespace flankcam {

struct Footpoint {
  Eigen::Vector3d point = Eigen::Vector3d::Zero();   // closest point on the mesh
  Eigen::Vector3d normal = Eigen::Vector3d::Zero();  // interpolated vertex normal, unit, mesh orientation
  Eigen::Vector3d barycentric = Eigen::Vector3d::Zero();  // of `point` in `face` (corner order)
  double distance = 0;                                // |p - point|
  int face = -1;
  bool on_boundary = false;  // footpoint lies on a boundary edge or boundary vertex
};

// Exact point-triangle closest point (Ericson, RTCD 5.1.5) with barycentric coordinates.
struct TrianglePoint {
  Eigen::Vector3d point, barycentric;
};
[[nodiscard]] TrianglePoint closest_on_triangle(const Eigen::Vector3d& p, const Eigen::Vector3d& a,
                                                const Eigen::Vector3d& b, const Eigen::Vector3d& c);

// Immutable search structure over one mesh; queries are const and thread-safe.
class SurfaceIndex {
 public:
  explicit SurfaceIndex(TriMesh mesh);
  ~SurfaceIndex();
  SurfaceIndex(SurfaceIndex&&) noexcept;
  SurfaceIndex& operator=(SurfaceIndex&&) noexcept;

  [[nodiscard]] Footpoint closest(const Eigen::Vector3d& p) const;
  // Both cores; result i belongs to points[i].
  [[nodiscard]] std::vector<Footpoint> closest(const std::vector<Eigen::Vector3d>& points) const;
  // Brute force over all triangles; the reference the tests compare against.
  [[nodiscard]] Footpoint closest_brute_force(const Eigen::Vector3d& p) const;

  [[nodiscard]] const TriMesh& mesh() const;
  [[nodiscard]] const std::vector<Eigen::Vector3d>& normals() const;  // per vertex
  [[nodiscard]] const MeshTopology& topology() const;
  [[nodiscard]] double covering_radius() const;  // max over triangles of max distance to nearest corner

 struct Impl;  // declared here so that the search visitor in the .cpp can see it

 private:
  std::unique_ptr<Impl> impl_;
};

}  // namespace flankcam
