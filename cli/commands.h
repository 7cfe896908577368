// The flankcam subcommands. Each registers its options on the CLI11 app and
// returns the function that runs it; main() only dispatches and reports errors.
#pragma once
#include <CLI/CLI.hpp>
#include <functional>

namespace flankcam::cli {

using Run = std::function<int()>;
Run add_envelope_command(CLI::App& app);
Run add_fit_command(CLI::App& app);
Run add_post_command(CLI::App& app);
Run add_run_command(CLI::App& app);
Run add_blade_command(CLI::App& app);
Run add_faces_command(CLI::App& app);
Run add_verify_command(CLI::App& app);

}  // namespace flankcam::cli
