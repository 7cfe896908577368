// One patch of a job, start to finish in the unit frame: initialisation (surface-driven from
// ordered user lines, or line-driven from one line: exploration + propagation), the joint
// optimisation, and the machined surface with its coverage.
#pragma once
#include <functional>
#include <optional>
#include <string>
#include <utility>
#include <vector>

#include "core/fitting.h"
#include "core/machined_surface.h"
#include "core/movability.h"

namespace flankcam {

enum class PatchInit { Lines, Line };
[[nodiscard]] const char* to_string(PatchInit i);

struct PatchSpec {
  std::string name;
  PatchInit init = PatchInit::Lines;
  std::vector<AxisLine> lines;  // unit frame. Lines: >= 2 ordered axis positions; Line: exactly one
  int rail = 0;                 // Lines: the rail (0: a, tool tip; 1: b) whose path is kept
  double length = 0;            // Lines: rigid axis length (unit frame); <= 0: mean length of the lines
};

struct PatchOptions {
  FitOptions fit;
  ExplorationOptions exploration;
  PropagationOptions propagation;
  MachinedSurfaceOptions machined;
  double tolerance = 1e-4;  // for coverage (unit frame)
  // Trim the optimised motion in t to the longest stretch where the tool does not gouge Φ (Ω below Φ
  // by more than `tolerance`): an overcut cannot be repaired, an undercut can by a neighbour.
  // Detection always trims; off by default here so hand-placed jobs keep their motion.
  bool trim_gouges = false;
  // With trim_gouges and no check surface: also the solid cutter against Φ as the collision check
  // judges it (with a check surface always), with the same margin. Detection's continued motions
  // pass Φ's boundary, where a flat end's rim can dip into Φ though Ω's side keeps off it.
  bool solid_cutter_on_phi = false;
  // With a check surface (fit.check) the motion is always trimmed to the longest stretch where the
  // tool keeps out of the part (cutter within fit.check.tolerance, body outside the clearance).
  // With a check surface: the holder end is chosen by the part (holder_up, fit.check.up the
  // tie-break), and with_check returns the fit turned so that its tip is the a end (rail 0).
  bool orient_by_part = false;
  // With a check surface: when neither the trimmed motion nor the shortened tool keeps clear along the
  // whole motion, the motion is refitted with the part's penalties too (with_check). Detection turns
  // this off for its many candidates (a refit costs as much as the fit itself).
  bool refit_with_check = true;
  // Stage messages ("exploring the line", ...) for progress output; may be empty.
  std::function<void(const std::string&)> on_stage;
};

struct PatchFit {
  Rails initial;
  FitResult fit;
  MachinedSurface machined;
  double coverage = 0;                      // share of Φ's area within the tolerance
  double seconds_init = 0, seconds_opt = 0;  // wall clock
  double t_from = 0, t_to = 1;              // the part of the optimised motion kept (trim_gouges)
  bool gouges = false;                      // Ω still lies below Φ beyond the tolerance somewhere
  // With a check surface (PatchOptions::fit.check): why the motion was trimmed (the worst intrusion
  // of the optimised motion, before trimming; unset when the part forced no trim), the worst intrusion left (<= 0: clear; unit frame,
  // beyond the tolerance for the cutter, inside the clearance for shank and holder), and whether
  // no stretch of the motion could be kept clear (the patch is then left untrimmed and refused).
  struct CheckTrim {
    bool body = false;                 // shank or holder (else the cutter)
    double intrusion = 0;              // unit frame
    Eigen::Vector3d at = Eigen::Vector3d::Zero();  // the part point, unit frame
  };
  std::optional<CheckTrim> check_trim;
  double check_intrusion = -INFINITY;
  bool check_refused = false;
  // What was done to the fitted cutter's length for the part (unit frame), at most one of the first
  // two non-zero: the tip ground shorter to keep it out of the part, or made longer to reach the
  // floor (lengthened_at_tip; ground back where it would meet the part, the net of the two); the
  // holder end made longer to keep the shank clear.
  double tip_shortened = 0;
  double tip_lengthened = 0;
  double holder_lengthened = 0;
  // The cutter made longer at an end to reach more of Φ (lengthened_to_reach, detection).
  double reach_lengthened = 0;
  // A tool and motion of their own as they stand (refitted, shared): nothing of them was ground off
  // or lengthened to keep out of the part.
  void clear_part_adjustments() { tip_shortened = tip_lengthened = holder_lengthened = reach_lengthened = 0; }
  std::optional<ExploredLine> explored;     // line-driven only
  std::optional<LineTrajectory> trajectory;  // line-driven only
};

// A fit that can be machined as it stands: its radii describe a tool (tool_defect), it does not gouge Φ beyond the
// tolerance, and (with a check surface) it keeps out of the part along its whole motion.
[[nodiscard]] bool machinable(const PatchFit& f);

// Throws InputError naming the patch when its lines are unusable (too few, zero length,
// a line that cannot be propagated, a motion that is not over the surface).
[[nodiscard]] PatchFit fit_patch(const SurfaceIndex& surface, const PatchSpec& spec, const PatchOptions& options);

// The machined surface of `fit.fit`, then (with trim_gouges) the rails trimmed in t to the longest
// run of envelope rows that do not gouge Φ beyond the tolerance, and the coverage. A trimmed motion's
// fit.eps_opt is measured again over what is kept (eq. 13 on the trimmed rails). Used by fit_patch.
[[nodiscard]] PatchFit machine_and_trim(const SurfaceIndex& surface, PatchFit fit, const PatchOptions& options);

// The check surface (options.fit.check) applied to a fit made without it: when its tool enters the
// part, two ways out are compared, the motion trimmed to its clear stretch and the motion refitted
// with the part's penalties (from the fitted rails) and then trimmed; the clear one covering more
// of Φ wins (neither clear: the one intruding least, `check_refused`). Without a check surface, or
// when the fit is clear already, it is only machined and measured. fit_patch fits this way, and
// `patches: auto` applies it to every detected patch.
[[nodiscard]] PatchFit with_check(const SurfaceIndex& surface, PatchFit plain, const PatchOptions& options);

// The cutter restricted to s in [lo, hi] of its axis (the rest ground off): rails through the new
// ends, the radii re-parametrised over the shorter axis (exact for cylinders and cones, a
// least-squares cubic spline with as many values for general tools: `radius_error` is its worst
// deviation, unit frame). What stays sweeps the same surface as before.
struct ToolCut {
  Rails rails;
  ToolRadius tool;
  double radius_error = 0;
};
[[nodiscard]] ToolCut cut_tool(const Rails& rails, const ToolRadius& tool, double lo, double hi);

// The cutter made longer at its tip by `e` (unit frame), the tip at the rails' a end (as with_check
// and detection's floor pass turn it; by CheckSurface::up): the axis continued beyond a, the
// meridian along its slope there (exact for cylinders and cones), so that a tip stopping above a
// floor reaches down to it; with_check then grinds off what meets the part. Untrimmed and
// unmachined; none for a fixed tool, a tip at b, or when the longer tool is no tool (tool_defect: a
// tip radius not above 0, among others) or breaks its limits.
[[nodiscard]] std::optional<PatchFit> lengthened_at_tip(const PatchFit& base, const PatchOptions& o, double e);

// The cutter made longer by `e` (unit frame) at its b end (`at_b`) or its a end: the axis continued
// beyond that end, the meridian holding its radius beyond b and going on along its slope beyond a (as
// cut_tool), so that a cutter whose end stops inside Φ (a flank taller than the lines its patch
// started from) reaches on over it. With a part the b end is the holder end (with_check turns the tip
// to a): the shank and holder move out with it. The tool's other adjustments are kept and
// `reach_lengthened` adds `e`. Untrimmed and unmachined; none for a fixed tool or when the longer
// cutter is no tool or breaks its limits (max_length).
[[nodiscard]] std::optional<PatchFit> lengthened_to_reach(const PatchFit& base, const PatchOptions& o, double e, bool at_b);

// The rails restricted to [t0, t1], reparametrised to [0, 1] (same control point count).
[[nodiscard]] Rails trimmed(const Rails& rails, double t0, double t1);

// The rails over [-before, 1 + after], reparametrised to [0, 1] (same control point count): each rail
// continued straight past its ends, as the start of a motion fitted further (detection).
[[nodiscard]] Rails continued(const Rails& rails, double before, double after);

// `original` over [-before, 1 + after], reparametrised to [0, 1] (same control point count), with
// `further` (a motion over that same span in its own [0, 1], as a fit from `continued` moved it) past
// each continued end: the stretch [0, 1] stays as it was, blended into `further` over `blend` of t
// inside each end continued (before / after > 0). A motion continued without moving what it machined.
[[nodiscard]] Rails anchored(const Rails& original, const Rails& further, double before, double after, double blend);

// The longest run of set entries of `ok` (the first one on a tie) as (first index, count); count 0
// when none is set.
[[nodiscard]] std::pair<size_t, size_t> longest_set_run(const std::vector<char>& ok);

// The stretch [t0, t1] of a motion that is itself the stretch [from, to] of an earlier one, in the
// earlier one's t: an end left where it was (t0 = 0, t1 = 1) keeps its value exactly.
[[nodiscard]] std::pair<double, double> kept_within(double from, double to, double t0, double t1);

// The same swept tool with its ends exchanged: rails a <-> b and d(s) -> d(1 - s) (the clamped
// uniform knots are symmetric, so reversing the radius coefficients reverses d for every shape).
// The envelope, its errors and coverage are unchanged; only which end is the tip changes.
[[nodiscard]] PatchFit reversed(PatchFit fit);

// The longest run of Ω's rows (t) without a point below Φ by more than `tolerance` (an Ω vertex, or
// a Φ vertex whose closest Ω point lies in the row), as [t0, t1] of the machined motion; {0, 0} when
// no two consecutive rows are clean.
[[nodiscard]] std::pair<double, double> ungouged_range(const MachinedSurface& machined, double tolerance);

}  // namespace flankcam
