// Fixed-decimal numbers for files people and machines read: same input, same text, never "-0.000".
#pragma once
#include <fmt/format.h>

#include <cmath>
#include <string>

namespace flankcam {

// x rounded to `decimals` places and printed with exactly that many; + 0.0 turns -0 into 0.
inline std::string fixed(double x, int decimals) {
  const double scale = std::pow(10.0, decimals);
  return fmt::format("{:.{}f}", std::round(x * scale) / scale + 0.0, decimals);
}

}  // namespace flankcam
