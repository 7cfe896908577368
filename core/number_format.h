// Fixed-decimal numbers for files people and machines read: same input, same text, never "-0.000".
#pragma once
#include <fmt/format.h>

#include <cmath>
#include <exception>
#include <optional>
#include <string>

namespace flankcam {

// x rounded to `decimals` places and printed with exactly that many; + 0.0 turns -0 into 0.
inline std::string fixed(double x, int decimals) {
  const double scale = std::pow(10.0, decimals);
  return fmt::format("{:.{}f}", std::round(x * scale) / scale + 0.0, decimals);
}

// The whole of `s` as a finite number ("1.5", "-2e3"); nothing for "", "1.2.3", "x3", "nan", "inf".
inline std::optional<double> parse_number(const std::string& s) {
  size_t used = 0;
  double v = 0;
  try {
    v = std::stod(s, &used);
  } catch (const std::exception&) {
    return std::nullopt;
  }
  if (used != s.size() || !std::isfinite(v)) return std::nullopt;
  return v;
}

}  // namespace flankcam
