// `flankcam post CL.apt [...] --machine M --out DIR`: APT CL-data from any source through a machine's
// kinematics into NC programs (one per file, plus one for all of them in order).
#include <fmt/format.h>

#include <filesystem>

#include "cli/commands.h"
#include "cli/post_stage.h"
#include "core/errors.h"
#include "postproc/tool_export.h"

namespace flankcam::cli {

namespace {
struct PostArgs {
  std::vector<std::string> apt;
  std::string machine, out, dialect, name = "all";
  double tool_length_mm = 0, tolerance_mm = 0.005, safe_height_mm = 10;
  bool line_numbers = false;
};

int run_post(const PostArgs& args) {
  const Machine m = find_machine(args.machine);
  const bool head = m.rotary[0].carries == Carrier::Head || m.rotary[1].carries == Carrier::Head;
  if (head && !(args.tool_length_mm > 0))
    throw InputError(fmt::format("--tool-length: machine {} turns the head; give the tool's length from the spindle "
                                 "nose to the tip (mm)",
                                 m.name));
  std::vector<PostInput> inputs;
  for (const std::string& file : args.apt) {
    PostInput in;
    in.cl = read_apt(file);
    in.patch = std::filesystem::path(file).stem().string();
    in.tool_length_mm = args.tool_length_mm;
    inputs.push_back(std::move(in));
  }
  PostSettings s;
  if (!args.dialect.empty()) s.dialects = {parse_dialect(args.dialect)};
  s.line_numbers = args.line_numbers;
  s.options.path.tolerance_mm = args.tolerance_mm;
  s.options.path.tool_length_mm = args.tool_length_mm;
  s.options.safe_height_mm = args.safe_height_mm;
  const std::filesystem::path out = args.out;
  std::filesystem::create_directories(out);
  const std::vector<WrittenProgram> written = write_programs(
      out, m, inputs, args.name, s,
      {fmt::format("flankcam post for machine {} ({}), units mm", m.name, m.kind()),
       fmt::format("linearisation tolerance {} mm, {} deg", args.tolerance_mm, s.options.path.angle_tolerance_deg)});
  // The simulator's tool goes with the programs when the CL-data carries the profile (flankcam's PPRINTs).
  for (const PostInput& in : inputs)
    if (in.cl.profile.size() >= 2)
      write_tool_stl((out / (in.patch + "-tool.stl")).string(), in.cl.profile, "tool of " + in.patch + ", mm");
  fmt::print("{:<24} {:<10} {:>6} {:>8} {:>6} {:>17} {:>17} {:>9}\n", "program", "dialect", "moves", "inserted", "slowed",
             m.rotary[0].name + " range deg", m.rotary[1].name + " range deg", "cut min");
  for (const WrittenProgram& w : written)
    fmt::print("{:<24} {:<10} {:>6} {:>8} {:>6} {:>8.3f}..{:<8.3f} {:>8.3f}..{:<8.3f} {:>9.3f}\n", w.file,
               to_string(w.dialect), w.moves, w.inserted, w.slowed, w.rotary_range[0][0], w.rotary_range[0][1],
               w.rotary_range[1][0], w.rotary_range[1][1], w.minutes);
  return 0;
}
}  // namespace

Run add_post_command(CLI::App& app) {
  auto args = std::make_shared<PostArgs>();
  CLI::App* cmd = app.add_subcommand("post", "post APT CL-data through a machine's kinematics into NC programs");
  cmd->add_option("apt", args->apt, "APT CL-data files (one program each, plus one for all in order)")->required();
  cmd->add_option("--machine", args->machine, "machine file, or the name of one in machines/")->required();
  cmd->add_option("--out", args->out, "output directory")->required();
  cmd->add_option("--dialect", args->dialect, dialect_names() + " (default: the machine's)");
  cmd->add_option("--tool-length", args->tool_length_mm, "spindle nose to tool tip, mm (machines that turn the head)");
  cmd->add_option("--tolerance", args->tolerance_mm, "linearisation tolerance at the tip, mm")
      ->capture_default_str()->check(CLI::PositiveNumber);
  cmd->add_option("--safe-height", args->safe_height_mm, "safe Z above the highest programmed point, mm")
      ->capture_default_str()->check(CLI::NonNegativeNumber);
  cmd->add_option("--name", args->name, "name of the all-files program")->capture_default_str();
  cmd->add_flag("--line-numbers", args->line_numbers, "number the blocks (N10, N20, ...)");
  return [args] { return run_post(*args); };
}

}  // namespace flankcam::cli
