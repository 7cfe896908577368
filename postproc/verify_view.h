// The 3D view of verify.html (postproc/viewer.h, the same viewer as report.html): what `flankcam
// verify` simulated, in the frame the program is written in (the part placed on the machine). The
// design surface coloured by each program's machined deviation, the part, every tool's assembly
// (cutter from its meridian, shank, holder) at each simulated position with the axis values the
// program states there, a marker per collision or gouge that jumps to its deepest position, and
// optionally the machine moving (its tables and heads from its chain).
#pragma once
#include <array>
#include <string>
#include <vector>

#include "core/mesh.h"
#include "postproc/verify.h"
#include "postproc/viewer.h"

namespace flankcam {

struct VerifyViewProgram {
  std::string name;                      // the program's file name, as the page shows it
  const VerifyReport* report = nullptr;  // not owned: its motion, blocks, hits and machined deviation
  std::vector<VerifyTool> tools;         // the tools the program was simulated with
  std::array<std::string, 5> axis_names{"X", "Y", "Z", "A", "C"};
  bool has_values = true;                // false: CL-data (poses only, no machine axes)
};

// One viewer patch per tool a program uses ("cone-1.ngc T1"), one track per program over all its
// simulated positions and, for several programs, one of the whole run; the surface coloured by each
// program's deviation (and the smallest of all); a marker per hit labelled with its program line.
// `part_mm` empty: the surface is the part. `machine` (may be null): the view's machine mode, the
// tables and heads moved by the programmed rotary values. Throws InputError when a program has no
// report.
[[nodiscard]] ViewerScene verify_view(const TriMesh& surface_mm, const TriMesh& part_mm, double tolerance_mm,
                                      const std::vector<VerifyViewProgram>& programs, const Machine* machine = nullptr);

}  // namespace flankcam
