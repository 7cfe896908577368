// flankcam's shipped data: machines/ and the tool catalogue machines/tools/. Installed, they live in
// <prefix>/share/flankcam beside <prefix>/bin/flankcam and are found from the running program
// (/proc/self/exe), wherever the prefix was moved; run from the build tree, the source tree's
// machines/ is used. Nothing absolute is needed after `cmake --install`.
#pragma once
#include <filesystem>

namespace flankcam::pipeline {

// The shipped machines folder. Throws InputError naming the places looked at when none exists.
[[nodiscard]] std::filesystem::path machines_dir();

// The tool catalogue (machines/tools); it may not exist.
[[nodiscard]] std::filesystem::path tools_dir();

}  // namespace flankcam::pipeline
