// `flankcam run JOB.yaml --out DIR`: the main job end to end (pipeline::run): fit every patch, check
// collisions, solve the machine's kinematics, post NC programs, and write the report (JSON, SVG
// pictures, HTML). This file only parses arguments and prints.
#include <fmt/format.h>

#include "cli/commands.h"
#include "pipeline/outputs.h"
#include "pipeline/run.h"

namespace flankcam::cli {

namespace {
struct RunArgs {
  std::string job, out;
  pipeline::RunOptions options;
  bool quiet = false;
};

int run_job(RunArgs args) {
  // Everything that can be refused before the fit is refused before it: the job, the machine,
  // output names, and the output folder.
  pipeline::Job job = pipeline::read_job(args.job);
  Machine machine = pipeline::check_run(job);
  pipeline::OutputDir out(args.out);
  args.options.progress = [&](const std::string& line) {
    if (!args.quiet) fmt::print(stderr, "flankcam run: {}\n", line);
  };
  const pipeline::RunResult run = pipeline::run(std::move(job), std::move(machine), args.options);
  pipeline::write_run(run, out);

  const pipeline::FittedJob& fitted = run.fit.fitted;
  const size_t tool_width = pipeline::tool_label_width(run.fit.job, fitted.patches);
  fmt::print("{:<16} {:<{}} {:>10} {:>9} {:>9} {:<11} {}\n", "patch", "tool", tool_width, "eps", "eps mm", "coverage", "collisions",
             "programs");
  for (const pipeline::FittedPatch& p : fitted.patches) {
    std::vector<std::string> programs;
    for (const pipeline::PostedProgram& w : run.programs)
      if (w.patch == p.job->name) programs.push_back(w.file);
    fmt::print("{:<16} {:<{}} {:>10.2e} {:>9.4f} {:>9} {:<11} {}\n", p.job->name, pipeline::tool_label(run.fit.job, p), tool_width,
               p.fit.fit.eps_opt.max, fitted.frame.length_to_mm(p.fit.fit.eps_opt.max),
               fmt::format("{:.1f}%", 100 * p.fit.coverage),
               p.collisions.clear() ? "none" : fmt::format("{} interval(s)", p.collisions.intervals.size()),
               programs.empty() ? "(none: collides)" : fmt::format("{}", fmt::join(programs, " ")));
  }
  if (fitted.cover) fmt::print("{}\n", pipeline::cover_summary(run.fit.job, fitted));
  fmt::print("programs, report.json and report.html in {}{}\n", args.out,
             fitted.cover ? fmt::format(" (detected patches as a job: {})", pipeline::detected_job_name) : "");
  const int colliding = run.fit.colliding();
  if (colliding > 0 && !args.options.allow_collisions) {
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
  cmd->add_option("--out", args->out, "output directory (written completely or not at all)")->required();
  cmd->add_option("--threads", args->options.threads, "threads")->capture_default_str()->check(CLI::Range(1, 256));
  cmd->add_flag("--quiet", args->quiet, "no progress on stderr");
  cmd->add_flag("--allow-collisions", args->options.allow_collisions, "write programs even for patches that collide or gouge");
  return [args] { return run_job(*args); };
}

}  // namespace flankcam::cli
