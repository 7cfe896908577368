// Tangential movability of a finite line along a surface (paper Sec. 3.3, 4.1-4.3).
// Work in the unit-diagonal frame: thresholds and step sizes are relative.
#pragma once
#include <Eigen/Core>
#include <string>
#include <vector>

#include "core/closest_point.h"

namespace flankcam {

// Signed distance of p to the smooth surface the mesh samples, along the footpoint's interpolated
// normal (positive on the side the normal points to): the flat facet's distance corrected by the
// quadratic bulge of the face through its corners' normals (an edge's midpoint lies off the chord
// by (v_j - v_i).(n_i - n_j) / 8). Facet distances vary by the chord error (h^2 / 8R) as a point
// moves over the faces; this removes most of it.
[[nodiscard]] double smooth_distance(const SurfaceIndex& surface, const Footpoint& f, const Eigen::Vector3d& p);

struct MovabilityOptions {
  int samples = 30;          // n points on the line
  double jump_ratio = 6.0;   // Remark 1: footpoint spacing over line spacing above this is a second branch
  std::string validate() const;
};

struct Movability {
  double F = 0;                  // F_l = F(x*), eq. (5) at the minimiser with |v_m| = 1, eq. (6)
  // Best velocity field; the part of v_m normal to the line has unit length (sliding along the line
  // does not move it, so it is not counted).
  Eigen::Vector3d v_a = Eigen::Vector3d::Zero(), v_b = Eigen::Vector3d::Zero();
  bool movable = false;          // false: characteristic with several branches (Remark 1) or too few samples
  int used_samples = 0;          // samples whose footpoint is inside the surface (not on its boundary)
  int boundary_samples = 0;      // samples whose footpoint lies on the surface boundary
  std::vector<Footpoint> footpoints;
};

// Minimises F(x) = x A x^T over x = (v_a, λ1, λ2), v_b = v_a + λ1 n1 + λ2 n2 (eq. 3), subject to
// unit length of v_m's component normal to the line (eq. 6, less the sliding of the line along
// itself, which is not a motion of the line). The generalised eigenproblem with its singular
// right-hand side is solved exactly: the axial component and λ are eliminated (Schur complement)
// and the smallest eigenpair of the remaining 2x2 form gives F_l and x*.
[[nodiscard]] Movability line_movability(const SurfaceIndex& surface, const Eigen::Vector3d& a, const Eigen::Vector3d& b,
                                         const MovabilityOptions& options = {});

struct ExplorationOptions {
  MovabilityOptions movability;
  int candidates = 15;        // per endpoint and round: candidates x candidates lines (paper Fig. 8: 15 x 15)
  int rounds = 6;
  double radius = 0.01;       // first sampling radius in the endpoints' normal planes (relative to the diagonal)
  double shrink = 0.5;        // radius factor per round
  unsigned seed = 1;          // sampling is random but seeded: same input, same line
  double good_enough = 1e-8;  // stop once F_l is this small (angles ~1e-4 rad): lower values are noise
                              // and chasing them walks the line away from the user's choice
  std::string validate() const;
};

struct ExploredLine {
  Eigen::Vector3d a, b;
  Movability movability;
  double F_start = 0;       // F_l of the user's line
  int lines_evaluated = 0;
};
// Line exploration (Sec. 4.2): around each endpoint sample alterations in the plane normal to the
// line, keep the movable line with the smallest F_l, shrink the radius, repeat.
[[nodiscard]] ExploredLine explore_line(const SurfaceIndex& surface, const Eigen::Vector3d& a, const Eigen::Vector3d& b,
                                        const ExplorationOptions& options = {});

struct OrientationOptions {
  MovabilityOptions movability;
  double first_step_deg = 4.0;   // pattern search over the line's direction: first angle step ...
  double last_step_deg = 0.25;   // ... halved down to this
  int max_evaluations = 40;
  double min_inside_share = 0.8;  // a candidate direction must keep this share of samples over Φ
  std::string validate() const;
};

struct OrientedLine {
  Eigen::Vector3d a, b;
  Movability movability;
  int lines_evaluated = 0;
};
// The direction of a finite line that minimises F_l (eq. 5) when the line turns about its point
// `pivot` (length kept): a pattern search over two angles normal to the line. Where the tool's
// meridian is far from a cylinder the axis leaves the tangent plane (its slope is the meridian's
// r'(s), eq. 3) and its direction is not a principal direction of Φ; F_l tells it, because it
// grows with the square of the direction's error while it hardly changes with the line's offset.
[[nodiscard]] OrientedLine orient_line(const SurfaceIndex& surface, const Eigen::Vector3d& a, const Eigen::Vector3d& b,
                                       const Eigen::Vector3d& pivot, const OrientationOptions& options = {});

struct PropagationOptions {
  MovabilityOptions movability;
  double step = 0.001;            // of the normalised midpoint velocity (Sec. 4.3)
  double max_movability = 2e-3;   // stop when F_l exceeds this
  double max_boundary_share = 0.5;  // stop when this share of footpoints lies on the surface boundary
  int max_steps = 5000;           // per direction
  // After each step, one Gauss-Newton step back to the start line's distances to Φ (a rigid tool's
  // radii, eq. 8). Not in the paper: without it the line drifts off the axis where F_l has several
  // near-minimal fields (spline tools, s-shaped motions).
  bool keep_radii = true;
  std::string validate() const;
};

enum class PropagationStop { Boundary, Movability, NotMovable, MaxSteps };
[[nodiscard]] const char* to_string(PropagationStop s);

struct LineTrajectory {
  std::vector<Eigen::Vector3d> a, b;  // ordered positions of the moving line, length L kept
  std::vector<double> F;              // F_l at each position
  PropagationStop stop_backward = PropagationStop::MaxSteps, stop_forward = PropagationStop::MaxSteps;
};
// Line propagation (Sec. 4.3): integrate the best tangential field in both directions,
// keeping the length, until F_l exceeds the threshold or the footpoints reach the boundary.
[[nodiscard]] LineTrajectory propagate_line(const SurfaceIndex& surface, const Eigen::Vector3d& a,
                                            const Eigen::Vector3d& b, const PropagationOptions& options = {});

}  // namespace flankcam
