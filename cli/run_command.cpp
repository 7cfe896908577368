// `flankcam run JOB.yaml --out DIR`: the main job end to end. Fit every patch, check collisions,
// solve the machine's kinematics, post NC programs, and write the report (JSON, SVG pictures, HTML).
#include <fmt/format.h>

#include <Eigen/Geometry>

#include <filesystem>
#include <optional>

#include "cli/commands.h"
#include "cli/fit_stage.h"
#include "cli/post_stage.h"
#include "core/atomic_file.h"
#include "core/closest_point.h"
#include "core/errors.h"
#include "core/mesh.h"
#include "postproc/report_html.h"
#include "postproc/report_svg.h"

namespace flankcam::cli {

namespace {
struct RunArgs {
  std::string job, out;
  int threads = 2;
  bool quiet = false;
  bool allow_collisions = false;
};

void write_text_file(const std::filesystem::path& path, const std::string& text) {
  write_file_atomically(path.string(), [&](std::ostream& o) { o << text; });
}

// The part's placement on the machine: part frame -> work frame.
ToolPose to_work(const PostJob& post, const ToolPose& p) {
  constexpr double deg = M_PI / 180;
  const Eigen::Matrix3d R = (Eigen::AngleAxisd(post.setup_rotate_deg[2] * deg, Eigen::Vector3d::UnitZ()) *
                             Eigen::AngleAxisd(post.setup_rotate_deg[1] * deg, Eigen::Vector3d::UnitY()) *
                             Eigen::AngleAxisd(post.setup_rotate_deg[0] * deg, Eigen::Vector3d::UnitX()))
                                .toRotationMatrix();
  const Eigen::Vector3d t(post.setup_translate_mm[0], post.setup_translate_mm[1], post.setup_translate_mm[2]);
  return {R * p.tip + t, (R * p.axis).normalized()};
}

// Spindle nose to tip: holder, shank and cutter, unless the job states it.
double tool_length(const Job& job, const FittedPatch& p) {
  if (job.post.tool_length_mm > 0) return job.post.tool_length_mm;
  return job.holder.length + job.holder.cylinder_length + job.holder.shank_length + p.assembly.cutter_length();
}

int run_job(const RunArgs& args) {
  const Job job = read_job(args.job);
  if (job.machine.empty())
    throw InputError(job.file.string() + ": machine: missing (flankcam run needs a machine file or one of machines/)");
  // Everything that can be refused before the fit is refused before it.
  const Machine machine = find_machine(job.machine, job.file.parent_path());
  PostSettings settings;
  for (const std::string& d : job.post.dialects) settings.dialects.push_back(parse_dialect(d));
  settings.line_numbers = job.post.line_numbers;
  settings.options.path.tolerance_mm = job.post.tolerance_mm;
  settings.options.path.angle_tolerance_deg = job.post.angle_tolerance_deg;
  settings.options.safe_height_mm = job.post.safe_height_mm;

  const Progress progress = [&](const std::string& line) {
    if (!args.quiet) fmt::print(stderr, "flankcam run: {}\n", line);
  };
  const FittedJob fitted = fit_job(job, args.threads, progress);
  // The part placed on the machine (work frame): links are planned against it and every program is
  // back-simulated before it is written.
  TriMesh part_work = job.part != job.surface ? load_mesh(job.part.string()).mesh : fitted.surface.mesh;
  for (Eigen::Vector3d& v : part_work.vertices) v = to_work(job.post, {v, Eigen::Vector3d::UnitZ()}).tip;
  const SurfaceIndex part_index(std::move(part_work));
  settings.options.part = &part_index;
  settings.options.clearance_mm = job.clearance_mm;
  settings.options.gouge_tolerance_mm = job.tolerance_mm;

  // Kinematics and programs for every patch allowed to run, all solved before any file is written:
  // an unreachable pose ends the run with nothing half done.
  std::vector<std::optional<ClProgram>> cl_data(fitted.patches.size());  // part coordinates
  std::vector<PostInput> inputs;                                        // work coordinates
  for (size_t k = 0; k < fitted.patches.size(); ++k) {
    const FittedPatch& p = fitted.patches[k];
    if (!p.collisions.clear() && !args.allow_collisions) continue;
    cl_data[k] = patch_program(job, fitted, p, int(k) + 1);
    ClProgram work = *cl_data[k];
    for (ClMove& mv : work.moves) mv.pose = to_work(job.post, mv.pose);
    ToolAssembly assembly = p.assembly;  // the program's cutter is the meridian
    assembly.cutter = p.profile_mm;
    inputs.push_back({std::move(work), p.job->name, tool_length(job, p), assembly});
  }
  const std::filesystem::path out = args.out;
  std::filesystem::create_directories(out);
  std::vector<WrittenProgram> programs;
  if (!inputs.empty()) {
    progress(fmt::format("kinematics and post: {} patch(es) on {} ({})", inputs.size(), machine.name, machine.kind()));
    programs = write_programs(
        out, machine, inputs, "all-patches", settings,
        {fmt::format("flankcam run of {}", job.file.filename().string()),
         fmt::format("machine {} ({}), units mm", machine.name, machine.kind()),
         fmt::format("linearisation tolerance {} mm, {} deg", job.post.tolerance_mm, job.post.angle_tolerance_deg),
         fmt::format("work frame = part rotated X {} Y {} Z {} deg, moved by ({}, {}, {}) mm", job.post.setup_rotate_deg[0],
                     job.post.setup_rotate_deg[1], job.post.setup_rotate_deg[2], job.post.setup_translate_mm[0],
                     job.post.setup_translate_mm[1], job.post.setup_translate_mm[2])});
  }

  nlohmann::ordered_json report;
  report["generator"] = "flankcam run";
  report["job"] = job.file.string();
  report["units"] = "mm";
  report["machine"] = {{"name", machine.name}, {"kind", machine.kind()}, {"file", machine.file},
                       {"dialect", machine.controller.dialect}, {"tcp", machine.controller.tcp}};
  report["surface"] = surface_report(job, fitted);
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
  html.columns = {"patch", "tool", "eps (rel.)", "eps mm", "coverage", "collisions", "programs"};

  fmt::print("{:<16} {:<9} {:>10} {:>9} {:>9} {:<11} {}\n", "patch", "tool", "eps", "eps mm", "coverage", "collisions",
             "programs");
  int colliding = 0;
  for (size_t k = 0; k < fitted.patches.size(); ++k) {
    const FittedPatch& p = fitted.patches[k];
    const std::string& name = p.job->name;
    const bool allowed = cl_data[k].has_value();
    colliding += !p.collisions.clear();
    std::vector<std::string> files = write_patch_files(
        out, job, fitted, p, {allowed ? &*cl_data[k] : nullptr, job.post.apt, job.post.cl, job.post.tool});
    std::vector<std::string> patch_programs;
    nlohmann::ordered_json program_entries = nlohmann::ordered_json::array();
    const WrittenProgram* chart = nullptr;
    for (const WrittenProgram& w : programs)
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
    for (size_t i = 0; i < svgs.size(); ++i) write_text_file(out / svg_files[i], svgs[i]);
    files.insert(files.end(), svg_files.begin(), svg_files.end());
    files.insert(files.end(), patch_programs.begin(), patch_programs.end());

    nlohmann::ordered_json entry = patch_report(job, fitted, p);
    entry["tool_length_mm"] = round_mm(tool_length(job, p));
    entry["programs"] = program_entries;
    entry["files"] = files;
    patches.push_back(entry);

    const std::vector<std::string> lines = collision_summary(p);
    const std::string collisions = p.collisions.clear() ? "none" : fmt::format("{} interval(s)", p.collisions.intervals.size());
    const std::string coverage = fmt::format("{:.1f}%", 100 * p.fit.coverage);
    fmt::print("{:<16} {:<9} {:>10.2e} {:>9.4f} {:>9} {:<11} {}\n", name, to_string(p.fit.fit.tool.shape),
               p.fit.fit.eps_opt.max, eps_mm, coverage, collisions,
               patch_programs.empty() ? "(none: collides)" : fmt::format("{}", fmt::join(patch_programs, " ")));
    html.rows.push_back({name, to_string(p.fit.fit.tool.shape), fmt::format("{:.2e}", p.fit.fit.eps_opt.max),
                         fmt::format("{:.4f}", eps_mm), coverage, collisions,
                         patch_programs.empty() ? "none" : fmt::format("{}", fmt::join(patch_programs, " "))});
    HtmlSection section;
    section.heading = "Patch " + name;
    section.warnings = lines;
    if (!allowed) section.warnings.push_back("No program was written for this patch: it collides or gouges.");
    const ToolDimensions dim = tool_dimensions(profile);
    section.facts = {{"eps (relative, eq. 13)", fmt::format("{:.3e}", p.fit.fit.eps_opt.max)},
                     {"eps", fmt::format("{:.4f} mm", eps_mm)},
                     {"coverage within tolerance", coverage},
                     {"tool", fmt::format("{}, length {:.3f} mm, D {:.3f} .. {:.3f} mm", to_string(p.fit.fit.tool.shape),
                                          dim.length_mm, dim.diameter_min_mm, dim.diameter_max_mm)},
                     {"tool length from the spindle nose", fmt::format("{:.3f} mm", tool_length(job, p))}};
    for (const WrittenProgram& w : programs)
      if (w.patch == name)
        section.facts.push_back({w.file, fmt::format("{} moves ({} inserted by linearisation), {} slowed by axis speed, "
                                                     "cut {:.2f} min",
                                                     w.moves, w.inserted, w.slowed, w.minutes)});
    section.svgs = svgs;
    section.files = files;
    html.sections.push_back(std::move(section));
  }
  nlohmann::ordered_json all = nlohmann::ordered_json::array();
  for (const WrittenProgram& w : programs)
    if (w.patch.empty()) all.push_back(program_report(w, machine));
  report["all_patches_programs"] = all;
  for (const WrittenProgram& w : programs)
    if (w.patch.empty()) html.intro.push_back("All patches in order, with tool changes: " + w.file);
  write_text_file(out / "report.json", report.dump(1) + "\n");
  write_text_file(out / "report.html", report_html(html));
  fmt::print("programs, report.json and report.html in {}\n", out.string());
  if (colliding > 0 && !args.allow_collisions) {
    fmt::print(stderr, "flankcam: {} patch(es) collide; no program was written for them (--allow-collisions to override)\n",
               colliding);
    return 4;
  }
  return 0;
}
}  // namespace

Run add_run_command(CLI::App& app) {
  auto args = std::make_shared<RunArgs>();
  CLI::App* cmd = app.add_subcommand("run", "the main job: fit, check, kinematics, NC programs and report");
  cmd->add_option("job", args->job, "job file (YAML) with machine: and post:")->required();
  cmd->add_option("--out", args->out, "output directory")->required();
  cmd->add_option("--threads", args->threads, "threads")->capture_default_str()->check(CLI::Range(1, 256));
  cmd->add_flag("--quiet", args->quiet, "no progress on stderr");
  cmd->add_flag("--allow-collisions", args->allow_collisions, "write programs even for patches that collide or gouge");
  return [args] { return run_job(*args); };
}

}  // namespace flankcam::cli
