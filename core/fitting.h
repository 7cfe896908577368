// Fitting the envelope of a moving surface of revolution to a design surface
// (paper Sec. 4.4-4.6). Everything here works in the unit-diagonal frame of Φ:
// lengths are relative to Φ's bounding-box diagonal.
#pragma once
#include <Eigen/Core>
#include <array>
#include <cmath>
#include <functional>
#include <optional>
#include <string>
#include <vector>

#include "core/bspline.h"
#include "core/closest_point.h"
#include "core/envelope.h"
#include "core/movability.h"

namespace flankcam {

enum class ToolShape { General, Cone, Cylinder };
[[nodiscard]] const char* to_string(ToolShape s);
[[nodiscard]] ToolShape tool_shape_from_string(const std::string& s);  // throws InputError

// Limits on a custom tool's shape (paper Sec. 4.6, "additional constraints on the meridian curve"),
// unit frame like everything here. Enforced inside optimize_motion: the radius unknowns D get
// one-sided penalties G D <= h in every solve, are projected onto {G D <= h} between solves, and
// the motion is fitted once more with the projected (feasible) radii held fixed. Radii r are those
// of the meridian (the planar envelope of the circles d(z), meridian()), not the sphere radii d.
struct ToolConstraints {
  double min_radius = 0;               // smallest meridian radius (min_diameter / 2)
  double max_radius = INFINITY;        // largest meridian radius (max_diameter / 2)
  double max_length = INFINITY;        // meridian length along the axis (tool_dimensions' length)
  double min_tip_radius = 0;           // meridian radius at the tip end (s = 0)
  // The largest radius there: a flat end standing on a floor that meets the flank at an acute angle
  // (a hub under a leaning blade) digs in with the rim away from the flank, and the rim at the flank
  // stays 2 r sin(90 deg - angle) above the floor; a small tip reaches lower. Not with detection
  // (job.cpp refuses it): held at both ends it makes lenses that fit no flank, and held at the tip
  // the part chooses it forbids the tip cut (cut_at_tip widens the tip) that keeps candidates out of
  // a hub (the HECC impeller, max_tip_diameter 4: no patch either way).
  double max_tip_radius = INFINITY;
  double max_cone_angle_rad = M_PI / 2;  // steepest meridian half angle, |asin d'(z)|
  bool convex = false;                 // d(s) concave: a meridian without a waist
  // A rounded end's radius (tool.end {corner: R}): the tip's ball radius (tool_end.h ball_radius)
  // at least this, so that the corner fits the tool. The ball centred R above the tip plane lies in
  // the tool when the sphere of the axis point there has d >= R (the canal surface's spheres are
  // inscribed), one linear row in D at that point (taken from the current radii).
  double min_ball_radius = 0;
  // The tip end is not known during the fit (detection turns a tool after it, by the part or the
  // holder's side): the tip limits (min_tip_radius, max_tip_radius, min_ball_radius) hold at both ends.
  bool either_end = false;
  [[nodiscard]] bool active() const;
  std::string validate() const;        // empty when valid, else names the field
};

// Tool radii along the axis: d(s) = sum_k c_k(s) D_k, with c the shape's basis
// (general: cubic spline with meridian_control_points values; cone: linear; cylinder: constant).
struct ToolRadius {
  ToolShape shape = ToolShape::General;
  std::vector<double> D;  // parameters, unit frame
  [[nodiscard]] std::vector<double> basis(double s) const;
  [[nodiscard]] double d(double s) const;
  [[nodiscard]] RadiusProfile profile() const;  // the same d(s) as a cubic B-spline
};

// Check surfaces (the part, without the design surface's own region): a fitted tool stays out of
// them. Unit frame. Every round, samples of the tool's axis are queried against the part: along the
// cutter (the fit's m x n samples, radius d_j) and along the body beyond it (shank and holder:
// `body` gives (distance beyond the cutter's end along the axis, radius) of each sample). A cutter
// sample whose signed distance to the part is below its radius minus `tolerance` gets a one-sided
// penalty on the motion and the radii; a body sample is judged at the part point found for its axis
// point against the body's outline (its gap below `clearance` plus the sag of the samples' spacing),
// or as a ball when its axis point is inside the part:
//   r = w (R - <p - q, g>),  q the part's closest point, g its outward direction,
// the same linearisation as eq. (10)'s plane term, so the optimisation tilts or shifts the axis (and
// narrows the radii) away from the part instead of cutting it.
struct CheckSurface {
  // Unset: no check surface. Its faces must be oriented out of the material (a closed part outward):
  // the sign of a distance is that of <p - q, pseudo-normal at q>, and positive (outside) where the closest
  // point lies on the part's boundary (the edge of the hole where Φ's twin was cut out).
  const SurfaceIndex* part = nullptr;
  // The whole part (closed, Φ's twin included), when `part` is it without the twin: a point is
  // inside when it lies more than `tolerance` inside this one (the sign of its closest face), which
  // stays right in front of the hole the twin leaves in `part`. Unset: `part`'s own faces decide.
  const SurfaceIndex* solid = nullptr;
  // Which faces of `solid` are Φ's twin (CheckPart::twin), and how far its chords stand off Φ at
  // most (CheckPart::twin_sag): behind a twin face a point is inside only when deeper than
  // tolerance + twin_sag. Unset: every face of `solid` counts alike.
  const std::vector<char>* solid_twin = nullptr;
  double twin_sag = 0;
  double tolerance = 0;   // how deep the cutter may enter the part
  double clearance = 0;   // how far shank and holder stay from it
  // (u beyond the cutter end, radius), u >= 0 not decreasing: two samples at one u are a step in
  // the radius (a holder's face over a narrower shank), the outline linear between samples.
  std::vector<Eigen::Vector2d> body;
  // The tool's holder side: the end of the axis segment whose direction from the other end points
  // along `up` (mean over the motion). Unset: the b end (s = 1), the tip is a.
  std::optional<Eigen::Vector3d> up;
  // The cutter's tip end is a ball (tool.end: ball): one sphere, tangent to the tip plane and to the
  // side, stands for the end instead of the flat end's rims (a corner radius is checked as flat, which
  // is on the safe side).
  bool ball_tip = false;
  double weight = 3;      // per unit of intrusion, relative to the plane term's weight
  // Samples farther from the part than their radius plus this are left out of a round, and so are
  // those more than this share of their radius inside it (the tool deep in the part: no nearby
  // motion is clear, the motion is trimmed there instead).
  double band = 0.05;
  double depth_limit = 0.5;
  // A floor under the tip (a hub below a blade's flank): per row, where the part's face nearest the
  // tip's lowest point (the flat end's rim over that face's plane, or the ball's) faces the tool (its
  // outward direction within 45 degrees of the axis, towards the holder) and that point stands less
  // than floor_reach x the tip radius above it, the point is pulled to floor_height above it
  // (two-sided, floor_weight relative to a row's plane terms). The fit's Φ samples leave the tip's
  // height along a cylinder's axis free and a cone's nearly so: without it the tip floats wherever
  // the rails happen to leave it and the flank's bottom rows next to the floor are not machined.
  // 0: no pull (the fit only keeps out of the part).
  double floor_reach = 0;
  double floor_height = 0;  // unit frame
  double floor_weight = 10;
};

struct FitOptions {
  int samples_s = 30, samples_t = 100;                            // n x m samples of R(t, s) (paper: 30 x 100)
  double w_plane = 1, w_fair = 0.1, w_point = 0.001, w_rigid = 0.1;  // μ1..μ4 of eq. (12)
  // true: F_fair (eq. 11) acts on each round's change of the rails, so it keeps the updates fair
  // without pulling a curved motion straight; false: on the rails themselves, as printed in the
  // paper (this biases curved exact envelopes by more than 1e-4 of the diagonal).
  bool fair_update = true;
  // Weak pull of the radii d_j to the initial meridian (not in the paper): fixes the nearly free
  // offset of axis and radius on nearly developable surfaces. 0 disables it.
  double w_anchor = 1e-4;
  ToolShape shape = ToolShape::General;
  int rail_control_points = 16;      // per rail a(t), b(t)
  int meridian_control_points = 10;  // general tools: cubic spline d(s) (paper: 10)
  int max_iterations = 25;           // outer iterations (footpoints recomputed between solves)
  int solver_iterations = 5;         // Levenberg-Marquardt iterations per outer iteration
  double stall = 2e-2;               // stop when a round lowers its objective by less than this, relatively
  // or when a round moves the envelope by less than this at every sample (unit frame). 1e-6 stops the
  // exact-envelope tests 2-12 rounds earlier but raises their ε by up to 15%, so the default only
  // stops a fit that has really stalled.
  double motion_tolerance = 1e-7;
  // or when in plateau_rounds rounds none of F_motion (at fresh footpoints), ε and the mean sample error
  // of the motion fell below its best so far by this share (fit_plateaued; plateau_rounds 0 disables it).
  // The motion's ends can slide along Φ's rim by ~2e-4 a round while each solve still lowers its own
  // objective by 4-7%, the envelope moves by ~1e-6 and ε grows: fit_bench's 1M-vertex fit ran all 25
  // rounds (ε 6.1e-6, best 4.5e-6 in round 13); with this it stops after 15 (ε 4.8e-6).
  double plateau = 1e-2;
  int plateau_rounds = 3;
  // Scale of a Cauchy loss on the sample residuals (unit frame; not in the paper). Samples whose
  // distance error is well above it (a local bump, a damaged scan) stop pulling the motion, so the
  // fit stays on the rest. The price is a larger worst error where the surface is simply not an
  // envelope: on rotor 37 a scale of 1e-3 raised the worst overcut from 0.11 to 0.15 mm (1e-4: 0.43 mm)
  // while coverage rose from 61% to 62% (72%). 0: plain least squares, as in the paper.
  double robust_scale = 0;
  ToolConstraints constraints;       // custom tools (not with fixed_tool)
  CheckSurface check;                // the part the tool must keep out of (none by default)
  // A tool from a catalogue (or shared by several patches): its radii are held constant and only
  // the motion is fitted (the paper's optimisation without d as unknowns). Its shape replaces `shape`.
  std::optional<ToolRadius> fixed_tool;
  // Penalty weight of a violated constraint row in the solve (per unit of violation, unit frame).
  double w_constraint = 100;
  int threads = 2;
  // Called after each outer iteration with its number (1-based) and F_motion; may be empty.
  std::function<void(int iteration, double objective)> on_iteration;
  std::string validate() const;      // empty when valid, else names the field
};

// The axis motion: rails a(t) (tool tip side, s = 0) and b(t) (s = 1), cubic B-splines,
// and the rigid length L the rigidity term keeps.
struct Rails {
  BSpline a, b;
  double length = 0;
  [[nodiscard]] Eigen::Vector3d point(double t, double s) const { return (1 - s) * a.point(t) + s * b.point(t); }
};
[[nodiscard]] LineMotion to_motion(const Rails& r);
// The motion's mean axis direction a -> b (unit directions at 21 uniform t, summed; not normalised):
// which way the tool stands (detection turns patches tip down by it, the check surface puts the
// holder at the upper end by it).
[[nodiscard]] Eigen::Vector3d mean_axis(const Rails& r);

// The tool's intrusion into the check surface per motion row: rows[i] over t_i = i / (rows - 1) is
// the worst (R_eff - signed distance) over the cutter and body samples of that row (<= 0: clear),
// and `body` says whether that worst sample belongs to the shank or holder (else the cutter).
struct CheckProfile {
  std::vector<double> intrusion;
  std::vector<char> body;
  std::vector<Eigen::Vector3d> at;  // the part point there
};
// `enclose`: as the collision check judges (core/collision.h), for deciding what to trim: the cutter
// sampled densely enough for the tolerance and every sample grown to enclose its slab of the solid;
// otherwise the fit's own samples (samples_s along the cutter). `design`: a cutter sample's intrusion
// at a part point within `design_within` of the design surface is Φ's to judge (left_to_design, as
// the collision check leaves it) and not counted.
[[nodiscard]] CheckProfile check_profile(const Rails& rails, const ToolRadius& tool, const CheckSurface& check,
                                         int rows, int samples_s, bool enclose = false,
                                         const SurfaceIndex* design = nullptr, double design_within = 0);

// Signed distances of points to the check surface as the cutter's samples are judged (the part
// without Φ's twin; inside, negative, decided by the whole part when `solid` is given, and then as
// deep as the point lies behind the whole part's nearest face, Φ's twin included); infinite
// without a part. A sphere of radius R at a point keeps out of the part when its distance >= R - tolerance.
[[nodiscard]] std::vector<double> cutter_clearances(const CheckSurface& check, const std::vector<Eigen::Vector3d>& points);

// Which way the holder should stand for a motion against a check surface: the end of the axis
// whose shank and holder (check.body) enter the part in fewer rows (then by less), as a direction
// for CheckSurface::up (± mean_axis(rails)); `fallback` decides a tie (no part, no body, both clear
// or both equally deep): the end along it. A blade's flank next to a hub gets its tip at the hub
// whichever way the machine's Z points.
[[nodiscard]] Eigen::Vector3d holder_up(const Rails& rails, const ToolRadius& tool, const CheckSurface& check, int rows,
                                        const Eigen::Vector3d& fallback);

// A finite line [a, b] (unit frame).
struct AxisLine {
  Eigen::Vector3d a, b;
};

// Surface-driven initialisation (Sec. 4.4): the endpoints of the ordered user lines are the
// control polygons of two cubic B-splines; the trajectory of `rail` (0: a, 1: b) and the
// length L (<= 0: mean length of the lines) give a rigid motion, refitted with
// `rail_control_points` control points.
[[nodiscard]] Rails rails_from_lines(const std::vector<AxisLine>& lines, int rail, double length,
                                     const FitOptions& options);
// Line-driven: the rails through the positions of a propagated line (Sec. 4.3).
[[nodiscard]] Rails rails_from_trajectory(const LineTrajectory& trajectory, const FitOptions& options);
// The rails' parameter t of each position of a trajectory: chord length of the line midpoints (what
// rails_from_trajectory fits the rails over).
[[nodiscard]] std::vector<double> trajectory_parameters(const LineTrajectory& trajectory);


struct ErrorStats {
  double max = 0, mean = 0;     // eq. (13) over the samples, unit frame (= relative to the diagonal)
  int samples = 0, excluded = 0;  // excluded: footpoint on Φ's boundary (the axis point is beyond Φ)
  std::vector<double> bin_edges;  // histogram of |dist - d_j| (unit frame)
  std::vector<int> histogram;
};
// ε of eq. (13): max_ij |dist(R(t_i, s_j), Φ) - d_j| (the paper prints "min"; it means the worst sample).
[[nodiscard]] ErrorStats sample_error(const SurfaceIndex& surface, const Rails& rails, const ToolRadius& tool,
                                      const FitOptions& options);

// Initial radii (Sec. 4.5, meridian update): footpoints of the samples mapped to the common
// (axial, radial) plane, a least-squares spline (or line, or constant) meridian through them, and
// d_j = distance of the axis point to that meridian.
[[nodiscard]] ToolRadius initial_tool(const SurfaceIndex& surface, const Rails& rails, const FitOptions& options);

// The half-meridian in the tool's own frame (z along a->b from a, r radial): the planar
// envelope of the circles (z, d(z)); unit frame.
[[nodiscard]] std::vector<Eigen::Vector2d> meridian(const ToolRadius& tool, double length, int points = 61);
// The cutter as the fit holds it, for ToolAssembly::cutter: the union of the spheres d(s) centred on the
// axis at z = s L, s in [0, 1], between the end planes z = 0 and z = L; its radius at `points` uniform z,
// max over s of sqrt(d(s)^2 - (z - s L)^2) (to ~1e-6 of L). Along the side it is the meridian; near the
// ends, where the envelope's characteristic circles run out, the end spheres. The spheres' radii d(z)
// themselves fall short of it on a sloped tool by d (1 / sqrt(1 - d'^2) - 1) (0.03 mm on rotor 37's
// tapers: a program refused by the back-simulation after a clean collision check). The collision
// check, the fit's trim and the back-simulation of a fitted tool all judge this one shape.
[[nodiscard]] std::vector<Eigen::Vector2d> cutter_union(const ToolRadius& tool, double length, int points = 121);

// Where the radii d(s) over an axis of `length` describe no tool of revolution: a sphere radius
// d <= 0, a slope |d'(z)| >= 1 (the circles nest inside each other: no meridian touches them all), or
// a meridian whose z turns back (the envelope of the circles folds), or a needle longer than
// kMaxSlenderness times its largest diameter. Checked at 241 points; none for every real tool. A
// fit on a stretch where Φ holds few samples can drift there; a cylinder fitted to a ruled flank
// can shrink until its axis lies in it.
struct ToolDefect {
  double s = 0;           // where along the axis, 0 (tip end) .. 1
  std::string what;       // "its radius reaches 0", ...
};
// Cutting length over largest diameter beyond which tool_defect calls a tool a needle.
constexpr double kMaxSlenderness = 20;
[[nodiscard]] std::optional<ToolDefect> tool_defect(const ToolRadius& tool, double length);

// The radii projected onto the constraints (least change of the parameters D): every row
// of G D <= h below holds afterwards within 1e-12. `length` is the axis length L (unit frame).
// Bounds on r are turned into bounds on d through the steepest slope the result may have. The ball
// rows (min_ball_radius) stand at axis points that depend on the radii, and the tip's upper bound
// is scaled by the radii (the tool as ground is wider in its tip plane than d there where it widens
// from its tip): both are taken from the result and the projection repeated until they settle, so
// the rows of the result's own radii hold.
// The ball row asks for R (1 + kBallMargin) (constraint_rows).
inline constexpr double kBallMargin = 1e-3;
[[nodiscard]] ToolRadius constrained_tool(const ToolRadius& tool, double length, const ToolConstraints& c);
// The constraint rows G D <= h for the current radii (the slope bound used for the r bounds and
// the axis point of the ball row are taken from `tool`); exposed for tests.
struct ConstraintRows {
  Eigen::MatrixXd G;
  Eigen::VectorXd h;
};
[[nodiscard]] ConstraintRows constraint_rows(const ToolRadius& tool, double length, const ToolConstraints& c);
// The worst violation of the constraints by the tool's meridian (meridian(tool, length, 121); the
// tip's upper bound by the tool as ground, cutter_union's radius in its end plane) and its length:
// 0 when every constraint holds within kConstraintSlack (a meridian on its bound, up to rounding,
// holds it); names the constraint in `what` (empty when they all hold).
inline constexpr double kConstraintSlack = 1e-9;
struct ConstraintCheck {
  double violation = 0;  // unit frame (radii, length) or radians (cone angle) or unit (waist depth)
  std::string what;
};
[[nodiscard]] ConstraintCheck check_constraints(const ToolRadius& tool, double length, const ToolConstraints& c);

// A fixed tool given by its meridian (z, r) from the tip (unit frame, z increasing): d(s) is the
// radius of the largest sphere centred on the axis at z = s L inside the tool (the distance of the
// axis point to the meridian), as a general spline with `control_points` values (Sec. 4.5's
// footpoint construction applied to the tool itself). L: the meridian's z extent.
[[nodiscard]] ToolRadius tool_from_meridian(const std::vector<Eigen::Vector2d>& zr, int control_points);

// The plateau rule (FitOptions::plateau): per outer round, measures of the motion before it at that
// round's fresh footpoints (unit frame). True when none of the last `rounds` entries of `history` has
// any measure below (1 - progress) times its smallest value before them.
struct RoundMeasures {
  double objective = 0;   // F_motion, eq. (12)
  double eps = 0;         // ε, eq. (13)
  double mean_error = 0;  // mean |dist - d_j| over the samples inside Φ
};
[[nodiscard]] bool fit_plateaued(const std::vector<RoundMeasures>& history, double progress, int rounds);

enum class FitStatus {
  Converged,       // the motion and radii stopped moving, a round could not lower F_motion, or a plateau
  IterationLimit,  // max_iterations outer rounds ran
  SolverFailed,    // Ceres reported FAILURE (or a cost that is not finite); the last good motion is kept
};
[[nodiscard]] const char* to_string(FitStatus s);

struct FitResult {
  Rails rails;
  ToolRadius tool;
  ErrorStats eps_ini, eps_opt;
  int iterations = 0;
  std::vector<double> objective;  // F_motion, eq. (12), after each outer iteration
  bool converged = false;  // status == Converged
  FitStatus status = FitStatus::IterationLimit;
  std::string message;  // why the solver failed (SolverFailed), else empty
};
// Joint optimisation of the rails and the radii (eqs. 8-12) from an initial motion. With
// options.fixed_tool only the rails (the initial length is replaced by none: use the tool's
// own length for `initial`); with options.constraints the radii stay admissible (see
// ToolConstraints) and a rails longer than constraints.max_length are shortened at the b end.
[[nodiscard]] FitResult optimize_motion(const SurfaceIndex& surface, const Rails& initial, const FitOptions& options);

// The rails with their b ends moved along the axis so that |b - a| = length (the tip end a kept).
[[nodiscard]] Rails with_length(const Rails& rails, double length);

// One tool for several motions (`tool: {shared: true}`): the meridian update of Sec. 4.5 over the
// samples of every motion, d_j = least squares over all their distances, then the constraints.
// Every rails must have the same length.
[[nodiscard]] ToolRadius shared_radii(const std::vector<const SurfaceIndex*>& surfaces, const std::vector<Rails>& rails,
                                      const FitOptions& options);
// One tool fitted jointly to several patches: eq. (12) summed over the patches, every patch's rails
// and the one set of radii as unknowns (constraints as in optimize_motion, without the max_length
// shortening: `length` is the common axis length), starting from the patches' separate fits `fits`
// with the shared_radii of their rails. Returns the patches' fits, all with the same tool.
[[nodiscard]] std::vector<FitResult> fit_shared_tool(const std::vector<const SurfaceIndex*>& surfaces,
                                                     std::vector<FitResult> fits, double length, const FitOptions& options);

}  // namespace flankcam
