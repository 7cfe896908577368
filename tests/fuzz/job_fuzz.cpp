// libFuzzer target: the job file reader (read_job), beside a small surface mesh `s.obj`.
#include <cstddef>
#include <cstdint>
#include <cstring>

#include "pipeline/job.h"
#include "core/errors.h"
#include "tests/fuzz/fuzz_input.h"

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  static const bool surface = [] {
    const char obj[] = "v 0 0 0\nv 10 0 0\nv 0 10 0\nv 0 0 10\nf 1 2 3\nf 1 3 4\n";
    flankcam::fuzz::write("s.obj", reinterpret_cast<const uint8_t*>(obj), std::strlen(obj));
    return true;
  }();
  (void)surface;
  const std::string path = flankcam::fuzz::write("job.yaml", data, size);
  try {
    (void)flankcam::pipeline::read_job(path);
  } catch (const flankcam::InputError&) {
  }
  return 0;
}
