// Collision and gouge checks of a tool assembly (cutter, shank, holder) moving along a sequence
// of poses against the whole part. Everything in mm.
//
// The assembly is a solid of revolution about the tool axis, z measured from the tip:
//   cutter  z in [0, L]: the union of the fitted spheres (z_j, d_j) (the tool the fit assumes);
//   shank   z in [L, L + Ls]: cylinder of diameter Ds;
//   holder  z beyond: a cone from Dh0 to Dh1 over Lh, then a cylinder of Dh1 over Lc.
// It is sampled along the axis in slabs of width h; a slab is queried for the nearest part point
// only when the part can be within reach (distance to the slab's bounding ball); the depth is
// measured exactly at that nearest point. Between poses the motion is subdivided so that no point
// of the assembly moves more than half the clearance per step, so no wall thinner than the
// clearance slips through.
#pragma once
#include <Eigen/Core>
#include <string>
#include <vector>

#include "core/closest_point.h"
#include "core/mesh.h"
#include "core/pose.h"

namespace flankcam {

struct ToolAssembly {
  std::vector<Eigen::Vector2d> cutter;  // spheres (z, radius) along the axis from the tip, z increasing, mm
  double shank_length = 0, shank_diameter = 0;
  double holder_length = 0, holder_diameter = 0, holder_diameter_far = 0;  // cone (equal diameters: cylinder)
  double holder_cylinder_length = 0;
  [[nodiscard]] double cutter_length() const { return cutter.empty() ? 0 : cutter.back().x(); }
  [[nodiscard]] double total_length() const;
  std::string validate() const;  // empty when valid, else names the field
};

enum class Component { Tool, Shank, Holder };
[[nodiscard]] const char* to_string(Component c);

struct CollisionOptions {
  double clearance_mm = 1.0;        // shank and holder must stay this far from the part
  double gouge_tolerance_mm = 0.01; // the cutter may enter the part this deep (the fit's tolerance)
  double slab_mm = 0;               // axial sampling; 0: from the gouge tolerance and the radii
  std::string validate() const;
};

struct CollisionInterval {
  Component component = Component::Holder;
  int pose_begin = 0, pose_end = 0;  // input poses bracketing the colliding positions
  double max_depth_mm = 0;           // deepest interference (radial; for the holder and shank plus the clearance)
  Eigen::Vector3d at = Eigen::Vector3d::Zero();  // the part point there
  int worst_pose = 0;
};

struct CollisionReport {
  std::vector<CollisionInterval> intervals;
  int positions_checked = 0;  // poses and the positions between them
  long queries = 0;           // closest-point queries made
  [[nodiscard]] bool clear() const { return intervals.empty(); }
};

[[nodiscard]] CollisionReport check_collisions(const SurfaceIndex& part, const std::vector<ToolPose>& poses,
                                               const ToolAssembly& tool, const CollisionOptions& options);

// The assembly at a pose as a closed triangle mesh (for viewing the offending positions).
[[nodiscard]] TriMesh assembly_mesh(const ToolAssembly& tool, const ToolPose& pose, int segments = 32);

}  // namespace flankcam
