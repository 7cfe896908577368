// `flankcam post CL.apt [...] --machine M --out DIR`: APT CL-data from any source through a machine's
// kinematics into NC programs (one per file, plus one for all of them in order; pipeline::post_apt).
#include <fmt/format.h>

#include "cli/commands.h"
#include "pipeline/outputs.h"
#include "pipeline/run.h"

namespace flankcam::cli {

namespace {
struct PostArgs {
  pipeline::PostRequest request;
  std::string out;
};

int run_post(const PostArgs& args) {
  pipeline::PostRun checked = pipeline::check_post(args.request);
  pipeline::OutputDir out(args.out);
  const pipeline::PostRun run = pipeline::post_apt(std::move(checked));
  pipeline::write_post(run, out);
  const Machine& m = run.machine;
  fmt::print("{:<24} {:<10} {:>6} {:>8} {:>6} {:>17} {:>17} {:>9}\n", "program", "dialect", "moves", "inserted", "slowed",
             m.rotary[0].name + " range deg", m.rotary[1].name + " range deg", "cut min");
  for (const pipeline::PostedProgram& w : run.programs)
    fmt::print("{:<24} {:<10} {:>6} {:>8} {:>6} {:>8.3f}..{:<8.3f} {:>8.3f}..{:<8.3f} {:>9.3f}\n", w.file,
               to_string(w.dialect), w.moves, w.inserted, w.slowed, w.rotary_range[0][0], w.rotary_range[0][1],
               w.rotary_range[1][0], w.rotary_range[1][1], w.minutes);
  return 0;
}
}  // namespace

Run add_post_command(CLI::App& app) {
  auto args = std::make_shared<PostArgs>();
  pipeline::PostRequest& r = args->request;
  CLI::App* cmd = app.add_subcommand("post", "post APT CL-data through a machine's kinematics into NC programs");
  cmd->add_option("apt", r.apt, "APT CL-data files (one program each, plus one for all in order)")->required();
  cmd->add_option("--machine", r.machine, "machine file, or the name of one in machines/")->required();
  cmd->add_option("--out", args->out, "output directory (written completely or not at all)")->required();
  cmd->add_option("--dialect", r.dialect, dialect_names() + " (default: the machine's)");
  cmd->add_option("--tool-length", r.tool_length_mm, "spindle nose to tool tip, mm (machines that turn the head)");
  cmd->add_option("--tolerance", r.tolerance_mm, "linearisation tolerance at the tip, mm")
      ->capture_default_str()->check(CLI::PositiveNumber);
  cmd->add_option("--safe-height", r.safe_height_mm, "safe Z above the highest programmed point, mm")
      ->capture_default_str()->check(CLI::NonNegativeNumber);
  cmd->add_option("--name", r.name, "name of the all-files program (a plain file name)")->capture_default_str();
  cmd->add_flag("--line-numbers", r.line_numbers, "number the blocks (N10, N20, ...)");
  return [args] { return run_post(*args); };
}

}  // namespace flankcam::cli
