#include "pipeline/fit_stage.h"

#include "cad/cad_reader.h"

#include <fmt/format.h>

#include <algorithm>
#include <cmath>
#include <memory>
#include <optional>
#include <tuple>

#include "core/check_surface.h"
#include "core/detect.h"
#include "core/errors.h"
#include "core/file_probe.h"
#include "core/number_format.h"
#include "postproc/apt.h"
#include "postproc/report_svg.h"
#include "postproc/tool_export.h"
#include "postproc/verify.h"

namespace flankcam::pipeline {

double round_mm(double x) { return std::isfinite(x) ? std::round(x * 1e6) / 1e6 + 0.0 : x; }  // + 0.0: no "-0"

namespace {
Eigen::Vector3d point(const std::array<double, 6>& l, int end) { return {l[3 * end], l[3 * end + 1], l[3 * end + 2]}; }

PatchSpec unit_spec(const PatchJob& p, const Similarity& frame) {
  PatchSpec s;
  s.name = p.name;
  s.init = p.init;
  s.rail = p.rail;
  s.length = p.length_mm > 0 ? frame.length_to_unit(p.length_mm) : 0;
  for (const auto& l : p.lines_mm) s.lines.push_back({frame.to_unit(point(l, 0)), frame.to_unit(point(l, 1))});
  return s;
}

// (z, r) points of the unit frame in mm.
std::vector<Eigen::Vector2d> profile_mm(const Similarity& fr, std::vector<Eigen::Vector2d> zr) {
  for (Eigen::Vector2d& p : zr) p *= fr.length_to_mm(1.0);
  return zr;
}

// The tool as ground, mm: the union of its spheres d(s) between its end planes (cutter_union), the
// one cutter of the fit's trim, the collision check, the back-simulation, the tool files and the
// CL-data's profile (so `verify`, reading that profile, judges the cutter the run judged).
std::vector<Eigen::Vector2d> tool_profile_mm(const Similarity& fr, const FitResult& r) {
  return profile_mm(fr, cutter_union(r.tool, r.rails.length));
}

// The side meridian (the envelope of the circles d(z), meridian()) a rounded end is cut into.
std::vector<Eigen::Vector2d> side_meridian_mm(const Similarity& fr, const FitResult& r) {
  return profile_mm(fr, meridian(r.tool, r.rails.length));
}

nlohmann::ordered_json vec_mm(const Eigen::Vector3d& v) { return {round_mm(v.x()), round_mm(v.y()), round_mm(v.z())}; }

nlohmann::ordered_json error_report(const ErrorStats& e, const Similarity& frame) {
  nlohmann::ordered_json h = nlohmann::ordered_json::array();
  for (size_t k = 0; k < e.histogram.size(); ++k)
    h.push_back({{"from_mm", round_mm(frame.length_to_mm(e.bin_edges[k]))},
                 {"to_mm", round_mm(frame.length_to_mm(e.bin_edges[k + 1]))},
                 {"samples", e.histogram[k]}});
  return {{"max_relative", e.max},
          {"max_mm", round_mm(frame.length_to_mm(e.max))},
          {"mean_relative", e.mean},
          {"mean_mm", round_mm(frame.length_to_mm(e.mean))},
          {"samples", e.samples},
          {"excluded_beyond_boundary", e.excluded},
          {"histogram", h}};
}
}  // namespace

std::vector<Eigen::Vector2d> body_samples(const HolderJob& h, const Similarity& fr) {
  struct Piece {
    double length, r0, r1;
  };
  const std::vector<Piece> pieces{{h.shank_length, h.shank_diameter / 2, h.shank_diameter / 2},
                                  {h.length, h.diameter / 2, h.diameter_far / 2},
                                  {h.cylinder_length, h.diameter_far / 2, h.diameter_far / 2}};
  double total = 0, r_min = INFINITY;
  for (const Piece& p : pieces)
    if (p.length > 0) total += p.length, r_min = std::min({r_min, p.r0, p.r1});
  std::vector<Eigen::Vector2d> out;
  if (!(total > 0)) return out;
  const double step = std::max(0.5 * r_min, total / 64);
  double start = 0;
  for (const Piece& p : pieces) {
    if (!(p.length > 0)) continue;
    const int k = std::max(1, int(std::ceil(p.length / step)));
    for (int i = 0; i <= k; ++i) {
      const double f = double(i) / k;
      // Shared with the previous piece's end unless the radius steps there.
      if (i == 0 && !out.empty() && std::abs(out.back().y() - fr.length_to_unit(p.r0)) < 1e-12) continue;
      out.emplace_back(fr.length_to_unit(start + f * p.length), fr.length_to_unit(p.r0 + f * (p.r1 - p.r0)));
    }
    start += p.length;
  }
  return out;
}

namespace {
ToolAssembly assembly_of(const Job& job, const Similarity& fr, const FitResult& r) {
  ToolAssembly a;
  a.cutter = tool_profile_mm(fr, r);
  const HolderJob& h = job.holder;
  a.shank_length = h.shank_length, a.shank_diameter = h.shank_diameter;
  a.holder_length = h.length, a.holder_diameter = h.diameter, a.holder_diameter_far = h.diameter_far;
  a.holder_cylinder_length = h.cylinder_length;
  return a;
}

}  // namespace

LoadedMesh load_job_surface(const Job& job, const Progress& progress) {
  const CadMesh surface = load_surface_file(
      job.surface.string(), job.surface_faces, job.surface_deflection_mm.value_or(surface_deflection_mm(job.tolerance_mm)));
  if (!surface.note.empty()) progress(job.surface.string() + ": " + surface.note);
  return surface.loaded;
}

std::optional<LoadedMesh> load_job_part(const Job& job) {
  if (!job.part_given) return std::nullopt;
  return load_part_file(job.part.string(), job.surface.string(), job.surface_faces,
                        job.part_deflection_mm.value_or(part_deflection_mm(job.clearance_mm)),
                        job.surface_deflection_mm.value_or(surface_deflection_mm(job.tolerance_mm)))
      .loaded;
}

namespace {
// How a patch's machined surface is judged: with the job's tool end swept, but for detected patches
// without a part: by the side envelope alone (a detected tool's tip end is known only when detect_job
// turns it afterwards). Detected with a part, the floor pass judged each patch so (CoverOptions::end);
// a held tool's patches skip that pass and are judged with the end only if their poses are cut short.
ToolEnd job_end(const Job& job, const Similarity& frame) {
  return ToolEnd{job.tool.end.kind, frame.length_to_unit(job.tool.end.corner_radius), frame.length_to_mm(1.0)};
}

MachinedSurfaceOptions machined_options(const Job& job, const Similarity& frame) {
  MachinedSurfaceOptions m;
  if (!job.cover || job.part_given) m.end = job_end(job, frame);
  return m;
}

// The fitted motion at its samples t_i in mm (part coordinates), with the overtravel poses.
std::vector<ToolPose> poses_mm(const Job& job, const Similarity& frame, const Rails& rails) {
  const int m = job.fit.samples_t;
  std::vector<ToolPose> poses;
  for (int i = 0; i < m; ++i) {
    const double t = double(i) / (m - 1);
    const Eigen::Vector3d a = frame.to_mm(rails.a.point(t)), b = frame.to_mm(rails.b.point(t));
    poses.push_back({a, (b - a).normalized()});
  }
  // overtravel: the motion continued by that many mm beyond both ends, along the tip's direction
  // of travel there, the axis held.
  if (job.overtravel_mm > 0 && poses.size() >= 2) {
    const auto beyond = [&](const ToolPose& end, const ToolPose& inner) {
      return ToolPose{end.tip + job.overtravel_mm * (end.tip - inner.tip).normalized(), end.axis};
    };
    const ToolPose first = beyond(poses[0], poses[1]), last = beyond(poses.back(), poses[poses.size() - 2]);
    poses.insert(poses.begin(), first);
    poses.push_back(last);
  }
  return poses;
}
}  // namespace

namespace {
// The run's collision check of a job's motions: the design surface in mm (contact points; it is the
// part too unless a separate one is given), and with a separate part the part without Φ's coarser
// twin (fit_job), judged with check_tolerance while the design surface is judged with the fitted
// tolerance.
class PartCheck {
 public:
  PartCheck(const Job& job, const FittedJob& f) : design_(f.surface.mesh) {
    if (f.check_part) check_index_.emplace(*f.check_part);
    o_.clearance_mm = job.clearance_mm;
    o_.gouge_tolerance_mm = job.tolerance_mm;
    o_part_ = o_;
    const CutJudgement judged = cut_judgement(job, f.check_twin_sag_mm);
    o_part_.gouge_tolerance_mm = judged.part_mm;
    o_part_.design = &design_;
    o_part_.design_within_mm = judged.design_within_mm;
  }
  PartCheck(const PartCheck&) = delete;
  PartCheck& operator=(const PartCheck&) = delete;
  const SurfaceIndex& design() const { return design_; }
  CollisionReport operator()(const std::vector<ToolPose>& poses, const ToolAssembly& assembly) const {
    CollisionReport r = check_collisions(design_, poses, assembly, o_);
    if (check_index_) {
      const CollisionReport c = check_collisions(*check_index_, poses, assembly, o_part_);
      r.intervals.insert(r.intervals.end(), c.intervals.begin(), c.intervals.end());
      r.positions_checked = std::max(r.positions_checked, c.positions_checked);
      r.queries += c.queries;
      std::stable_sort(r.intervals.begin(), r.intervals.end(), [](const CollisionInterval& a, const CollisionInterval& b) {
        return a.pose_begin < b.pose_begin;
      });
    }
    return r;
  }
  // The patch's motion and its earlier passes' (their poses, the same tool; their intervals index
  // their own poses, which index like the last pass's).
  CollisionReport patch(const FittedPatch& p) const {
    CollisionReport r = (*this)(p.poses, p.assembly);
    for (const PassMotion& pm : p.earlier_passes) {
      const CollisionReport c = (*this)(pm.poses, p.assembly);
      r.intervals.insert(r.intervals.end(), c.intervals.begin(), c.intervals.end());
      r.positions_checked += c.positions_checked;
    }
    return r;
  }

 private:
  SurfaceIndex design_;
  std::optional<SurfaceIndex> check_index_;
  CollisionOptions o_, o_part_;
};
}  // namespace

void check_job(const Job& job, FittedJob& f, const Progress& progress) {
  progress(fmt::format("collision checks against {} ({} triangles), clearance {} mm", job.part.string(),
                       f.part ? f.part->faces.size() : f.surface.mesh.faces.size(), job.clearance_mm));
  const PartCheck check(job, f);
  const SurfaceIndex& design = check.design();
  for (FittedPatch& p : f.patches) {
    const FitResult& r = p.fit.fit;
    // Radii that describe no tool (a stretch with few samples of Φ let them drift): nothing to check,
    // grind or post. Detection never keeps such a fit; a user's lines can lead to one.
    if (const std::optional<ToolDefect> d = tool_defect(r.tool, r.rails.length))
      throw InputError(fmt::format("patch {}: the fitted radii describe no tool: {} at {:.3f} mm from its tip end; set "
                                   "tool.min_diameter and tool.max_cone_angle, or start the patch elsewhere",
                                   p.job->name, d->what, d->s * f.frame.length_to_mm(r.rails.length)));
    p.poses = poses_mm(job, f.frame, r.rails);
    p.assembly = assembly_of(job, f.frame, r);
    // tool.end: the profile ends in it, and a rounded end is the cutter the check sees (tool_end.h).
    const EndProfile end = checked_end_profile(p.assembly.cutter, side_meridian_mm(f.frame, r), job.tool.end);
    p.profile_mm = end.profile;
    p.end_points = end.end_points;
    p.end_radius_mm = end.radius;
    if (job.tool.end.kind != EndKind::Flat) p.assembly = assembly_from_meridian(p.profile_mm, p.assembly);
    const double half = 0.5 * p.assembly.cutter_length();
    p.contacts.clear();
    for (const ToolPose& q : p.poses) p.contacts.push_back(design.closest(q.tip + half * q.axis).point);
    for (PassMotion& pm : p.earlier_passes) {  // earlier passes: their own poses, the same tool
      pm.poses = poses_mm(job, f.frame, pm.rails);
      pm.contacts.clear();
      for (const ToolPose& q : pm.poses) pm.contacts.push_back(design.closest(q.tip + half * q.axis).point);
    }
    p.collisions = check.patch(p);
    for (const std::string& line : collision_summary(p)) progress(line);
  }
}

void shorten_to_clear(const Job& job, FittedJob& f, const Progress& progress) {
  std::vector<std::optional<KeptPoses>> keep(f.patches.size());
  for (size_t k = 0; k < f.patches.size(); ++k) {
    const FittedPatch& p = f.patches[k];
    const size_t n = p.poses.size();
    if (p.collisions.clear() || n < 2) continue;
    // The longest run of poses in no interval: the positions between two of its poses are clear too
    // (an interval names the pose at or before each colliding position).
    std::vector<char> clear(n, 1);
    for (const CollisionInterval& iv : p.collisions.intervals)
      for (int i = std::max(iv.pose_begin, 0); i <= iv.pose_end && size_t(i) < n; ++i) clear[size_t(i)] = 0;
    const auto [best0, best_len] = longest_set_run(clear);
    // Three quarters of the motion at least: the run's check overrules the fit's near the ends of
    // what the fit kept (its samples missed a part point the check sees); a motion colliding over more
    // than a quarter is refused, its collisions reported, and so is any with the job's overtravel
    // (the overtravel poses beyond both ends are the user's: shortened, one would be lost).
    if (4 * best_len < 3 * n || job.overtravel_mm > 0) continue;
    const CollisionInterval& worst = *std::max_element(
        p.collisions.intervals.begin(), p.collisions.intervals.end(),
        [](const CollisionInterval& a, const CollisionInterval& b) { return a.max_depth_mm < b.max_depth_mm; });
    keep[k] = KeptPoses{best0, best0 + best_len - 1,
                        worst.max_depth_mm >= 0
                            ? fmt::format("beyond them the {} would {} {:.3f} mm deep", to_string(worst.component),
                                          worst.component == Component::Tool ? "gouge" : "collide", worst.max_depth_mm)
                            : fmt::format("beyond them the {} would come {:.3f} mm from the part, inside the clearance",
                                          to_string(worst.component), -worst.max_depth_mm)};
  }
  if (std::none_of(keep.begin(), keep.end(), [](const auto& k) { return k.has_value(); })) return;
  keep_poses(job, f, keep, &FittedPatch::kept_clear, "to their clear stretches", progress);
  // Checked again as they are now (the positions between the kept poses are those checked before, so
  // this finds nothing unless the kept motion differs from them): what is not clear is refused.
  const PartCheck check(job, f);
  for (size_t k = 0; k < f.patches.size(); ++k) {
    if (!keep[k]) continue;
    FittedPatch& p = f.patches[k];
    p.collisions = check.patch(p);
    for (const std::string& line : collision_summary(p)) progress(line);
  }
}

std::vector<std::string> collision_summary(const FittedPatch& p) {
  std::vector<std::string> out;
  for (const CollisionInterval& iv : p.collisions.intervals)
    out.push_back(iv.max_depth_mm >= 0
                      ? fmt::format("patch {}: {} {} at poses {}-{}, {:.3f} mm deep at ({:.3f}, {:.3f}, {:.3f})", p.job->name,
                                    to_string(iv.component), iv.component == Component::Tool ? "gouges" : "collides",
                                    iv.pose_begin, iv.pose_end, iv.max_depth_mm, iv.at.x(), iv.at.y(), iv.at.z())
                      : fmt::format("patch {}: {} inside the clearance at poses {}-{}, {:.3f} mm from the part at "
                                    "({:.3f}, {:.3f}, {:.3f})",
                                    p.job->name, to_string(iv.component), iv.pose_begin, iv.pose_end, -iv.max_depth_mm,
                                    iv.at.x(), iv.at.y(), iv.at.z()));
  return out;
}

namespace {
void report_fit(const Job& job, const FittedJob& out, const FittedPatch& fp, const Progress& progress) {
  const std::string& name = fp.job->name;
  const FitResult& r = fp.fit.fit;
  // Detected patches were timed as part of the detection, not on their own.
  const std::string seconds = job.cover ? std::string()
                                        : fmt::format(", {:.1f} s + {:.1f} s", fp.fit.seconds_init, fp.fit.seconds_opt);
  progress(fmt::format("patch {}: eps {:.2e} -> {:.2e} of the diagonal ({:.4f} mm), coverage {:.1f}% within {} mm{}", name,
                       r.eps_ini.max, r.eps_opt.max, out.frame.length_to_mm(r.eps_opt.max), 100 * fp.fit.coverage,
                       job.tolerance_mm, seconds));
  if (r.status == FitStatus::SolverFailed)
    progress(fmt::format("patch {}: the least-squares solver failed ({}); the last good motion is kept", name, r.message));
  if (fp.fit.tip_shortened > 0)
    progress(fmt::format("patch {}: the tool ground {:.3f} mm shorter at its tip to keep its end out of the part", name,
                         out.frame.length_to_mm(fp.fit.tip_shortened)));
  if (fp.fit.tip_lengthened > 0)
    progress(fmt::format("patch {}: the cutter made {:.3f} mm longer at its tip to reach the floor", name,
                         out.frame.length_to_mm(fp.fit.tip_lengthened)));
  if (fp.fit.holder_lengthened > 0)
    progress(fmt::format("patch {}: the cutter made {:.3f} mm longer at its holder end to keep the shank clear of the part", name,
                         out.frame.length_to_mm(fp.fit.holder_lengthened)));
  if (fp.fit.reach_lengthened > 0)
    progress(fmt::format("patch {}: the cutter made {:.3f} mm longer to reach the surface beyond its end", name,
                         out.frame.length_to_mm(fp.fit.reach_lengthened)));
  if (const auto& c = fp.fit.check_trim) {
    const Eigen::Vector3d at = out.frame.to_mm(c->at);
    progress(fmt::format("patch {}: {} t {:.3f}-{:.3f}: the {} would {} {:.3f} mm {} the part at ({:.3f}, {:.3f}, {:.3f})",
                         name, fp.fit.check_refused ? "not trimmed (no clear stretch), kept" : "trimmed to", fp.fit.t_from,
                         fp.fit.t_to, c->body ? "shank or holder" : "cutter", c->body ? "come" : "cut",
                         out.frame.length_to_mm(c->intrusion), c->body ? "inside the clearance of" : "beyond check_tolerance into", at.x(), at.y(),
                         at.z()));
  } else if (fp.fit.t_from > 0 || fp.fit.t_to < 1) {
    progress(fmt::format("patch {}: trimmed to t {:.3f}-{:.3f}: beyond it the cutter would gouge the design surface by more "
                         "than the tolerance",
                         name, fp.fit.t_from, fp.fit.t_to));
  }
  if (fp.fit.t_from < 0 || fp.fit.t_to > 1)
    progress(fmt::format("patch {}: motion continued past the end of its fit to t {:.3f}-{:.3f}: its contact line still "
                         "lay over the design surface there",
                         name, fp.fit.t_from, fp.fit.t_to));
}

// tool: {shared: true}: one custom tool for every patch, fitted jointly to all of them (eq. 12
// summed over the patches, common length the mean of theirs), starting from their separate fits;
// each patch is then machined and trimmed again with its own options.
void share_tool(const Job& job, const std::vector<const SurfaceIndex*>& targets, const std::vector<PatchOptions>& options,
                const FitOptions& o, FittedJob& out, const Progress& progress) {
  std::vector<FitResult> fits;
  double length = 0;
  for (const FittedPatch& fp : out.patches) {
    fits.push_back(fp.fit.fit);
    length += fp.fit.fit.rails.length / double(out.patches.size());
  }
  length = std::min(length, o.constraints.max_length);
  progress(fmt::format("shared tool: one tool of length {:.3f} mm for {} patches", out.frame.length_to_mm(length),
                       out.patches.size()));
  fits = fit_shared_tool(targets, std::move(fits), length, o);
  for (size_t k = 0; k < fits.size(); ++k) {
    FittedPatch& fp = out.patches[k];
    fp.fit.fit = std::move(fits[k]);
    fp.fit.clear_part_adjustments();
    fp.fit = machine_and_trim(*targets[k], std::move(fp.fit), options[k]);
    report_fit(job, out, fp, progress);
  }
}

// A catalogue tool's patch against the best custom tool (general shape, radii free) fitted to the same
// patch (its lines as given or detected), for the report.
void compare_custom_tool(const Job& job, const Similarity& frame, const SurfaceIndex& target, const PatchSpec& spec,
                         const PatchOptions& o, FittedPatch& fp, const Progress& progress) {
  PatchOptions custom = o;
  custom.fit.fixed_tool.reset();
  custom.fit.shape = ToolShape::General;
  custom.fit.on_iteration = nullptr;
  custom.on_stage = nullptr;
  // A comparison, not the job: lines a custom tool cannot follow (its radii describing no tool) say so.
  PatchFit c;
  try {
    c = fit_patch(target, spec, custom);
  } catch (const InputError& e) {
    fp.custom = CustomComparison{};
    fp.custom->failed = e.what();
    progress(fmt::format("patch {}: catalogue tool {}: eps {:.4f} mm, coverage {:.1f}%; no custom tool on the same lines: {}",
                         fp.job->name, job.tool.catalogue->name, frame.length_to_mm(fp.fit.fit.eps_opt.max),
                         100 * fp.fit.coverage, fp.custom->failed));
    return;
  }
  const ToolDimensions dims = tool_dimensions(tool_profile_mm(frame, c.fit));
  fp.custom = CustomComparison{frame.length_to_mm(c.fit.eps_opt.max), c.coverage, dims.diameter_min_mm,
                               dims.diameter_max_mm, dims.length_mm, {}};
  progress(fmt::format("patch {}: catalogue tool {}: eps {:.4f} mm, coverage {:.1f}%; best custom tool: eps {:.4f} mm, "
                       "coverage {:.1f}%",
                       fp.job->name, job.tool.catalogue->name, frame.length_to_mm(fp.fit.fit.eps_opt.max),
                       100 * fp.fit.coverage, fp.custom->eps_mm, 100 * fp.custom->coverage));
}

// `patches: auto`: detect_patches over the whole surface with the job's fit options; the detected
// patches become init: lines jobs (all of them before any pointer is taken) and keep their fits.
// With a catalogue tool `fit.fixed_tool` is it and `tool_length` its axis length (unit frame).
void detect_job(const Job& job, const SurfaceIndex& index, const FitOptions& fit, double tool_length, FittedJob& out,
                const Progress& progress) {
  CoverOptions co;
  co.coverage = job.cover->coverage;
  co.max_patches = job.cover->max_patches;
  co.exchanges = job.cover->exchanges;
  co.regions = job.cover->regions;
  co.floor_tip = out.frame.length_to_unit(job.cover->floor_tip_diameter_mm / 2);
  co.patch.fit = fit;
  // With a part, every candidate patch is kept out of it (with_check: tip shortened, trimmed or refitted;
  // rejected when nothing stays clear), its holder at the end whose shank keeps out of the part (a
  // blade's flank next to a hub: the tip at the hub, whichever way the work frame's Z points there).
  co.patch.orient_by_part = true;
  co.patch.refit_with_check = false;
  // Detection turns a custom tool after its fit (by the part, or holder up without one): its tip
  // limits hold at both ends, so that they hold at the end that becomes the tip.
  co.patch.fit.constraints.either_end = !fit.fixed_tool;
  if (job.part_given) co.end = job_end(job, out.frame);  // the floor pass (fit_options pulls the tip onto the part)
  co.patch.tolerance = out.frame.length_to_unit(job.tolerance_mm);
  // Candidate radii within the tool's limits (max_diameter, min_diameter): the default candidates
  // below the largest allowed, and that radius at 1/2, 3/4 and full.
  const ToolConstraints& tc = fit.constraints;
  const double least = std::max(tc.min_radius, tc.min_ball_radius);
  if (std::isfinite(tc.max_radius) || least > 0) {
    std::vector<double> radii;
    for (double r : co.radii)
      if (r <= tc.max_radius && r >= least) radii.push_back(r);
    if (std::isfinite(tc.max_radius))
      for (double f : {0.5, 0.75, 1.0})
        if (f * tc.max_radius >= least) radii.push_back(f * tc.max_radius);
    std::sort(radii.begin(), radii.end());
    radii.erase(std::unique(radii.begin(), radii.end()), radii.end());
    // None of them: a corner larger than every default, no max_diameter; it and 1.5 and 2 times it.
    if (radii.empty() && least > 0 && !std::isfinite(tc.max_radius)) radii = {least, 1.5 * least, 2 * least};
    if (!radii.empty()) co.radii = radii;
  }
  // Tool policy: tool: {shared: true} one tool for every patch (detect_patches holds the first
  // patch's tool for the others, then refits them jointly); a catalogue tool is held throughout,
  // its seeds at its own radii. Held tools stand with the holder up in the work frame.
  const Eigen::Vector3d up_part = setup_rotation(job.post).transpose() * Eigen::Vector3d::UnitZ();
  co.shared_tool = job.tool.shared;
  co.up = up_part;
  if (fit.fixed_tool) {
    co.tool_length = tool_length;
    co.radii.clear();
    for (double s : {0.25, 0.5, 0.75}) co.radii.push_back(fit.fixed_tool->d(s));
  }
  Detection d = detect_patches(index, co, [&](const CoverProgress& c) {
    progress(fmt::format("detect: {}: seed {} of {}, {} patches, coverage {:.1f}%", c.stage, c.seed, c.seeds, c.patches,
                         100 * c.coverage));
  });
  // Detection does not know the machine: without a part, every patch is turned so that its tool
  // stands with the tip down and the holder up in the work frame (the setup applied), as a spindle
  // holds it (with a part, with_check has put the tip at a already). Not a held tool (shared or
  // catalogue): turned round it would be its mirror image; detection started it holder up.
  for (DetectedPatch& dp : d.patches) {
    if (fit.check.part || d.shared_tool || mean_axis(dp.fit.fit.rails).dot(up_part) >= 0) continue;
    dp.fit = reversed(std::move(dp.fit));
    for (AxisLine& l : dp.spec.lines) std::swap(l.a, l.b);
  }
  out.detected.reserve(d.patches.size());
  for (const DetectedPatch& dp : d.patches) {
    PatchJob pj;
    pj.name = dp.spec.name;
    pj.init = PatchInit::Lines;
    pj.rail = 0;
    pj.length_mm = out.frame.length_to_mm(dp.spec.length);
    for (const AxisLine& l : dp.spec.lines) {
      const Eigen::Vector3d a = out.frame.to_mm(l.a), b = out.frame.to_mm(l.b);
      pj.lines_mm.push_back({a.x(), a.y(), a.z(), b.x(), b.y(), b.z()});
    }
    out.detected.push_back(std::move(pj));
  }
  for (size_t k = 0; k < d.patches.size(); ++k) {
    FittedPatch fp;
    fp.job = &out.detected[k];
    fp.fit = std::move(d.patches[k].fit);
    if (job.tool.catalogue) {
      PatchOptions o;
      o.fit = fit;
      o.fit.fixed_tool.reset();
      o.tolerance = co.patch.tolerance;
      o.machined = machined_options(job, out.frame);
      compare_custom_tool(job, out.frame, index, d.patches[k].spec, o, fp, progress);
    }
    report_fit(job, out, fp, progress);
    out.patches.push_back(std::move(fp));
  }
  CoverResult c;
  c.owner = std::move(d.owner);
  c.deviation_mm = std::move(d.deviation);
  for (double& x : c.deviation_mm) x = out.frame.length_to_mm(x);
  c.coverage = d.coverage;
  c.overcut_mm = out.frame.length_to_mm(d.overcut);
  c.stop = to_string(d.stop);
  c.seeds_tried = d.seeds_tried;
  c.exchanged = d.exchanged;
  c.regions_searched = d.regions_searched;
  c.from_regions = d.from_regions;
  c.one_tool = d.shared_tool;
  c.coverage_held_tool = d.coverage_held_tool;
  c.joint_refit = d.joint_refit;
  if (job.tool.shared && !job.tool.catalogue && d.patches.size() > 1)
    progress(fmt::format("shared tool: {:.1f}% with the held tool (the better of the first two patches' own), joint refit of all patches {}",
                         100 * d.coverage_held_tool, d.joint_refit ? "kept" : "not kept (it covered less)"));
  out.cover = std::move(c);
  progress(cover_summary(job, out));
}
}  // namespace

namespace {
// The job's tool limits in the unit frame.
ToolConstraints unit_constraints(const ToolJob& t, const Similarity& fr) {
  ToolConstraints c;
  c.min_radius = fr.length_to_unit(t.min_diameter_mm / 2);
  c.max_radius = std::isfinite(t.max_diameter_mm) ? fr.length_to_unit(t.max_diameter_mm / 2) : INFINITY;
  c.max_length = std::isfinite(t.max_length_mm) ? fr.length_to_unit(t.max_length_mm) : INFINITY;
  c.min_tip_radius = fr.length_to_unit(t.min_tip_diameter_mm / 2);
  c.max_tip_radius = std::isfinite(t.max_tip_diameter_mm) ? fr.length_to_unit(t.max_tip_diameter_mm / 2) : INFINITY;
  c.max_cone_angle_rad = t.max_cone_angle_deg * M_PI / 180;
  c.convex = t.convex;
  // A corner end must fit the fitted tool's tip: held in the fit, not found too large after it.
  if (t.end.kind == EndKind::Corner && !t.catalogue) c.min_ball_radius = fr.length_to_unit(t.end.corner_radius);
  return c;
}

// A catalogue tool in the unit frame: its sphere radii (tool_from_meridian) and axis length.
std::pair<ToolRadius, double> unit_catalogue_tool(const CatalogueTool& t, const Similarity& fr) {
  std::vector<Eigen::Vector2d> zr = t.meridian_mm();
  for (Eigen::Vector2d& p : zr) p *= fr.scale;
  return {tool_from_meridian(zr, 12), zr.back().x() - zr.front().x()};
}

// +1 when the patch's lines lie on the side Φ's normals point to, else -1 (the allowance's side).
int lines_side(const SurfaceIndex& index, const PatchSpec& spec) {
  double sum = 0;
  for (const AxisLine& l : spec.lines) {
    const Eigen::Vector3d mid = 0.5 * (l.a + l.b);
    const Footpoint f = index.closest(mid);
    sum += (mid - f.point).dot(f.normal) >= 0 ? 1 : -1;
  }
  return sum >= 0 ? 1 : -1;
}

// Φ moved by `offset` (unit frame) along its vertex normals times `side`: the target of a fit that
// leaves that much stock.
TriMesh offset_mesh(const TriMesh& mesh, double offset, int side) {
  TriMesh out = mesh;
  const std::vector<Eigen::Vector3d> n = vertex_normals(mesh);
  for (size_t v = 0; v < out.vertices.size(); ++v) out.vertices[v] += side * offset * n[v];
  return out;
}

// passes: every pass but the last with the last pass's tool held, its motion fitted to Φ offset by
// the pass's allowance towards the tool (started from the last pass's motion).
void fit_earlier_passes(const Job& job, const FitOptions& fit, FittedJob& out, const Progress& progress) {
  for (size_t k = 0; k + 1 < job.passes_mm.size(); ++k)
    for (FittedPatch& fp : out.patches) {
      PassMotion pm;
      pm.allowance_mm = job.passes_mm[k];
      const SurfaceIndex target(
          pm.allowance_mm > 0 ? offset_mesh(out.unit_surface, out.frame.length_to_unit(pm.allowance_mm), fp.allowance_side)
                              : out.unit_surface);
      FitOptions o = fit;
      o.fixed_tool = fp.fit.fit.tool;
      o.constraints = {};
      // A motion continued past the end of its fit (detection; t_from < 0 or t_to > 1) runs beyond Φ
      // there, where the offset has no samples to move the pass: as the last pass was, the pass is
      // fitted over the stretch of the first fit (its rails' [τ0, τ1]), continued straight as far and
      // fitted again.
      const double w = fp.fit.t_to - fp.fit.t_from;
      const double tau0 = std::max(0.0, -fp.fit.t_from) / w, tau1 = 1 - std::max(0.0, fp.fit.t_to - 1) / w;
      FitResult r;
      if ((tau0 > 0 || tau1 < 1) && tau1 - tau0 > 0.02) {  // (a kept stretch wholly beyond the fit: as it is)
        const FitResult inner = optimize_motion(target, trimmed(fp.fit.fit.rails, tau0, tau1), o);
        r = optimize_motion(target, continued(inner.rails, tau0 / (tau1 - tau0), (1 - tau1) / (tau1 - tau0)), o);
      } else {
        r = optimize_motion(target, fp.fit.fit.rails, o);
      }
      pm.rails = r.rails;
      pm.eps_mm = out.frame.length_to_mm(r.eps_opt.max);
      pm.coverage = coverage(target.mesh(), machined_surface(target, r.rails, r.tool).design_deviation,
                             out.frame.length_to_unit(job.tolerance_mm));
      progress(fmt::format("patch {}: pass {} (allowance {} mm): eps {:.4f} mm, coverage {:.1f}%", fp.job->name, k + 1,
                           pm.allowance_mm, pm.eps_mm, 100 * pm.coverage));
      fp.earlier_passes.push_back(std::move(pm));
    }
}
}  // namespace

FittedJob fit_job(const Job& job, int threads, const Progress& progress) {
  FittedJob out;
  out.surface = load_job_surface(job, progress);
  const TriMesh& mesh = out.surface.mesh;
  const BoundingBox box = bounding_box(mesh.vertices);
  progress(fmt::format("surface {}: {} vertices, {} triangles, diagonal {:.3f} mm", job.surface.string(),
                       mesh.vertices.size(), mesh.faces.size(), box.diagonal()));
  out.frame = unit_diagonal_frame(mesh);
  out.unit_surface = transformed(mesh, out.frame);
  const SurfaceIndex index(out.unit_surface);
  // The part as the fit's check surface (without Φ's twin), unit frame; loaded before any fit so a
  // bad part file fails first.
  std::optional<SurfaceIndex> check_index, solid_index;
  std::vector<char> twin_faces;  // of solid_index
  double twin_sag = 0;           // unit frame
  if (const std::optional<LoadedMesh> part = load_job_part(job)) {
    const CheckPart cp = check_part(transformed(part->mesh, out.frame), index, out.frame.length_to_unit(job.tolerance_mm));
    out.part = part->mesh;
    out.check_part = cp.mesh;
    for (Eigen::Vector3d& v : out.check_part->vertices) v = out.frame.to_mm(v);
    out.check_twin_faces = cp.twin_faces;
    twin_faces = cp.twin;
    twin_sag = cp.twin_sag;
    out.check_twin_sag_mm = out.frame.length_to_mm(cp.twin_sag);
    progress(fmt::format("part {}: {} triangles, {} of them the design surface's twin (left to the surface itself{}){}; the "
                         "fit keeps the tool out of the rest",
                         job.part.string(), part->mesh.faces.size(), cp.twin_faces,
                         cp.twin_faces ? fmt::format(", up to {:.3f} mm off it", out.frame.length_to_mm(cp.twin_sag)) : "",
                         cp.turned_outward ? ", turned outward" : ""));
    check_index.emplace(cp.mesh);
    TriMesh whole = transformed(part->mesh, out.frame);
    if (cp.turned_outward)
      for (auto& face : whole.faces) std::swap(face[1], face[2]);
    solid_index.emplace(std::move(whole));
  }
  std::optional<std::pair<ToolRadius, double>> catalogue;
  if (job.tool.catalogue) catalogue = unit_catalogue_tool(*job.tool.catalogue, out.frame);
  const auto fit_options = [&] {
    FitOptions o = job.fit;
    o.threads = threads;
    if (job.robust_mm) o.robust_scale = out.frame.length_to_unit(*job.robust_mm);
    o.constraints = unit_constraints(job.tool, out.frame);
    if (catalogue) o.fixed_tool = catalogue->first;
    if (check_index) {
      o.check.part = &*check_index;
      o.check.solid = &*solid_index;
      o.check.solid_twin = &twin_faces;
      o.check.twin_sag = twin_sag;
      o.check.tolerance = out.frame.length_to_unit(job.check_tolerance_mm.value_or(job.tolerance_mm));
      o.check.clearance = out.frame.length_to_unit(job.clearance_mm);
      o.check.body = body_samples(job.holder, out.frame);
      o.check.ball_tip = job.tool.end.kind == EndKind::Ball;
      // A floor under the tip (a hub): the tip pulled onto it, to half the tolerance above it, where it
      // stands within one tip radius of it.
      o.check.floor_reach = 1;
      o.check.floor_height = 0.5 * out.frame.length_to_unit(job.tolerance_mm);
      // Detected patches: the tie-break of the holder end (detect_job orients them by the part).
      if (job.cover) o.check.up = setup_rotation(job.post).transpose() * Eigen::Vector3d::UnitZ();
    }
    return o;
  };
  if (job.cover) {
    detect_job(job, index, fit_options(), catalogue ? catalogue->second : 0.0, out, progress);
    require_detected_patch(job, out);
    // passes: the detected patches are fitted to Φ itself (the last pass, allowance 0); their tools
    // stand on the side of their lines.
    if (job.passes_mm.size() > 1)
      for (FittedPatch& fp : out.patches) fp.allowance_side = lines_side(index, unit_spec(*fp.job, out.frame));
    fit_earlier_passes(job, fit_options(), out, progress);
    check_job(job, out, progress);
    return out;
  }
  // With an allowance each patch is fitted to Φ offset towards its tool; the offset surfaces live here.
  std::vector<std::unique_ptr<SurfaceIndex>> offsets;
  std::vector<const SurfaceIndex*> targets;
  std::vector<PatchOptions> patch_options;
  for (const PatchJob& p : job.patches) {
    PatchOptions o;
    o.fit = fit_options();
    o.tolerance = out.frame.length_to_unit(job.tolerance_mm);
    o.machined = machined_options(job, out.frame);
    o.on_stage = [&](const std::string& s) { progress(fmt::format("patch {}: {}", p.name, s)); };
    o.fit.on_iteration = [&](int it, double objective) {
      progress(fmt::format("patch {}: iteration {}, F_motion {:.3e}", p.name, it, objective));
    };
    PatchSpec spec = unit_spec(p, out.frame);
    FittedPatch fp;
    fp.job = &p;
    const SurfaceIndex* target = &index;
    const double allowance = job.passes_mm.empty() ? job.allowance_mm : job.passes_mm.back();
    if (allowance > 0 || job.passes_mm.size() > 1) fp.allowance_side = lines_side(index, spec);
    if (allowance > 0) {
      offsets.push_back(
          std::make_unique<SurfaceIndex>(offset_mesh(out.unit_surface, out.frame.length_to_unit(allowance), fp.allowance_side)));
      target = offsets.back().get();
      progress(fmt::format("patch {}: fitted to the surface offset by the allowance {} mm", p.name, allowance));
    }
    if (catalogue) {
      // The catalogue tool's length is the axis length; the user's lines keep their tip ends.
      PatchSpec fixed = spec;
      fixed.length = catalogue->second;
      for (AxisLine& l : fixed.lines) l.b = l.a + catalogue->second * (l.b - l.a).normalized();
      fp.fit = fit_patch(*target, fixed, o);
      compare_custom_tool(job, out.frame, *target, spec, o, fp, progress);
    } else {
      fp.fit = fit_patch(*target, spec, o);
    }
    report_fit(job, out, fp, progress);
    out.patches.push_back(std::move(fp));
    targets.push_back(target);
    patch_options.push_back(o);
  }
  if (job.tool.shared && !catalogue && out.patches.size() > 1)
    share_tool(job, targets, patch_options, fit_options(), out, progress);
  fit_earlier_passes(job, fit_options(), out, progress);
  check_job(job, out, progress);
  return out;
}

nlohmann::ordered_json surface_report(const Job& job, const FittedJob& f) {
  const TriMesh& m = f.surface.mesh;
  const MeshTopology topo = mesh_topology(m);
  const BoundingBox box = bounding_box(m.vertices);
  return {{"file", job.surface.string()},
          {"vertices", m.vertices.size()},
          {"triangles", m.faces.size()},
          {"components", topo.components},
          {"boundary_edges", topo.boundary_edges},
          {"diagonal_mm", round_mm(box.diagonal())},
          {"area_mm2", round_mm(surface_area(m))},
          {"bbox_min_mm", vec_mm(box.min)},
          {"bbox_max_mm", vec_mm(box.max)},
          {"read", {{"polygons_triangulated", f.surface.report.polygons_triangulated},
                    {"dropped_degenerate", f.surface.report.dropped_degenerate},
                    {"dropped_duplicate", f.surface.report.dropped_duplicate},
                    {"flipped_to_orient", f.surface.report.flipped_to_orient}}}};
}

nlohmann::ordered_json patch_report(const Job& job, const FittedJob& f, const FittedPatch& p) {
  const Similarity& fr = f.frame;
  const FitResult& r = p.fit.fit;
  const int m = job.fit.samples_t, n = job.fit.samples_s;
  nlohmann::ordered_json j;
  j["name"] = p.job->name;
  j["init"] = to_string(p.job->init);
  j["eps_ini"] = r.eps_ini.max;
  j["eps_opt"] = r.eps_opt.max;
  j["eps_opt_mm"] = round_mm(fr.length_to_mm(r.eps_opt.max));
  j["eps_note"] = "eps_* are relative to the design surface's bounding-box diagonal (eq. 13); *_mm in mm";
  j["error_initial"] = error_report(r.eps_ini, fr);
  j["error_optimised"] = error_report(r.eps_opt, fr);
  auto& axis = j["axis"] = nlohmann::ordered_json::array();
  for (int i = 0; i < m; ++i) {
    const double t = double(i) / (m - 1);
    const Eigen::Vector3d a = fr.to_mm(r.rails.a.point(t)), b = fr.to_mm(r.rails.b.point(t));
    axis.push_back({round_mm(a.x()), round_mm(a.y()), round_mm(a.z()), round_mm(b.x()), round_mm(b.y()), round_mm(b.z())});
  }
  auto& radius = j["radius"] = nlohmann::ordered_json::array();
  for (int k = 0; k < n; ++k) radius.push_back(round_mm(fr.length_to_mm(r.tool.d(double(k) / (n - 1)))));

  const double L = fr.length_to_mm(r.rails.length);
  nlohmann::ordered_json tool;
  tool["shape"] = to_string(r.tool.shape);
  tool["end"] = {{"kind", to_string(job.tool.end.kind)}, {"radius_mm", round_mm(p.end_radius_mm)}};  // tool.end
  tool["length"] = round_mm(L);
  auto& profile = tool["profile"] = nlohmann::ordered_json::array();
  const std::vector<Eigen::Vector2d>& meridian_mm = p.profile_mm;
  for (const Eigen::Vector2d& zr : meridian_mm) profile.push_back({round_mm(zr.x()), round_mm(zr.y())});
  tool["profile_note"] = "meridian [z, r] in mm, z along the axis from the tool tip end (a) towards b";
  const ToolDimensions dims = tool_dimensions(meridian_mm, p.end_points);
  tool["diameter_min"] = round_mm(dims.diameter_min_mm);
  tool["diameter_max"] = round_mm(dims.diameter_max_mm);
  // The cone of the meridian itself: spheres d(z) = d0 + k z envelope a cone of half angle asin(k).
  if (r.tool.shape == ToolShape::Cone) tool["cone_half_angle_deg"] = std::round(dims.cone_half_angle_deg * 1e6) / 1e6 + 0.0;
  if (job.tool.catalogue) {
    const CatalogueTool& c = *job.tool.catalogue;
    tool["catalogue"] = {{"name", c.name}, {"family", c.family}, {"file", c.file.string()}, {"line", c.line}};
  }
  const ToolConstraints limits = unit_constraints(job.tool, fr);
  if (limits.active()) {
    const ConstraintCheck cc = check_constraints(r.tool, r.rails.length, limits);
    nlohmann::ordered_json lim;
    if (job.tool.min_diameter_mm > 0) lim["min_diameter_mm"] = job.tool.min_diameter_mm;
    if (std::isfinite(job.tool.max_diameter_mm)) lim["max_diameter_mm"] = job.tool.max_diameter_mm;
    if (std::isfinite(job.tool.max_length_mm)) lim["max_length_mm"] = job.tool.max_length_mm;
    if (job.tool.min_tip_diameter_mm > 0) lim["min_tip_diameter_mm"] = job.tool.min_tip_diameter_mm;
    if (std::isfinite(job.tool.max_tip_diameter_mm)) lim["max_tip_diameter_mm"] = job.tool.max_tip_diameter_mm;
    if (job.tool.max_cone_angle_deg < 90) lim["max_cone_angle_deg"] = job.tool.max_cone_angle_deg;
    if (job.tool.convex) lim["convex"] = true;
    if (limits.min_ball_radius > 0) lim["end_corner_mm"] = job.tool.end.corner_radius;
    lim["met"] = cc.what.empty();
    if (!cc.what.empty()) lim["violated"] = cc.what;
    tool["constraints"] = lim;
  }
  if (job.tool.shared) tool["shared"] = true;
  j["tool"] = tool;
  if (p.custom)
    j["compare_custom_tool"] = {
        {"note", "the catalogue tool (this patch) against the best custom tool (general shape) fitted to the same patch"},
        {"catalogue", {{"eps_mm", round_mm(fr.length_to_mm(r.eps_opt.max))}, {"coverage", p.fit.coverage}}},
        {"custom", p.custom->failed.empty()
                       ? nlohmann::ordered_json{{"eps_mm", round_mm(p.custom->eps_mm)}, {"coverage", p.custom->coverage},
                                                {"diameter_min", round_mm(p.custom->diameter_min_mm)},
                                                {"diameter_max", round_mm(p.custom->diameter_max_mm)},
                                                {"length", round_mm(p.custom->length_mm)}}
                       : nlohmann::ordered_json{{"failed", p.custom->failed}}}};
  if (!job.passes_mm.empty()) {
    auto& passes = j["passes"] = nlohmann::ordered_json::array();
    for (const PassMotion& pm : p.earlier_passes)
      passes.push_back({{"allowance_mm", pm.allowance_mm}, {"eps_mm", round_mm(pm.eps_mm)}, {"coverage", pm.coverage}});
    passes.push_back({{"allowance_mm", job.passes_mm.back()}, {"eps_mm", round_mm(fr.length_to_mm(r.eps_opt.max))},
                      {"coverage", p.fit.coverage}});
  }
  if (const double a = job.passes_mm.empty() ? job.allowance_mm : job.passes_mm.back(); a > 0)
    j["allowance"] = {{"allowance_mm", a},
                      {"note", "the fit's target, coverage and deviation are the design surface offset by the allowance "
                               "towards the tool"}};
  if (job.overtravel_mm > 0) j["overtravel_mm"] = job.overtravel_mm;
  j["coverage"] = p.fit.coverage;
  j["tolerance_mm"] = job.tolerance_mm;
  double dmin = INFINITY, dmax = -INFINITY;
  int uncovered = 0;
  for (double d : p.fit.machined.design_deviation) {
    if (!std::isfinite(d)) {
      ++uncovered;
      continue;
    }
    dmin = std::min(dmin, d);
    dmax = std::max(dmax, d);
  }
  j["deviation"] = {{"note", "design surface vs machined envelope along the surface normal: undercut > 0, overcut < 0"},
                    {"min_mm", std::isfinite(dmin) ? round_mm(fr.length_to_mm(dmin)) : 0.0},
                    {"max_mm", std::isfinite(dmax) ? round_mm(fr.length_to_mm(dmax)) : 0.0},
                    {"vertices_not_reached", uncovered},
                    {"envelope_folded_triangles", p.fit.machined.omega.folded_triangles}};
  auto& col = j["collisions"] = nlohmann::ordered_json::array();
  for (const CollisionInterval& iv : p.collisions.intervals)
    col.push_back({{"component", to_string(iv.component)},
                   {"poses", {iv.pose_begin, iv.pose_end}},
                   {"worst_pose", iv.worst_pose},
                   {"depth_mm", round_mm(iv.max_depth_mm)},
                   {"at_mm", vec_mm(iv.at)}});
  // Detection made the cutter longer to reach more of the surface (reaching_further).
  if (p.fit.reach_lengthened > 0) j["cutter_lengthened_to_reach_mm"] = round_mm(fr.length_to_mm(p.fit.reach_lengthened));
  // With a separate part: the fit kept the tool out of it (check surface), trimming where it could not.
  if (f.check_part) {
    nlohmann::ordered_json c = {{"part_triangles", f.part ? f.part->faces.size() : 0},
                                {"twin_triangles_left_to_the_surface", f.check_twin_faces},
                                {"check_tolerance_mm", job.check_tolerance_mm.value_or(job.tolerance_mm)},
                                {"clearance_mm", job.clearance_mm},
                                {"kept_t", {p.fit.t_from, p.fit.t_to}},  // beyond [0, 1]: continued past the fit's end
                                {"worst_intrusion_mm", round_mm(fr.length_to_mm(p.fit.check_intrusion))},
                                {"tip_shortened_mm", round_mm(fr.length_to_mm(p.fit.tip_shortened))},
                                {"tip_lengthened_mm", round_mm(fr.length_to_mm(p.fit.tip_lengthened))},
                                {"holder_end_lengthened_mm", round_mm(fr.length_to_mm(p.fit.holder_lengthened))},
                                {"refused", p.fit.check_refused}};
    if (const auto& t = p.fit.check_trim)
      c["trimmed_because"] = {{"component", t->body ? "shank or holder" : "cutter"},
                              {"intrusion_mm", round_mm(fr.length_to_mm(t->intrusion))},
                              {"at_mm", vec_mm(fr.to_mm(t->at))}};
    c["note"] = "intrusion: beyond check_tolerance for the cutter, inside the clearance for shank and holder (<= 0: clear)";
    j["check_surface"] = std::move(c);
  }
  // flankcam run: the cut shortened where its lead had no clear point (kept_t above is after it).
  if (!p.kept_for_leads.empty()) j["shortened_for_leads"] = p.kept_for_leads;
  // The cut shortened to its longest stretch clear of collisions (the run's check found the rest not
  // clear; kept_t above is after it).
  if (!p.kept_clear.empty()) j["shortened_clear_of_collisions"] = p.kept_clear;
  j["collision_check"] = {{"part", job.part.string()},
                          {"clearance_mm", job.clearance_mm},
                          {"gouge_tolerance_mm", job.tolerance_mm},
                          {"part_gouge_tolerance_mm", job.check_tolerance_mm.value_or(job.tolerance_mm)},
                          {"positions_checked", p.collisions.positions_checked},
                          {"note", "depth_mm > 0: inside the tool/shank/holder; tool: inside the cutter beyond the tolerance; "
                                   "shank/holder: closer than the clearance when <= 0"}};
  j["iterations"] = r.iterations;
  j["converged"] = r.converged;
  j["status"] = to_string(r.status);  // converged, iteration limit, or the solver failed
  if (!r.message.empty()) j["solver_message"] = r.message;
  if (p.fit.explored) {
    j["exploration"] = {{"F_user_line", p.fit.explored->F_start},
                        {"F_explored", p.fit.explored->movability.F},
                        {"lines_evaluated", p.fit.explored->lines_evaluated},
                        {"line_mm", {vec_mm(fr.to_mm(p.fit.explored->a)), vec_mm(fr.to_mm(p.fit.explored->b))}}};
    j["propagation"] = {{"positions", p.fit.trajectory->a.size()},
                        {"stop_backward", to_string(p.fit.trajectory->stop_backward)},
                        {"stop_forward", to_string(p.fit.trajectory->stop_forward)}};
  }
  if (!job.cover)  // a detected patch was fitted among the detection's candidates, not timed on its own
    j["seconds"] = {{"init", std::round(p.fit.seconds_init * 1000) / 1000},
                    {"optimisation", std::round(p.fit.seconds_opt * 1000) / 1000}};
  return j;
}

std::string tool_sheet(const Job& job, const FittedPatch& p) {
  const std::vector<Eigen::Vector2d>& zr = p.profile_mm;
  const ToolDimensions dims = tool_dimensions(zr, p.end_points);
  const std::string& name = p.job->name;
  const auto angle = [&](size_t i) {  // local half angle of the meridian, deg (positive: widening towards the shank)
    const size_t a = i == 0 ? 0 : i - 1, b = std::min(zr.size() - 1, i + 1);
    return std::atan2(zr[b].y() - zr[a].y(), zr[b].x() - zr[a].x()) * 180 / M_PI + 0.0;
  };
  double steepest = 0;
  for (size_t i = 0; i < zr.size(); ++i) steepest = std::max(steepest, std::abs(angle(i)));
  std::string out = fmt::format("# grinding sheet: tool of patch {} ({} tool{}), mm and degrees\n", name,
                                to_string(p.fit.fit.tool.shape), job.tool.shared ? ", shared by every patch" : "");
  out += "# z from the tip along the axis, r the radius of the flank; grind to the profile within the tolerance\n";
  out += fmt::format("tolerance_mm,{}\n", fixed(job.tolerance_mm, 6));
  if (job.tool.end.kind != EndKind::Flat)  // tool.end: the arc's radius (the ball's is the fitted tool's)
    out += fmt::format("end_{}_radius_mm,{}\n", to_string(job.tool.end.kind), fixed(p.end_radius_mm, 4));
  out += fmt::format("cutting_length_mm,{}\n", fixed(dims.length_mm, 4));
  out += fmt::format("tip_diameter_mm,{}\n", fixed(2 * zr.front().y(), 4));
  out += fmt::format("end_diameter_mm,{}\n", fixed(2 * zr.back().y(), 4));
  out += fmt::format("min_diameter_mm,{}\n", fixed(dims.diameter_min_mm, 4));
  out += fmt::format("max_diameter_mm,{}\n", fixed(dims.diameter_max_mm, 4));
  out += fmt::format("cone_half_angle_deg,{}\n", fixed(dims.cone_half_angle_deg, 4));
  out += fmt::format("steepest_half_angle_deg,{}\n", fixed(steepest, 4));
  out += "point,z_mm,r_mm,diameter_mm,half_angle_deg\n";
  for (size_t i = 0; i < zr.size(); ++i)
    out += fmt::format("{},{},{},{},{}\n", i + 1, fixed(zr[i].x(), 4), fixed(zr[i].y(), 4), fixed(2 * zr[i].y(), 4), fixed(angle(i), 4));
  return out;
}

ClProgram pass_program(const Job& job, const FittedJob& f, const FittedPatch& p, const PassMotion& pm, int tool) {
  ClProgram cl = flank_program(p.job->name, pm.poses, p.profile_mm, job.feed_mm_min, job.spindle_rpm, job.lead_in_mm,
                               job.retract_mm);
  cl.tool = tool;
  cl.cutter = enveloping_cutter(p.profile_mm, p.end_points, p.end_radius_mm);  // tool.end: the corner in CUTTER
  const size_t first = job.lead_in_mm < job.retract_mm ? 2 : 1;
  for (size_t i = 0; i < pm.poses.size(); ++i) cl.moves[first + i].contact = pm.contacts[i];
  cl.comments.push_back(fmt::format("FLANKCAM PASS WITH ALLOWANCE {} MM ON {}, EPS {:.4f} MM", pm.allowance_mm,
                                    job.surface.filename().string(), pm.eps_mm));
  (void)f;
  return cl;
}

namespace {
// The cover's union anew from the patches that get programs (not refused): owner (patch indices),
// deviation, coverage and overcut.
void judge_cover(const Job& job, FittedJob& f) {
  const size_t nv = f.unit_surface.vertices.size();
  MachinedSurface none;  // a refused patch machines nothing
  none.design_deviation.assign(nv, std::numeric_limits<double>::quiet_NaN());
  std::vector<const MachinedSurface*> ms;
  for (const FittedPatch& p : f.patches) ms.push_back(p.refused ? &none : &p.fit.machined);
  CoverResult& c = *f.cover;
  UnionDeviation u = union_deviation(ms, nv);
  c.owner = std::move(u.owner);
  c.coverage = coverage(f.unit_surface, u.deviation, f.frame.length_to_unit(job.tolerance_mm));
  c.overcut_mm = 0;
  c.deviation_mm = std::move(u.deviation);
  for (double& x : c.deviation_mm) {
    if (std::isfinite(x)) c.overcut_mm = std::max(c.overcut_mm, -x);
    x = f.frame.length_to_mm(x);
  }
  c.overcut_mm = f.frame.length_to_mm(c.overcut_mm);
}
}  // namespace

void keep_poses(const Job& job, FittedJob& f, const std::vector<std::optional<KeptPoses>>& keep, std::string FittedPatch::*note,
                const std::string& shortened, const Progress& progress) {
  if (std::none_of(keep.begin(), keep.end(), [](const auto& k) { return k.has_value(); })) return;
  std::optional<SurfaceIndex> design;  // Φ (unit frame), built for the first patch judged against it
  const double tolerance = f.frame.length_to_unit(job.tolerance_mm);
  const MachinedSurfaceOptions mo = machined_options(job, f.frame);
  const size_t before = job.overtravel_mm > 0 ? 1 : 0;  // poses_mm: the overtravel pose before t = 0
  for (size_t k = 0; k < keep.size() && k < f.patches.size(); ++k) {
    if (!keep[k]) continue;
    FittedPatch& p = f.patches[k];
    const size_t i0 = keep[k]->first, i1 = std::min(keep[k]->last, p.poses.size() - 1);
    if (!(i0 < i1) || p.poses.size() < 2 * before + 2)
      throw InputError(fmt::format("patch {}: keep_poses: poses {}-{} of {}", p.job->name, i0, i1, p.poses.size()));
    // The rails between the kept poses' parameters (an overtravel pose kept: its end of the motion).
    // The poses lie evenly in t over the rails (poses_mm, or a stretch of them kept before, whose
    // rails were trimmed to it): m of them besides the overtravel poses.
    const long m = long(p.poses.size() - 2 * before);
    const auto t_of = [&](size_t i) { return double(std::clamp<long>(long(i) - long(before), 0, m - 1)) / double(m - 1); };
    const double t0 = t_of(i0), t1 = t_of(i1);
    const double coverage_before = p.fit.coverage;
    p.fit.fit.rails = trimmed(p.fit.fit.rails, t0, t1);
    std::tie(p.fit.t_from, p.fit.t_to) = kept_within(p.fit.t_from, p.fit.t_to, t0, t1);
    // Earlier passes: their poses index like the last pass's, at the same t of their own rails.
    for (PassMotion& pm : p.earlier_passes) {
      pm.rails = trimmed(pm.rails, t0, t1);
      const SurfaceIndex pass_target(pm.allowance_mm > 0 ? offset_mesh(f.unit_surface, f.frame.length_to_unit(pm.allowance_mm),
                                                                        p.allowance_side)
                                                          : f.unit_surface);
      pm.coverage = coverage(pass_target.mesh(), machined_surface(pass_target, pm.rails, p.fit.fit.tool).design_deviation, tolerance);
    }
    // Judged against the fit's target: Φ, or Φ offset by the allowance.
    const double allowance = job.passes_mm.empty() ? job.allowance_mm : job.passes_mm.back();
    std::optional<SurfaceIndex> offset;
    if (allowance > 0) offset.emplace(offset_mesh(f.unit_surface, f.frame.length_to_unit(allowance), p.allowance_side));
    if (!offset && !design) design.emplace(f.unit_surface);
    const SurfaceIndex& target = offset ? *offset : *design;
    p.fit.machined = machined_surface(target, p.fit.fit.rails, p.fit.fit.tool, mo);
    p.fit.coverage = coverage(f.unit_surface, p.fit.machined.design_deviation, tolerance);
    const auto cut = [&](auto& v) {
      if (v.size() != p.poses.size()) return;
      v.erase(v.begin() + long(i1) + 1, v.end());
      v.erase(v.begin(), v.begin() + long(i0));
    };
    const size_t total = p.poses.size();
    for (PassMotion& pm : p.earlier_passes) cut(pm.contacts), cut(pm.poses);  // their poses index like the last pass's
    cut(p.contacts);
    cut(p.poses);
    p.*note = fmt::format("poses {}-{} of {} kept (t {:.3f}-{:.3f}): {}", i0 + 1, i1 + 1, total, p.fit.t_from, p.fit.t_to,
                          keep[k]->why);
    progress(fmt::format("patch {}: {}; coverage {:.1f}% -> {:.1f}%", p.job->name, p.*note, 100 * coverage_before,
                         100 * p.fit.coverage));
  }
  if (!f.cover) return;
  judge_cover(job, f);
  progress(cover_summary(job, f) + " after the cuts were shortened " + shortened);
}

void refuse_colliding(const Job& job, FittedJob& f, const Progress& progress) {
  bool any = false;
  for (FittedPatch& p : f.patches)
    if (!p.collisions.clear() && !p.refused) p.refused = any = true;
  if (!any || !f.cover) return;
  judge_cover(job, f);
  progress(cover_summary(job, f) + " without the refused patches");
}

ClProgram patch_program(const Job& job, const FittedJob& f, const FittedPatch& p, int tool) {
  ClProgram cl = flank_program(p.job->name, p.poses, p.profile_mm, job.feed_mm_min, job.spindle_rpm, job.lead_in_mm,
                               job.retract_mm);
  cl.tool = tool;
  cl.cutter = enveloping_cutter(p.profile_mm, p.end_points, p.end_radius_mm);  // tool.end: the corner in CUTTER
  const size_t first = job.lead_in_mm < job.retract_mm ? 2 : 1;  // flank_program: clearance, lead-in, then the pass
  for (size_t i = 0; i < p.poses.size(); ++i) cl.moves[first + i].contact = p.contacts[i];
  cl.comments.push_back(fmt::format("FLANKCAM FIT OF {}, EPS {:.4f} MM, TOLERANCE {} MM", job.surface.filename().string(),
                                    f.frame.length_to_mm(p.fit.fit.eps_opt.max), job.tolerance_mm));
  if (!p.collisions.clear()) cl.comments.push_back("WARNING: COLLISIONS ALLOWED, SEE REPORT.JSON");
  return cl;
}

}  // namespace flankcam::pipeline

namespace flankcam::pipeline {

std::string tool_label(const Job& job, const FittedPatch& p) {
  if (job.tool.catalogue) return job.tool.catalogue->name;
  return std::string(to_string(p.fit.fit.tool.shape)) + (job.tool.shared ? " (shared)" : "");
}

size_t tool_label_width(const Job& job, const std::vector<FittedPatch>& patches) {
  size_t w = 9;
  for (const FittedPatch& p : patches) w = std::max(w, tool_label(job, p).size());
  return w;
}

namespace {
// Patches refused for collisions (refuse_colliding): left out of the cover's union.
long refused_patches(const FittedJob& f) {
  return std::count_if(f.patches.begin(), f.patches.end(), [](const FittedPatch& p) { return p.refused; });
}
}  // namespace

std::string cover_summary(const Job& job, const FittedJob& f) {
  if (!f.cover) return {};
  const long refused = refused_patches(f);
  return fmt::format("whole surface: {} patches{}, {:.1f}% within {} mm (stopped: {}{}{}{})", f.patches.size(),
                     job.tool.catalogue ? ", one catalogue tool" : job.tool.shared ? ", one shared tool" : "",
                     100 * f.cover->coverage, job.tolerance_mm, f.cover->stop,
                     f.cover->exchanged > 0 ? fmt::format("; {} exchanged for better", f.cover->exchanged) : "",
                     f.cover->from_regions > 0 ? fmt::format("; {} found in uncovered regions searched alone", f.cover->from_regions) : "",
                     refused > 0 ? fmt::format("; {} refused for collisions, not counted", refused) : "");
}

void require_detected_patch(const Job& job, const FittedJob& f) {
  if (!f.cover || !f.patches.empty()) return;
  throw ProgramRefused(fmt::format(
      "patches: auto: no patch machines any of the surface within {} mm ({} candidate motions fitted); nothing written: a larger "
      "tolerance, looser tool limits or patches listed by hand (init: lines) may find one",
      job.tolerance_mm, f.cover->seeds_tried));
}

namespace {
// The cover's tool policy: one custom tool per patch, one shared tool, or one catalogue tool.
nlohmann::ordered_json tool_policy_report(const Job& job, const CoverResult& c) {
  if (job.tool.catalogue)
    return {{"policy", "catalogue"}, {"name", job.tool.catalogue->name}, {"tools", 1},
            {"note", "the catalogue tool held for every detected patch, only the motions fitted"}};
  if (!job.tool.shared) return {{"policy", "per patch"}, {"note", "one custom tool fitted with each patch"}};
  return {{"policy", "shared"}, {"tools", 1}, {"coverage_tool_held", c.coverage_held_tool},
          {"joint_refit_kept", c.joint_refit},
          {"note", "one custom tool for every patch: of the first two patches' own tools, the one that covers more when "
                   "held for the other, held while the others were detected, then all "
                   "patches refitted jointly with one tool (kept when the union's coverage did not drop)"}};
}
}  // namespace

nlohmann::ordered_json cover_report(const Job& job, const FittedJob& f) {
  const CoverResult& c = *f.cover;
  int uncut = 0;
  for (double d : c.deviation_mm) uncut += std::isfinite(d) ? 0 : 1;
  nlohmann::ordered_json out = {{"note", "patches: auto; the whole design surface against the union of the detected patches' machined "
                   "surfaces: coverage is the share of its area within the tolerance"},
          {"coverage", c.coverage},
          {"target_coverage", job.cover->coverage},
          {"max_patches", job.cover->max_patches},
          {"exchanges", job.cover->exchanges},
          {"patches_exchanged", c.exchanged},
          {"regions", job.cover->regions},
          {"regions_searched", c.regions_searched},
          {"patches_from_regions", c.from_regions},
          {"patches_refused", refused_patches(f)},
          {"patches", f.patches.size()},
          {"stop", c.stop},
          {"tolerance_mm", job.tolerance_mm},
          {"overcut_mm", round_mm(c.overcut_mm)},
          {"vertices_not_reached", uncut},
          {"trajectories_fitted", c.seeds_tried},
          {"tool", tool_policy_report(job, c)},
          {"detected_job", detected_job_name}};
  if (job.cover->floor_tip_diameter_mm > 0) out["floor_tip_diameter_mm"] = job.cover->floor_tip_diameter_mm;
  return out;
}

namespace {
// A YAML double-quoted scalar (JSON string syntax is valid YAML).
std::string quoted(const std::string& s) { return nlohmann::json(s).dump(); }
std::string num(double x) { return fmt::format("{}", x); }
std::string file_key(const std::filesystem::path& p, const std::vector<int>& faces, const std::optional<double>& deflection) {
  std::string s = "{file: " + quoted(std::filesystem::absolute(p).lexically_normal().string());
  if (!faces.empty()) s += fmt::format(", faces: [{}]", fmt::join(faces, ", "));
  if (deflection) s += ", deflection: " + num(*deflection);
  return s + "}";
}
}  // namespace

std::string detected_job_yaml(const Job& job, const FittedJob& f) {
  std::string y = fmt::format(
      "# The patches flankcam detected for {} (patches: auto, {}), written out as init: lines.\n"
      "# `flankcam fit` or `flankcam run` of this file fits them again from these lines. Lengths in mm.\n",
      job.file.filename().string(), cover_summary(job, f));
  if (job.cover && job.cover->floor_tip_diameter_mm > 0)
    y += fmt::format("# cover.floor_tip_diameter {} mm narrowed some tips in detection; it is no limit of this job, and\n"
                     "# such a patch fitted again from its lines may widen its tip (tool.max_tip_diameter holds every patch).\n",
                     num(job.cover->floor_tip_diameter_mm));
  y += "surface: " + file_key(job.surface, job.surface_faces, job.surface_deflection_mm) + "\n";
  if (job.part_given) y += "part: " + file_key(job.part, {}, job.part_deflection_mm) + "\n";
  if (job.check_tolerance_mm) y += fmt::format("check_tolerance: {}\n", num(*job.check_tolerance_mm));
  const HolderJob& h = job.holder;
  if (h.shank_length > 0 || h.length > 0 || h.cylinder_length > 0)
    y += fmt::format("holder: {{shank_length: {}, shank_diameter: {}, length: {}, diameter: {}, diameter_far: {}, "
                     "cylinder_length: {}}}\n",
                     num(h.shank_length), num(h.shank_diameter), num(h.length), num(h.diameter), num(h.diameter_far),
                     num(h.cylinder_length));
  y += fmt::format("clearance: {}\nfeed: {}\nspindle: {}\nlead_in: {}\nretract: {}\n", num(job.clearance_mm),
                   num(job.feed_mm_min), num(job.spindle_rpm), num(job.lead_in_mm), num(job.retract_mm));
  const FitOptions& o = job.fit;
  const ToolJob& t = job.tool;
  const std::string end = t.end.kind == EndKind::Ball     ? ", end: ball"
                          : t.end.kind == EndKind::Corner ? ", end: {corner: " + num(t.end.corner_radius) + "}"
                                                          : "";
  if (t.catalogue) {
    y += fmt::format("tool: {{catalogue: {}{}{}}}\n", t.catalogue->name, t.shared ? ", shared: true" : "", end);
  } else {
    std::string extra;
    if (t.min_diameter_mm > 0) extra += ", min_diameter: " + num(t.min_diameter_mm);
    if (std::isfinite(t.max_diameter_mm)) extra += ", max_diameter: " + num(t.max_diameter_mm);
    if (std::isfinite(t.max_length_mm)) extra += ", max_length: " + num(t.max_length_mm);
    if (t.min_tip_diameter_mm > 0) extra += ", min_tip_diameter: " + num(t.min_tip_diameter_mm);
    if (std::isfinite(t.max_tip_diameter_mm)) extra += ", max_tip_diameter: " + num(t.max_tip_diameter_mm);
    if (t.max_cone_angle_deg < 90) extra += ", max_cone_angle: " + num(t.max_cone_angle_deg);
    if (t.convex) extra += ", convex: true";
    if (t.shared) extra += ", shared: true";
    extra += end;
    y += fmt::format("tool: {{shape: {}, control_points: {}{}}}\n", to_string(o.shape), o.meridian_control_points, extra);
  }
  if (job.allowance_mm > 0) y += "allowance: " + num(job.allowance_mm) + "\n";
  if (!job.passes_mm.empty()) {
    std::vector<std::string> passes;
    for (double a : job.passes_mm) passes.push_back("{allowance: " + num(a) + "}");
    y += fmt::format("passes: [{}]\n", fmt::join(passes, ", "));
  }
  if (job.overtravel_mm > 0) y += "overtravel: " + num(job.overtravel_mm) + "\n";
  if (job.depth_cuts > 1) y += fmt::format("depth_cuts: {}\n", job.depth_cuts);
  y += fmt::format("tolerance: {}\nsampling: {{s: {}, t: {}}}\n", num(job.tolerance_mm), o.samples_s, o.samples_t);
  y += fmt::format("weights: {{plane: {}, fair: {}, point: {}, rigid: {}, anchor: {}}}\n", num(o.w_plane), num(o.w_fair),
                   num(o.w_point), num(o.w_rigid), num(o.w_anchor));
  y += fmt::format("fit: {{iterations: {}, rail_control_points: {}{}}}\n", o.max_iterations, o.rail_control_points,
                   job.robust_mm ? ", robust: " + num(*job.robust_mm) : "");
  if (!job.machine.empty()) {
    const std::filesystem::path local = job.file.parent_path() / job.machine;
    y += "machine: " +
         quoted(is_file(local) ? std::filesystem::absolute(local).lexically_normal().string()
                                                        : job.machine) +
         "\n";
  }
  const PostJob& p = job.post;
  y += "post:\n";
  if (!p.dialects.empty()) y += fmt::format("  dialects: [{}]\n", fmt::join(p.dialects, ", "));
  y += fmt::format("  apt: {}\n  cl: {}\n  tool: {}\n  line_numbers: {}\n", p.apt, p.cl, p.tool, p.line_numbers);
  y += fmt::format("  tolerance: {}\n  angle_tolerance: {}\n", num(p.tolerance_mm), num(p.angle_tolerance_deg));
  if (p.tool_length_mm > 0) y += "  tool_length: " + num(p.tool_length_mm) + "\n";
  y += "  safe_height: " + num(p.safe_height_mm) + "\n";
  y += fmt::format("  setup: {{rotate: [{}, {}, {}], translate: [{}, {}, {}]}}\n", num(p.setup_rotate_deg[0]),
                   num(p.setup_rotate_deg[1]), num(p.setup_rotate_deg[2]), num(p.setup_translate_mm[0]),
                   num(p.setup_translate_mm[1]), num(p.setup_translate_mm[2]));
  if (f.patches.empty()) {
    y += "# no patch was detected\npatches: []\n";
    return y;
  }
  y += "patches:\n";
  for (const FittedPatch& fp : f.patches) {
    const PatchJob& pj = *fp.job;
    if (fp.refused) y += fmt::format("  # {}: refused for collisions (no program; see report.json)\n", pj.name);
    y += fmt::format("  - name: {}\n    init: lines\n    rail: {}\n", pj.name, pj.rail);
    if (pj.length_mm > 0) y += "    length: " + fixed(pj.length_mm, 6) + "\n";
    y += "    lines:\n";
    for (const auto& l : pj.lines_mm) {
      std::vector<std::string> v;
      for (double x : l) v.push_back(fixed(x, 6));
      y += fmt::format("      - [{}]\n", fmt::join(v, ", "));
    }
  }
  return y;
}

}  // namespace flankcam::pipeline
