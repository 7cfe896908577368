// `flankcam verify --job JOB.yaml PROGRAM [PROGRAM ...] --out DIR`: back-simulates NC programs (any
// of the four dialects, by extension) or APT CL-data through the job's machine against its part
// (pipeline::verify), and writes verify.json and verify.html. Exit 0 clean, 4 collision, gouge, a
// rapid inside the job's clearance or a cutting block off the CL-data, 2 bad input. This file only
// parses arguments and prints.
#include <fmt/format.h>

#include "cli/commands.h"
#include "pipeline/output_dir.h"
#include "pipeline/verify.h"

namespace flankcam::cli {

namespace {
struct VerifyArgs {
  pipeline::VerifyRequest request;
  std::string out;
  bool quiet = false;
};

int run_verify(const VerifyArgs& args) {
  // A bad --out is refused before anything is read or simulated.
  pipeline::OutputDir out(args.out);
  const pipeline::VerifyRun run = pipeline::verify(args.request);
  pipeline::write_verify(run, out);
  if (!args.quiet)
    for (const pipeline::VerifiedProgram& r : run.programs) {
      const VerifyReport& v = r.report;
      if (v.clean())
        fmt::print("{}: clean, {} motion blocks, min rapid clearance {:.3f} mm, {:.1f}% of the design surface's vertices it "
                   "reaches within {} mm ({:.1f}% of them all){}\n",
                   r.file, v.blocks.size(), r.min_rapid_all_mm(), 100 * v.design.coverage(), run.options.gouge_tolerance_mm,
                   100 * v.design.share_of_all(),
                   v.cl_compared ? fmt::format(", {} cutting blocks on the CL-data within {} mm", v.cl_blocks,
                                               run.options.cl_tolerance_mm)
                                 : "");
      else
        fmt::print("{}\n", v.first_problem(r.file));
      if (!r.cl_note.empty()) fmt::print("{}: {}\n", r.file, r.cl_note);
    }
  if (const int bad = run.failing(); bad > 0) {
    fmt::print(stderr, "flankcam verify: {} of {} program(s) collide or gouge, or come inside the rapid clearance (verify.json)\n",
               bad, run.programs.size());
    return 4;
  }
  return 0;
}
}  // namespace

Run add_verify_command(CLI::App& app) {
  auto args = std::make_shared<VerifyArgs>();
  CLI::App* cmd = app.add_subcommand("verify", "back-simulate NC programs or APT CL-data against the job's part");
  cmd->add_option("--job", args->request.job, "job file (YAML): machine, part, holder, setup, tolerance")->required();
  cmd->add_option("programs", args->request.programs, "programs (.nc .ngc .h .mpf) or CL-data (.apt)")->required();
  cmd->add_option("--out", args->out, "output directory for verify.json and verify.html (written completely or not at all)")
      ->required();
  cmd->add_option("--tool", args->request.tools,
                  "T=FILE: tool T's meridian CSV (z_mm,r_mm); default NAME-tool.csv beside the program");
  cmd->add_option("--cl", args->request.cl,
                  "PROGRAM=FILE: the APT CL-data PROGRAM was posted from; default NAME.apt beside the program");
  cmd->add_flag("--quiet", args->quiet, "no summary on stdout");
  return [args] { return run_verify(*args); };
}

}  // namespace flankcam::cli
