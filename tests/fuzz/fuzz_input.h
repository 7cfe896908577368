// Fuzz targets read files, as flankcam does: each input is written to a file in a private
// temporary folder (one per process) and handed to the public reader. Any exception other than
// InputError (MachineError is one) escapes and is a finding: flankcam would say "internal error".
#pragma once
#include <cstddef>
#include <cstdint>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <string>
#include <system_error>

namespace flankcam::fuzz {

inline const std::filesystem::path& folder() {
  static const std::filesystem::path dir = [] {
    std::string tmpl = (std::filesystem::temp_directory_path() / "flankcam-fuzz-XXXXXX").string();
    if (!mkdtemp(tmpl.data())) std::abort();
    return std::filesystem::path(tmpl);
  }();
  // Removed at a normal exit (libFuzzer's -max_total_time, -runs); a crash leaves it for a look.
  // Registered after `dir` is complete, so it runs before `dir` is destroyed.
  static const int removed_at_exit = std::atexit([] {
    std::error_code ec;
    std::filesystem::remove_all(folder(), ec);
  });
  (void)removed_at_exit;
  return dir;
}

inline std::string write(const std::string& name, const uint8_t* data, size_t size) {
  const std::filesystem::path p = folder() / name;
  std::ofstream(p, std::ios::binary | std::ios::trunc).write(reinterpret_cast<const char*>(data), std::streamsize(size));
  return p.string();
}

}  // namespace flankcam::fuzz
