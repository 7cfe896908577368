// Files a user sees are written to a temporary name and renamed into place, so an error never
// leaves a partial file behind. Temporary names are unpredictable and created exclusively
// (O_CREAT | O_EXCL | O_NOFOLLOW): a file or symlink planted at any name makes the write fail,
// never redirects it.
#pragma once
#include <functional>
#include <ostream>
#include <string>

namespace flankcam {

// Creates `path` for writing only if nothing (not even a dangling symlink) is there; mode 0666
// minus the umask. Returns the open file descriptor. Throws InputError naming the path and reason.
[[nodiscard]] int create_exclusive(const std::string& path);

// Writes `path` through `fill`: into a fresh temporary file beside it, renamed over `path` on
// success (rename replaces a symlink at `path`, it never writes through it). On any exception the
// temporary file is removed and the exception propagates. Throws InputError when the file cannot
// be written.
void write_file_atomically(const std::string& path, const std::function<void(std::ostream&)>& fill);

// Same for writers that need a file name (e.g. OpenMesh): `write(tmp_path)` must create tmp_path
// inside a fresh private directory (mkdtemp, mode 0700) beside `path`; it is renamed to `path` on
// success and the directory removed in every case.
void write_path_atomically(const std::string& path, const std::function<void(const std::string&)>& write);

}  // namespace flankcam
