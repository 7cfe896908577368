// libFuzzer target: the APT CL-data reader (parse_apt, which read_apt calls on the file's text).
#include <cstddef>
#include <cstdint>
#include <string>

#include "core/errors.h"
#include "postproc/apt.h"

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  try {
    (void)flankcam::parse_apt(std::string(reinterpret_cast<const char*>(data), size), "fuzz.apt");
  } catch (const flankcam::InputError&) {
  }
  return 0;
}
