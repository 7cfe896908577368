// The custom tool handed to tool grinders and simulators: its half-profile (meridian) as DXF R12
// (axis along X, profile above it, origin at the tool tip, mm) and its key dimensions.
#pragma once
#include <Eigen/Core>
#include <string>
#include <vector>

namespace flankcam {

struct ToolDimensions {
  double length_mm = 0;                         // along the axis, tip (z = 0) to the end of the cutting part
  double diameter_min_mm = 0, diameter_max_mm = 0;
  double cone_half_angle_deg = 0;               // the side's taper over its middle half; 0 for a cylinder
};
// `profile`: meridian points (z, r) in mm from the tip, z increasing. `end_points`: the leading
// points that are a rounded end (core/tool_end.h EndProfile): the diameters and the cone are the
// side's (from profile[end_points] on), the length the whole tool's.
[[nodiscard]] ToolDimensions tool_dimensions(const std::vector<Eigen::Vector2d>& profile, int end_points = 0);

// DXF R12 ASCII text: the profile as connected LINE entities on layer PROFILE, closed by the end
// faces down to the axis and the axis itself on layer AXIS; `title` goes into a comment (999).
// A rounded end is in the profile itself (its arc as lines, a ball's reaching the axis).
[[nodiscard]] std::string tool_dxf(const std::vector<Eigen::Vector2d>& profile, const std::string& title);
void write_tool_dxf(const std::string& path, const std::vector<Eigen::Vector2d>& profile, const std::string& title);

// The tool as a closed solid for simulators (ASCII STL, mm): the meridian revolved about +Z with
// `segments` facets around, tip at the origin, end faces capped. Chordal error r (1 - cos(pi/segments)).
[[nodiscard]] std::string tool_stl(const std::vector<Eigen::Vector2d>& profile, const std::string& title, int segments = 180);
void write_tool_stl(const std::string& path, const std::vector<Eigen::Vector2d>& profile, const std::string& title);

}  // namespace flankcam
