// One model of an NC program, shared by every G-code dialect: blocks of motion (programmed joint
// values or tip + angles, with feed), tool change, spindle, coolant and comments. `post` builds it
// from APT CL-data through a machine's kinematics; the emitters (postproc/gcode.h) only format it.
#pragma once
#include <array>
#include <cmath>
#include <string>
#include <variant>
#include <vector>

#include "core/closest_point.h"
#include "core/collision.h"
#include "kinematics/path.h"
#include "postproc/apt.h"

namespace flankcam {

enum class Dialect { Iso, LinuxCnc, Heidenhain, Sinumerik };
// The one table of dialects: machine files (controller.dialect), `post --dialect` and job files
// (post.dialects) all accept exactly these names and aliases.
struct DialectInfo {
  Dialect dialect = Dialect::Iso;
  std::string name;                  // canonical: iso, linuxcnc, heidenhain, sinumerik
  std::vector<std::string> aliases;  // also accepted (fanuc for iso)
  std::string extension;             // of its programs: .nc, .ngc, .h, .mpf
  std::string help;                  // what it is, one line
};
[[nodiscard]] const std::vector<DialectInfo>& dialect_table();
[[nodiscard]] const DialectInfo& dialect_info(Dialect d);
// "iso (or fanuc), linuxcnc, heidenhain, sinumerik": for help texts and messages.
[[nodiscard]] std::string dialect_names();
[[nodiscard]] std::string to_string(Dialect d);
// A name or alias of the table; throws InputError "dialect: 'X' is not one of ..." otherwise.
[[nodiscard]] Dialect parse_dialect(const std::string& name);
[[nodiscard]] std::string file_extension(Dialect d);  // ".nc", ".ngc", ".h", ".mpf"
// The machine's controller.dialect checked against the table (kinematics keeps it as text);
// throws MachineError "FILE:LINE: controller.dialect: ..." naming the machine file.
[[nodiscard]] Dialect machine_dialect(const Machine& m);

struct NcComment {
  std::string text;
};
struct NcToolChange {
  int number = 1;
  std::string name;
  double diameter_mm = 0;  // the cutter's largest
  double length_mm = 0;    // the length the program is posted with (nose to tip on head machines), else the cutter's
};
struct NcSpindle {
  double rpm = 0;  // 0: stop
  bool clockwise = true;
};
struct NcCoolant {
  bool on = true;
};
// Programmed axes of a move, in the order X Y Z, first rotary, second rotary.
enum NcAxis : unsigned { AxisX = 1, AxisY = 2, AxisZ = 4, AxisR1 = 8, AxisR2 = 16, AxesLinear = 7, AxesRotary = 24, AxesAll = 31 };
struct NcMove {
  bool rapid = false;
  unsigned axes = AxesAll;  // the words this block writes (rapids of the safe approach move some)
  Joints at;                // programmed values: machine joints, or tip + angles under TCP
  ToolPose pose;            // the intended pose at the end of the block (part frame)
  double feed_mm_min = 0;   // G94 F: tip feed under TCP, else the feed of the linear axes' path
  double inverse_time = 0;  // G93 F: 1 / block minutes
  int cl_move = -1;         // index of the CL move it ends at; -1: inserted by linearisation or the approach
};
using NcBlock = std::variant<NcComment, NcToolChange, NcSpindle, NcCoolant, NcMove>;

struct NcProgram {
  std::string name;                  // program name (patch)
  int number = 1;                    // program number (Fanuc O-number)
  std::vector<std::string> header;   // comments after the program start
  std::string machine;               // machine name
  std::array<std::string, 2> rotary_names{"A", "C"};
  bool tcp = false;                  // programmed values are tip + angles (G43.4, TCPM, TRAORI, LinuxCNC trt)
  bool inverse_time = true;          // G93 for the feed moves
  double safe_z = 0;                 // programmed Z of the safe height: rotaries turn only up there
  std::vector<NcBlock> blocks;
};

// The cut judged apart (a separate part given, and the design surface Φ): feed blocks are swept
// against `cut_part`, the part without its coarser twin of Φ (core/check_surface.h), with the gouge
// tolerance (the check tolerance), and against Φ itself with design_gouge_tolerance_mm (the fit's
// tolerance), not against the whole part, whose twin would show the fitted cut as a gouge; a cutter
// hit on `cut_part` within design_within_mm of Φ (the twin's sag plus the tolerance: the cut part's
// coarse edges along the hole the twin left) is Φ's, left to Φ's own judgement. Rapids still meet
// the whole part. Not owned; the same frame as the part. No cut_part: the whole part judges the cut.
struct CutApart {
  const SurfaceIndex* cut_part = nullptr;
  double design_gouge_tolerance_mm = 0.01;
  double design_within_mm = 0;
};

struct PostOptions {
  Dialect dialect = Dialect::Iso;
  bool line_numbers = false;         // N words (Heidenhain always numbers its blocks)
  PathOptions path;                  // kinematics: tool length, linearisation tolerances
  double max_inverse_time = 99999.999;  // controller's largest G93 F; shorter blocks are slowed to it
  // Without a part: safe Z this far above the highest programmed point. With a part: this far above
  // the part's highest point in the machine frame over the rotary angles the program uses (plus the
  // largest assembly radius when a head axis tilts the tool).
  double safe_height_mm = 10;
  // The part in the work frame (setup applied), not owned. Null: links are not planned against the
  // part and not checked (the header says so), as for foreign CL-data.
  const SurfaceIndex* part = nullptr;
  double clearance_mm = 1;           // links: the assembly this far from the part (normal offset margin)
  double lead_mm = 2;                // approach / retract off the surface along its normal (at least the
                                     // cutter's radius variation + clearance, so an axial move cannot cut)
  double gouge_tolerance_mm = 0.01;  // back-simulation: the cutter may be this deep in the part in the cut
  // With a separate part: the cut judged apart (CutApart; `gouge_tolerance_mm` for its cut_part) and
  // Φ itself, `design`, both in the work frame, not owned. Links are still planned and checked against `part`.
  CutApart apart;
  const SurfaceIndex* design = nullptr;
  std::string validate() const;      // empty when valid
  // Φ when the cut is judged apart (both apart.cut_part and design given), else null.
  const SurfaceIndex* design_apart() const { return apart.cut_part ? design : nullptr; }
};

// One tool's CL-data and what the program needs to know about the tool.
struct PostInput {
  ClProgram cl;
  std::string patch;  // for messages: "patch 'NAME': pose I ... out of reach"
  double tool_length_mm = 0;  // spindle nose to tip (head axes); 0: PostOptions::path.tool_length_mm
  ToolAssembly assembly{};    // cutter, shank, holder for the link planning and the back-simulation;
                              // no cutter: the CL-data's profile without shank and holder
};

struct PostedSection {
  std::string patch;
  JointPath path;      // the solved, linearised motion (every pose, input and inserted)
  int first_block = 0, end_block = 0;  // this section's blocks in NcProgram::blocks
  int slowed_blocks = 0;  // blocks stretched by an axis speed or the inverse-time limit
  // The section's CL-data as posted (the input's frame): with PostOptions::part its links as planned
  // (lead-in and lead-out along the surface normal, planned again farther out when the
  // back-simulation asked for it), else the input's moves.
  ClProgram cl{};
};
struct Posted {
  NcProgram program;
  std::vector<PostedSection> sections;
  // With a part: the program's text was back-simulated (postproc/verify.h) in PostOptions::dialect.
  bool links_checked = false;
  int worst_line = 0;        // the first colliding or gouging line, 0 when clean
  // Why the program must not run, "" when clean: "back-simulation: FILE:LINE: holder collision D mm
  // at (..) in motion block B (rapid); ..." or "link planning: patch 'P': no lead-out off CL move K ...".
  std::string refused;
  double min_link_clearance_mm = INFINITY;  // over every rapid block and component
  // The linearisation the program was posted with (PathOptions::tolerance_mm, angle_tolerance_deg;
  // the tolerance is also the controller's blending tolerance in the text): the options' own, or
  // finer where the back-simulation found the cutter in the part in cutting blocks alone at them
  // (halved `refined` times, at most kMaxRefinements); `refined_for` the first such problem.
  double tolerance_mm = 0, angle_tolerance_deg = 0;
  int refined = 0;
  std::string refined_for;
  static constexpr int kMaxRefinements = 3;
};

// The stretch of a CL program's cut that can be entered and left clear of o.part (required), as
// post() plans the links: the moves of the cut [first, last] (between its approach and its leave) and
// the moves kept [kept_first, kept_last], the outermost ones off which the planner finds a clear
// lead-in and lead-out (judged by the back-simulation with o's distances and options). An end whose
// lead has no clear point is moved inwards (by doubling steps, then bisection) to the first move whose
// lead has; `why` names the first lead that was not clear (empty: none was trimmed); `none`: no two
// moves of the cut can be entered and left. A CL program without a feed move: first == moves.size().
// Costs up to ~100 back-simulated lead candidates per move tried.
struct LeadRange {
  size_t first = 0, last = 0, kept_first = 0, kept_last = 0;
  bool none = false;
  std::string why;
  [[nodiscard]] bool trimmed() const { return none || kept_first != first || kept_last != last; }
};
[[nodiscard]] LeadRange clear_lead_range(const ClProgram& cl, const ToolAssembly& assembly, const PostOptions& o);

// Builds the program for one or several CL programs in order (a tool change for each new tool):
// IK along each whole CL program (one branch per path), linearisation of feed moves, inverse-time
// feeds stretched by the axis speeds, a safe approach for every rapid that changes the orientation
// (safe Z, rotaries, X Y, Z) and a retract to safe Z at the end. Throws MachineError naming the
// patch and pose when a pose is out of reach.
// With PostOptions::part the links are planned against it: the CL-data's own approach and leave
// moves (rapids before the first feed move, axial lead-in/out) are replaced by a lead-in and a
// lead-out along the surface normal (or turned, lifted, farther out where that is not clear), each
// lead point chosen by the back-simulation's own judgement of the lead and the rapid along the axis
// above it; under TCP the moves between safe Z and the cut follow the tool axis; the emitted text is
// back-simulated and, when a motion still hits the part, planned again with doubled distances (a
// lead with no clear point at those keeps one at the configured distances), else returned with
// `refused` set (nothing is thrown). When only cutting blocks put the cutter in the part, the
// program is linearised again with both tolerances halved (up to Posted::kMaxRefinements times): the
// machine's straight joint moves between the points of a fit that comes close to the tolerance
// (HECC impeller: 0.0183 mm fitted, 0.0203 mm in the program at 0.005 mm / 0.05°) can take it past.
// A lead with no clear point at all is refused like a hit, before any back-simulation.
[[nodiscard]] Posted post(const std::vector<PostInput>& inputs, const Machine& m, const PostOptions& o,
                          const std::string& name, const std::vector<std::string>& header);

}  // namespace flankcam
