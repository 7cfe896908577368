// `flankcam fit JOB.yaml --out DIR`: fit every patch of a job (paper Sec. 4) and write the report,
// the machined envelopes coloured by deviation and the tool profiles.
#include <fmt/format.h>

#include <filesystem>
#include <optional>

#include "cli/commands.h"
#include "cli/fit_stage.h"
#include "core/atomic_file.h"

namespace flankcam::cli {

namespace {
struct FitArgs {
  std::string job, out;
  int threads = 2;
  bool quiet = false;
  bool allow_collisions = false;
};

int run_fit(const FitArgs& args) {
  const Job job = read_job(args.job);
  const Progress progress = [&](const std::string& line) {
    if (!args.quiet) fmt::print(stderr, "flankcam fit: {}\n", line);
  };
  const FittedJob fitted = fit_job(job, args.threads, progress);

  const std::filesystem::path out = args.out;
  std::filesystem::create_directories(out);
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
  auto& patches = report["patches"] = nlohmann::ordered_json::array();
  fmt::print("{:<16} {:<6} {:<9} {:>10} {:>10} {:>9}  files\n", "patch", "init", "tool", "eps", "eps mm", "coverage");
  for (const FittedPatch& p : fitted.patches) {
    nlohmann::ordered_json entry = patch_report(job, fitted, p);
    // A colliding motion gets no CL-data unless allowed.
    std::optional<ClProgram> cl;
    if (p.collisions.clear() || args.allow_collisions) cl = patch_program(job, fitted, p, 1);
    const std::vector<std::string> files = write_patch_files(out, job, fitted, p, {cl ? &*cl : nullptr});
    entry["files"] = files;
    patches.push_back(entry);
    fmt::print("{:<16} {:<6} {:<9} {:>10.2e} {:>10.4f} {:>8.1f}%  {}\n", p.job->name, to_string(p.job->init),
               to_string(p.fit.fit.tool.shape), p.fit.fit.eps_opt.max, fitted.frame.length_to_mm(p.fit.fit.eps_opt.max),
               100 * p.fit.coverage, fmt::join(files, " "));
  }
  write_file_atomically((out / "report.json").string(), [&](std::ostream& o) { o << report.dump(1) << '\n'; });
  fmt::print("report: {}\n", (out / "report.json").string());
  // A colliding or gouging motion must not go to a machine unnoticed: one line per patch, exit 4.
  int colliding = 0;
  for (const FittedPatch& p : fitted.patches) {
    if (p.collisions.clear()) continue;
    ++colliding;
    std::vector<std::string> parts;
    for (const CollisionInterval& iv : p.collisions.intervals)
      parts.push_back(fmt::format("{} {}-{} ({:.3f} mm)", to_string(iv.component), iv.pose_begin, iv.pose_end, iv.max_depth_mm));
    fmt::print(stderr, "flankcam: patch {} {}collides: {}\n", p.job->name, args.allow_collisions ? "(allowed) " : "",
               fmt::join(parts, ", "));
  }
  return colliding > 0 && !args.allow_collisions ? 4 : 0;
}
}  // namespace

Run add_fit_command(CLI::App& app) {
  auto args = std::make_shared<FitArgs>();
  CLI::App* cmd = app.add_subcommand("fit", "fit tool and motion to every patch of a job; write report and meshes");
  cmd->add_option("job", args->job, "job file (YAML)")->required();
  cmd->add_option("--out", args->out, "output directory")->required();
  cmd->add_option("--threads", args->threads, "threads")->capture_default_str()->check(CLI::Range(1, 256));
  cmd->add_flag("--quiet", args->quiet, "no progress on stderr");
  cmd->add_flag("--allow-collisions", args->allow_collisions, "exit 0 even when a patch collides or gouges");
  return [args] { return run_fit(*args); };
}

}  // namespace flankcam::cli
