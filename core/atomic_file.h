// Files a user sees are written to a temporary name and renamed into place,
// so an error never leaves a partial file behind.
#pragma once
#include <functional>
#include <ostream>
#include <string>

namespace flankcam {

// Writes `path` through `fill`; on any exception the temporary file is removed
// and the exception propagates. Throws InputError when the file cannot be written.
void write_file_atomically(const std::string& path, const std::function<void(std::ostream&)>& fill);

// Same for writers that need a file name (e.g. OpenMesh): `write(tmp_path)`
// must create tmp_path; it is renamed to `path` on success.
void write_path_atomically(const std::string& path, const std::function<void(const std::string&)>& write);

}  // namespace flankcam
