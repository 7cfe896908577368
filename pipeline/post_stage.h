// The post-processing stage, shared by `flankcam post` (APT from any source) and `flankcam run`:
// find the machine, post every CL program through its kinematics into one NC program per patch and
// dialect, plus one that runs all patches in order. Nothing is written here (see outputs.h).
#pragma once
#include <array>
#include <filesystem>
#include <nlohmann/json.hpp>
#include <string>
#include <vector>

#include "kinematics/machine.h"
#include "postproc/nc_program.h"

namespace flankcam::pipeline {

// A machine by file path, or by name among the shipped machines/ (e.g. "xyzac-trt"). Throws
// InputError naming the shipped ones when neither exists.
[[nodiscard]] Machine find_machine(const std::string& name_or_path, const std::filesystem::path& relative_to = {});

struct PostSettings {
  std::vector<Dialect> dialects;  // empty: the machine's own
  bool line_numbers = false;
  PostOptions options;            // dialect is set per program
};

// The dialects a machine is posted in: the settings' or the machine's own.
[[nodiscard]] std::vector<Dialect> dialects_of(const Machine& m, const PostSettings& settings);

// One posted NC program and what the reports say about it.
struct PostedProgram {
  std::string file, patch;        // patch "" for the all-patches program
  Dialect dialect = Dialect::Iso;
  Posted posted;                  // the program model (its motion for the 3D view)
  int moves = 0, inserted = 0, slowed = 0, singular = 0, branch_changes = 0;
  std::array<std::array<double, 2>, 2> rotary_range{};  // min, max degrees per rotary axis
  double minutes = 0;             // feed time of the cut moves
  std::array<std::vector<double>, 2> rotary_deg;  // programmed angles per move (for the chart)
  nlohmann::ordered_json singular_stretches = nlohmann::ordered_json::array();  // kinematics/path.h singular_stretches
};

// Posts `inputs` (one per patch, in order): PATCH.EXT for each and, with more than one,
// ALL_NAME.EXT, per dialect. `header`: comment lines at the top of every program. Throws when any
// patch fails (out of reach), so nothing is written for a run that cannot be machined.
[[nodiscard]] std::vector<PostedProgram> post_programs(const Machine& m, const std::vector<PostInput>& inputs,
                                                       const std::string& all_name, const PostSettings& settings,
                                                       const std::vector<std::string>& header);

[[nodiscard]] nlohmann::ordered_json program_report(const PostedProgram& w, const Machine& m);

}  // namespace flankcam::pipeline
