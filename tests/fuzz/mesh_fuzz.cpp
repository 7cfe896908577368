// libFuzzer target: the mesh reader (load_mesh). The first byte picks the format by extension.
#include <cstddef>
#include <cstdint>

#include "core/errors.h"
#include "core/mesh.h"
#include "tests/fuzz/fuzz_input.h"

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  if (size < 1) return 0;
  static const char* const names[] = {"in.obj", "in.stl", "in.off", "in.ply"};
  const std::string path = flankcam::fuzz::write(names[data[0] % 4], data + 1, size - 1);
  try {
    (void)flankcam::load_mesh(path);
  } catch (const flankcam::InputError&) {
  }
  return 0;
}
