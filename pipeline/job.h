// The job file (YAML): the design surface, the tool shape, the fitting options and the patches
// with their initialisation lines, all in part coordinates and millimetres. Every error names the
// file, the line and the key.
#pragma once
#include <Eigen/Core>
#include <array>
#include <filesystem>
#include <optional>
#include <string>
#include <vector>

#include "core/fitting.h"
#include "core/patch.h"
#include "core/tool_end.h"
#include "pipeline/tool_catalogue.h"
#include "postproc/nc_program.h"

namespace flankcam::pipeline {

struct PatchJob {
  std::string name;
  PatchInit init = PatchInit::Lines;
  std::vector<std::array<double, 6>> lines_mm;  // [ax, ay, az, bx, by, bz]; a is the tool-tip end
  int rail = 0;
  double length_mm = 0;  // <= 0: mean length of the lines
};

// Shank and holder above the cutter (mm); absent: only the cutter is checked (gouge).
struct HolderJob {
  double shank_length = 0, shank_diameter = 0;
  double length = 0, diameter = 0, diameter_far = 0, cylinder_length = 0;
};

// `flankcam run`: what to write for the machine (all lengths mm).
struct PostJob {
  std::vector<std::string> dialects;   // empty: the machine's own dialect
  bool apt = true, cl = true, tool = true;  // APT CL-data, CL CSV, tool DXF/CSV/STL
  bool line_numbers = false;
  double tolerance_mm = 0.005;         // linearisation: tip off the intended motion
  double angle_tolerance_deg = 0.05;   // linearisation: axis off the intended motion
  double tool_length_mm = 0;           // spindle nose to tip; 0: holder + shank + cutter lengths
  double safe_height_mm = 10;          // safe Z above the highest programmed point
  // Setup: how the part sits on the machine. Programs are in the work frame x_work = R x_part + t,
  // R = Rz(c) Ry(b) Rx(a) for setup.rotate [a, b, c] degrees; t = setup.translate (mm).
  std::array<double, 3> setup_rotate_deg{0, 0, 0}, setup_translate_mm{0, 0, 0};
  // `setup: auto` (or `rotate: auto`): `run` picks the rotation (pipeline/run.h choose_setup) that keeps
  // every patch's motion away from the machine's singular orientations; setup_rotate_deg is then set.
  bool setup_auto = false;
};

// `patches: auto`: the patches are detected (core/detect.h), optional `cover: {coverage, max_patches, exchanges, regions}`.
struct CoverJob {
  double coverage = 0.95;  // share of the surface's area to bring within the tolerance, (0, 1]
  int max_patches = 8;     // 1 .. 32
  int exchanges = 3;       // 0 .. 16: rounds at max_patches that try to replace the weakest patch
  int regions = 2;         // 0 .. 8: uncovered regions per round searched as surfaces of their own (CoverOptions::regions)
  double floor_tip_diameter_mm = 0;  // > 0: the floor pass also fits each round's best with a tip this narrow (CoverOptions::floor_tip)
};

// `tool:` beyond shape and control points (mm, deg): limits on a custom tool, enforced in the fit;
// or a catalogue tool (only the motion is fitted); or one tool shared by every patch.
struct ToolJob {
  double min_diameter_mm = 0, max_diameter_mm = INFINITY;  // of the meridian
  double max_length_mm = INFINITY;                         // cutting length
  double min_tip_diameter_mm = 0;                          // at the tip end
  double max_tip_diameter_mm = INFINITY;                   // at the tip end
  double max_cone_angle_deg = 90;                          // steepest half angle of the meridian
  bool convex = false;                                     // no waist
  std::optional<CatalogueTool> catalogue;                  // tool: {catalogue: NAME}
  bool shared = false;                                     // one tool for all patches
  ToolEnd end;                                             // tool.end: flat (default), ball, {corner: R mm}
};


// The setup's rotation R (work = R part + t).
[[nodiscard]] Eigen::Matrix3d setup_rotation(const PostJob& post);

struct Job {
  std::filesystem::path file;     // the job file itself
  std::filesystem::path surface;  // resolved against the job file's folder
  std::vector<int> surface_faces;               // STEP/IGES: the flank's faces (1-based, `flankcam faces`); empty: all
  std::optional<double> surface_deflection_mm;  // STEP/IGES chordal deflection; unset: tolerance / 20
  std::filesystem::path part;     // the whole part for collision checks (default: the surface)
  std::optional<double> part_deflection_mm;     // STEP/IGES; unset: clearance / 10
  bool part_given = false;                      // `part:` present (it may name the surface's own model)
  HolderJob holder;
  double clearance_mm = 1.0;      // shank and holder to part
  // With `part:`: how deep the cutter may enter the part (besides the design surface, which is
  // judged with `tolerance`); the fit keeps the tool out of it. Unset: tolerance.
  std::optional<double> check_tolerance_mm;
  double feed_mm_min = 1000, spindle_rpm = 10000;  // for the CL-data
  double lead_in_mm = 5, retract_mm = 50;          // approach and retract along the tool axis
  double tolerance_mm = 0.01;
  std::optional<double> robust_mm;  // Cauchy scale of the fit; unset: FitOptions' relative default
  FitOptions fit;                   // sampling, weights, shape, iterations (unit-free parts)
  ToolJob tool;                     // constraints, catalogue, shared (mm; turned into fit options per surface)
  double allowance_mm = 0;          // stock left on the design surface: the fit's target is Φ offset by it
  std::vector<double> passes_mm;    // passes: [{allowance: A}, ...], in order; empty: one pass at allowance_mm
  double overtravel_mm = 0;         // the motion continued beyond the surface at both ends
  int depth_cuts = 1;               // `run`: the flank's height in this many axial levels, the deepest last
  std::vector<PatchJob> patches;   // empty with `patches: auto`
  std::optional<CoverJob> cover;   // set: `patches: auto`
  std::string machine;  // `run`: a machine file (relative to the job file) or a name in machines/
  PostJob post;
};

// How the cut is judged with a separate part, in the fit's trim, the collision check and the
// back-simulation alike: the part without Φ's coarser twin by `part_mm` (check_tolerance), Φ itself by
// `design_mm` (the fitted tolerance), and a cutter hit on that part within `design_within_mm` of Φ
// (the twin's sag plus the tolerance: where the part's coarse faces meet the twin's hole) left to Φ.
struct CutJudgement {
  double part_mm = 0, design_mm = 0, design_within_mm = 0;
  // As the post's and the back-simulation's options take it, with that part (not owned).
  [[nodiscard]] CutApart apart(const SurfaceIndex* cut_part) const { return {cut_part, design_mm, design_within_mm}; }
};
[[nodiscard]] CutJudgement cut_judgement(const Job& job, double twin_sag_mm);

// Throws InputError "FILE:LINE: KEY: what is wrong" for unknown keys, wrong types, bad values,
// missing files.
[[nodiscard]] Job read_job(const std::filesystem::path& file);

}  // namespace flankcam::pipeline
