// Typed exceptions for bad input. The CLI turns each into one line and a
// non-zero exit; expected numerical outcomes are results, never thrown.
#pragma once
#include <stdexcept>
#include <string>

namespace flankcam {

// Bad user input: a file, a key, a value. The message names what is wrong.
struct InputError : std::runtime_error {
  using std::runtime_error::runtime_error;
};

// A machine definition that cannot describe a machine (names the file and field).
struct MachineError : InputError {
  using InputError::InputError;
};

// No program can be written: its motions collide or gouge, or detection found no patch to machine
// (the CLI exits with 4).
struct ProgramRefused : std::runtime_error {
  using std::runtime_error::runtime_error;
};

}  // namespace flankcam
