// APT CL-data (ISO 4343 style) and CL-data as CSV: the machine-independent program of a patch,
// tip points and tool axes in part coordinates (mm). Written by flankcam and read back from any
// source (`flankcam post`).
#pragma once
#include <Eigen/Core>
#include <limits>
#include <string>
#include <vector>

#include "core/pose.h"

namespace flankcam {

// APT-7 cutter: d diameter, r corner radius, e/f radial/axial corner centre, alpha bottom angle
// from horizontal, beta side angle from the axis (degrees), h height.
struct AptCutter {
  double d = 0, r = 0, e = 0, f = 0, alpha_deg = 0, beta_deg = 0, h = 0;
};
// The APT-7 cone that envelopes a meridian (z, r) from the tip: exact for cones and cylinders,
// the smallest enclosing cone with the profile's end slope for a general tool. A rounded end
// (core/tool_end.h: the profile's first `end_points` points, an arc of `end_radius`): the cone is
// the side's, r the corner radius, e and f the corner centre's radial and axial position.
[[nodiscard]] AptCutter enveloping_cutter(const std::vector<Eigen::Vector2d>& profile, int end_points = 0,
                                          double end_radius = 0);

struct ClMove {
  ToolPose pose;
  bool rapid = false;
  double feed_mm_min = 0;  // feed moves
  // A point of the contact curve (the design surface point nearest the middle of the cutter);
  // NaN when unknown (rapids, CL-data from elsewhere). Written to the CSV only.
  Eigen::Vector3d contact = Eigen::Vector3d::Constant(std::numeric_limits<double>::quiet_NaN());
};

struct ClProgram {
  std::string partno;
  int tool = 1;
  AptCutter cutter;
  std::vector<Eigen::Vector2d> profile;  // the true meridian (z, r), mm, written as PPRINT lines
  double spindle_rpm = 0;                // 0: no SPINDL
  bool clockwise = true, coolant = true;
  std::vector<std::string> comments;     // PPRINT lines after PARTNO
  std::vector<ClMove> moves;
};

// A flank pass: rapid to `clearance_mm` above the first pose along its axis, rapid to `lead_mm`
// above it, feed in, the poses at `feed`, feed out `lead_mm` along the last axis, rapid to clearance.
[[nodiscard]] ClProgram flank_program(const std::string& partno, const std::vector<ToolPose>& poses,
                                      const std::vector<Eigen::Vector2d>& profile, double feed_mm_min, double spindle_rpm,
                                      double lead_mm, double clearance_mm);

// APT text: 6 decimals for XYZ, 9 for IJK, lines kept within 72 columns with `$` continuations.
[[nodiscard]] std::string apt_text(const ClProgram& p);
void write_apt(const std::string& path, const ClProgram& p);

// What read_apt accepts; a value outside is an error naming the line.
struct AptRanges {
  static constexpr double coordinate_mm = 1e6;                 // |GOTO x, y, z|
  static constexpr double feed_mm_min[2] = {0.1, 1e6};         // FEDRAT (programs write F to 0.1 mm/min)
  static constexpr double spindle_rpm = 1e6;                   // SPINDL, 0 .. this
  static constexpr double tool_number = 99999;                 // LOADTL, a whole number 0 .. this
  static constexpr double tool_size_mm = 1e4;                  // CUTTER lengths, PPRINT 'PROFILE values
};

// Reads APT CL-data: `$` continuations, `$$` comments, FEDRAT/f,MMPM or FEDRAT/MMPM,f,
// SPINDL/n,RPM,CLW or SPINDL/RPM,n,CLW, RAPID for the next GOTO, GOTO with 3 or 6 values.
// Other major words are skipped. Throws InputError "FILE:LINE: ..." for what it cannot parse
// and for values outside AptRanges.
[[nodiscard]] ClProgram read_apt(const std::string& path);
[[nodiscard]] ClProgram parse_apt(const std::string& text, const std::string& name);

// CL-data as CSV: index, motion (rapid/feed), tip x y z, axis i j k, contact point cx cy cz (empty when
// unknown), feed.
[[nodiscard]] std::string cl_csv(const ClProgram& p);

}  // namespace flankcam
