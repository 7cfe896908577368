#include "pipeline/run.h"

#include <fmt/format.h>
#include <omp.h>

#include <Eigen/Geometry>
#include <algorithm>
#include <optional>

#include "core/errors.h"
#include "pipeline/output_dir.h"
#include "postproc/verify.h"

namespace flankcam::pipeline {

std::string RunOptions::validate() const {
  if (threads < 1 || threads > 256) return "threads: 1 .. 256";
  return {};
}

ThreadScope::ThreadScope(int threads) : previous_(omp_get_max_threads()) { omp_set_num_threads(threads); }
ThreadScope::~ThreadScope() { omp_set_num_threads(previous_); }

int FitRun::colliding() const {
  int n = 0;
  for (const FittedPatch& p : fitted.patches) n += !p.collisions.clear();
  return n;
}

namespace {
// The files `fit` writes per patch (outputs.h), also written by `run`.
void plan_fit_files(const std::string& name, bool tool, bool apt, bool cl, OutputPlan& plan) {
  const std::string owner = "patch " + name;
  for (const char* suffix : {"-envelope.ply", "-deviation.ply", "-collisions.obj"}) plan.add(name + suffix, owner);
  if (tool)
    for (const char* suffix : {"-tool.csv", "-tool.dxf", "-tool.stl", "-tool-sheet.csv"}) plan.add(name + suffix, owner);
  if (apt) plan.add(name + ".apt", owner);
  if (cl) plan.add(name + "-cl.csv", owner);
}

// The passes of a patch as one CL program: each pass's moves in order, each pass entered by a rapid
// (so no feed motion joins one pass to the next).
ClProgram all_passes(const std::vector<ClProgram>& passes) {
  ClProgram all = passes.back();
  if (passes.size() == 1) return all;
  all.moves.clear();
  for (const ClProgram& pass : passes)
    for (size_t i = 0; i < pass.moves.size(); ++i) {
      all.moves.push_back(pass.moves[i]);
      if (i == 0) all.moves.back().rapid = true;
    }
  return all;
}

// depth_cuts: level k of n (k = 1 .. n) of one pass. The flank's height is the cutter's length H
// (the fitted tool spans the flank from its tip to H); level k stands (n - k) H / n higher along the
// tool axis, so it cuts the top k/n of the flank and the last level, the fitted motion itself, the
// full depth. Lifted along its axis the tool's side at a flank height z is its radius at z - Δ:
// a tool that narrows away from the tip would cut into the flank there, so the level is also moved
// off the surface (along the contact normal, perpendicular to the axis) by the largest such gain
// (0 for cylinders and tools widening towards the shank, which leave Δ tan(α) of stock instead).
ClProgram depth_level(const ClProgram& pass, const FittedPatch& p, int level, int levels, const SurfaceIndex& design) {
  if (level == levels && levels == 1) return pass;
  const std::vector<Eigen::Vector2d>& zr = p.profile_mm;
  const auto r_at = [&](double z) {
    if (z <= zr.front().x()) return zr.front().y();
    if (z >= zr.back().x()) return zr.back().y();
    const auto it = std::upper_bound(zr.begin(), zr.end(), z, [](double v, const Eigen::Vector2d& q) { return v < q.x(); });
    const Eigen::Vector2d &a = *(it - 1), &b = *it;
    return a.y() + (b.y() - a.y()) * (z - a.x()) / (b.x() - a.x());
  };
  const double H = p.assembly.cutter_length(), lift = H * (levels - level) / levels;
  double off = 0;
  for (int k = 0; k <= 200 && lift > 0; ++k) {
    const double z = (H - lift) * k / 200;
    off = std::max(off, r_at(z) - r_at(z + lift));
  }
  ClProgram out = pass;
  out.comments.push_back(off > 0 ? fmt::format("FLANKCAM DEPTH CUT {} OF {}: TIP {:.4f} MM ABOVE FULL DEPTH, {:.4f} MM OFF THE SURFACE",
                                               level, levels, lift, off)
                                 : fmt::format("FLANKCAM DEPTH CUT {} OF {}: TIP {:.4f} MM ABOVE FULL DEPTH", level, levels, lift));
  // The contact normal per move (from the design surface to the axis); moves without a contact
  // (approach, retract) take the nearest one's.
  std::vector<Eigen::Vector3d> normal(out.moves.size(), Eigen::Vector3d::Zero());
  for (size_t i = 0; i < out.moves.size(); ++i) {
    const ClMove& m = out.moves[i];
    if (!m.contact.allFinite()) continue;
    const Eigen::Vector3d e = m.pose.axis.normalized();
    Eigen::Vector3d w = m.pose.tip + 0.5 * H * e - m.contact;
    w -= w.dot(e) * e;
    if (w.norm() > 1e-12) normal[i] = w.normalized();
  }
  for (size_t i = 1; i < normal.size(); ++i)
    if (normal[i].isZero()) normal[i] = normal[i - 1];
  for (size_t i = normal.size(); i-- > 1;)
    if (normal[i - 1].isZero()) normal[i - 1] = normal[i];
  for (size_t i = 0; i < out.moves.size(); ++i) {
    ClMove& m = out.moves[i];
    const Eigen::Vector3d e = m.pose.axis.normalized();
    m.pose.tip += lift * e + off * normal[i];
    // The contact: the design surface nearest the middle of the engaged part of the cutter.
    if (m.contact.allFinite()) m.contact = design.closest(m.pose.tip + 0.5 * (H - lift) * e).point;
  }
  return out;
}

// A posted section's CL-data (work frame, links planned by the post) back in part coordinates, as
// NAME.apt runs it: entered by a rapid to the lead point moved `retract_mm` up the tool axis and a rapid
// down the axis to it (lead_point checked that axial rapid from beyond the part's reach), then the
// planned feed in along the surface normal, the cut and the feed out, left by a rapid `retract_mm` up
// the axis. The contacts stay as they are (the sections were posted with part-frame contacts).
ClProgram apt_section(ClProgram cl, const PostJob& post, double retract_mm) {
  for (ClMove& mv : cl.moves) mv.pose = from_work(post, mv.pose);
  if (cl.moves.empty()) return cl;
  const auto up = [&](const ClMove& at) {
    ClMove mv;
    mv.pose = {at.pose.tip + retract_mm * at.pose.axis.normalized(), at.pose.axis};
    mv.rapid = true;
    return mv;
  };
  if (cl.moves.front().rapid) cl.moves.insert(cl.moves.begin(), up(cl.moves.front()));
  if (!cl.moves.back().rapid) cl.moves.push_back(up(cl.moves.back()));
  return cl;
}

void check_options(const RunOptions& o) {
  if (auto err = o.validate(); !err.empty()) throw InputError(err);
}

PostSettings settings_of(const Job& job) {
  PostSettings s;
  for (const std::string& d : job.post.dialects) s.dialects.push_back(parse_dialect(d));
  s.line_numbers = job.post.line_numbers;
  s.options.path.tolerance_mm = job.post.tolerance_mm;
  s.options.path.angle_tolerance_deg = job.post.angle_tolerance_deg;
  s.options.safe_height_mm = job.post.safe_height_mm;
  return s;
}

// Fit and check every patch; CL-data for those allowed to run, tool numbers from `tool_of`.
template <class ToolOf>
FitRun fit_run(Job job, const RunOptions& o, ToolOf tool_of) {
  check_options(o);
  const ThreadScope threads(o.threads);
  FitRun r;
  r.job = std::move(job);
  r.allow_collisions = o.allow_collisions;
  r.fitted = fit_job(r.job, o.threads, o.progress);
  if (!o.allow_collisions) {
    shorten_to_clear(r.job, r.fitted, o.progress);
    refuse_colliding(r.job, r.fitted, o.progress);
  }
  r.cl_data.resize(r.fitted.patches.size());
  for (size_t k = 0; k < r.fitted.patches.size(); ++k) {
    const FittedPatch& p = r.fitted.patches[k];
    if (!p.refused) r.cl_data[k] = patch_program(r.job, r.fitted, p, tool_of(k));
  }
  return r;
}
}  // namespace

void check_fit_outputs(const Job& job) {
  OutputPlan plan;
  plan.add("report.json", "the report");
  if (job.cover) plan.add(detected_job_name, "the detected patches (patches: auto)");
  for (const PatchJob& p : job.patches) plan_fit_files(p.name, true, true, true, plan);
}

Machine check_run(const Job& job) {
  if (job.machine.empty())
    throw InputError(job.file.string() + ": machine: missing (flankcam run needs a machine file or one of machines/)");
  Machine machine = find_machine(job.machine, job.file.parent_path());
  const PostSettings settings = settings_of(job);
  OutputPlan plan;
  plan.add("report.json", "the report");
  plan.add("report.html", "the report");
  if (job.cover) {
    plan.add(detected_job_name, "the detected patches (patches: auto)");
    plan.add(cover_owner_svg_name, "the report (patches: auto)");
    plan.add(cover_deviation_svg_name, "the report (patches: auto)");
  }
  const std::vector<Dialect> dialects = dialects_of(machine, settings);
  for (const PatchJob& p : job.patches) {
    plan_fit_files(p.name, job.post.tool, job.post.apt, job.post.cl, plan);
    for (const char* suffix : {"-deviation.svg", "-tool.svg", "-angles.svg"}) plan.add(p.name + suffix, "patch " + p.name);
    for (const Dialect d : dialects) plan.add(p.name + file_extension(d), "the NC program of patch " + p.name);
  }
  if (job.patches.size() > 1)
    for (const Dialect d : dialects) plan.add(all_patches_name + file_extension(d), "the program of all patches in order");
  return machine;
}

FitRun fit(Job job, const RunOptions& options) {
  check_fit_outputs(job);
  return fit_run(std::move(job), options, [](size_t) { return 1; });
}

ToolPose to_work(const PostJob& post, const ToolPose& p) {
  const Eigen::Matrix3d R = setup_rotation(post);
  const Eigen::Vector3d t(post.setup_translate_mm[0], post.setup_translate_mm[1], post.setup_translate_mm[2]);
  return {R * p.tip + t, (R * p.axis).normalized()};
}

ToolPose from_work(const PostJob& post, const ToolPose& p) {
  const Eigen::Matrix3d Rt = setup_rotation(post).transpose();
  const Eigen::Vector3d t(post.setup_translate_mm[0], post.setup_translate_mm[1], post.setup_translate_mm[2]);
  return {Rt * (p.tip - t), (Rt * p.axis).normalized()};
}

ClProgram to_work(const PostJob& post, ClProgram cl) {
  for (ClMove& mv : cl.moves) mv.pose = to_work(post, mv.pose);
  return cl;
}

TriMesh to_work(const PostJob& post, TriMesh mesh) {
  for (Eigen::Vector3d& v : mesh.vertices) v = to_work(post, {v, Eigen::Vector3d::UnitZ()}).tip;
  return mesh;
}

double tool_length(const Job& job, const FittedPatch& p) {
  if (job.post.tool_length_mm > 0) return job.post.tool_length_mm;
  return job.holder.length + job.holder.cylinder_length + job.holder.shank_length + p.assembly.cutter_length();
}

namespace {
SetupCandidate evaluate_setup(const Job& job, const Machine& m, const std::vector<const ClProgram*>& cl,
                              const std::vector<double>& tool_length_mm, const std::array<double, 3>& rotate_deg) {
  SetupCandidate c;
  c.rotate_deg = rotate_deg;
  c.min_singular_deg = 180;
  PostJob post = job.post;
  post.setup_rotate_deg = rotate_deg;
  for (size_t k = 0; k < cl.size(); ++k) {
    std::vector<ToolPose> poses;
    for (const ClMove& mv : cl[k]->moves)
      if (!mv.rapid) poses.push_back(to_work(post, mv.pose));
    if (poses.size() < 2) continue;
    PathOptions po;
    po.tool_length_mm = tool_length_mm[k];
    po.tolerance_mm = job.post.tolerance_mm;
    po.angle_tolerance_deg = job.post.angle_tolerance_deg;
    const JointPath path = solve_path(m, poses, {}, po);
    if (!path.reachable) {
      c.reachable = false;
      c.why = fmt::format("patch {} pose {}: {}", k + 1, path.failed_pose, path.why);
      return c;
    }
    c.singular_stretches += int(singular_stretches(path).size());
    for (size_t j = 0; j < path.poses.size(); ++j) {
      c.min_singular_deg = std::min(c.min_singular_deg, singularity_angle_deg(m, path.poses[j].axis));
      if (j == 0) continue;
      const auto [rot, turn] = block_turn(path, j);
      if (rot >= 0.1) c.max_rotary_per_deg = std::max(c.max_rotary_per_deg, rot / std::max(turn, 1e-3));
    }
  }
  return c;
}
}  // namespace

SetupDecision choose_setup(const Job& job, const Machine& m, const std::vector<const ClProgram*>& cl,
                           const std::vector<double>& tool_length_mm) {
  constexpr double kClearDeg = 10;  // the tool axis at least this far from a singular orientation
  SetupDecision d;
  std::vector<std::array<double, 3>> rotations;
  for (const double c : {0.0, 90.0, 180.0, 270.0})
    for (const double mag : {0.0, 15.0, 30.0})
      for (const double a : {0.0, mag, -mag})
        for (const double b : {0.0, mag, -mag})
          if (std::max(std::abs(a), std::abs(b)) == mag &&
              std::find(rotations.begin(), rotations.end(), std::array<double, 3>{a, b, c}) == rotations.end())
            rotations.push_back({a, b, c});
  std::optional<SetupCandidate> best, farthest;
  const auto evaluate = [&](const std::vector<std::array<double, 3>>& candidates) {
    for (const auto& r : candidates) {
      const SetupCandidate c = evaluate_setup(job, m, cl, tool_length_mm, r);
      ++d.candidates;
      if (r == std::array<double, 3>{0, 0, 0}) d.unrotated = c;
      if (!c.reachable) continue;
      if (!farthest || c.min_singular_deg > farthest->min_singular_deg + 1e-9) farthest = c;
      if (!best && c.singular_stretches == 0 && c.min_singular_deg >= kClearDeg) best = c;
    }
  };
  evaluate(rotations);
  // None clear: the part turned over as well (180 deg about X, the same tilts and turns), for a part
  // whose flanks open downwards (the HECC diffuser, hub on top: none of the above reaches it).
  if (!best) {
    std::vector<std::array<double, 3>> flipped;
    for (const auto& r : rotations) flipped.push_back({r[0] > 0 ? r[0] - 180 : r[0] + 180, r[1], r[2]});
    evaluate(flipped);
  }
  if (!best && !farthest)
    throw InputError(fmt::format("{}: post.setup: auto: no candidate rotation reaches every pose on {} (unrotated: {})",
                                 job.file.string(), m.name, d.unrotated.why));
  d.chosen = best ? *best : *farthest;
  const SetupCandidate& c = d.chosen;
  const SetupCandidate& u = d.unrotated;
  d.reason = fmt::format(
      "post.setup auto: rotate [{}, {}, {}] of {} candidates: {} singular stretch(es), tool axis >= {:.1f} deg from a "
      "singular orientation, at most {:.1f} deg of rotary travel per deg of axis turn{}",
      c.rotate_deg[0], c.rotate_deg[1], c.rotate_deg[2], d.candidates, c.singular_stretches, c.min_singular_deg,
      c.max_rotary_per_deg,
      !u.reachable ? fmt::format(" (unrotated: out of reach, {})", u.why)
                   : fmt::format(" (unrotated: {} stretch(es), {:.1f} deg, {:.1f} deg/deg)", u.singular_stretches,
                                 u.min_singular_deg, u.max_rotary_per_deg));
  if (!best) d.reason += fmt::format("; no candidate keeps {} deg from it, this one is the farthest", kClearDeg);
  return d;
}

RunResult run(Job job, Machine machine, const RunOptions& options) {
  RunResult r;
  r.settings = settings_of(job);
  // One tool for every patch (shared or from the catalogue): one tool number, so no tool change.
  const bool one_tool = job.tool.shared || job.tool.catalogue.has_value();
  r.fit = fit_run(std::move(job), options, [one_tool](size_t k) { return one_tool ? 1 : int(k) + 1; });
  r.machine = std::move(machine);
  if (r.fit.job.post.setup_auto) {
    std::vector<const ClProgram*> cl;
    std::vector<double> lengths;
    for (size_t k = 0; k < r.fit.fitted.patches.size(); ++k)
      if (r.fit.cl_data[k]) cl.push_back(&*r.fit.cl_data[k]), lengths.push_back(tool_length(r.fit.job, r.fit.fitted.patches[k]));
    r.setup = choose_setup(r.fit.job, r.machine, cl, lengths);
    r.fit.job.post.setup_rotate_deg = r.setup->chosen.rotate_deg;
    options.progress(r.setup->reason);
  }
  const Job& j = r.fit.job;
  const ThreadScope threads(options.threads);
  // Kinematics and programs for every patch allowed to run, all solved before any file is written:
  // an unreachable pose ends the run with nothing half done.
  r.posted_cl.resize(r.fit.fitted.patches.size());
  std::optional<SurfaceIndex> design;  // depth_cuts: the contacts of the levels (part coordinates, mm)
  if (j.depth_cuts > 1) design.emplace(r.fit.fitted.surface.mesh);
  // A patch's sections (part coordinates): passes, each its own section of the patch's program, in
  // order, the last pass being the fit; depth_cuts: within each pass its levels, the deepest last.
  const auto sections_of = [&](size_t k) {
    const FittedPatch& p = r.fit.fitted.patches[k];
    std::vector<ClProgram> passes, sections;
    for (const PassMotion& pm : p.earlier_passes) passes.push_back(pass_program(j, r.fit.fitted, p, pm, r.fit.cl_data[k]->tool));
    passes.push_back(*r.fit.cl_data[k]);
    for (const ClProgram& pass : passes)
      for (int level = 1; level <= j.depth_cuts; ++level)
        sections.push_back(j.depth_cuts == 1 ? pass : depth_level(pass, p, level, j.depth_cuts, *design));
    return sections;
  };
  const size_t patches = r.fit.fitted.patches.size();
  if (std::none_of(r.fit.cl_data.begin(), r.fit.cl_data.end(), [](const auto& c) { return c.has_value(); })) {
    for (const FittedPatch& p : r.fit.fitted.patches) r.tool_length_mm.push_back(tool_length(j, p));
    return r;
  }
  // The part placed on the machine (work frame): the links are planned against it, and every
  // program is back-simulated from its text before anything is written.
  const SurfaceIndex part_index(to_work(j.post, r.fit.fitted.part ? *r.fit.fitted.part : r.fit.fitted.surface.mesh));
  PostSettings settings = r.settings;  // r.settings must not keep a pointer to part_index
  settings.options.part = &part_index;
  settings.options.clearance_mm = j.clearance_mm;
  settings.options.gouge_tolerance_mm = j.tolerance_mm;
  // With a separate part the cut is judged as the fit's check judges it: the part without Φ's coarser
  // twin by check_tolerance, Φ by the fitted tolerance.
  std::optional<SurfaceIndex> cut_part, design_work;
  if (r.fit.fitted.check_part) {
    cut_part.emplace(to_work(j.post, *r.fit.fitted.check_part));
    design_work.emplace(to_work(j.post, r.fit.fitted.surface.mesh));
    settings.options.design = &*design_work;
    const CutJudgement c = cut_judgement(j, r.fit.fitted.check_twin_sag_mm);
    settings.options.gouge_tolerance_mm = c.part_mm;
    settings.options.apart = c.apart(&*cut_part);
  }
  // A cut whose end has no clear lead (a tool standing deep in a passage where the motion was trimmed
  // for the part) is shortened to the outermost poses that can be entered and left, every section of
  // the patch alike; its coverage and the cover's union are judged anew (keep_poses). None: refused.
  std::vector<std::optional<KeptPoses>> keep(patches);
  std::vector<std::vector<ClProgram>> sections(patches);
  const auto refuse = [&](const FittedPatch& p, const std::string& why) {
    return ProgramRefused(fmt::format("link planning: patch '{}': {}; nothing written", p.job->name, why));
  };
  for (size_t k = 0; k < patches; ++k) {
    if (!r.fit.cl_data[k]) continue;
    const FittedPatch& p = r.fit.fitted.patches[k];
    sections[k] = sections_of(k);
    size_t i0 = 0, i1 = p.poses.size() - 1;
    std::string why;
    for (const ClProgram& section : sections[k]) {
      const LeadRange lr = clear_lead_range(to_work(j.post, section), p.assembly, settings.options);
      if (lr.none) throw refuse(p, lr.why);
      if (!lr.trimmed()) continue;
      i0 = std::max(i0, lr.kept_first - lr.first);
      i1 = std::min(i1, lr.kept_last - lr.first);
      if (why.empty()) why = lr.why;
    }
    if (why.empty()) continue;
    if (!(i0 < i1)) throw refuse(p, why);
    keep[k] = KeptPoses{i0, i1, why};
  }
  keep_poses(j, r.fit.fitted, keep, &FittedPatch::kept_for_leads, "for their leads", options.progress);
  std::vector<PostInput> inputs;  // work coordinates
  for (size_t k = 0; k < patches; ++k) {
    const FittedPatch& p = r.fit.fitted.patches[k];
    r.tool_length_mm.push_back(tool_length(j, p));
    if (!r.fit.cl_data[k]) continue;
    if (keep[k]) {  // its CL-data and sections anew from the kept poses
      r.fit.cl_data[k] = patch_program(j, r.fit.fitted, p, r.fit.cl_data[k]->tool);
      sections[k] = sections_of(k);
    }
    r.posted_cl[k] = all_passes(sections[k]);  // replaced by the programs' planned links below
    // The cutter the collision check judged: the tool's meridian.
    for (ClProgram& section : sections[k]) inputs.push_back({to_work(j.post, std::move(section)), p.job->name, r.tool_length_mm.back(), p.assembly});
  }
  const Machine& m = r.machine;
  options.progress(fmt::format("kinematics and post: {} patch(es) on {} ({})", inputs.size(), m.name, m.kind()));
  r.programs = post_programs(
      m, inputs, all_patches_name, settings,
      {fmt::format("flankcam run of {}", j.file.filename().string()), fmt::format("machine {} ({}), units mm", m.name, m.kind()),
       fmt::format("linearisation tolerance {} mm, {} deg", j.post.tolerance_mm, j.post.angle_tolerance_deg),
       fmt::format("work frame = part rotated X {} Y {} Z {} deg, moved by ({}, {}, {}) mm", j.post.setup_rotate_deg[0],
                   j.post.setup_rotate_deg[1], j.post.setup_rotate_deg[2], j.post.setup_translate_mm[0],
                   j.post.setup_translate_mm[1], j.post.setup_translate_mm[2])});
  for (const PostedProgram& w : r.programs)
    if (w.posted.refined > 0)
      options.progress(fmt::format("{}: linearised at {:.6g} mm, {:.6g} deg instead of {} mm, {} deg, at which the cut entered the part: {}", w.file,
                                   w.posted.tolerance_mm, w.posted.angle_tolerance_deg, j.post.tolerance_mm,
                                   j.post.angle_tolerance_deg, w.posted.refined_for));
  // NAME.apt and NAME-cl.csv carry the links of the patch's program (the first dialect's): the CL-data
  // as posted, section by section, back in part coordinates. (The post must still be given the
  // unplanned CL-data: planned twice, the second plan would lead off the first's lead point.)
  for (size_t k = 0; k < r.fit.fitted.patches.size(); ++k) {
    if (!r.posted_cl[k]) continue;
    const std::string& name = r.fit.fitted.patches[k].job->name;
    const auto w = std::find_if(r.programs.begin(), r.programs.end(), [&](const PostedProgram& p) { return p.patch == name; });
    if (w == r.programs.end()) continue;
    std::vector<ClProgram> sections;
    for (const PostedSection& sec : w->posted.sections) sections.push_back(apt_section(sec.cl, j.post, j.retract_mm));
    r.posted_cl[k] = all_passes(sections);
  }
  return r;
}

PostRun check_post(const PostRequest& req) {
  PostRun r;
  r.request = req;
  r.machine = find_machine(req.machine);
  const Machine& m = r.machine;
  const bool head = m.rotary[0].carries == Carrier::Head || m.rotary[1].carries == Carrier::Head;
  if (head && !(req.tool_length_mm > 0))
    throw InputError(fmt::format("--tool-length: machine {} turns the head; give the tool's length from the spindle "
                                 "nose to the tip (mm)",
                                 m.name));
  if (!req.dialect.empty()) r.settings.dialects = {parse_dialect(req.dialect)};
  r.settings.line_numbers = req.line_numbers;
  r.settings.options.path.tolerance_mm = req.tolerance_mm;
  r.settings.options.path.tool_length_mm = req.tool_length_mm;
  r.settings.options.safe_height_mm = req.safe_height_mm;
  // Every program gets its own file: PATCH.EXT from the APT file's stem, ALL.EXT from --name.
  check_file_name(req.name, "--name");
  OutputPlan plan;
  const std::vector<Dialect> dialects = dialects_of(m, r.settings);
  for (const std::string& file : req.apt) {
    const std::string stem = std::filesystem::path(file).stem().string();
    const std::string owner = "the program of " + file;
    check_file_name(stem, file);
    for (const Dialect d : dialects) plan.add(stem + file_extension(d), owner);
    plan.add(stem + "-tool.stl", "the tool of " + file);
  }
  if (req.apt.size() > 1)
    for (const Dialect d : dialects) plan.add(req.name + file_extension(d), "the program of all files in order (--name)");
  return r;
}

PostRun post_apt(PostRun r) {
  const PostRequest& req = r.request;
  for (const std::string& file : req.apt) {
    PostInput in;
    in.cl = read_apt(file);
    in.patch = std::filesystem::path(file).stem().string();
    in.tool_length_mm = req.tool_length_mm;
    r.inputs.push_back(std::move(in));
  }
  r.programs = post_programs(
      r.machine, r.inputs, req.name, r.settings,
      {fmt::format("flankcam post for machine {} ({}), units mm", r.machine.name, r.machine.kind()),
       fmt::format("linearisation tolerance {} mm, {} deg", req.tolerance_mm, r.settings.options.path.angle_tolerance_deg)});
  return r;
}

}  // namespace flankcam::pipeline
