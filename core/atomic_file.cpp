#include "core/atomic_file.h"

#include <cstdio>
#include <filesystem>
#include <fstream>
#include <unistd.h>

#include "core/errors.h"

namespace flankcam {
namespace fs = std::filesystem;

namespace {
std::string temporary_name(const std::string& path) {
  const fs::path p(path);
  // Same directory (rename is atomic there); keep the extension for writers that dispatch on it.
  return (p.parent_path() / ("." + p.stem().string() + ".tmp" + std::to_string(::getpid()) +
                             p.extension().string()))
      .string();
}
}  // namespace

void write_path_atomically(const std::string& path, const std::function<void(const std::string&)>& write) {
  const std::string tmp = temporary_name(path);
  try {
    write(tmp);
    std::error_code ec;
    fs::rename(tmp, path, ec);
    if (ec) throw InputError(path + ": cannot write file (" + ec.message() + ")");
  } catch (...) {
    std::error_code ignored;
    fs::remove(tmp, ignored);
    throw;
  }
}

void write_file_atomically(const std::string& path, const std::function<void(std::ostream&)>& fill) {
  write_path_atomically(path, [&](const std::string& tmp) {
    std::ofstream out(tmp, std::ios::binary);
    if (!out) throw InputError(path + ": cannot open for writing");
    fill(out);
    out.flush();
    if (!out) throw InputError(path + ": write failed (disk full?)");
  });
}

}  // namespace flankcam
