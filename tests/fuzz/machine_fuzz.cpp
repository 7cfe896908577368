// libFuzzer target: the machine file reader (load_machine) and postproc's check of its dialect.
#include <cstddef>
#include <cstdint>

#include "core/errors.h"
#include "kinematics/machine.h"
#include "postproc/nc_program.h"
#include "tests/fuzz/fuzz_input.h"

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  const std::string path = flankcam::fuzz::write("machine.yaml", data, size);
  try {
    const flankcam::Machine m = flankcam::load_machine(path);
    (void)flankcam::machine_dialect(m);
  } catch (const flankcam::InputError&) {
  }
  return 0;
}
