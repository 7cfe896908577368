// Automatic patch detection (core/detect.h).
//   detect_bench                       auto cover of a 13k-vertex blade side, tolerance 0.01 mm (goal <= 30 s on 2 cores)
//   detect_bench envelopes [auto|line] the 16 exact envelopes (4 motions x 4 tools): coverage within 1e-4 of the
//                                      diagonal, worst overcut; line: one line perturbed by 1% and 2 degrees
//   detect_bench mesh FILE TOL_MM      auto cover of a mesh (mm), coverage within TOL_MM
//   detect_bench diag KIND/TOOL [MERIDIAN_CPS [RAIL_CPS [N_S N_T]]]  diagnosis of one exact envelope: oracle fit from the
//                                      exact motion, the first auto patch against it, maps of where it misses
//   detect_bench diag-offsets KIND/TOOL  F_l and the short-sweep radius spread of lines parallel to the exact axis
#include <fmt/format.h>

#include <Eigen/Geometry>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <algorithm>
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


// Where a fit leaves Φ uncovered, on the envelope's own (t, s) grid (vertex i * n_s + j): rows of t
// (down), columns of s (across); '.' within tolerance, 'u' undercut, 'o' overcut, ' ' not machined,
// per cell the most frequent failure among its vertices (a cell is '.' when >= 90% of it is).
void print_miss_map(const std::vector<double>& dev, int n_s, int n_t, double tol) {
  const int rows = 20, cols = 11;
  for (int r = 0; r < rows; ++r) {
    std::string line = "    |";
    for (int c = 0; c < cols; ++c) {
      int ok = 0, under = 0, over = 0, none = 0, all = 0;
      for (int i = r * n_t / rows; i < (r + 1) * n_t / rows; ++i)
        for (int j = c * n_s / cols; j < (c + 1) * n_s / cols; ++j) {
          const double d = dev[size_t(i) * n_s + j];
          ++all;
          if (!std::isfinite(d)) ++none;
          else if (d > tol) ++under;
          else if (d < -tol) ++over;
          else ++ok;
        }
      char ch = '.';
      if (ok * 10 < all * 9) ch = over >= std::max(under, none) ? 'o' : under >= none ? 'u' : ' ';
      line += ch;
    }
    fmt::print("{}|\n", line);
  }
}

// Per-case diagnosis of one exact envelope: an oracle fit from the exact axis motion (can the
// optimiser and the tool representation reach 1e-4 at all?), then the auto detection's first patch
// against the exact motion (seed, propagation reach and drift, fit errors, t-trim, where it misses).
void diagnose(const std::string& which, int meridian_cps, int rail_cps, bool offsets, int n_s, int n_t) {
  const std::vector<std::pair<const char*, RadiusProfile>> tools = {{"cylinder", cylinder_profile(6)},
                                                                    {"cone", cone_profile(6, 9)},
                                                                    {"barrel", barrel_profile(6, 1.5)},
                                                                    {"spline", spline_profile({5.0, 6.5, 7.5, 6.5, 7.0, 8.5})}};
  const auto slash = which.find('/');
  const std::string kind = which.substr(0, slash), tool = which.substr(slash + 1);
  RadiusProfile profile;
  for (const auto& [name, p] : tools)
    if (name == tool) profile = p;
  AnalyticMotionOptions mo;
  mo.kind = kind;
  const LineMotion motion = analytic_motion(mo);
  const EnvelopeGrid g = envelope_grid(motion, profile, n_s, n_t, 1);
  const Similarity frame = unit_diagonal_frame(g.mesh);
  const SurfaceIndex surface(transformed(g.mesh, frame));
  const double tol = 1e-4;
  const auto A = [&](double t) { return frame.to_unit(motion.a(t)); };
  const auto B = [&](double t) { return frame.to_unit(motion.b(t)); };
  // Nearest exact axis position of a line (by midpoint), and the line's error against it.
  const auto t_of = [&](const Eigen::Vector3d& mid) {
    double best_t = 0, best = 1e9;
    for (int i = 0; i <= 2000; ++i) {
      const double t = -0.2 + 1.4 * i / 2000.0;
      const double d = (0.5 * (A(t) + B(t)) - mid).norm();
      if (d < best) best = d, best_t = t;
    }
    return best_t;
  };
  struct LineError {
    double t, angle_deg, offset, slide;  // nearest t; angle; distance of the midpoint from the exact axis; along it
  };
  const auto line_error = [&](const Eigen::Vector3d& a, const Eigen::Vector3d& b) {
    const double t = t_of(0.5 * (a + b));
    const Eigen::Vector3d ea = A(t), eb = B(t), e = (eb - ea).normalized(), d = (b - a).normalized();
    const Eigen::Vector3d w = 0.5 * (a + b) - 0.5 * (ea + eb);
    return LineError{t, std::acos(std::clamp(std::abs(d.dot(e)), 0.0, 1.0)) * 180 / M_PI, (w - w.dot(e) * e).norm(), w.dot(e)};
  };
  FitOptions fo;
  fo.meridian_control_points = meridian_cps;
  fo.rail_control_points = rail_cps;
  PatchOptions po;
  po.tolerance = tol;
  po.fit = fo;
  {
    LineTrajectory tr;
    for (int i = 0; i <= 200; ++i) {
      tr.a.push_back(A(i / 200.0));
      tr.b.push_back(B(i / 200.0));
      tr.F.push_back(0);
    }
    for (bool trim : {false, true}) {
      PatchFit f;
      f.initial = rails_from_trajectory(tr, po.fit);
      f.fit = optimize_motion(surface, f.initial, po.fit);
      po.trim_gouges = trim;
      f = machine_and_trim(surface, std::move(f), po);
      fmt::print("oracle (exact axis motion, {} rail / {} meridian cps, trim {}): eps_ini {:.2e} eps_opt {:.2e} "
                 "({} it, {}), coverage {:.1f}%, t [{:.3f}, {:.3f}], overcut {:.2e}\n",
                 rail_cps, meridian_cps, trim, f.fit.eps_ini.max, f.fit.eps_opt.max, f.fit.iterations, to_string(f.fit.status),
                 100 * f.coverage, f.t_from, f.t_to, worst_overcut(f.machined.design_deviation, {&f.machined}));
      if (trim) print_miss_map(f.machined.design_deviation, g.n_s, g.n_t, tol);
    }
  }
  if (offsets) {
    // F of lines parallel to the exact axis at t = 0.4, moved towards Φ (+) or away (-) by delta, and the
    // largest F over a short propagation (the sweep a seed would start).
    const Eigen::Vector3d a = A(0.4), b = B(0.4), m = 0.5 * (a + b);
    const Footpoint f = surface.closest(m);
    Eigen::Vector3d towards = f.point - m;
    const Eigen::Vector3d e = (b - a).normalized();
    towards = (towards - towards.dot(e) * e).normalized();
    const double dist = (f.point - m).norm();
    for (double delta : {-0.1, -0.05, -0.02, -0.01, -0.005, 0.0, 0.005, 0.01, 0.02, 0.03, 0.04}) {
      if (delta >= dist) continue;
      const Eigen::Vector3d sa = a + delta * towards, sb = b + delta * towards;
      const Movability mv = line_movability(surface, sa, sb, po.exploration.movability);
      PropagationOptions pr = po.propagation;
      for (int steps : {20, 100}) {
        pr.max_steps = steps;
        pr.step = 0.002;
        const LineTrajectory tr = propagate_line(surface, sa, sb, pr);
        double fmax = 0, fmean = 0;
        for (double x : tr.F) fmax = std::max(fmax, x), fmean += x / double(tr.F.size());
        // Radius constancy: per sample along the line, the spread of its distance to Φ over the positions.
        double spread = 0;
        int used = 0;
        for (int j = 1; j < 15; ++j) {
          const double sj = j / 15.0;
          double lo = 1e9, hi = -1e9;
          bool ok = true;
          for (size_t k = 0; k < tr.a.size(); ++k) {
            const Eigen::Vector3d x = (1 - sj) * tr.a[k] + sj * tr.b[k];
            const Footpoint fp = surface.closest(x);
            if (fp.on_boundary) ok = false;
            const double dd = std::abs(smooth_distance(surface, fp, x));
            lo = std::min(lo, dd), hi = std::max(hi, dd);
          }
          if (ok) spread += (hi - lo) * (hi - lo), ++used;
        }
        spread = used ? std::sqrt(spread / used) : -1;
        fmt::print("  offset {:+.3f} (radius {:.3f}): F {:.2e}; {} steps of 0.002: {} positions, F mean {:.2e} max {:.2e}, radius spread {:.2e}\n", delta,
                   dist - delta, mv.F, steps, tr.a.size(), fmean, fmax, spread);
      }
    }
    return;
  }
  CoverOptions o;
  o.patch.tolerance = tol;
  o.patch.fit = fo;
  o.max_patches = 1;
  const Detection d = detect_patches(surface, o);
  if (d.patches.empty()) {
    fmt::print("auto: no patch\n");
    return;
  }
  const PatchFit& f = d.patches[0].fit;
  if (f.trajectory) {
    const LineTrajectory& tr = *f.trajectory;
    double max_angle = 0, max_offset = 0, max_slide = 0;
    for (size_t k = 0; k < tr.a.size(); ++k) {
      const LineError e = line_error(tr.a[k], tr.b[k]);
      max_angle = std::max(max_angle, e.angle_deg);
      max_offset = std::max(max_offset, e.offset);
      max_slide = std::max(max_slide, std::abs(e.slide));
    }
    for (int q = 0; q <= 10; ++q) {
      const size_t k = std::min(tr.a.size() - 1, size_t(q) * (tr.a.size() - 1) / 10);
      const LineError e = line_error(tr.a[k], tr.b[k]);
      fmt::print("    position {:4}: t {:.3f} angle {:.3f} deg offset {:.2e} slide {:+.2e} F {:.1e}\n", k, e.t, e.angle_deg,
                 e.offset, e.slide, tr.F[k]);
    }
    const LineError e0 = line_error(tr.a.front(), tr.b.front()), e1 = line_error(tr.a.back(), tr.b.back());
    fmt::print("auto trajectory: {} positions, t {:.3f} .. {:.3f} (stops {}/{}), length {:.4f} (exact {:.4f}), "
               "drift: angle <= {:.2f} deg, offset <= {:.2e}, slide <= {:.2e}\n",
               tr.a.size(), e0.t, e1.t, to_string(tr.stop_backward), to_string(tr.stop_forward),
               (tr.b[0] - tr.a[0]).norm(), (B(0.5) - A(0.5)).norm(), max_angle, max_offset, max_slide);
  }
  {
    PatchFit u;
    u.initial = f.initial;
    u.fit = optimize_motion(surface, f.initial, o.patch.fit);
    PatchOptions pu = o.patch;
    pu.trim_gouges = false;
    u = machine_and_trim(surface, std::move(u), pu);
    const LineError r0 = line_error(u.fit.rails.a.point(0), u.fit.rails.b.point(0)),
                    r1 = line_error(u.fit.rails.a.point(1), u.fit.rails.b.point(1));
    fmt::print("auto fit untrimmed: eps_ini {:.2e} eps_opt {:.2e} ({} it, {}), coverage {:.1f}%, overcut {:.2e}, "
               "rails t {:.3f} .. {:.3f}\n",
               u.fit.eps_ini.max, u.fit.eps_opt.max, u.fit.iterations, to_string(u.fit.status), 100 * u.coverage,
               worst_overcut(u.machined.design_deviation, {&u.machined}), r0.t, r1.t);
    print_miss_map(u.machined.design_deviation, g.n_s, g.n_t, tol);
    for (int again = 0; again < 2; ++again) {
      PatchFit w;
      w.initial = u.fit.rails;
      w.fit = optimize_motion(surface, w.initial, o.patch.fit);
      w = machine_and_trim(surface, std::move(w), pu);
      fmt::print("refit from the fitted rails: eps_ini {:.2e} eps_opt {:.2e} ({} it, {}), coverage {:.1f}%, overcut {:.2e}\n",
                 w.fit.eps_ini.max, w.fit.eps_opt.max, w.fit.iterations, to_string(w.fit.status), 100 * w.coverage,
                 worst_overcut(w.machined.design_deviation, {&w.machined}));
      u = std::move(w);
    }
  }
  fmt::print("auto patch (trimmed): t [{:.3f}, {:.3f}], coverage {:.1f}% (union {:.1f}%), gouges {}\n", f.t_from, f.t_to,
             100 * f.coverage, 100 * d.coverage, f.gouges);
  print_miss_map(f.machined.design_deviation, g.n_s, g.n_t, tol);
}

}  // namespace

int main(int argc, char** argv) {
  const std::string mode = argc > 1 ? argv[1] : "";
  if (mode == "envelopes") {
    envelopes(argc > 2 && std::string(argv[2]) == "line", argc > 3 ? argv[3] : "");
  } else if ((mode == "diag" || mode == "diag-offsets") && argc > 2) {
    diagnose(argv[2], argc > 3 ? std::stoi(argv[3]) : 10, argc > 4 ? std::stoi(argv[4]) : 16, mode == "diag-offsets",
             argc > 5 ? std::stoi(argv[5]) : 66, argc > 6 ? std::stoi(argv[6]) : 200);
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
