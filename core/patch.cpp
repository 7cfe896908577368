#include "core/patch.h"

#include <algorithm>

#include <chrono>
#include <cmath>

#include "core/errors.h"

namespace flankcam {

const char* to_string(PatchInit i) { return i == PatchInit::Lines ? "lines" : "line"; }

namespace {
double seconds_since(std::chrono::steady_clock::time_point t0) {
  return std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
}
}  // namespace

PatchFit fit_patch(const SurfaceIndex& surface, const PatchSpec& spec, const PatchOptions& o) {
  const std::string where = "patch '" + spec.name + "': ";
  const auto stage = [&](const std::string& what) {
    if (o.on_stage) o.on_stage(what);
  };
  if (spec.init == PatchInit::Lines && spec.lines.size() < 2)
    throw InputError(where + "init: lines needs at least 2 lines");
  if (spec.init == PatchInit::Line && spec.lines.size() != 1) throw InputError(where + "init: line needs exactly one line");
  for (size_t k = 0; k < spec.lines.size(); ++k)
    if (!((spec.lines[k].b - spec.lines[k].a).norm() > 1e-9))
      throw InputError(where + "line " + std::to_string(k) + " has zero length");
  if (spec.rail != 0 && spec.rail != 1) throw InputError(where + "rail: must be 0 (tool tip, a) or 1 (b)");

  if (!(o.tolerance > 0)) throw InputError(where + "tolerance: must be positive");
  PatchFit out;
  const auto t0 = std::chrono::steady_clock::now();
  try {
    if (spec.init == PatchInit::Lines) {
      stage("surface-driven rails through " + std::to_string(spec.lines.size()) + " lines");
      out.initial = rails_from_lines(spec.lines, spec.rail, spec.length, o.fit);
    } else {
      stage("exploring the user line");
      out.explored = explore_line(surface, spec.lines[0].a, spec.lines[0].b, o.exploration);
      stage("propagating the line");
      out.trajectory = propagate_line(surface, out.explored->a, out.explored->b, o.propagation);
      out.initial = rails_from_trajectory(*out.trajectory, o.fit);
    }
    out.seconds_init = seconds_since(t0);
    stage("optimising rails and radii");
    const auto t1 = std::chrono::steady_clock::now();
    FitOptions plain = o.fit;
    plain.check = {};
    out.fit = optimize_motion(surface, out.initial, plain);
    out.seconds_opt = seconds_since(t1);
  } catch (const InputError& e) {
    throw InputError(where + e.what());
  }
  stage("machined envelope and deviation");
  if (!o.fit.check.part) return machine_and_trim(surface, std::move(out), o);
  const auto t2 = std::chrono::steady_clock::now();
  out = with_check(surface, std::move(out), o);
  out.seconds_opt += seconds_since(t2);
  return out;
}

PatchFit with_check(const SurfaceIndex& surface, PatchFit plain, const PatchOptions& o) {
  if (!o.fit.check.part) return machine_and_trim(surface, std::move(plain), o);
  const CheckProfile profile = check_profile(plain.fit.rails, plain.fit.tool, o.fit.check, 2 * o.fit.samples_t, o.fit.samples_s);
  const bool clear = std::all_of(profile.intrusion.begin(), profile.intrusion.end(), [](double v) { return !(v > 0); });
  PatchFit trimmed_plain = machine_and_trim(surface, plain, o);
  if (clear) return trimmed_plain;
  if (o.on_stage) o.on_stage("refitting with the part as a check surface");
  PatchFit refit = plain;
  refit.fit = optimize_motion(surface, plain.fit.rails, o.fit);
  refit.fit.eps_ini = plain.fit.eps_ini;
  refit.fit.iterations += plain.fit.iterations;
  refit = machine_and_trim(surface, std::move(refit), o);
  const auto good = [](const PatchFit& f) { return !f.check_refused && !(f.check_intrusion > 0) && !f.gouges; };
  // A refit that keeps clear by fitting Φ much worse is no way out.
  const bool a = good(trimmed_plain),
             b = good(refit) && refit.fit.eps_opt.max <= std::max(o.tolerance, 2 * plain.fit.eps_opt.max);
  if (a != b) return b ? refit : trimmed_plain;
  if (a) return refit.coverage > trimmed_plain.coverage ? refit : trimmed_plain;
  return trimmed_plain;  // neither clear: the plain fit, reported with its collisions
}

namespace {
// Rows of Ω (t) without a point below Φ by more than `tolerance`: an Ω vertex, or a Φ vertex whose
// closest Ω point lies in the row.
std::vector<char> ungouged_rows(const MachinedSurface& ms, double tolerance) {
  const int n_t = ms.omega.n_t, n_s = ms.omega.n_s;
  std::vector<char> ok(size_t(n_t), 1);
  for (int i = 0; i < n_t; ++i)
    for (int j = 0; j < n_s; ++j) {
      const double d = ms.omega_deviation[size_t(i) * n_s + j];
      if (std::isfinite(d) && d < -tolerance) ok[size_t(i)] = 0;
    }
  // Φ's vertices below Ω (measured from Φ's side) mark the row of their closest point too.
  for (size_t v = 0; v < ms.design_deviation.size(); ++v)
    if (ms.design_deviation[v] < -tolerance && ms.design_row[v] >= 0) ok[size_t(ms.design_row[v])] = 0;
  return ok;
}

// The longest run of good rows as [t0, t1] (rows at t = i / (n - 1)); {0, 0} with fewer than two.
std::pair<double, double> longest_run(const std::vector<char>& ok) {
  const int n = int(ok.size());
  int best_lo = 0, best_len = 0;
  for (int i = 0; i < n;) {
    if (!ok[size_t(i)]) {
      ++i;
      continue;
    }
    int j = i;
    while (j < n && ok[size_t(j)]) ++j;
    if (j - i > best_len) best_len = j - i, best_lo = i;
    i = j;
  }
  if (best_len < 2) return {0.0, 0.0};
  return {double(best_lo) / (n - 1), double(best_lo + best_len - 1) / (n - 1)};
}

// The rows (as many as Ω's) where the tool keeps out of the check surface, and the worst row.
std::vector<char> clear_rows(const PatchFit& f, const PatchOptions& o, CheckProfile& profile) {
  const int rows = f.machined.omega.n_t;
  profile = check_profile(f.fit.rails, f.fit.tool, o.fit.check, rows, o.fit.samples_s);
  std::vector<char> ok(size_t(rows), 1);
  for (int i = 0; i < rows; ++i) ok[size_t(i)] = !(profile.intrusion[size_t(i)] > 0);
  return ok;
}
}  // namespace

std::pair<double, double> ungouged_range(const MachinedSurface& ms, double tolerance) {
  return longest_run(ungouged_rows(ms, tolerance));
}

PatchFit machine_and_trim(const SurfaceIndex& surface, PatchFit out, const PatchOptions& o) {
  out.machined = machined_surface(surface, out.fit.rails, out.fit.tool, o.machined);
  out.t_from = 0;
  out.t_to = 1;
  const bool check = o.fit.check.part != nullptr;
  CheckProfile profile;
  // The rows to keep: not gouging Φ (trim_gouges) and clear of the check surface (with a part).
  const auto keep = [&] {
    std::vector<char> ok(size_t(out.machined.omega.n_t), 1);
    if (o.trim_gouges) ok = ungouged_rows(out.machined, o.tolerance);
    if (check) {
      const std::vector<char> clear = clear_rows(out, o, profile);
      for (size_t i = 0; i < ok.size(); ++i) ok[i] = ok[i] && clear[i];
    }
    return ok;
  };
  // Trimmed rails are sampled anew, so the ends are checked again (a few rounds).
  for (int round = 0; (o.trim_gouges || check) && round < 3; ++round) {
    const std::vector<char> ok = keep();
    if (std::all_of(ok.begin(), ok.end(), [](char c) { return c != 0; })) break;
    if (check && round == 0) {  // why: the worst intrusion before trimming
      const auto worst = std::max_element(profile.intrusion.begin(), profile.intrusion.end());
      const size_t i = size_t(worst - profile.intrusion.begin());
      out.check_trim = {profile.body[i] != 0, *worst, profile.at[i]};
    }
    const auto [t0, t1] = longest_run(ok);
    if (!(t1 - t0 > 0.02)) {  // nothing (or almost nothing) can be cut: left as it is, reported
      out.check_refused = check && std::any_of(profile.intrusion.begin(), profile.intrusion.end(), [](double v) { return v > 0; });
      break;
    }
    const double w = out.t_to - out.t_from;
    out.t_to = out.t_from + w * t1;
    out.t_from += w * t0;
    out.fit.rails = trimmed(out.fit.rails, t0, t1);
    out.machined = machined_surface(surface, out.fit.rails, out.fit.tool, o.machined);
  }
  const auto [t0, t1] = ungouged_range(out.machined, o.tolerance);
  out.gouges = !(t0 == 0.0 && t1 == 1.0);
  if (check) {
    (void)clear_rows(out, o, profile);
    out.check_intrusion = *std::max_element(profile.intrusion.begin(), profile.intrusion.end());
  }
  out.coverage = coverage(surface.mesh(), out.machined.design_deviation, o.tolerance);
  return out;
}

Rails trimmed(const Rails& r, double t0, double t1) {
  const int samples = std::max(8 * r.a.size(), 200);
  Eigen::MatrixXd A(samples, 3), B(samples, 3);
  const std::vector<double> ts = uniform_parameters(samples);
  for (int i = 0; i < samples; ++i) {
    const double t = t0 + (t1 - t0) * ts[size_t(i)];
    A.row(i) = r.a.point(t).transpose();
    B.row(i) = r.b.point(t).transpose();
  }
  return {fit_bspline(A, ts, r.a.size()), fit_bspline(B, ts, r.b.size()), r.length};
}

PatchFit reversed(PatchFit f) {
  std::swap(f.initial.a, f.initial.b);
  std::swap(f.fit.rails.a, f.fit.rails.b);
  std::reverse(f.fit.tool.D.begin(), f.fit.tool.D.end());
  return f;
}

}  // namespace flankcam
