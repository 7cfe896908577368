#include "pipeline/outputs.h"

#include <fmt/format.h>

#include <algorithm>
#include <array>

#include "core/atomic_file.h"
#include "core/number_format.h"
#include "postproc/gcode.h"
#include "postproc/report_html.h"
#include "postproc/report_svg.h"
#include "postproc/tool_export.h"
#include "postproc/viewer.h"

namespace flankcam::pipeline {

namespace {
std::vector<std::array<unsigned char, 3>> deviation_colors(const std::vector<double>& dev, double tol) {
  std::vector<std::array<unsigned char, 3>> c(dev.size());
  for (size_t i = 0; i < dev.size(); ++i) c[i] = deviation_color(dev[i], tol);
  return c;
}

void write_text(OutputDir& out, const std::string& name, const std::string& text) {
  write_file_atomically(out.file(name), [&](std::ostream& o) { o << text; });
}

struct PatchOutputs {
  const ClProgram* program = nullptr;  // CL-data (none for a colliding patch unless collisions are allowed)
  bool apt = true, cl = true, tool = true;
  const ClProgram* apt_program = nullptr;  // NAME.apt when it differs from `program` (every pass of the patch)
};

std::vector<std::string> write_patch_files(OutputDir& out, const Job& job, const FittedJob& f, const FittedPatch& p,
                                           const PatchOutputs& what) {
  const Similarity& fr = f.frame;
  const std::string& name = p.job->name;
  const MachinedSurface& ms = p.fit.machined;
  const auto to_mm = [&](std::vector<double> v) {
    for (double& x : v) x = fr.length_to_mm(x);
    return v;
  };
  const std::string tol = fmt::format("tolerance {} mm; deviation_mm > 0 undercut, < 0 overcut, nan not reached", job.tolerance_mm);

  TriMesh omega = ms.omega.mesh;
  for (auto& v : omega.vertices) v = fr.to_mm(v);
  const std::vector<double> omega_dev = to_mm(ms.omega_deviation);
  write_ply(out.file(name + "-envelope.ply"), omega, deviation_colors(omega_dev, job.tolerance_mm), omega_dev, "deviation_mm",
            "machined envelope of patch " + name + "; " + tol);
  const std::vector<double> design_dev = to_mm(ms.design_deviation);
  write_ply(out.file(name + "-deviation.ply"), f.surface.mesh, deviation_colors(design_dev, job.tolerance_mm), design_dev,
            "deviation_mm", "design surface vs patch " + name + "; " + tol);
  std::vector<std::string> files = {name + "-envelope.ply", name + "-deviation.ply"};
  const std::vector<Eigen::Vector2d>& profile = p.profile_mm;
  if (what.tool) {
    write_file_atomically(out.file(name + "-tool.csv"), [&](std::ostream& o) {
      o << "# tool of patch " << name << ": meridian of a " << to_string(p.fit.fit.tool.shape)
        << " tool, mm, z along the axis from the tip end\nz_mm,r_mm\n";
      for (const Eigen::Vector2d& zr : profile) o << fixed(zr.x(), 6) << ',' << fixed(zr.y(), 6) << '\n';
    });
    const std::string title =
        fmt::format("patch {}, {} tool, length {:.3f} mm", name, to_string(p.fit.fit.tool.shape), p.assembly.cutter_length());
    write_tool_dxf(out.file(name + "-tool.dxf"), profile, title);
    write_tool_stl(out.file(name + "-tool.stl"), profile, title);
    files.insert(files.end(), {name + "-tool.csv", name + "-tool.dxf", name + "-tool.stl"});
    if (!job.tool.catalogue) {  // a custom tool is ground: its sheet goes beside the DXF
      write_text(out, name + "-tool-sheet.csv", tool_sheet(job, p));
      files.push_back(name + "-tool-sheet.csv");
    }
  }
  if (what.program) {
    if (what.apt)
      write_apt(out.file(name + ".apt"), what.apt_program ? *what.apt_program : *what.program), files.push_back(name + ".apt");
    if (what.cl) {
      // The CSV holds what NAME.apt holds: every pass and depth level in order.
      write_file_atomically(out.file(name + "-cl.csv"),
                            [&](std::ostream& o) { o << cl_csv(what.apt_program ? *what.apt_program : *what.program); });
      files.push_back(name + "-cl.csv");
    }
  }

  if (!p.collisions.clear()) {
    TriMesh all;
    for (const CollisionInterval& iv : p.collisions.intervals) {
      const TriMesh one = assembly_mesh(p.assembly, p.poses[size_t(iv.worst_pose)]);
      const int base = int(all.vertices.size());
      all.vertices.insert(all.vertices.end(), one.vertices.begin(), one.vertices.end());
      for (auto fc : one.faces) all.faces.push_back({fc[0] + base, fc[1] + base, fc[2] + base});
    }
    write_obj(out.file(name + "-collisions.obj"), all,
              "patch " + name + ": tool assembly at the worst pose of each collision interval, mm");
    files.push_back(name + "-collisions.obj");
  }
  return files;
}

void write_program(OutputDir& out, const PostedProgram& p, const PostSettings& s) {
  write_nc(out.file(p.file), p.posted.program, {p.dialect, s.line_numbers, p.posted.tolerance_mm});  // as back-simulated
}
// The 3D view of report.html: Φ with each patch's deviation, Ω, the fitted poses, collision markers,
// and the motion of every posted program (the first dialect's) taken back to the part frame.
ViewerScene viewer_scene(const Job& job, const FittedJob& fitted, const std::vector<PostedProgram>& programs,
                         const Machine& machine) {
  ViewerScene v;
  v.tolerance_mm = job.tolerance_mm;
  v.surface_mm = fitted.surface.mesh;
  if (fitted.part) v.part_mm = *fitted.part;
  std::vector<std::string> names;
  for (const FittedPatch& p : fitted.patches) {
    ViewerPatch vp{p.job->name, p.profile_mm, p.assembly, p.fit.machined.design_deviation, p.fit.machined.omega.mesh, p.poses, {}};
    for (double& d : vp.design_deviation_mm) d = fitted.frame.length_to_mm(d);
    for (auto& x : vp.envelope_mm.vertices) x = fitted.frame.to_mm(x);
    const std::vector<std::string> labels = collision_summary(p);
    for (size_t i = 0; i < p.collisions.intervals.size(); ++i)
      vp.markers.push_back({p.collisions.intervals[i].at, p.collisions.intervals[i].worst_pose, labels.at(i), {}});
    names.push_back(vp.name);
    v.patches.push_back(std::move(vp));
  }
  const ToolPose o = to_work(job.post, {Eigen::Vector3d::Zero(), Eigen::Vector3d::UnitZ()});  // o.tip: the translation
  const Eigen::Matrix3d R = setup_rotation(job.post).transpose();  // work -> part
  const std::array<std::string, 2> rotary{machine.rotary[0].name, machine.rotary[1].name};
  for (const PostedProgram& w : programs)
    if (w.dialect == programs.front().dialect) v.tracks.push_back(viewer_track(w.posted, w.file, rotary, R, -R * o.tip, names));
  for (size_t k = 0; k < fitted.patches.size(); ++k)  // patches without a program: their fitted poses
    if (std::none_of(programs.begin(), programs.end(), [&](const PostedProgram& w) { return w.patch == names[k]; })) {
      ViewerTrack t{names[k] + " (fitted poses, no program)", {"X", "Y", "Z", rotary[0], rotary[1]}, false, {}};
      for (const ToolPose& q : fitted.patches[k].poses) t.frames.push_back({q, {}, false, int(k), 0});
      v.tracks.push_back(std::move(t));
    }
  return v;
}

// `patches: auto`: the whole surface, which patch machines each point and the union's deviation.
HtmlSection cover_section(OutputDir& out, const Job& job, const FittedJob& fitted) {
  const CoverResult& c = *fitted.cover;
  std::vector<std::string> names;
  for (const FittedPatch& p : fitted.patches) names.push_back(p.job->name);
  HtmlSection section;
  section.heading = "Whole surface";
  section.facts = {{"patches", fmt::format("{} (stopped: {})", fitted.patches.size(), c.stop)},
                   {"coverage within tolerance", fmt::format("{:.1f}% within {} mm", 100 * c.coverage, job.tolerance_mm)},
                   {"worst overcut", fmt::format("{:.4f} mm", c.overcut_mm)}};
  section.svgs = {patch_owner_svg(fitted.surface.mesh, c.owner, names, "Which patch machines each point of the design surface"),
                  deviation_map_svg(fitted.surface.mesh, c.deviation_mm, job.tolerance_mm, {}, {},
                                    "Signed deviation of the design surface from all patches together", 160, {},
                                    "machined by no patch")};
  section.files = {cover_owner_svg_name, cover_deviation_svg_name};
  for (size_t i = 0; i < section.svgs.size(); ++i) write_text(out, section.files[i], section.svgs[i]);
  return section;
}

}  // namespace

std::vector<std::vector<std::string>> write_fit(const FitRun& run, OutputDir& out) {
  const Job& job = run.job;
  const FittedJob& fitted = run.fitted;
  nlohmann::ordered_json report;
  report["generator"] = "flankcam fit";
  report["job"] = job.file.string();
  report["units"] = "mm";
  report["surface"] = surface_report(job, fitted);
  report["options"] = {{"tool_shape", to_string(job.fit.shape)},
                       {"tolerance_mm", job.tolerance_mm},
                       {"sampling", {{"s", job.fit.samples_s}, {"t", job.fit.samples_t}}},
                       {"weights", {{"plane", job.fit.w_plane}, {"fair", job.fit.w_fair}, {"point", job.fit.w_point},
                                    {"rigid", job.fit.w_rigid}, {"anchor", job.fit.w_anchor}}}};
  if (fitted.cover) {
    report["cover"] = cover_report(job, fitted);
    write_text(out, detected_job_name, detected_job_yaml(job, fitted));
  }
  auto& patches = report["patches"] = nlohmann::ordered_json::array();
  std::vector<std::vector<std::string>> all_files;
  for (size_t k = 0; k < fitted.patches.size(); ++k) {
    const FittedPatch& p = fitted.patches[k];
    nlohmann::ordered_json entry = patch_report(job, fitted, p);
    const auto& cl = run.cl_data[k];
    std::vector<std::string> files = write_patch_files(out, job, fitted, p, {cl ? &*cl : nullptr});
    entry["files"] = files;
    patches.push_back(entry);
    all_files.push_back(std::move(files));
  }
  write_text(out, "report.json", report.dump(1) + "\n");
  out.commit();
  return all_files;
}

std::vector<std::vector<std::string>> write_run(const RunResult& run, OutputDir& out) {
  const Job& job = run.fit.job;
  const FittedJob& fitted = run.fit.fitted;
  const Machine& machine = run.machine;
  const std::vector<PostedProgram>& programs = run.programs;
  for (const PostedProgram& w : programs) write_program(out, w, run.settings);

  nlohmann::ordered_json report;
  report["generator"] = "flankcam run";
  report["job"] = job.file.string();
  report["units"] = "mm";
  report["machine"] = {{"name", machine.name}, {"kind", machine.kind()}, {"file", machine.file},
                       {"dialect", machine.controller.dialect}, {"tcp", machine.controller.tcp}};
  report["surface"] = surface_report(job, fitted);
  if (run.setup) {  // post.setup: auto
    const auto cand = [](const SetupCandidate& c) {
      return nlohmann::ordered_json{{"rotate_deg", c.rotate_deg}, {"reachable", c.reachable},
                                    {"singular_stretches", c.singular_stretches},
                                    {"min_singular_angle_deg", std::round(c.min_singular_deg * 1e3) / 1e3},
                                    {"max_rotary_deg_per_axis_deg", std::round(c.max_rotary_per_deg * 1e3) / 1e3}};
    };
    report["setup"] = {{"auto", true}, {"candidates", run.setup->candidates}, {"chosen", cand(run.setup->chosen)},
                       {"unrotated", cand(run.setup->unrotated)}, {"reason", run.setup->reason}};
  }
  if (fitted.cover) {
    report["cover"] = cover_report(job, fitted);
    write_text(out, detected_job_name, detected_job_yaml(job, fitted));
  }
  auto& patches = report["patches"] = nlohmann::ordered_json::array();

  HtmlReport html;
  html.title = "flankcam: " + job.file.filename().string();
  html.intro = {fmt::format("Design surface {} ({} triangles), machine {} ({}, {}). Lengths in mm; eps is relative to the "
                            "surface's bounding-box diagonal ({:.3f} mm).",
                            job.surface.filename().string(), fitted.surface.mesh.faces.size(), machine.name,
                            machine.kind(), machine.controller.dialect, 1 / fitted.frame.scale),
                fmt::format("Colours: green within the tolerance {} mm, red material left (undercut), blue overcut, "
                            "grey not reached by the patch.",
                            job.tolerance_mm)};
  if (fitted.cover)
    html.intro.push_back(fmt::format("Patches detected automatically (patches: auto; written out as init: lines in {}). "
                                     "W{}.",
                                     detected_job_name, cover_summary(job, fitted).substr(1)));
  html.columns = {"patch", "tool", "eps (rel.)", "eps mm", "coverage", "collisions", "programs"};

  std::vector<std::vector<std::string>> all_files;
  for (size_t k = 0; k < fitted.patches.size(); ++k) {
    const FittedPatch& p = fitted.patches[k];
    const std::string& name = p.job->name;
    const auto& cl = run.fit.cl_data[k];
    const bool allowed = cl.has_value();
    std::vector<std::string> files =
        write_patch_files(out, job, fitted, p,
                          {allowed ? &*cl : nullptr, job.post.apt, job.post.cl, job.post.tool,
                           run.posted_cl[k] ? &*run.posted_cl[k] : nullptr});
    std::vector<std::string> patch_programs;
    nlohmann::ordered_json program_entries = nlohmann::ordered_json::array();
    const PostedProgram* chart = nullptr;
    for (const PostedProgram& w : programs)
      if (w.patch == name) {
        patch_programs.push_back(w.file);
        program_entries.push_back(program_report(w, machine));
        if (!chart) chart = &w;
      }

    // Pictures.
    const std::vector<Eigen::Vector2d>& profile = p.profile_mm;
    std::vector<double> dev = p.fit.machined.design_deviation;
    for (double& d : dev) d = fitted.frame.length_to_mm(d);
    const double eps_mm = fitted.frame.length_to_mm(p.fit.fit.eps_opt.max);
    std::vector<std::string> svgs = {
        deviation_map_svg(fitted.surface.mesh, dev, job.tolerance_mm, p.poses, profile,
                          fmt::format("{}: signed deviation of the design surface, eps {:.4f} mm", name, eps_mm)),
        tool_profile_svg(profile, fmt::format("{}: {} tool", name, to_string(p.fit.fit.tool.shape)))};
    std::vector<std::string> svg_files = {name + "-deviation.svg", name + "-tool.svg"};
    if (chart) {
      std::array<AngleSeries, 2> series;
      for (size_t a = 0; a < 2; ++a)
        series[a] = {machine.rotary[a].name, chart->rotary_deg[a], machine.rotary[a].min_deg, machine.rotary[a].max_deg,
                     machine.rotary[a].continuous};
      svgs.push_back(angle_chart_svg(series, fmt::format("{}: rotary axes over {} ({})", name, chart->file, machine.name)));
      svg_files.push_back(name + "-angles.svg");
    }
    for (size_t i = 0; i < svgs.size(); ++i) write_text(out, svg_files[i], svgs[i]);
    files.insert(files.end(), svg_files.begin(), svg_files.end());
    files.insert(files.end(), patch_programs.begin(), patch_programs.end());

    nlohmann::ordered_json entry = patch_report(job, fitted, p);
    entry["tool_length_mm"] = round_mm(run.tool_length_mm[k]);
    entry["programs"] = program_entries;
    entry["files"] = files;
    patches.push_back(entry);

    const std::string collisions = p.collisions.clear() ? "none" : fmt::format("{} interval(s)", p.collisions.intervals.size());
    const std::string coverage = fmt::format("{:.1f}%", 100 * p.fit.coverage);
    html.rows.push_back({name, tool_label(job, p), fmt::format("{:.2e}", p.fit.fit.eps_opt.max),
                         fmt::format("{:.4f}", eps_mm), coverage, collisions,
                         patch_programs.empty() ? "none" : fmt::format("{}", fmt::join(patch_programs, " "))});
    HtmlSection section;
    section.heading = "Patch " + name;
    section.warnings = collision_summary(p);
    if (!allowed) section.warnings.push_back("No program was written for this patch: it collides or gouges.");
    const ToolDimensions dim = tool_dimensions(profile);
    section.facts = {{"eps (relative, eq. 13)", fmt::format("{:.3e}", p.fit.fit.eps_opt.max)},
                     {"eps", fmt::format("{:.4f} mm", eps_mm)},
                     {"coverage within tolerance", coverage},
                     {"tool", fmt::format("{}, length {:.3f} mm, D {:.3f} .. {:.3f} mm", to_string(p.fit.fit.tool.shape),
                                          dim.length_mm, dim.diameter_min_mm, dim.diameter_max_mm)},
                     {"tool length from the spindle nose", fmt::format("{:.3f} mm", run.tool_length_mm[k])}};
    for (const PostedProgram& w : programs)
      if (w.patch == name)
        section.facts.push_back({w.file, fmt::format("{} moves ({} inserted by linearisation), {} slowed by axis speed, "
                                                     "cut {:.2f} min",
                                                     w.moves, w.inserted, w.slowed, w.minutes)});
    section.svgs = svgs;
    section.files = files;
    html.sections.push_back(std::move(section));
    all_files.push_back(std::move(files));
  }
  if (fitted.cover) html.sections.insert(html.sections.begin(), cover_section(out, job, fitted));
  nlohmann::ordered_json all = nlohmann::ordered_json::array();
  for (const PostedProgram& w : programs)
    if (w.patch.empty()) all.push_back(program_report(w, machine));
  report["all_patches_programs"] = all;
  for (const PostedProgram& w : programs)
    if (w.patch.empty()) html.intro.push_back("All patches in order, with tool changes: " + w.file);
  write_text(out, "report.json", report.dump(1) + "\n");
  html.viewer = viewer_html(viewer_scene(job, fitted, programs, machine));
  write_text(out, "report.html", report_html(html));
  out.commit();
  return all_files;
}

void write_post(const PostRun& run, OutputDir& out) {
  for (const PostedProgram& w : run.programs) write_program(out, w, run.settings);
  // The simulator's tool goes with the programs when the CL-data carries the profile (flankcam's PPRINTs).
  for (const PostInput& in : run.inputs)
    if (in.cl.profile.size() >= 2) write_tool_stl(out.file(in.patch + "-tool.stl"), in.cl.profile, "tool of " + in.patch + ", mm");
  out.commit();
}

}  // namespace flankcam::pipeline
