// A blade-like free-form surface that is not an envelope: lofted NACA 4-digit sections, tapered and
// twisted along the span (the paper's Fig. 18 situation), for examples and tests. One side of the
// blade (suction side, the convex one) between two chord fractions, as a triangle mesh in mm.
#pragma once
#include <Eigen/Core>
#include <string>
#include <vector>

#include "core/mesh.h"

namespace flankcam {

struct BladeOptions {
  double span = 60;            // along +Z, mm
  double chord_hub = 40, chord_tip = 32;  // mm
  double twist_deg = 20;       // section rotation at the tip relative to the hub, about the stacking axis
  double camber = 0.05, camber_position = 0.4, thickness = 0.12;  // NACA 4-digit (m, p, t)
  double chord_from = 0.1, chord_to = 0.9;  // the part of the suction side the mesh covers
  int grid_chord = 80, grid_span = 40;
  std::string validate() const;  // empty when valid
};

struct Blade {
  BladeOptions options;
  TriMesh mesh;  // suction side, normals pointing away from the blade (towards the tool)
  // The surface point and its outward unit normal at chord fraction u and span fraction v.
  [[nodiscard]] Eigen::Vector3d point(double u, double v) const;
  [[nodiscard]] Eigen::Vector3d normal(double u, double v) const;
};

[[nodiscard]] Blade make_blade(const BladeOptions& o);

// Suggested initialisation lines for `patches` equal chord ranges: `lines_per_patch` span-wise lines
// per patch, each the span at fraction u moved `offset_mm` along the surface normal and extended
// `overhang_mm` beyond hub and tip: [ax, ay, az, bx, by, bz] with a at the hub.
[[nodiscard]] std::vector<std::vector<std::array<double, 6>>> blade_lines(const Blade& b, int patches, int lines_per_patch,
                                                                         double offset_mm, double overhang_mm);

}  // namespace flankcam
