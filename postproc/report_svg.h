// Pictures for the job report (SVG, self-contained, mm): the design surface coloured by signed
// deviation with the tool at a few poses, the tool profile with its dimensions, and the rotary axes'
// angles over a program.
#pragma once
#include <Eigen/Core>
#include <array>
#include <string>
#include <vector>

#include "core/mesh.h"
#include "core/pose.h"
#include "postproc/tool_export.h"

namespace flankcam {

// Deviation colours: green within the tolerance, red for undercut (material left, > 0), blue for
// overcut (< 0), saturated at 4x the tolerance; grey where undefined (NaN).
[[nodiscard]] std::array<unsigned char, 3> deviation_color(double dev_mm, double tol_mm);

// A point where a motion hit the part (collision of the assembly, or a gouge of the cutter), drawn
// as a ringed cross with its label (e.g. "L123 holder 0.52").
struct SvgHitMarker {
  Eigen::Vector3d point = Eigen::Vector3d::Zero();  // mm, the surface's frame
  std::string label;
  bool gouge = false;  // orange; collisions magenta
};

// The surface seen along its mean normal (over the faces with a deviation), rasterised to at most
// `columns` cells across, each cell the deviation at the nearest surface point; the tool's outline
// (meridian `profile`) at `tool_poses`; collisions and gouges at `hits`.
[[nodiscard]] std::string deviation_map_svg(const TriMesh& surface_mm, const std::vector<double>& deviation_mm, double tol_mm,
                                            const std::vector<ToolPose>& tool_poses,
                                            const std::vector<Eigen::Vector2d>& profile, const std::string& title,
                                            int columns = 160, const std::vector<SvgHitMarker>& hits = {},
                                            const std::string& uncut_label = "not reached by this patch");

// Patch colours for pictures of several patches (a fixed qualitative palette; grey for -1, none).
[[nodiscard]] std::array<unsigned char, 3> patch_color(int patch);

// The surface seen along its mean normal (over the owned vertices), each cell coloured by the patch
// that machines its nearest vertex (`owner`: index into `names`, -1 none: grey), with a legend.
[[nodiscard]] std::string patch_owner_svg(const TriMesh& surface_mm, const std::vector<int>& owner,
                                          const std::vector<std::string>& names, const std::string& title,
                                          int columns = 160);

// The tool standing on its tip: full silhouette, axis, length, end diameters and cone angle.
[[nodiscard]] std::string tool_profile_svg(const std::vector<Eigen::Vector2d>& profile, const std::string& title);

struct AngleSeries {
  std::string name;                  // axis name
  std::vector<double> deg;           // per block
  double min_deg = 0, max_deg = 0;   // travel limits (ignored when continuous)
  bool continuous = false;
};
// Both rotary axes over the blocks of a program, with their travel limits where they are in view.
[[nodiscard]] std::string angle_chart_svg(const std::array<AngleSeries, 2>& series, const std::string& title);

}  // namespace flankcam
