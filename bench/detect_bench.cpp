// Automatic patch detection (core/detect.h).
//   detect_bench                       auto cover of a 13k-vertex blade side, tolerance 0.01 mm (goal <= 30 s on 2 cores)
//   detect_bench envelopes [auto|line] the 16 exact envelopes (4 motions x 4 tools): coverage within 1e-4 of the
//                                      diagonal, worst overcut; line: one line perturbed by 1% and 2 degrees
//   detect_bench mesh FILE TOL_MM      auto cover of a mesh (mm), coverage within TOL_MM
#include <fmt/format.h>

#include <Eigen/Geometry>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <string>

#include "core/blade.h"
#include "core/detect.h"
#include "core/envelope.h"
#include "core/mesh.h"

using namespace flankcam;

namespace {

double seconds_since(std::chrono::steady_clock::time_point t0) {
  return std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
}

double worst_overcut(const std::vector<double>& design_dev, const std::vector<const MachinedSurface*>& ms) {
  double worst = 0;
  for (double d : design_dev)
    if (std::isfinite(d)) worst = std::max(worst, -d);
  for (const MachinedSurface* m : ms)
    for (double d : m->omega_deviation)
      if (std::isfinite(d)) worst = std::max(worst, -d);
  return worst;
}

void cover_mesh(const TriMesh& mesh_mm, double tol_mm, const std::string& what) {
  const auto t0 = std::chrono::steady_clock::now();
  const Similarity frame = unit_diagonal_frame(mesh_mm);
  const SurfaceIndex surface(transformed(mesh_mm, frame));
  CoverOptions o;
  o.patch.tolerance = frame.length_to_unit(tol_mm);
  const Detection d = detect_patches(surface, o, [&](const CoverProgress& p) {
    std::fprintf(stderr, "  [%6.1f s] %s: seed %d of %d, %d patches, coverage %.1f%%\n", seconds_since(t0),
                 p.stage.c_str(), p.seed, p.seeds, p.patches, 100 * p.coverage);
  });
  std::vector<const MachinedSurface*> ms;
  for (const auto& p : d.patches) ms.push_back(&p.fit.machined);
  fmt::print("{}: {} vertices, diagonal {:.2f} mm: {} patches, coverage {:.1f}% within {} mm, worst overcut {:.4f} mm, "
             "{} ({} fits), {:.1f} s\n",
             what, mesh_mm.vertices.size(), 1 / frame.scale, d.patches.size(), 100 * d.coverage, tol_mm,
             frame.length_to_mm(worst_overcut(d.deviation, ms)), to_string(d.stop), d.seeds_tried, seconds_since(t0));
  for (const auto& p : d.patches)
    fmt::print("  {}: own coverage {:.1f}%, first brought {:.1f}%, t in [{:.3f}, {:.3f}], eps {:.4f} mm\n", p.spec.name,
               100 * p.fit.coverage, 100 * p.new_area, p.fit.t_from, p.fit.t_to, frame.length_to_mm(p.fit.fit.eps_opt.max));
}

void envelopes(bool line_driven, const std::string& only) {
  const std::vector<std::pair<const char*, RadiusProfile>> tools = {{"cylinder", cylinder_profile(6)},
                                                                    {"cone", cone_profile(6, 9)},
                                                                    {"barrel", barrel_profile(6, 1.5)},
                                                                    {"spline", spline_profile({5.0, 6.5, 7.5, 6.5, 7.0, 8.5})}};
  double total = 0;
  for (const char* kind : {"twist", "arc", "helix", "s-curve"})
    for (const auto& [tool, profile] : tools) {
      if (!only.empty() && only != std::string(kind) + "/" + tool) continue;
      const auto t0 = std::chrono::steady_clock::now();
      AnalyticMotionOptions mo;
      mo.kind = kind;
      const LineMotion motion = analytic_motion(mo);
      const EnvelopeGrid g = envelope_grid(motion, profile, 66, 200, 1);
      const Similarity frame = unit_diagonal_frame(g.mesh);
      const SurfaceIndex surface(transformed(g.mesh, frame));
      const double tol = 1e-4;
      double cov = 0, over = 0;
      int patches = 1;
      std::string stop;
      if (line_driven) {
        const Eigen::Vector3d a = frame.to_unit(motion.a(0.5)), b = frame.to_unit(motion.b(0.5));
        const Eigen::Vector3d e = (b - a).normalized(), n = e.cross(Eigen::Vector3d(0.3, 0.5, 0.8).normalized()).normalized();
        const Eigen::Vector3d mid = 0.5 * (a + b) + 0.01 * n, e2 = Eigen::AngleAxisd(2 * M_PI / 180, e.cross(n)) * e;
        const double L = (b - a).norm();
        PatchSpec spec;
        spec.name = "line";
        spec.init = PatchInit::Line;
        spec.lines = {{mid - 0.5 * L * e2, mid + 0.5 * L * e2}};
        PatchOptions po;
        po.tolerance = tol;
        po.trim_gouges = true;
        const PatchFit f = fit_patch(surface, spec, po);
        cov = f.coverage;
        over = worst_overcut(f.machined.design_deviation, {&f.machined});
        stop = fmt::format("t [{:.3f}, {:.3f}]", f.t_from, f.t_to);
      } else {
        CoverOptions o;
        o.patch.tolerance = tol;
        const Detection d = detect_patches(surface, o, [&](const CoverProgress& p) {
          std::fprintf(stderr, "  [%6.1f s] %s: seed %d of %d, %d patches, coverage %.1f%%\n", seconds_since(t0),
                       p.stage.c_str(), p.seed, p.seeds, p.patches, 100 * p.coverage);
        });
        std::vector<const MachinedSurface*> ms;
        for (const auto& p : d.patches) ms.push_back(&p.fit.machined);
        cov = d.coverage;
        over = worst_overcut(d.deviation, ms);
        patches = int(d.patches.size());
        stop = to_string(d.stop);
      }
      const double s = seconds_since(t0);
      total += s;
      fmt::print("{:8} {:8} patches {} coverage {:5.1f}% overcut {:.2e} ({}) {:.1f} s\n", kind, tool, patches, 100 * cov,
                 over, stop, s);
      std::fflush(stdout);
    }
  fmt::print("total {:.1f} s\n", total);
}

}  // namespace

int main(int argc, char** argv) {
  const std::string mode = argc > 1 ? argv[1] : "";
  if (mode == "envelopes") {
    envelopes(argc > 2 && std::string(argv[2]) == "line", argc > 3 ? argv[3] : "");
  } else if (mode == "mesh" && argc > 3) {
    cover_mesh(load_mesh(argv[2]).mesh, std::stod(argv[3]), argv[2]);
  } else {
    BladeOptions bo;
    bo.grid_chord = 162;
    bo.grid_span = 81;
    const Blade blade = make_blade(bo);
    cover_mesh(blade.mesh, 0.01, "blade (bench)");
    fmt::print("goal: <= 30 s on 2 cores\n");
  }
  return 0;
}
