// The surface a fitted motion really machines: the envelope Ω of the tool of revolution
// under the fitted rails, and its signed deviation from the design surface Φ.
#pragma once
#include <vector>

#include "core/closest_point.h"
#include "core/envelope.h"
#include "core/fitting.h"

namespace flankcam {

struct MachinedSurfaceOptions {
  int grid_s = 60, grid_t = 300;  // tessellation of Ω over (s, t)
  std::string validate() const;
};

struct MachinedSurface {
  EnvelopeGrid omega;                     // Ω, same frame as Φ
  int sheet = 1;                          // the envelope sheet that faces Φ
  int tool_side = 1;                      // +1: Φ's normals point to the tool (out of the material)
  std::vector<double> omega_deviation;    // per Ω vertex: signed distance to Φ along Φ's tool-side
                                          // normal (undercut > 0, overcut < 0); NaN beyond Φ
  std::vector<double> design_deviation;   // per Φ vertex: the same measured from Ω; NaN where Ω does
                                          // not cover the vertex
  std::vector<int> design_row;            // per Φ vertex: the Ω grid row (t index) of its closest point; -1: none
};

// Deviations are in the frame of `design` (unit frame in the fitting).
[[nodiscard]] MachinedSurface machined_surface(const SurfaceIndex& design, const Rails& rails, const ToolRadius& tool,
                                               const MachinedSurfaceOptions& options = {});

// Share of Φ's area (vertex areas, a third of each incident triangle) whose |deviation| <= tolerance.
[[nodiscard]] double coverage(const TriMesh& design, const std::vector<double>& design_deviation, double tolerance);

// +1 when Φ's vertex normals point to the side of the axis samples (the tool side), else -1.
[[nodiscard]] int tool_side(const SurfaceIndex& design, const Rails& rails);

}  // namespace flankcam
