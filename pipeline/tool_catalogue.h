// The tool catalogue: machines/tools/*.yaml, one file per family (cylinder, taper, barrel, lens,
// oval) listing standard sizes. Read by a checked reader: every error names the file, the line and
// the key. A job picks one with `tool: {catalogue: NAME}` and only the motion is fitted for it.
#pragma once
#include <Eigen/Core>
#include <filesystem>
#include <string>
#include <vector>

namespace flankcam::pipeline {

struct CatalogueTool {
  std::string name, family;  // family: cylinder | taper | barrel | lens | oval
  std::filesystem::path file;
  int line = 0;
  double diameter_mm = 0;        // cylinder; circle segments: the largest diameter
  double tip_diameter_mm = 0;    // taper: at the tip
  double half_angle_deg = 0;     // taper
  double profile_radius_mm = 0;  // circle segments: radius of the flank's arc
  double widest_at_mm = 0;       // circle segments: where the diameter is largest, from the tip
  double length_mm = 0;          // cutting length
  // The meridian (z, r) from the tip, z in [0, length], mm.
  [[nodiscard]] std::vector<Eigen::Vector2d> meridian_mm(int points = 81) const;
};

// One catalogue file. Throws InputError "FILE:LINE: KEY: what is wrong".
[[nodiscard]] std::vector<CatalogueTool> read_tool_file(const std::filesystem::path& file);
// Every *.yaml in `dir` (sorted by file name); tool names must be unique across them.
[[nodiscard]] std::vector<CatalogueTool> read_catalogue(const std::filesystem::path& dir);
// The tool called `name`; InputError naming the folder and the known names otherwise.
[[nodiscard]] CatalogueTool find_catalogue_tool(const std::filesystem::path& dir, const std::string& name);

}  // namespace flankcam::pipeline
