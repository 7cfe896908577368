// Exact closest points on a triangle mesh: a bounding-volume hierarchy of the faces with an
// oriented box per node (principal axes, so boxes are thin along the surface normal), four
// children per node bounded in one 4-wide float pass, leaves of four faces with float lower
// bounds before the exact double test; searched nearer child first and pruned by conservative
// bounds. The cost per query grows like log n at any distance from the surface; the answer equals
// brute force, face included (ties go to the lower face index), whatever the thread count.
// Meshes of up to 131k faces also keep a local certificate per leaf (its corner-sharing
// neighbourhood and a lower bound on the distance to every face outside it): a batch query on or
// next to the surface, started from the previous answer's leaf, is then settled by a handful of
// leaves without the descent from the root. Every mesh also keeps a hashed grid of cells about a
// leaf wide, each listing the leaves within a tenth of a cell of it: a query on the surface (or
// within that tenth) is settled by its cell's few leaves, with no descent, at any mesh size.
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

  // A query that is not finite (NaN or infinite coordinates, e.g. from an overflowing input) has
  // no footpoint: face -1, distance +inf, NaN point and normal, on_boundary true (so callers that
  // leave out samples beyond Φ's rim leave it out too). Never throws.
  [[nodiscard]] Footpoint closest(const Eigen::Vector3d& p) const;
  // Both cores; result i belongs to points[i]. Answered in Morton order of the points (neighbours
  // share cached nodes): the same footpoints as one closest() per point.
  [[nodiscard]] std::vector<Footpoint> closest(const std::vector<Eigen::Vector3d>& points) const;
  // Brute force over all triangles; the reference the tests compare against (same tie rule).
  [[nodiscard]] Footpoint closest_brute_force(const Eigen::Vector3d& p) const;
  // The closest point to p among the mesh's points x in the slab lo <= <x, direction> <= hi
  // (direction unit): the faces clipped to the slab. The footpoint's face, point, distance and
  // barycentric coordinates (of the point in the whole face); no face (as for a query that is not
  // finite) when no face meets the slab. A solid of revolution about `direction` judged slab by
  // slab (shank and holder against the part) sees in each slab its own nearest part point, not a
  // nearer one beside a narrower part of the body that hides a farther one entering a wider part.
  [[nodiscard]] Footpoint closest_in_slab(const Eigen::Vector3d& p, const Eigen::Vector3d& direction, double lo,
                                          double hi) const;
  // The same by brute force over all faces (the tests' reference).
  [[nodiscard]] Footpoint closest_in_slab_brute_force(const Eigen::Vector3d& p, const Eigen::Vector3d& direction,
                                                      double lo, double hi) const;

  [[nodiscard]] const TriMesh& mesh() const;
  [[nodiscard]] const std::vector<Eigen::Vector3d>& normals() const;  // per vertex
  [[nodiscard]] const MeshTopology& topology() const;
  [[nodiscard]] double covering_radius() const;  // max over triangles of max distance to nearest corner
  // The angle-weighted pseudo-normal at a footpoint of this mesh (Bærentzen & Aanæs, IEEE TVCG 11(3),
  // 2005): the face normal inside a face, the normalised sum of both faces' normals on an edge, the
  // angle-weighted vertex normal at a corner. On a closed, consistently oriented mesh the sign of
  // <p - footpoint, pseudo-normal> tells outside (> 0) from inside for any p, also next to sharp edges
  // where the closest face's own normal may point either way (a thin blade's edge or tip: points far
  // above it looked deep inside). Edge neighbours are found on first use (both cores may ask).
  [[nodiscard]] Eigen::Vector3d pseudo_normal(const Footpoint& f) const;

 struct Impl;  // declared here so that the search visitor in the .cpp can see it

 private:
  // closest(p), starting with the faces of `hint_leaf` (from an earlier query; -1: none), which
  // becomes the leaf of the answer. The same footpoint whatever the hint: a near one saves time.
  [[nodiscard]] Footpoint closest_from(const Eigen::Vector3d& p, int& hint_leaf) const;
  std::unique_ptr<Impl> impl_;
};

}  // namespace flankcam
