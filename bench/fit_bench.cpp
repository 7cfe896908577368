// Seconds for line-driven initialisation (exploration + propagation) and for the optimisation
// on a 13,200-vertex exact envelope at 30 x 100 samples.
// Goals (issue 3): <= 2 s and <= 1 s on 2 cores (paper, Table 1: 25-90 s and 3-25 s on 4 cores).
#include <fmt/format.h>

#include <chrono>

#include "core/fitting.h"

using namespace flankcam;

int main() {
  AnalyticMotionOptions mo;
  mo.kind = "helix";
  const LineMotion m = analytic_motion(mo);
  const EnvelopeGrid g = envelope_grid(m, cone_profile(6, 9), 66, 200, 1);
  const Similarity frame = unit_diagonal_frame(g.mesh);
  const SurfaceIndex surface(transformed(g.mesh, frame));
  const Eigen::Vector3d off(0.004, -0.003, 0.002);
  FitOptions o;
  o.shape = ToolShape::Cone;
  const auto t0 = std::chrono::steady_clock::now();
  const ExploredLine best = explore_line(surface, frame.to_unit(m.a(0.5)) + off, frame.to_unit(m.b(0.5)) - off);
  const LineTrajectory tr = propagate_line(surface, best.a, best.b);
  const Rails rails = rails_from_trajectory(tr, o);
  const auto t1 = std::chrono::steady_clock::now();
  const FitResult r = optimize_motion(surface, rails, o);
  const auto t2 = std::chrono::steady_clock::now();
  fmt::print("fit: {} vertices, {} x {} samples, {} positions propagated, {} outer iterations\n",
             surface.mesh().vertices.size(), o.samples_s, o.samples_t, tr.a.size(), r.iterations);
  fmt::print("fit: line-driven initialisation {:.2f} s [goal <= 2 s], optimisation {:.2f} s [goal <= 1 s], "
             "eps_ini {:.2e}, eps_opt {:.2e} (relative to the diagonal)\n",
             std::chrono::duration<double>(t1 - t0).count(), std::chrono::duration<double>(t2 - t1).count(),
             r.eps_ini.max, r.eps_opt.max);
}
