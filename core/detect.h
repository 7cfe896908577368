// Automatic detection of flank-milling patches (the paper's open problem, Sec. 6): candidate axis
// lines over the whole surface ranked by tangential movability F_l (eq. 5), explored (Sec. 4.2),
// propagated (Sec. 4.3) and optimised (Sec. 4.5), chosen greedily by the area their machined
// surface brings within tolerance that no earlier patch covers. Unit-diagonal frame throughout.
#pragma once
#include <Eigen/Core>
#include <functional>
#include <optional>
#include <string>
#include <vector>

#include "core/patch.h"

namespace flankcam {

struct CoverOptions {
  double coverage = 0.95;  // share of Φ's area to bring within `patch.tolerance`
  int max_patches = 8;
  // Seeding (Sec. 4.1): seed points on a grid of this many cells across the surface's area, at each
  // `directions` line directions in the tangent plane, offset along ±normal by each radius.
  int seed_points = 48;
  int directions = 5;
  // When the best fit from these seeds brings less than `orient_below` of the uncovered area: per
  // seed point and side, the most movable `oriented_lines` turned to their least F_l (orient_line),
  // refined, explored and fitted as above (general tools: their axis leaves the tangent plane).
  double orient_below = 0.4;
  int oriented_lines = 3;
  int oriented_refined = 8;
  int oriented_explored = 3;  // refined and unrefined each
  int oriented_fitted = 3;
  std::vector<double> radii = {0.025, 0.05, 0.09};  // candidate tool radii (unit frame)
  int refined_seeds = 8;   // best-ranked seeds (half on each side of Φ) moved to the nearest axis per patch
  int sweep_steps = 20;    // a seed's short sweep each way (refinement score) ...
  double sweep_step = 0.002;  // ... in steps of this (unit frame)
  int refine_evaluations = 48;  // pattern-search sweeps per seed, after the 9 of the offset scan
  int explored_seeds = 3;  // best refined seeds propagated per patch
  int explored_unrefined = 3;  // and the most movable unrefined seeds, explored (Sec. 4.2) and propagated
  int fitted_seeds = 3;    // of those, this many are fitted (in turn, among those sweeping the most uncovered area)
  double band = 0.03;      // overlap into covered area a new patch's trajectory keeps (unit frame, arc length)
  int lines = 8;           // axis lines written per patch (init: lines) to reproduce it
  // Candidates fitted in a round but not chosen are kept (at most this many, by their gain on the
  // uncovered area): the next round starts from the best of them (a flank of its own, seeded and
  // fitted while another won, is not searched for again).
  int spares = 8;
  // At max_patches short of the target: up to this many exchange rounds. The patch that brings the
  // least no other patch covers is set aside (a spare) and one more round searched from what is then
  // uncovered; the round's best patch takes the place when it brings more, else the set-aside patch
  // returns and the next weakest is tried. Not with a shared tool (the held tool is chosen by the first two patches).
  int exchanges = 3;
  // Uncovered regions (edge-connected, at least `region_min` of Φ's area, the largest `regions` of
  // them) that a round's best patch brings less than `region_below` of: searched as a surface of their
  // own (the region and `band` around it; lines explored and propagated over it alone, one patch),
  // and that patch, judged on Φ as it is and refitted there, is a candidate of the round. Lines seeded
  // over the whole surface reach across such a block (a twisted blade's tip at the trailing edge) into
  // covered surface and fit neither. Not in the first round (one region: the whole surface).
  // Each region is searched twice: with lines around its least-curvature directions, and with lines
  // across Φ's width (`across`; Φ's middle extent axis, that of the whole surface, `width`). Where a
  // blade twists (the HECC impeller's inlet at its shroud) the least-curvature direction runs
  // diagonally over the flank and a tool along it leaves the corner; the tool across the flank (hub
  // to shroud, as a swarf cut is laid) machined 57.7% of that corner where the first search's best
  // machined 31.5%. Both patches are candidates of the round.
  int regions = 2;
  double region_min = 0.01;
  double region_below = 0.5;
  bool across = false;
  std::optional<Eigen::Vector3d> width;  // unset: the surface's own middle extent axis
  // Each round's best patch continued past the ends of its motion where its last row of Ω still lies
  // over Φ (detect.cpp, `continued`), and each patch of the chosen cover again in finish_cover (with a
  // part). Off for the one-patch search of an uncovered region: its patch is continued on the whole
  // surface, as the round's best, where its end is judged.
  bool continue_ends = true;
  // With a part, once the cover is chosen: each patch with its cutter made longer at its holder end
  // where that end stops inside Φ (finish_cover; custom tools, not shared), kept when the union's
  // coverage grows. Off for the one-patch search of an uncovered region.
  bool reach_further = true;
  // The last pass sweeps the cover again while a patch was replaced since another was last judged
  // (what that one is judged against has changed), at most this many sweeps.
  int finish_sweeps = 3;
  // The floor pass, with a part under the tools' tips (patch.fit.check.floor_reach > 0, a hub under a
  // blade's flank): candidates are fitted without the floor's pull on the tip; each round's best is
  // fitted again from its motion with it, both judged with the tool's `end` swept (as the program cuts:
  // the end machines the flank's bottom rows where the tip stands on the floor), and the one bringing
  // more uncovered area is the patch. The pull on every candidate had them meet the part and be
  // trimmed (HECC impeller: the first patch 16.7% of the blade against 30.7%). Off for the one-patch
  // search of an uncovered region (its patch is a candidate of the round, finished as its best).
  std::optional<ToolEnd> end;
  bool floor_pass = true;
  // > 0 (unit frame, a radius): the floor pass also fits the round's best with its tip at most this
  // wide (ToolConstraints::max_tip_radius; its axis's tip end tilted to within it first), pulled
  // onto the floor, judged the same way; the three compete by the uncovered area they bring. Where a
  // flank leans over its floor (the HECC impeller's pressure side meets its hub at 68-86°) a flat
  // end square to an axis along the flank dips with the rim away from it and leaves its rim at the
  // flank 2 r sin(90° − angle) above the floor (up to 3.7 mm for a Ø10 tip); a narrow tip reaches
  // lower. Narrow tips on every candidate cost the rest of the flank (the impeller with tips of at
  // most Ø3 mm: 46.4% at 5 patches, against 82.3% with Ø10). Measured: the narrow variant (Ø2 mm)
  // won no round of the impeller's cover: its tip stands where the wide tool's did, on the hub only
  // where the motion dips deepest.
  double floor_tip = 0;
  PatchOptions patch;      // fit, exploration, propagation, machined surface, tolerance
  // Tool policy (issue 14). Default: one custom tool per patch, fitted with it.
  // patch.fit.fixed_tool set (a catalogue tool): every candidate's motion is fitted to that tool,
  // whose axis is `tool_length` long (motion only, the paper's fit without d as unknowns).
  // shared_tool: one custom tool for every patch (one tool to grind, one tool change): the first two
  // patches are fitted as usual, each one's tool is held for the other (its motion refitted), and
  // the tool of the pair that covers more is then held for every later candidate (motion only), so
  // every patch is one that tool can cut; at the end all patches are refitted jointly
  // (fit_shared_tool from their motions), kept when the union's coverage does not drop.
  bool shared_tool = false;
  double tool_length = 0;  // unit frame; with patch.fit.fixed_tool
  // With a held tool (fixed or shared) its ends are not interchangeable: candidates start with the
  // b end (holder) along `up` (the machine's spindle side), and the patch whose tool is shared is turned so.
  // Unset: the start whose initial error is lower. A check surface's own up takes precedence.
  std::optional<Eigen::Vector3d> up;
  std::string validate() const;  // empty when valid, else names the field
};

enum class CoverStop { Coverage, MaxPatches, NoProgress };
[[nodiscard]] const char* to_string(CoverStop s);

struct CoverProgress {
  int seed = 0, seeds = 0;   // seed k of N within the current patch
  int patches = 0;           // accepted so far
  double coverage = 0;       // whole-surface coverage so far
  std::string stage;         // "seeding", "exploring", "fitting", ...
};

struct DetectedPatch {
  PatchSpec spec;            // name auto-k, init: lines, rail 0: re-running it reproduces the patch
  PatchFit fit;              // the fit trimmed in t where it gouged Φ (fit.t_from, fit.t_to), its machined surface
  double new_area = 0;       // share of Φ's area this patch brought within tolerance first
};

struct Detection {
  std::vector<DetectedPatch> patches;   // machining order: along Φ's longest extent
  std::vector<int> owner;               // per Φ vertex: index into patches of the patch that machines it, -1: none
  std::vector<double> deviation;        // per Φ vertex: the union (most material removed, min over patches); NaN: uncut
  double coverage = 0;                  // share of Φ's area with |deviation| <= tolerance
  double overcut = 0;                   // worst overcut of the union (>= 0, unit frame)
  CoverStop stop = CoverStop::NoProgress;
  int seeds_tried = 0;                  // trajectories fitted
  int exchanged = 0;                    // patches replaced by a better one in exchange rounds
  int regions_searched = 0;             // uncovered regions searched as surfaces of their own (CoverOptions::regions)
  int from_regions = 0;                 // patches (of the final set) that such a search found
  // shared_tool: every patch has the same tool (same radii, tip at the a end). The union's coverage
  // with the held tool (of the first two patches' own tools, the one that covers more of both when
  // held for the other), and whether the joint refit replaced it (coverage not lower).
  bool shared_tool = false;
  double coverage_held_tool = 0;
  bool joint_refit = false;
};

// `patches: auto` of a job: one call. With a check surface (patch.fit.check), a candidate trimmed
// where its tool enters the part has the sweep before and after its kept stretch fitted as candidates
// of their own. Throws InputError for invalid options; a surface on which no
// line is movable gives an empty Detection with stop NoProgress.
[[nodiscard]] Detection detect_patches(const SurfaceIndex& surface, const CoverOptions& options,
                                       const std::function<void(const CoverProgress&)>& on_progress = {});

// The last pass of detect_patches, with a part, custom tools not shared: each patch of `cover` in
// turn, against what the other patches cover, is offered
//  - the floor pass again (CoverOptions::floor_pass, with `end` and the part's floor pull): fitted
//    again with its tip pulled onto the floor, and with CoverOptions::floor_tip narrow, judged with
//    the tool's end swept; a round chose its best by the area then uncovered, where a narrow tip's
//    lower reach (the HECC impeller's hub rows) cost flank that later patches machine anyway. Each
//    of these variants (the patch as it is, pulled, narrow) also with its cutter made longer at its
//    tip (lengthened_at_tip), not only the one that brings most;
//  - then the winner with its cutter made longer at its holder end (CoverOptions::reach_further)
//    where that end's column of Ω still lies over Φ (lengthened_to_reach: by 10%, 25%, 50% of its
//    length and to the tool's max_length), judged as a candidate;
//  - then the winner with its motion continued past its ends (CoverOptions::continue_ends: by steps
//    of 5% of it, at most 40% an end, its tool held, while it brings more of what the others leave),
//    judged against the part as the floor pass judges.
// The variant under which the union's coverage of Φ grows most replaces the patch in `cover`. A
// patch is judged again once another has been replaced since (CoverOptions::finish_sweeps); its floor
// variants, which depend on the patch alone, are kept until it is replaced, so judging it again only
// chooses among them anew (and makes the holder-end variants again).
// `on_patch(k, coverage)` before patch k is judged, with the union's coverage so far. Returns the
// indices of the patches replaced, in the order replaced (a patch replaced in two sweeps twice).
std::vector<size_t> finish_cover(const SurfaceIndex& surface, std::vector<PatchFit>& cover, const CoverOptions& o,
                                 const std::function<void(size_t, double)>& on_patch = {});

// The union of several machined surfaces over Φ: owner and deviation per vertex (see Detection).
struct UnionDeviation {
  std::vector<int> owner;
  std::vector<double> deviation;
};
[[nodiscard]] UnionDeviation union_deviation(const std::vector<const MachinedSurface*>& machined, size_t vertices);

// The uncovered parts of a surface: edge-connected components of vertices not `covered` (vertices
// sorted, area the sum of `area` over them), by decreasing area (ties: the lowest vertex first).
// `ring`: one-ring neighbours.
struct Region {
  std::vector<int> vertices;
  double area = 0;
};
[[nodiscard]] std::vector<Region> uncovered_regions(const std::vector<std::vector<int>>& ring, const std::vector<char>& covered,
                                                    const std::vector<double>& area);

// A region of a mesh with what lies within `band` of it along edges: the faces whose corners all lie
// there, as a surface of its own (same coordinates), and per vertex its index in the mesh.
struct SubSurface {
  TriMesh mesh;
  std::vector<int> whole;
};
[[nodiscard]] SubSurface sub_surface(const TriMesh& m, const std::vector<std::vector<int>>& ring,
                                     const std::vector<int>& region, double band);

// Lines through the rails at `count` uniform t (unit frame), an `init: lines` description of the motion.
[[nodiscard]] std::vector<AxisLine> lines_of(const Rails& rails, int count);

}  // namespace flankcam
