// Questions about a path named in user input. The throwing std::filesystem overloads abort the
// program on a name the system refuses (too long, embedded control characters, no permission);
// these answer false instead, so the caller can say "file not found" naming the key.
#pragma once
#include <filesystem>
#include <system_error>

namespace flankcam {

[[nodiscard]] inline bool is_file(const std::filesystem::path& p) noexcept {
  std::error_code ec;
  return std::filesystem::is_regular_file(p, ec);
}

}  // namespace flankcam
