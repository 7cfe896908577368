#include "core/patch.h"

#include <fmt/format.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <tuple>

#include "core/collision.h"
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
    // Radii that describe no tool (a meridian folding back on itself has no envelope, no end, no
    // grinding profile): refused here, before anything is machined with them.
    if (const std::optional<ToolDefect> d = tool_defect(out.fit.tool, out.fit.rails.length))
      throw InputError(fmt::format("the fitted radii describe no tool: {} at {:.0f}% of its length from its tip end; set "
                                   "tool.min_diameter and tool.max_cone_angle, or start the patch elsewhere",
                                   d->what, 100 * d->s));
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
  const auto [best_lo, best_len] = longest_set_run(ok);
  if (best_len < 2) return {0.0, 0.0};
  const double n = double(ok.size());
  return {double(best_lo) / (n - 1), double(best_lo + best_len - 1) / (n - 1)};
}

// The cutter at each of Ω's rows judged as the collision check judges the program: check_collisions
// on the program's own poses (`poses` of them at t_j = j / (poses - 1), as the pipeline posts the
// rails), the motion between them straight and subdivided by half of `step`; a hit between poses
// j and j + 1 counts for every row in [t_j, t_j+1]. (The machine moves straight between the posted
// poses: on the HECC diffuser's trailing edge those chords cut 0.021 mm into the vane where Ω's 300
// rows found nothing, and the program was refused.) Per row, the deepest cutter hit into `target`
// beyond `tolerance` (-inf: none), and where, the cutter sampled for `slab_tolerance` (the final
// check's tolerance). `design`: hits within design_within of Φ are Φ's (left_to_design), as in the
// collision check and the back-simulation.
struct CutterHits {
  std::vector<double> depth;
  std::vector<Eigen::Vector3d> at;
};
CutterHits cutter_hits(const SurfaceIndex& target, const Rails& rails, const ToolRadius& tool, const std::optional<ToolEnd>& end, int rows,
                       int pose_count, double tolerance, double slab_tolerance, double step, const SurfaceIndex* design,
                       double design_within) {
  CutterHits out{std::vector<double>(size_t(rows), -INFINITY), std::vector<Eigen::Vector3d>(size_t(rows), Eigen::Vector3d::Zero())};
  // The cutter as the job's collision check sees it: with a rounded end (MachinedSurfaceOptions::end),
  // that end; flat, which holds it, where the tool is too short for it.
  ToolAssembly cutter;
  cutter.cutter = cutter_union(tool, rails.length);
  if (end && end->kind != EndKind::Flat) try {
      cutter.cutter = checked_end_profile(cutter.cutter, meridian(tool, rails.length), *end).profile;
    } catch (const InputError&) {
    }
  const int P = std::max(pose_count, 2);
  std::vector<ToolPose> poses;
  for (int j = 0; j < P; ++j) {
    const double t = double(j) / (P - 1);
    const Eigen::Vector3d a = rails.a.point(t), b = rails.b.point(t);
    poses.push_back({a, (b - a).normalized()});
  }
  CollisionOptions co;
  co.gouge_tolerance_mm = tolerance;
  co.slab_tolerance_mm = slab_tolerance;
  co.clearance_mm = step;
  co.design = design;
  co.design_within_mm = design_within;
  CollisionReport r;
  try {
    r = check_collisions(target, poses, cutter, co);
  } catch (const InputError&) {  // beyond the check's bounds: the fit's own samples decide alone
    return out;
  }
  for (const CollisionInterval& iv : r.intervals) {
    const double t0 = double(iv.pose_begin) / (P - 1), t1 = double(iv.pose_end) / (P - 1);
    const int i0 = std::max(0, int(std::floor(t0 * (rows - 1) + 1e-9)));
    const int i1 = std::min(rows - 1, int(std::ceil(t1 * (rows - 1) - 1e-9)));
    for (int i = i0; i <= i1; ++i)
      if (iv.max_depth_mm > out.depth[size_t(i)]) out.depth[size_t(i)] = iv.max_depth_mm, out.at[size_t(i)] = iv.at;
  }
  return out;
}

// The share of the tolerance the trims keep in hand: a row is kept when the cutter enters Φ or the
// part by at most (1 - kTrimMargin) of its tolerance, so that the program, which follows the fit to
// ~2e-4 mm and is swept between its blocks, is not refused at the tolerance itself (HECC impeller:
// the fit trimmed at exactly 0.02 mm, the collision check then found 0.0200x mm and refused it).
constexpr double kTrimMargin = 0.1;

// The design surface's share of the part as the trims and the collision check see it: a cutter hit
// within the twin's sag plus Φ's tolerance of Φ (left_to_design), both unit frame.
double design_within(const PatchOptions& o) { return o.fit.check.twin_sag + o.tolerance; }

// The step the motion between Ω's rows is checked at (cutter_hits): the clearance, else ten times the
// tolerance (both unit frame).
double hit_step(const PatchOptions& o) { return o.fit.check.clearance > 0 ? o.fit.check.clearance : 10 * o.tolerance; }

// The check surface at Ω's rows: the fit's samples (shank, holder and cutter; intrusion beyond the check
// tolerance) and the cutter as the collision check judges it (hits deeper than `threshold`).
struct PartCheck {
  CheckProfile profile;
  CutterHits hits;
};
PartCheck part_check(const SurfaceIndex& surface, const PatchFit& f, const PatchOptions& o, double threshold) {
  const int rows = f.machined.omega.n_t;
  const CheckSurface& c = o.fit.check;
  return {check_profile(f.fit.rails, f.fit.tool, c, rows, o.fit.samples_s, true, &surface, design_within(o)),
          cutter_hits(*c.part, f.fit.rails, f.fit.tool, o.machined.end, rows, o.fit.samples_t, threshold, c.tolerance, hit_step(o), &surface,
                      design_within(o))};
}
// Its intrusion per row with the cutter's hits counted beyond `threshold` (those deeper than it): the
// worst of the two, and where.
CheckProfile intrusion(const PartCheck& pc, double threshold) {
  CheckProfile p = pc.profile;
  for (size_t i = 0; i < p.intrusion.size(); ++i) {
    const double d = pc.hits.depth[i];
    if (d > threshold && d - threshold > p.intrusion[i]) p.intrusion[i] = d - threshold, p.body[i] = 0, p.at[i] = pc.hits.at[i];
  }
  return p;
}
}  // namespace

ToolCut cut_tool(const Rails& r, const ToolRadius& tool, double lo, double hi) {
  ToolCut out{r, tool};
  if (r.a.size() == r.b.size()) {  // (1 - s) a(t) + s b(t) is the spline with the mixed control points
    out.rails.a.ctrl = (1 - lo) * r.a.ctrl + lo * r.b.ctrl;
    out.rails.b.ctrl = (1 - hi) * r.a.ctrl + hi * r.b.ctrl;
  } else {
    const int samples = 8 * std::max(r.a.size(), r.b.size());
    const std::vector<double> ts = uniform_parameters(samples);
    Eigen::MatrixXd A(samples, 3), B(samples, 3);
    for (int i = 0; i < samples; ++i) A.row(i) = r.point(ts[size_t(i)], lo).transpose(), B.row(i) = r.point(ts[size_t(i)], hi).transpose();
    out.rails.a = fit_bspline(A, ts, r.a.size());
    out.rails.b = fit_bspline(B, ts, r.b.size());
  }
  out.rails.length = r.length * (hi - lo);
  if (tool.shape == ToolShape::Cone) {
    out.tool.D = {tool.d(lo), tool.d(hi)};
  } else if (tool.shape == ToolShape::General) {
    const int K = int(tool.D.size()), samples = 16 * K;
    const std::vector<double> ss = uniform_parameters(samples);
    Eigen::MatrixXd P(samples, 1);
    // Below the tip (lo < 0: the cutter made longer there) the meridian goes on along its slope at
    // the tip; the spline itself would hold the tip's radius.
    const double slope = tool.profile().d_s(0);
    const auto radius = [&](double s) { return s < 0 ? tool.d(0) + s * slope : tool.d(s); };
    for (int i = 0; i < samples; ++i) P(i, 0) = radius(lo + (hi - lo) * ss[size_t(i)]);
    const BSpline f = fit_bspline(P, ss, K);
    out.tool.D.assign(f.ctrl.data(), f.ctrl.data() + K);
    for (int i = 0; i < samples; ++i) out.radius_error = std::max(out.radius_error, std::abs(out.tool.d(ss[size_t(i)]) - P(i, 0)));
  }
  return out;
}

namespace {
// Whether the tool's tip is the rails' a end: its holder end (CheckSurface::up, else b) is b.
bool tip_is_a(const Rails& r, const CheckSurface& c) { return !c.up || mean_axis(r).dot(*c.up) >= 0; }

// The longest stretch of t (over 2 m rows) along which the tool keeps out of the part by the check
// profile (hits next to Φ left to Φ, as the trim leaves them).
std::pair<double, double> clear_run(const SurfaceIndex& surface, const Rails& r, const ToolRadius& tool, const PatchOptions& o) {
  const int rows = 2 * o.fit.samples_t;
  const CheckProfile p = check_profile(r, tool, o.fit.check, rows, o.fit.samples_s, false, &surface, design_within(o));
  std::vector<char> ok(static_cast<size_t>(rows));
  for (int i = 0; i < rows; ++i) ok[size_t(i)] = !(p.intrusion[size_t(i)] > 0);
  return longest_run(ok);
}
// A cut of the tool (cut_tool) the fit may make: its radii within a tenth of the tolerance of the
// tool's, still a tool (tool_defect), within the constraints.
bool admissible_cut(const ToolCut& cut, const PatchOptions& o) {
  return !(cut.radius_error > 0.1 * o.tolerance) && !tool_defect(cut.tool, cut.rails.length) &&
         !(check_constraints(cut.tool, cut.rails.length, o.fit.constraints).violation > 0.01 * o.tolerance);
}
// The tool made longer by `e` (a share of its length) beyond its b end (at_b) or below its a end, the
// axis and side continued (cut_tool beyond [0, 1]); none when that is no cut the fit may make.
std::optional<ToolCut> longer_cut(const PatchFit& base, const PatchOptions& o, double e, bool at_b) {
  const Rails& r = base.fit.rails;
  ToolCut c = at_b ? cut_tool(r, base.fit.tool, 0, 1 + e) : cut_tool(r, base.fit.tool, -e, 1);
  if (!admissible_cut(c, o)) return std::nullopt;  // tool_defect in it refuses a tip radius not above 0
  return c;
}
// `base` with the rails and tool of `cut`.
PatchFit with_cut(PatchFit base, ToolCut cut) {
  base.fit.rails = std::move(cut.rails);
  base.fit.tool = std::move(cut.tool);
  return base;
}

// The cutter ground shorter at its tip end (the end away from the holder, CheckSurface::up) until it
// keeps out of the part: what stays of the tool sweeps the same surface, only the strip the cut-off
// length made is lost. Cuts of 5%, 10%, ... 60% of the length are tried; the one whose longest clear
// stretch of rows times its remaining length is largest is kept. It is then shortened by bisection
// (to 1/64 of a step) to the least cut that keeps the same clear stretch with half the check
// tolerance in hand (machine_and_trim's denser check trims at a margin of it): a 5% step of a 50 mm
// tool is 2.5 mm of flank left at the hub. Both cuts are returned, the least first, measured;
// with_check keeps the one that machines more. None when the
// tool is a fixed one (a catalogue or shared tool cannot be ground) or no cut helps.
std::vector<PatchFit> cut_at_tip(const SurfaceIndex& surface, const PatchFit& plain, const PatchOptions& o) {
  if (o.fit.fixed_tool) return {};
  const Rails& r = plain.fit.rails;
  const bool tip_at_a = tip_is_a(r, o.fit.check);
  const auto cut_by = [&](double c) {
    return tip_at_a ? cut_tool(r, plain.fit.tool, c, 1) : cut_tool(r, plain.fit.tool, 0, 1 - c);
  };
  constexpr double step = 0.05;
  double best_score = 0, best_c = 0, best_run = 0;
  std::optional<ToolCut> best;
  for (int k = 1; k <= 12; ++k) {
    const double c = step * k;
    ToolCut cut = cut_by(c);
    if (!admissible_cut(cut, o)) continue;
    const auto [t0, t1] = clear_run(surface, cut.rails, cut.tool, o);
    const double score = (t1 - t0) * (1 - c);
    if (score > best_score) best_score = score, best_c = c, best_run = t1 - t0, best = std::move(cut);
    if (t0 == 0.0 && t1 == 1.0) break;  // clear everywhere: a longer cut only loses
  }
  if (!best) return {};
  std::vector<ToolCut> cuts{*best};
  PatchOptions strict = o;
  strict.fit.check.tolerance *= 0.5;
  std::optional<ToolCut> least;
  for (double lo = best_c - step, hi = best_c; hi - lo > step / 64;) {
    const double c = 0.5 * (lo + hi);
    ToolCut cut = cut_by(c);
    bool keeps = admissible_cut(cut, o);
    if (keeps) {
      const auto [t0, t1] = clear_run(surface, cut.rails, cut.tool, strict);
      keeps = t1 - t0 >= best_run - 1e-12;
    }
    if (keeps) hi = c, least = std::move(cut);
    else lo = c;
  }
  if (least) cuts.insert(cuts.begin(), std::move(*least));
  if (o.on_stage)
    o.on_stage("tip shortened by " + std::to_string(int(std::lround(100 * (1 - cuts[0].rails.length / r.length)))) +
               "% of the tool length");
  std::vector<PatchFit> out;
  for (ToolCut& cut : cuts) {
    PatchFit f = with_cut(plain, std::move(cut));
    // Net of a lengthening at the tip (lengthened_at_tip) that is ground back here.
    const double net = f.tip_lengthened - (r.length - f.fit.rails.length);
    f.tip_lengthened = std::max(net, 0.0);
    f.tip_shortened = std::max(-net, 0.0);
    try {
      f.fit.eps_opt = sample_error(surface, f.fit.rails, f.fit.tool, o.fit);
    } catch (const InputError&) {
      continue;  // what stays of the tool is no longer over Φ
    }
    out.push_back(std::move(f));
  }
  return out;
}

// The cutter made longer at its holder end (the side continued beyond s = 1: exact for cylinders
// and cones, within a tenth of the tolerance for a general meridian, as cut_tool) so that the shank
// starts farther out: a flank whose edge the cutter's end reaches (the HECC diffuser's shroud side)
// had its shank pass that edge inside the clearance and the motion trimmed. Lengths of 1, 2, 4 and 8
// clearances are tried, within max_length; the shortest whose clear stretch is longest is kept
// (untrimmed: machine_and_trim judges the longer cutter against Φ and the part). None when the tool
// is a fixed one or no length helps.
std::optional<PatchFit> lengthened_at_holder(const SurfaceIndex& surface, const PatchFit& base, const PatchOptions& o) {
  if (o.fit.fixed_tool || !(o.fit.check.clearance > 0)) return std::nullopt;
  const Rails& r = base.fit.rails;
  const bool tip_at_a = tip_is_a(r, o.fit.check);
  const auto [b0, b1] = clear_run(surface, r, base.fit.tool, o);
  double best_run = b1 - b0;
  std::optional<ToolCut> best;
  for (const double k : {1.0, 2.0, 4.0, 8.0}) {
    std::optional<ToolCut> longer = longer_cut(base, o, k * o.fit.check.clearance / r.length, tip_at_a);
    if (!longer) continue;
    const auto [t0, t1] = clear_run(surface, longer->rails, longer->tool, o);
    if (t1 - t0 > best_run + 1e-9) best_run = t1 - t0, best = std::move(longer);
    if (t0 == 0.0 && t1 == 1.0) break;  // clear everywhere: longer only risks more
  }
  if (!best) return std::nullopt;
  PatchFit f = with_cut(base, std::move(*best));
  f.holder_lengthened = f.fit.rails.length - r.length;
  return f;
}

}  // namespace

std::optional<PatchFit> lengthened_at_tip(const PatchFit& base, const PatchOptions& o, double e) {
  const Rails& r = base.fit.rails;
  if (o.fit.fixed_tool || !(e > 0) || !tip_is_a(r, o.fit.check)) return std::nullopt;
  std::optional<ToolCut> longer = longer_cut(base, o, e / r.length, false);
  if (!longer) return std::nullopt;
  PatchFit out = with_cut(base, std::move(*longer));
  out.clear_part_adjustments();
  out.tip_lengthened = e;
  return out;
}

std::optional<PatchFit> lengthened_to_reach(const PatchFit& base, const PatchOptions& o, double e, bool at_b) {
  const Rails& r = base.fit.rails;
  if (o.fit.fixed_tool || !(e > 0)) return std::nullopt;
  std::optional<ToolCut> longer = longer_cut(base, o, e / r.length, at_b);
  if (!longer) return std::nullopt;
  PatchFit out = with_cut(base, std::move(*longer));
  out.reach_lengthened += e;
  return out;
}

PatchFit with_check(const SurfaceIndex& surface, PatchFit plain, const PatchOptions& options) {
  if (!options.fit.check.part) return machine_and_trim(surface, std::move(plain), options);
  PatchOptions o = options;
  // The holder end chosen by the part, and the tool turned so before it is judged: its tip at the a
  // end, where the machined surface sweeps the tool's end (MachinedSurfaceOptions::end). Every
  // motion below keeps that orientation.
  if (o.orient_by_part) {
    o.fit.check.up = holder_up(plain.fit.rails, plain.fit.tool, o.fit.check, 2 * o.fit.samples_t,
                               o.fit.check.up.value_or(mean_axis(plain.fit.rails)));
    if (mean_axis(plain.fit.rails).dot(*o.fit.check.up) < 0) plain = reversed(std::move(plain));
    o.fit.constraints.either_end = false;  // its tip is at a now: the tip's limits hold there alone
  }
  // Clear along the whole motion: machine_and_trim's check (as dense as the collision check) found
  // no intrusion to trim for (check_trim is set only for one).
  PatchFit best = machine_and_trim(surface, plain, o);
  if (!best.check_trim) return best;
  // The tool shortened at its tip (a hub under the flank's lower edge): clear, it is compared with the
  // trimmed plain motion by coverage (and replaces it when that is not clear).
  if (o.on_stage) o.on_stage("shortening the tool at its tip to keep out of the part");
  bool shortened = false;
  PatchFit base = plain;  // the untrimmed motion and tool of `best`
  for (PatchFit& cut : cut_at_tip(surface, plain, o)) {
    PatchFit m = machine_and_trim(surface, cut, o);
    if (machinable(m) && (!machinable(best) || m.coverage > best.coverage)) best = std::move(m), base = std::move(cut), shortened = true;
  }
  // Still trimmed for the shank or holder: the cutter made longer at its holder end.
  if (best.check_trim && best.check_trim->body)
    if (std::optional<PatchFit> longer = lengthened_at_holder(surface, base, o)) {
      if (o.on_stage) o.on_stage("cutter made longer at its holder end to keep the shank clear");
      PatchFit m = machine_and_trim(surface, std::move(*longer), o);
      if (machinable(m) && (!machinable(best) || m.coverage > best.coverage)) best = std::move(m);
    }
  // The tip was what entered the part (shortening it gained most), or no refit is wanted: a penalised
  // refit, which tilts the whole axis, is not tried (on the HECC impeller it never beat the shortened
  // tool, at ~10 s a patch).
  if (shortened || !o.refit_with_check) return best;
  if (o.on_stage) o.on_stage("refitting with the part as a check surface");
  PatchFit refit = plain;
  try {
    refit.fit = optimize_motion(surface, plain.fit.rails, o.fit);
  } catch (const InputError&) {
    return best;  // the penalties pushed the motion off Φ: no way out there
  }
  refit.fit.eps_ini = plain.fit.eps_ini;
  refit.fit.iterations += plain.fit.iterations;
  refit = machine_and_trim(surface, std::move(refit), o);
  // A refit that keeps clear by fitting Φ much worse is no way out.
  const bool a = machinable(best);
  const bool b = machinable(refit) && refit.fit.eps_opt.max <= std::max(o.tolerance, 2 * plain.fit.eps_opt.max);
  if (a != b) return b ? refit : best;
  if (a && refit.coverage > best.coverage) return refit;
  return best;  // the better clear one, or neither clear: reported with its collisions
}

std::pair<double, double> ungouged_range(const MachinedSurface& ms, double tolerance) {
  return longest_run(ungouged_rows(ms, tolerance));
}

PatchFit machine_and_trim(const SurfaceIndex& surface, PatchFit out, const PatchOptions& o) {
  out.machined = machined_surface(surface, out.fit.rails, out.fit.tool, o.machined);
  out.t_from = 0;
  out.t_to = 1;
  const bool check = o.fit.check.part != nullptr;
  const int rows = out.machined.omega.n_t;
  // With a part (a job that is collision-checked and posted) or the solid cutter judged against Φ the
  // trims keep kTrimMargin of the tolerances in hand; otherwise they trim at Φ's tolerance.
  const bool solid = o.trim_gouges && (check || o.solid_cutter_on_phi);
  const double phi_keep = solid ? (1 - kTrimMargin) * o.tolerance : o.tolerance;
  const double part_keep = (1 - kTrimMargin) * o.fit.check.tolerance;
  // The last evaluation of the motion (keep()), and whether the motion has changed since: the final
  // judgement at the full tolerances is derived from it (a hit deeper than a tolerance is deeper than
  // the trim's threshold too), or it is evaluated anew.
  CutterHits phi_hits;  // `solid`: the cutter against Φ as the collision check sees it
  PartCheck part;
  CheckProfile profile;  // part's intrusion at the trim's threshold
  bool current = false;
  // The rows to keep: not gouging Φ (trim_gouges: Ω's samples against Φ and, `solid`, the cutter
  // against Φ as the collision check judges it, whose solid cutter with flat ends sees what Ω's side
  // envelope does not, its rims at Φ's edges) and clear of the check surface (with a part).
  const auto keep = [&] {
    std::vector<char> ok(size_t(rows), 1);
    if (o.trim_gouges) {
      ok = ungouged_rows(out.machined, phi_keep);
      if (solid) {
        phi_hits =
            cutter_hits(surface, out.fit.rails, out.fit.tool, o.machined.end, rows, o.fit.samples_t, phi_keep, o.tolerance, hit_step(o), nullptr, 0);
        for (size_t i = 0; i < ok.size(); ++i) ok[i] = ok[i] && !std::isfinite(phi_hits.depth[i]);
      }
    }
    if (check) {
      part = part_check(surface, out, o, part_keep);
      profile = intrusion(part, part_keep);
      for (size_t i = 0; i < ok.size(); ++i) ok[i] = ok[i] && !(profile.intrusion[i] > 0);
    }
    current = true;
    return ok;
  };
  // Trimmed rails are sampled anew, so the ends are checked again (a few rounds).
  for (int round = 0; (o.trim_gouges || check) && round < 3; ++round) {
    const std::vector<char> ok = keep();
    if (std::all_of(ok.begin(), ok.end(), [](char c) { return c != 0; })) break;
    if (check && round == 0) {  // why: the worst intrusion before trimming (none: Φ's gouges were why)
      const auto worst = std::max_element(profile.intrusion.begin(), profile.intrusion.end());
      const size_t i = size_t(worst - profile.intrusion.begin());
      if (*worst > 0) out.check_trim = {profile.body[i] != 0, *worst, profile.at[i]};
    }
    const auto [t0, t1] = longest_run(ok);
    if (!(t1 - t0 > 0.02)) {  // nothing (or almost nothing) can be cut: left as it is, reported
      out.check_refused = check && std::any_of(profile.intrusion.begin(), profile.intrusion.end(), [](double v) { return v > 0; });
      break;
    }
    std::tie(out.t_from, out.t_to) = kept_within(out.t_from, out.t_to, t0, t1);
    out.fit.rails = trimmed(out.fit.rails, t0, t1);
    out.machined = machined_surface(surface, out.fit.rails, out.fit.tool, o.machined);
    current = false;
  }
  // ε of the motion as kept: the trimmed-off stretch (where the motion may leave Φ by millimetres)
  // is not machined, so it is not what the patch's ε reports.
  if (out.t_from > 0 || out.t_to < 1) {
    try {
      out.fit.eps_opt = sample_error(surface, out.fit.rails, out.fit.tool, o.fit);
    } catch (const InputError&) {
      // no sample of the kept stretch lies over Φ: the whole motion's ε stays
    }
  }
  const auto [t0, t1] = ungouged_range(out.machined, o.tolerance);
  out.gouges = !(t0 == 0.0 && t1 == 1.0);
  if ((check || solid) && !current) (void)keep();
  if (solid && !out.gouges)
    out.gouges = std::any_of(phi_hits.depth.begin(), phi_hits.depth.end(), [&](double d) { return d > o.tolerance; });
  if (check) {
    const CheckProfile final_profile = intrusion(part, o.fit.check.tolerance);
    out.check_intrusion = *std::max_element(final_profile.intrusion.begin(), final_profile.intrusion.end());
  }
  out.coverage = coverage(surface.mesh(), out.machined.design_deviation, o.tolerance);
  return out;
}

bool machinable(const PatchFit& f) {
  return !tool_defect(f.fit.tool, f.fit.rails.length) && !f.gouges && !f.check_refused && !(f.check_intrusion > 0);
}

std::pair<size_t, size_t> longest_set_run(const std::vector<char>& ok) {
  size_t best_lo = 0, best_len = 0;
  for (size_t i = 0; i < ok.size();) {
    if (!ok[i]) {
      ++i;
      continue;
    }
    size_t j = i;
    while (j < ok.size() && ok[j]) ++j;
    if (j - i > best_len) best_len = j - i, best_lo = i;
    i = j;
  }
  return {best_lo, best_len};
}

namespace {
// The rails over [t0, t1] of `point(rail, t)` (rail 0: a, 1: b), reparametrised to [0, 1] by least
// squares on dense samples (same control point count).
template <class Point>
Rails resampled(const Rails& r, double t0, double t1, Point point) {
  const int samples = std::max(8 * r.a.size(), 200);
  Eigen::MatrixXd A(samples, 3), B(samples, 3);
  const std::vector<double> ts = uniform_parameters(samples);
  for (int i = 0; i < samples; ++i) {
    const double t = t0 + (t1 - t0) * ts[size_t(i)];
    A.row(i) = point(0, t).transpose();
    B.row(i) = point(1, t).transpose();
  }
  return {fit_bspline(A, ts, r.a.size()), fit_bspline(B, ts, r.b.size()), r.length};
}
const BSpline& rail(const Rails& r, int k) { return k == 0 ? r.a : r.b; }
}  // namespace

Rails trimmed(const Rails& r, double t0, double t1) {
  return resampled(r, t0, t1, [&](int k, double t) { return rail(r, k).point(t); });
}

Rails continued(const Rails& r, double before, double after) {
  // Each rail beyond an end along its chord over the last `step` of t (a least-squares spline's end
  // derivatives swing; its end span's cubic continued leaves the motion within a tenth of its length).
  constexpr double step = 0.05;
  return resampled(r, -before, 1 + after, [&](int k, double t) -> Eigen::Vector3d {
    const BSpline& c = rail(r, k);
    if (t < 0) return c.point(0) + t * (c.point(step) - c.point(0)) / step;
    if (t > 1) return c.point(1) + (t - 1) * (c.point(1) - c.point(1 - step)) / step;
    return c.point(t);
  });
}

Rails anchored(const Rails& original, const Rails& further, double before, double after, double blend) {
  const double span = 1 + before + after;
  return resampled(original, -before, 1 + after, [&](int k, double t) -> Eigen::Vector3d {
    const Eigen::Vector3d f = rail(further, k).point((t + before) / span);
    if (t <= 0 || t >= 1) return f;
    double l = 0;  // the share of `further` inside a continued end
    if (before > 0 && t < blend) l = 1 - t / blend;
    if (after > 0 && t > 1 - blend) l = std::max(l, 1 - (1 - t) / blend);
    return (1 - l) * rail(original, k).point(t) + l * f;
  });
}

std::pair<double, double> kept_within(double from, double to, double t0, double t1) {
  const double w = to - from;
  return {t0 == 0 ? from : from + w * t0, t1 == 1 ? to : from + w * t1};
}

PatchFit reversed(PatchFit f) {
  std::swap(f.initial.a, f.initial.b);
  std::swap(f.fit.rails.a, f.fit.rails.b);
  std::reverse(f.fit.tool.D.begin(), f.fit.tool.D.end());
  return f;
}

}  // namespace flankcam
