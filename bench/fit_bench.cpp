// Seconds for line-driven initialisation (exploration + propagation) and for the optimisation of a
// general tool (spline meridian) on a 13,200-vertex exact envelope at 30 x 100 samples, and the whole
// fit of a 1,000,000-vertex envelope read from an OBJ file (reading, index, initialisation, optimisation).
// Goals (issue 16): <= 0.5 s and <= 0.5 s on 2 cores; the 1M-vertex surface in <= 10 s including loading.
// Wall-clock seconds depend on the load of the machine; CPU seconds (all threads) are printed beside.
// Usage: fit_bench [--no-1m]
#include <fmt/format.h>
#include <omp.h>

#include <chrono>
#include <cstdio>
#include <ctime>
#include <string>

#include "core/fitting.h"

using namespace flankcam;

namespace {
struct Clock {
  std::chrono::steady_clock::time_point wall = std::chrono::steady_clock::now();
  std::clock_t cpu = std::clock();
  [[nodiscard]] std::string since() const {
    return fmt::format("{:.2f} s ({:.2f} CPU-s)", std::chrono::duration<double>(std::chrono::steady_clock::now() - wall).count(),
                       double(std::clock() - cpu) / CLOCKS_PER_SEC);
  }
};

struct Timed {
  std::string init, opt;
  FitResult r;
  size_t positions = 0;
};

Timed fit_line_driven(const SurfaceIndex& surface, const LineMotion& m, const Similarity& frame, const FitOptions& o) {
  const Eigen::Vector3d off(0.004, -0.003, 0.002);
  Timed out;
  const Clock t0;
  const ExploredLine best = explore_line(surface, frame.to_unit(m.a(0.5)) + off, frame.to_unit(m.b(0.5)) - off);
  const LineTrajectory tr = propagate_line(surface, best.a, best.b);
  const Rails rails = rails_from_trajectory(tr, o);
  out.init = t0.since();
  out.positions = tr.a.size();
  const Clock t1;
  out.r = optimize_motion(surface, rails, o);
  out.opt = t1.since();
  return out;
}
}  // namespace

int main(int argc, char** argv) {
  const bool big = !(argc > 1 && std::string(argv[1]) == "--no-1m");
  AnalyticMotionOptions mo;
  mo.kind = "helix";
  const LineMotion m = analytic_motion(mo);
  const RadiusProfile barrel = barrel_profile(6, 1.5);
  FitOptions o;
  o.shape = ToolShape::General;
  o.threads = omp_get_max_threads();
  {
    const EnvelopeGrid g = envelope_grid(m, barrel, 66, 200, 1);
    const Similarity frame = unit_diagonal_frame(g.mesh);
    const SurfaceIndex surface(transformed(g.mesh, frame));
    const Timed t = fit_line_driven(surface, m, frame, o);
    fmt::print("fit: {} vertices, {} threads, general tool, {} x {} samples, {} positions propagated, {} outer iterations ({})\n",
               surface.mesh().vertices.size(), o.threads, o.samples_s, o.samples_t, t.positions, t.r.iterations,
               to_string(t.r.status));
    fmt::print("fit: line-driven initialisation {} [goal <= 0.5 s], optimisation {} [goal <= 0.5 s], eps_ini {:.2e}, "
               "eps_opt {:.2e} (relative to the diagonal)\n",
               t.init, t.opt, t.r.eps_ini.max, t.r.eps_opt.max);
  }
  if (big) {
    const std::string path = "/tmp/flankcam_fit_bench_1m.obj";
    write_obj(path, envelope_grid(m, barrel, 577, 1733, 1).mesh);
    const Clock total;
    const Clock t_load;
    const LoadedMesh loaded = load_mesh(path);
    const std::string load = t_load.since();
    const Similarity frame = unit_diagonal_frame(loaded.mesh);
    const Clock t_index;
    const SurfaceIndex surface(transformed(loaded.mesh, frame));
    const std::string index = t_index.since();
    const Timed t = fit_line_driven(surface, m, frame, o);
    fmt::print("fit 1M: {} vertices: load {}, index {}, initialisation {}, optimisation {}: total {} [goal <= 10 s], "
               "{} outer iterations ({}), eps_opt {:.2e}\n",
               surface.mesh().vertices.size(), load, index, t.init, t.opt, total.since(), t.r.iterations,
               to_string(t.r.status), t.r.eps_opt.max);
    std::remove(path.c_str());
  }
}
