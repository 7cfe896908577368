// The end of the tool at its tip: flat, ball or corner radius (bull nose). The fitted tool is the
// canal surface of the spheres d(s) (paper Sec. 3); its side, in the tool's half plane, is the
// meridian (z, r) of core/fitting.h meridian(), z from the tip end a along a->b. The end closes it:
//   flat:   the tip face, a disk at the meridian's first point z0 (a sharp corner);
//   corner: a torus: the circle of radius R tangent to the tip plane z = z0 and to the side
//           (centre (z0 + R, rc): the side offset inwards by R at the height z0 + R); the tip face
//           keeps the disk of radius rc, the side is the tool above the tangent point;
//   ball:   the corner whose rc is 0: the sphere on the axis tangent to the tip plane and to the
//           side. Its radius is the tip radius for a cylinder; on a cone of half angle α widening
//           away from the tip it is r0 cos α / (1 - sin α) = d(0) (1 + sin α) (the sphere's centre
//           lies d(0)(1 + sin α) above the tip, not at the axis point a, so that it is tangent to
//           the cone and its lowest point is the tip).
// The tip plane stays where it is (the programmed tool tip): a rounded end replaces the side's
// lowest band, it does not lengthen the tool.
#pragma once
#include <Eigen/Core>
#include <cmath>
#include <string>
#include <vector>

namespace flankcam {

enum class EndKind { Flat, Ball, Corner };
[[nodiscard]] const char* to_string(EndKind k);

struct ToolEnd {
  EndKind kind = EndKind::Flat;
  double corner_radius = 0;  // Corner: R, in the meridian's unit (mm in jobs); ignored otherwise
  double unit_mm = 1;        // mm per unit of the meridian, for the numbers in error messages
};

struct EndProfile {
  // The whole meridian from the tip: (z0, rc) (the rim of the tip face; rc = 0 for a ball), the
  // end's arc, then the side; z strictly increasing. Flat: the side meridian unchanged.
  std::vector<Eigen::Vector2d> profile;
  int end_points = 0;              // profile[0, end_points) belong to the end (arc; 0 for flat)
  double radius = 0;               // R of the arc (0 for flat)
  Eigen::Vector2d centre{0, 0};    // (z, r) of the arc's centre
  double tip_z = 0;                // z0: the tip plane
  double side_s = 0;               // the side is the tool for s >= side_s (s of the tangent point)
};

// `side`: meridian() of the fitted tool (z increasing, sampled uniformly in s from 0 to 1).
// Throws InputError when the corner radius is not positive or larger than the ball radius (the
// largest that fits: rc would be negative), or the tool is too short for it.
[[nodiscard]] EndProfile end_profile(const std::vector<Eigen::Vector2d>& side, const ToolEnd& end, int arc_points = 16);

// The cutter the collision check sees, in one unit: `cutter` the union of the tool's spheres between
// its end planes (fitting.h's cutter_union), `side` its side meridian (fitting.h's meridian). A flat
// end: end_profile of the union. A rounded end: end_profile of the side meridian, its points at or
// above the union's top replaced by the union's there (the tool ends where the union of its spheres
// does, at its end plane, where the fit put shank and holder).
[[nodiscard]] EndProfile checked_end_profile(const std::vector<Eigen::Vector2d>& cutter, const std::vector<Eigen::Vector2d>& side,
                                             const ToolEnd& end);

// The profile's radius at z (z, r points with z increasing): linear between its points, its end
// radii beyond them.
[[nodiscard]] double profile_radius(const std::vector<Eigen::Vector2d>& profile, double z);

// The point of a polyline in the tool's half plane (z, r) nearest to q: the segment it lies on (from
// point `segment` to the next; segments of zero length are passed over: their point ends a neighbour
// too), the point, and its distance. Ties: the first. All its points one: that point (segment 0);
// no points: an infinite distance.
struct PolylinePoint {
  size_t segment = 0;
  Eigen::Vector2d at = Eigen::Vector2d::Zero();
  double distance = INFINITY;
};
[[nodiscard]] PolylinePoint polyline_nearest(const std::vector<Eigen::Vector2d>& line, const Eigen::Vector2d& q);

// The radius of the ball end of this side meridian (the corner radius with rc = 0).
[[nodiscard]] double ball_radius(const std::vector<Eigen::Vector2d>& side);

// Signed distance in the tool's half plane from (z, rho) to the tool end: > 0 outside the tool,
// < 0 inside. `reached` is false when the nearest point of the end is its top (the tangent point or
// the flat face's rim): the side, not the end, is nearest there.
struct EndDistance {
  double distance = 0;
  bool reached = false;
};
[[nodiscard]] EndDistance end_distance(const EndProfile& end, double z, double rho);

}  // namespace flankcam
