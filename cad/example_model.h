// A small multi-face B-rep written as STEP or IGES through Open CASCADE, for tests and examples: the
// suction side of core/blade.h's twisted NACA blade as two B-spline faces sharing the mid-chord edge,
// and a floor plane below it trimmed by a bore whose cylinder wall shares the hole's edge.
// Faces in the file, in explode order: 1 blade from chord_from to the middle, 2 the middle to chord_to,
// 3 the floor (normal +z), 4 the bore wall (normal towards its axis). Normals point out of the material.
#pragma once
#include <string>

#include "core/blade.h"

namespace flankcam {

struct ExampleModelOptions {
  BladeOptions blade;                  // the flank; grid_* unused
  int points_chord = 41, points_span = 13;  // samples per blade face, interpolated by a bicubic B-spline
  double floor_z_mm = -3;              // floor plane, below the blade's hub section (z = 0)
  double floor_x0_mm = -20, floor_x1_mm = 40, floor_y0_mm = -10, floor_y1_mm = 40;
  double hole_x_mm = 10, hole_y_mm = 28, hole_radius_mm = 5, hole_depth_mm = 10;
  std::string unit = "MM";             // "MM" or "INCH": the length unit the file is written in
  std::string validate() const;        // empty when valid
};

// Writes .step/.stp or .iges/.igs (by extension). Throws InputError when it cannot.
void write_example_model(const std::string& path, const ExampleModelOptions& options);

}  // namespace flankcam
