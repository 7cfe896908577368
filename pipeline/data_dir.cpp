#include "pipeline/data_dir.h"

#include "core/errors.h"

namespace flankcam::pipeline {
namespace fs = std::filesystem;

fs::path machines_dir() {
  std::error_code ec;
  const fs::path exe = fs::read_symlink("/proc/self/exe", ec);
  fs::path installed;
  if (!ec) {
    // FLANKCAM_DATA_FROM_BIN: the data folder relative to the bin folder (e.g. ../share/flankcam).
    installed = (exe.parent_path() / FLANKCAM_DATA_FROM_BIN / "machines").lexically_normal();
    if (fs::is_directory(installed, ec)) return installed;
  }
  const fs::path source = FLANKCAM_SOURCE_MACHINES_DIR;  // the build tree's program
  if (fs::is_directory(source, ec)) return source;
  throw InputError("the shipped machines are missing: looked in " + (installed.empty() ? std::string("(no /proc/self/exe)") : installed.string()) +
                   " and " + source.string());
}

fs::path tools_dir() { return machines_dir() / "tools"; }

}  // namespace flankcam::pipeline
