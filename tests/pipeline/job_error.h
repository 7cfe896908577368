// The InputError message read_job gives for a job file, or "(accepted)".
#pragma once
#include <string>

#include "core/errors.h"
#include "pipeline/job.h"

namespace flankcam::test {
inline std::string job_error(const std::string& file) {
  try {
    (void)pipeline::read_job(file);
  } catch (const InputError& e) {
    return e.what();
  }
  return "(accepted)";
}
}  // namespace flankcam::test
