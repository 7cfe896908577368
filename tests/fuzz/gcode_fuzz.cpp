// libFuzzer target: the NC program reader (parse_nc). The first byte picks the dialect.
#include <cstddef>
#include <cstdint>
#include <string>

#include "core/errors.h"
#include "postproc/gcode.h"

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  if (size < 1) return 0;
  const auto& table = flankcam::dialect_table();
  const flankcam::Dialect d = table[data[0] % table.size()].dialect;
  try {
    (void)flankcam::parse_nc(std::string(reinterpret_cast<const char*>(data + 1), size - 1), d, {"A", "C"}, "fuzz.nc");
  } catch (const flankcam::InputError&) {
  }
  return 0;
}
