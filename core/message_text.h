// User text inside one-line error messages: a value read from a file may hold newlines or control
// characters, which must not break the message over lines or into the terminal.
#pragma once
#include <fmt/format.h>

#include <cstddef>
#include <string>

namespace flankcam {

// Control characters escaped (a newline as \n), cut after `max_chars` with "...".
[[nodiscard]] inline std::string escaped(const std::string& s, std::size_t max_chars = 60) {
  std::string out;
  for (std::size_t i = 0; i < s.size(); ++i) {
    if (i == max_chars) return out + "...";
    const unsigned char c = static_cast<unsigned char>(s[i]);
    if (c == '\n') out += "\\n";
    else if (c == '\r') out += "\\r";
    else if (c == '\t') out += "\\t";
    else if (c < 0x20 || c == 0x7f) out += fmt::format("\\x{:02x}", c);
    else out += char(c);
  }
  return out;
}
// 'escaped text', as messages quote values.
[[nodiscard]] inline std::string in_quotes(const std::string& s) { return "'" + escaped(s) + "'"; }

}  // namespace flankcam
