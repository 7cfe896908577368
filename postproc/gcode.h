// NC program text per controller dialect (one emitter each, all formatting one NcProgram) and a
// reader that takes such programs back to programmed positions, for back-simulation through the
// forward kinematics.
//
// Dialects: iso (Fanuc style: G43.4 TCP or G43 + joints, G93/G94), linuxcnc (joints, or tip + angles
// under its trt kinematics; G93 with F on every G1; G64 P blending tolerance), heidenhain
// (conversational: L X+.. A+.. F, FUNCTION TCPM, feed in mm/min), sinumerik (TRAORI with rotary
// angles, G93). Numbers: 4 decimals for mm and degrees, 4 for inverse-time F, mm/min F rounded down to
// 0.001 (at least 1 decimal); no "-0".
#pragma once
#include <string>
#include <vector>

#include "postproc/nc_program.h"

namespace flankcam {

struct EmitOptions {
  Dialect dialect = Dialect::Iso;
  bool line_numbers = false;        // N10, N20, ... (Heidenhain numbers every block regardless)
  double blend_tolerance_mm = 0.005;  // LinuxCNC G64 P, Sinumerik CYCLE832: path blending tolerance
};

[[nodiscard]] std::string nc_text(const NcProgram& p, const EmitOptions& o);
void write_nc(const std::string& path, const NcProgram& p, const EmitOptions& o);

// A motion block as read back: the programmed values after it (modal), which of them the program
// has stated so far, and the modes in force.
struct NcPoint {
  int line = 0;             // 1-based line in the text
  bool rapid = false;
  Joints at;                // X Y Z and the two rotary values (machine rotary order)
  unsigned known = 0;       // NcAxis mask of the values programmed so far
  unsigned stated = AxesAll;  // NcAxis mask of the values this block writes (the others are modal)
  bool tcp = false;         // G43.4 / FUNCTION TCPM / TRAORI in force (LinuxCNC: always false, the machine decides)
  bool inverse_time = false;
  double f = 0;             // the F in force (1/min under G93, else mm/min)
  int tool = 0;
};

// Reads a program in `d` whose rotary words are `rotary_names` (machine order). Throws InputError
// "FILE:LINE: what" for words or blocks it does not understand.
[[nodiscard]] std::vector<NcPoint> parse_nc(const std::string& text, Dialect d, const std::array<std::string, 2>& rotary_names,
                                            const std::string& file);

}  // namespace flankcam
