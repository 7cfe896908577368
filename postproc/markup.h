// Text inside SVG and HTML: the characters markup would take for its own escaped.
#pragma once
#include <string>

namespace flankcam {

inline std::string markup_escape(const std::string& s) {
  std::string out;
  for (char c : s) {
    if (c == '<') out += "&lt;";
    else if (c == '>') out += "&gt;";
    else if (c == '&') out += "&amp;";
    else if (c == '"') out += "&quot;";
    else out += c;
  }
  return out;
}

}  // namespace flankcam
