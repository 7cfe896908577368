// Back-simulation of an NC program from its text: every motion block (rapids, links, lead-in/out,
// tool changes, the cut) through the machine's forward kinematics as the controller interpolates it
// (joints linearly; under TCP the tip on a line and the rotary angles linearly), the tool assembly
// (cutter, shank, holder) swept against the part at positions no farther apart than `step_mm` for
// any point of the assembly. Everything in mm, in the frame the program is written in (the work
// frame: the part placed on the machine with its setup).
//
// Feed blocks are the cut: the cutter may enter the part by the gouge tolerance (the fit's
// tolerance), shank and holder must not touch. Rapids must not touch the part at all.
#pragma once
#include <Eigen/Core>
#include <array>
#include <string>
#include <vector>

#include "core/closest_point.h"
#include "core/collision.h"
#include "core/errors.h"
#include "kinematics/machine.h"
#include "postproc/apt.h"
#include "postproc/gcode.h"
#include "postproc/nc_program.h"

namespace flankcam {

struct VerifyTool {
  int number = 0;          // T number; 0: the tool for any T without its own entry
  ToolAssembly assembly;   // cutter meridian (z, r) from the tip, shank, holder
  double length_mm = 0;    // spindle nose to tip as the program is posted (head axes)
};

struct VerifyOptions {
  double gouge_tolerance_mm = 0.01;  // feed blocks: the cutter may be this deep in the part
  double link_clearance_mm = 0;      // rapids: every part of the assembly at least this far from the part
  double step_mm = 0.25;             // no point of the assembly moves more than this between checked positions
  double cutter_slab_mm = 0.25;      // axial sampling of the cutter (shank and holder: 1 mm)
  double report_clearance_mm = 25;   // clearances beyond this are reported as this (the search stops there)
  // Comparison with the CL-data (when given): every cutting position's tip within this of the CL
  // motion and its axis within the angle of the CL axis there: the post's linearisation tolerances
  // plus what writing 4 decimals and sampling between the linearisation's checks may add.
  double cl_tolerance_mm = 0.005 + 0.002;
  double cl_angle_tolerance_deg = 0.05 + 0.01;
  // The cut judged apart (CutApart, with gouge_tolerance_mm for its cut_part) when the design
  // surface is given too.
  CutApart apart;
  std::string validate() const;
};

// The CL-data a program was posted from, in the program's frame (setup applied). Its feed motion
// (tip on a line, axis on a great circle between consecutive GOTOs) is what the program's feed blocks
// must follow; the planner's lead-in and lead-out (straight along the surface normal off a CL pose,
// axis held: see lead_direction) are the only feed blocks allowed off it.
struct ClReference {
  int tool = 0;      // the program's T number it belongs to; 0: every tool
  ClProgram cl;
  std::string file;  // for messages
};

// A feed block that leaves the CL motion: its worst position.
struct ClDeviation {
  int block = 0, line = 0;
  double deviation_mm = 0;  // the simulated tip's distance from the CL motion
  double angle_deg = 0;     // the simulated axis' angle to the CL axis at the nearest point
  Eigen::Vector3d tip = Eigen::Vector3d::Zero();  // simulated tip (program frame)
};

// The planner's direction off the surface at a pose: from the part's point nearest the middle of the
// cutter to the axis, across the axis (the flank's normal at the contact line); the axis when the part
// lies on it. Lead-in and lead-out run along it.
[[nodiscard]] Eigen::Vector3d lead_direction(const SurfaceIndex& part, const ToolPose& p, double cutter_length_mm);
// The planner's lead offsets per unit of lead, in the order it tries them: `normal` (lead_direction,
// across `axis`), turned about the axis by 20, 40, 60 and 90 degrees either way, each lifted along the
// axis by none, half or all of the lead (lifts outer). The link planner takes the first clear one (and
// twice as far); `verify` recognises a lead block along any of them.
[[nodiscard]] std::vector<Eigen::Vector3d> lead_offsets(const Eigen::Vector3d& normal, const Eigen::Vector3d& axis);

// One motion block as simulated.
struct VerifiedBlock {
  int block = 0;   // index among the motion blocks, 0-based
  int line = 0;    // 1-based line in the program text (APT: the GOTO's index + 1)
  bool rapid = false;
  bool tool_change = false;  // a move of the tool-change macro (rapid, machine joints) before `line`
  int tool = 0;
  std::array<double, 3> min_clearance_mm{};  // cutter, shank, holder (Component order); negative: inside
  double minutes = 0;
};

struct VerifyHit {
  int block = 0, line = 0;
  bool rapid = false;
  bool tool_change = false;  // in the tool-change macro's moves before `line`
  Component component = Component::Tool;
  // How far inside the part (beyond nothing: raw depth); <= 0 in a rapid that keeps off the part but
  // comes inside the rapid clearance (VerifyOptions::link_clearance_mm): minus its distance from it.
  double depth_mm = 0;
  Eigen::Vector3d point = Eigen::Vector3d::Zero();  // the part point there (program frame)
  int position = -1;                                // the deepest position: index into VerifyReport::motion
  // "gouge" (the cutter in a feed block), "collision" (anything else inside the part) or "clearance"
  // (a rapid off the part but inside the rapid clearance).
  [[nodiscard]] std::string kind() const;
  // "holder collision 1.2340 mm deep", "cutter gouge 0.0300 mm deep" or "shank 0.0198 mm from the
  // part, inside the rapid clearance of 0.5 mm" (`clearance_mm`: VerifyReport::link_clearance_mm).
  [[nodiscard]] std::string what(double clearance_mm) const;
};

struct AxisViolation {
  int block = 0, line = 0;
  std::string axis;      // X, Y, Z or the rotary's name
  bool speed = false;    // false: a travel limit
  double value = 0, limit = 0;  // mm or deg (limits), mm/min or deg/min (speeds)
};

struct Deviation {  // the machined design surface Φ (when one is given)
  std::vector<double> deviation_mm;  // per vertex: > 0 material left, < 0 overcut, NaN not reached
  int reached = 0, within = 0;       // vertices reached, and of those within the tolerance
  double tolerance_mm = 0;
  [[nodiscard]] double coverage() const { return reached > 0 ? double(within) / reached : 0; }
  // The same share of all of Φ's vertices.
  [[nodiscard]] double share_of_all() const { return deviation_mm.empty() ? 0 : double(within) / double(deviation_mm.size()); }
};

// One simulated position, kept for the 3D view's playback (postproc/verify_view.h).
struct VerifiedPosition {
  ToolPose pose;      // program frame
  Joints programmed;  // X Y Z (mm) and the rotaries (deg) as the program states them, interpolated; CL-data: zero
  int block = 0;      // index into VerifyReport::blocks
};

struct VerifyReport {
  double link_clearance_mm = 0;  // what the rapids were judged against (VerifyOptions)
  std::vector<VerifiedBlock> blocks;
  std::vector<VerifyHit> hits;            // worst per block and component
  std::vector<AxisViolation> violations;  // travel limits and speeds
  bool cl_compared = false;               // CL-data was given: feed blocks compared with it
  int cl_blocks = 0;                      // feed blocks compared (leads included)
  double cl_max_deviation_mm = 0, cl_max_angle_deg = 0;  // largest over the compared positions
  std::vector<ClDeviation> cl_deviations; // feed blocks off the CL motion
  int tool_changes = 0;                   // tool changes simulated (moves to the change position and back)
  double cycle_minutes = 0, cut_minutes = 0;
  long positions = 0;                     // simulated positions
  std::vector<VerifiedPosition> motion;   // each of them, in order
  Deviation design;                       // empty unless a design surface was given
  [[nodiscard]] bool clean() const { return hits.empty() && cl_deviations.empty(); }
  // "FILE:LINE: holder collision 1.234 mm deep at (x, y, z) in motion block B (rapid); ..." for the
  // first line that hits the part, comes inside the rapid clearance or leaves the CL-data (its
  // deepest hit), or "".
  [[nodiscard]] std::string first_problem(const std::string& file) const;
};

// The program's dialect from its file name: .nc iso, .ngc linuxcnc, .h heidenhain, .mpf sinumerik;
// false for .apt / .cls (CL-data). Throws InputError for others.
[[nodiscard]] bool is_cl_data_file(const std::string& path);
[[nodiscard]] Dialect dialect_of_file(const std::string& path);

// `tools`: one per T number the program calls (or number 0 for all). `design` may be null. `cl`:
// the CL-data per tool (empty: the program is checked geometrically only).
// A tool change between motion blocks is simulated as the machine's change macro runs it
// (Machine::tool_change: Z to its height, then X Y, then the rotaries, each given value only; the
// default is Z at its upper limit) with the old tool, and the next block starts there with the new one.
[[nodiscard]] VerifyReport verify_program(const std::vector<NcPoint>& program, const Machine& m, bool linuxcnc_trt,
                                          const SurfaceIndex& part, const std::vector<VerifyTool>& tools,
                                          const VerifyOptions& o, const SurfaceIndex* design = nullptr,
                                          const std::vector<ClReference>& cl = {});
// Reads the text (parse_nc) and simulates it.
[[nodiscard]] VerifyReport verify_text(const std::string& text, Dialect d, const std::string& file, const Machine& m,
                                       const SurfaceIndex& part, const std::vector<VerifyTool>& tools,
                                       const VerifyOptions& o, const SurfaceIndex* design = nullptr,
                                       const std::vector<ClReference>& cl = {});
// APT CL-data: tip on a line and the axis turned on a great circle per GOTO, no machine.
[[nodiscard]] VerifyReport verify_cl(const ClProgram& cl, const SurfaceIndex& part, const VerifyTool& tool,
                                     const VerifyOptions& o, const SurfaceIndex* design = nullptr);

// The cutter of a meridian (z, r) from the tip, as an assembly with the given shank and holder.
[[nodiscard]] ToolAssembly assembly_from_meridian(const std::vector<Eigen::Vector2d>& meridian_mm, const ToolAssembly& holder);

}  // namespace flankcam
