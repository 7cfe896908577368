// Collision and gouge checks of a tool assembly (cutter, shank, holder) moving along a sequence
// of poses against the whole part. Everything in mm.
//
// The assembly is a solid of revolution about the tool axis, z measured from the tip:
//   cutter  z in [0, L]: radii (z_j, r_j), linear between them: the tool's meridian (cutter_from_meridian);
//   shank   z in [L, L + Ls]: cylinder of diameter Ds;
//   holder  z beyond: a cone from Dh0 to Dh1 over Lh, then a cylinder of Dh1 over Lc.
// It is sampled along the axis in slabs of width h; a slab is queried for the nearest part point
// only when the part can be within reach (distance to the slab's bounding ball); the depth is
// measured exactly at that nearest point. Shank and holder slabs never straddle a change of the
// body's profile (the holder's face, the end of its cone), and each is also judged at its own
// nearest part point within the slab widened by the clearance (SurfaceIndex::closest_in_slab): a
// nearer point beside the shank cannot hide one entering the holder through its face. Between poses the motion is subdivided so that no point
// of the assembly moves more than half the clearance per step, so no wall thinner than the
// clearance slips through. A sample far from the part skips the positions it cannot reach the
// part from (the distance bounds the travel; found by bisection), so the cost follows the
// queries, not the positions times the samples.
#pragma once
#include <Eigen/Core>
#include <cmath>
#include <functional>
#include <string>
#include <vector>

#include "core/closest_point.h"
#include "core/mesh.h"
#include "core/pose.h"

namespace flankcam {

struct ToolAssembly {
  std::vector<Eigen::Vector2d> cutter;  // meridian (z, radius) along the axis from the tip, z increasing, mm
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
  // The tolerance the cutter's axial sampling is spaced for (0: gouge_tolerance_mm). The samples are
  // grown to enclose their slabs, so a depth depends on where the slabs fall: the fit, trimming at a
  // share of the tolerance, samples as the final check at the full tolerance does.
  double slab_tolerance_mm = 0;
  // Bounds on the work: positions grow with the motion's travel over half the clearance, axial
  // samples with the tool's length over the slabs, and the closest-point queries are at most
  // positions x samples. Beyond a bound check_collisions throws InputError saying what to change
  // instead of running for hours (a 50 m part); within them a check takes at most minutes.
  int max_positions = 1000000;   // 48 MB of poses
  double max_work = 2e8;         // positions x samples (examples/conical-tool: 100 x ~200)
  // The part without Φ's twin (core/check_surface.h) next to Φ: a cutter hit at a part point within
  // design_within_mm of Φ (the twin's sag plus the tolerance: where the part's coarse faces meet the
  // hole the twin left, e.g. a blade's top face at its coarse edge) is Φ's, left to Φ's own check.
  const SurfaceIndex* design = nullptr;
  double design_within_mm = 0;
  // Called with the share of the work done (0..1), from one thread at a time; may be empty.
  std::function<void(double)> progress;
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

// A cutter hit on the part without Φ's twin at `part_point` that is Φ's to judge: within `within_mm`
// of the design surface (the twin's sag plus the tolerance), where the part's coarse faces meet the
// hole the twin left. check_collisions and the back-simulation's sweep (postproc/verify) skip these.
[[nodiscard]] inline bool left_to_design(const SurfaceIndex& design, const Eigen::Vector3d& part_point, double within_mm) {
  return design.closest(part_point).distance <= within_mm;
}

// Part points that may stand inside a tool beside an axis sample whose nearest part point
// (`nearest`) lies beyond the tool's ends, in the bulge of the sample's ball; callers judge them with
// their own solid (check_collisions, the back-simulation's sweep). The sample stands `z` from the tip,
// its slab is [lo, hi]. Its slab's own nearest part point; for the tip's sample (lo = 0) over a floor
// (`nearest` below the tip plane), which hides a ledge or a hub rising into the end face under the
// rim, instead the nearest part points within [0, step], [step, 2 step], [2 step, 4 step], ... up to
// `hi` (within a slab the one nearest the axis point stands at its floor, so the thin slabs next to
// the tip plane find an intrusion step deep or deeper to within half its depth; the nearest of them
// is the whole slab's), and the one nearest to the rim point (`tip_radius` off the axis) on the side
// of `nearest`, where a tilted end meets a floor first.
[[nodiscard]] std::vector<Footpoint> beside_nearest_points(const SurfaceIndex& part, const ToolPose& pose, double z, double lo,
                                                           double hi, const Eigen::Vector3d& nearest, double tip_radius,
                                                           double step);

// The cutter of a tool whose meridian (z, r) from its tip end is given (an APT profile, a tool end's
// profile; any unit): from the tip plane z = 0 up, the first radius above the tip standing at z = 0.
// A ball end's tip on the axis is kept once.
[[nodiscard]] std::vector<Eigen::Vector2d> cutter_from_meridian(const std::vector<Eigen::Vector2d>& meridian);

[[nodiscard]] CollisionReport check_collisions(const SurfaceIndex& part, const std::vector<ToolPose>& poses,
                                               const ToolAssembly& tool, const CollisionOptions& options);

// The assembly at a pose as a closed triangle mesh (for viewing the offending positions).
[[nodiscard]] TriMesh assembly_mesh(const ToolAssembly& tool, const ToolPose& pose, int segments = 32);

}  // namespace flankcam
