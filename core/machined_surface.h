// The surface a fitted motion really machines: the envelope Ω of the tool of revolution
// under the fitted rails, and its signed deviation from the design surface Φ.
#pragma once
#include <optional>
#include <vector>

#include "core/closest_point.h"
#include "core/envelope.h"
#include "core/fitting.h"
#include "core/tool_end.h"

namespace flankcam {

struct MachinedSurfaceOptions {
  int grid_s = 60, grid_t = 300;  // tessellation of Ω over (s, t); grid_t poses for the tool's end
  // The tool's end at the tip (core/tool_end.h; corner radius in the rails' frame). Unset: the side
  // envelope alone, as the fit models it. Set: Ω is the side above the end (s >= the end's
  // tangent point), and the end's sweep (tip face, torus, ball) joins it in the deviation of Φ.
  std::optional<ToolEnd> end;
  std::string validate() const;
};

struct MachinedSurface {
  EnvelopeGrid omega;                     // Ω, same frame as Φ
  int sheet = 1;                          // the envelope sheet that faces Φ
  int tool_side = 1;                      // +1: Φ's normals point to the tool (out of the material)
  std::vector<double> omega_deviation;    // per Ω vertex: signed distance to Φ along Φ's tool-side
                                          // normal (undercut > 0, overcut < 0); NaN beyond Φ
  std::vector<double> design_deviation;   // per Φ vertex: its distance to Ω, signed as above; NaN where Ω does
                                          // not cover the vertex, its nearest Ω point is on a fold,
                                          // the cutter at some pose holds it deeper than that says, or
                                          // it claims an overcut the cutter's side does not reach
  std::vector<int> design_row;            // per Φ vertex: the Ω grid row (t index) of its closest point; -1: none
  std::vector<char> design_by_end;        // per Φ vertex: 1 where the tool's end, not its side, machines it
};

// Deviations are in the frame of `design` (unit frame in the fitting).
[[nodiscard]] MachinedSurface machined_surface(const SurfaceIndex& design, const Rails& rails, const ToolRadius& tool,
                                               const MachinedSurfaceOptions& options = {});

// Share of Φ's area (vertex areas, a third of each incident triangle) whose |deviation| <= tolerance.
[[nodiscard]] double coverage(const TriMesh& design, const std::vector<double>& design_deviation, double tolerance);

// +1 when Φ's vertex normals point to the side of the axis samples (the tool side), else -1.
[[nodiscard]] int tool_side(const SurfaceIndex& design, const Rails& rails);

}  // namespace flankcam
