// flankcam: 5-axis flank milling with custom tools of revolution.
#include <CLI/CLI.hpp>
#include <cstdio>
#include <exception>

#include "cli/commands.h"
#include "core/errors.h"
#include "postproc/verify.h"

int main(int argc, char** argv) {
  CLI::App app{"flankcam: 5-axis flank milling toolpaths with custom tools of revolution"};
  app.require_subcommand(1);
  app.set_version_flag("--version", "flankcam 0.1.0");
  std::vector<std::pair<CLI::App*, flankcam::cli::Run>> commands;
  const auto register_command = [&](flankcam::cli::Run (*add)(CLI::App&)) {
    const size_t before = app.get_subcommands({}).size();
    flankcam::cli::Run run = add(app);
    commands.emplace_back(app.get_subcommands({})[before], std::move(run));
  };
  register_command(&flankcam::cli::add_envelope_command);
  register_command(&flankcam::cli::add_fit_command);
  register_command(&flankcam::cli::add_post_command);
  register_command(&flankcam::cli::add_run_command);
  register_command(&flankcam::cli::add_blade_command);
  register_command(&flankcam::cli::add_faces_command);
  register_command(&flankcam::cli::add_verify_command);
  try {
    app.parse(argc, argv);
  } catch (const CLI::ParseError& e) {
    // --help and --version print and succeed; a usage error is bad input like any other: exit 2.
    return app.exit(e) == 0 ? 0 : 2;
  }
  try {
    for (auto& [sub, run] : commands)
      if (sub->parsed()) return run();
  } catch (const flankcam::ProgramRefused& e) {
    std::fprintf(stderr, "flankcam: refused: %s\n", e.what());
    return 4;
  } catch (const flankcam::InputError& e) {
    std::fprintf(stderr, "flankcam: error: %s\n", e.what());
    return 2;
  } catch (const std::exception& e) {
    std::fprintf(stderr, "flankcam: internal error: %s\n", e.what());
    return 3;
  }
  return 1;
}
