// `flankcam fit JOB.yaml --out DIR`: fit every patch of a job (paper Sec. 4, pipeline::fit) and write
// the report, the machined envelopes coloured by deviation and the tool profiles.
#include <fmt/format.h>

#include "cli/commands.h"
#include "pipeline/outputs.h"
#include "pipeline/run.h"

namespace flankcam::cli {

namespace {
struct FitArgs {
  std::string job, out;
  pipeline::RunOptions options;
  bool quiet = false;
};

int run_fit(FitArgs args) {
  pipeline::Job job = pipeline::read_job(args.job);
  pipeline::check_fit_outputs(job);
  pipeline::OutputDir out(args.out);
  args.options.progress = [&](const std::string& line) {
    if (!args.quiet) fmt::print(stderr, "flankcam fit: {}\n", line);
  };
  const pipeline::FitRun fit = pipeline::fit(std::move(job), args.options);
  const std::vector<std::vector<std::string>> files = pipeline::write_fit(fit, out);

  const size_t tool_width = pipeline::tool_label_width(fit.job, fit.fitted.patches);
  fmt::print("{:<16} {:<6} {:<{}} {:>10} {:>10} {:>9}  files\n", "patch", "init", "tool", tool_width, "eps", "eps mm", "coverage");
  for (size_t k = 0; k < fit.fitted.patches.size(); ++k) {
    const pipeline::FittedPatch& p = fit.fitted.patches[k];
    fmt::print("{:<16} {:<6} {:<{}} {:>10.2e} {:>10.4f} {:>8.1f}%  {}\n", p.job->name, to_string(p.job->init),
               pipeline::tool_label(fit.job, p), tool_width, p.fit.fit.eps_opt.max, fit.fitted.frame.length_to_mm(p.fit.fit.eps_opt.max),
               100 * p.fit.coverage, fmt::join(files[k], " "));
  }
  if (fit.fitted.cover) {
    fmt::print("{}\n", pipeline::cover_summary(fit.job, fit.fitted));
    fmt::print("detected patches as a job: {}\n", (std::filesystem::path(args.out) / pipeline::detected_job_name).string());
  }
  fmt::print("report: {}\n", (std::filesystem::path(args.out) / "report.json").string());
  // A colliding or gouging motion must not go to a machine unnoticed: one line per patch, exit 4.
  for (const pipeline::FittedPatch& p : fit.fitted.patches) {
    if (p.collisions.clear()) continue;
    std::vector<std::string> parts;
    for (const CollisionInterval& iv : p.collisions.intervals)
      parts.push_back(fmt::format("{} {}-{} ({:.3f} mm)", to_string(iv.component), iv.pose_begin, iv.pose_end, iv.max_depth_mm));
    fmt::print(stderr, "flankcam: patch {} {}collides: {}\n", p.job->name, args.options.allow_collisions ? "(allowed) " : "",
               fmt::join(parts, ", "));
  }
  return fit.colliding() > 0 && !args.options.allow_collisions ? 4 : 0;
}
}  // namespace

Run add_fit_command(CLI::App& app) {
  auto args = std::make_shared<FitArgs>();
  CLI::App* cmd = app.add_subcommand("fit", "fit tool and motion to every patch of a job; write report and meshes");
  cmd->add_option("job", args->job, "job file (YAML)")->required();
  cmd->add_option("--out", args->out, "output directory (written completely or not at all)")->required();
  cmd->add_option("--threads", args->options.threads, "threads")->capture_default_str()->check(CLI::Range(1, 256));
  cmd->add_flag("--quiet", args->quiet, "no progress on stderr");
  cmd->add_flag("--allow-collisions", args->options.allow_collisions, "exit 0 even when a patch collides or gouges");
  return [args] { return run_fit(*args); };
}

}  // namespace flankcam::cli
