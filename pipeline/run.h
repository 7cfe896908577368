// The pipeline as a library: job in, results out. Each command is one function returning a struct
// that keeps everything the reports and files need (the job, the fitted patches, the CL-data, the
// posted programs); outputs.h writes those files. Nothing here prints: progress goes to a callback.
//   fit:  read job -> fit -> check                          (flankcam fit)
//   run:  read job -> fit -> check -> kinematics -> post    (flankcam run)
//   post: APT files -> kinematics -> post                   (flankcam post)
#pragma once
#include <array>
#include <filesystem>
#include <optional>
#include <string>
#include <vector>

#include "kinematics/machine.h"
#include "pipeline/fit_stage.h"
#include "pipeline/job.h"
#include "pipeline/post_stage.h"
#include "postproc/apt.h"

namespace flankcam::pipeline {

struct RunOptions {
  int threads = 2;                // Ceres is single-threaded (deterministic); OpenMP loops use these
  bool allow_collisions = false;  // CL-data and programs even for patches that collide or gouge
  Progress progress = [](const std::string&) {};
  std::string validate() const;   // empty when valid
};

// Sets the OpenMP thread count for the lifetime of the object and restores the previous one.
class ThreadScope {
 public:
  explicit ThreadScope(int threads);
  ~ThreadScope();
  ThreadScope(const ThreadScope&) = delete;
  ThreadScope& operator=(const ThreadScope&) = delete;
 private:
  int previous_;
};

// `flankcam fit`: the job, its fitted patches and their CL-data (tool 1, part coordinates; none
// for a colliding patch unless collisions are allowed). Move-only: fitted.patches point into job.
struct FitRun {
  Job job;
  FittedJob fitted;
  std::vector<std::optional<ClProgram>> cl_data;  // per patch
  bool allow_collisions = false;
  [[nodiscard]] int colliding() const;            // patches that collide or gouge
  FitRun() = default;
  FitRun(FitRun&&) = default;
  FitRun& operator=(FitRun&&) = default;
  FitRun(const FitRun&) = delete;
};

// `post.setup: auto`: one candidate rotation of the part on the table and how its motion runs.
struct SetupCandidate {
  std::array<double, 3> rotate_deg{0, 0, 0};  // as post.setup.rotate: about X, then Y, then Z
  bool reachable = true;
  std::string why;                  // unreachable: the first patch and pose that is out of reach
  int singular_stretches = 0;       // kinematics/path.h singular_stretches over every patch
  double min_singular_deg = 0;      // closest approach of the tool axis to a singular orientation
  double max_rotary_per_deg = 0;    // largest rotary travel per degree of tool-axis turn in a block
};
struct SetupDecision {
  SetupCandidate chosen, unrotated;  // unrotated: rotate [0, 0, 0] for comparison
  int candidates = 0;
  std::string reason;                // one sentence: what was chosen and why
};
// Tries rotations about X and Y of 0, +-15, +-30 deg combined with 0, 90, 180, 270 deg about the
// table normal (Z), with the job's translation: the first (in that order, least rotation first)
// whose every patch is reachable, has no singular stretch and keeps the tool axis at least 10 deg
// from a singular orientation; else the reachable one farthest from it. `cl`: per patch (part frame).
[[nodiscard]] SetupDecision choose_setup(const Job& job, const Machine& m, const std::vector<const ClProgram*>& cl,
                                         const std::vector<double>& tool_length_mm);

// `flankcam run`: the fit (CL-data with tool numbers 1, 2, ... per patch), the machine, and the
// posted programs (per dialect: one per allowed patch, then all-patches when more than one).
struct RunResult {
  FitRun fit;
  Machine machine;
  PostSettings settings;
  std::vector<PostedProgram> programs;
  std::vector<double> tool_length_mm;  // per patch, spindle nose to tip
  std::optional<SetupDecision> setup;   // post.setup: auto (the job's post.setup_rotate_deg is the chosen one)
  // Per patch with a program: the CL-data of its program, every section (pass, depth level) in order,
  // in part coordinates, as NAME.apt and NAME-cl.csv hold it: each section with the links its program
  // was posted with (a rapid to the lead point moved `retract` up the tool axis, a rapid down the axis to
  // it, the feed in along the surface normal, the cut, the feed out, a rapid `retract` up the axis).
  std::vector<std::optional<ClProgram>> posted_cl;
};

// The name of the program that runs all patches of `flankcam run` in order.
inline const std::string all_patches_name = "all-patches";

// Everything about a job that can be refused before the fit: the machine (run), the dialects,
// and output file names that would clash (e.g. a patch named all-patches). Throws InputError.
void check_fit_outputs(const Job& job);
[[nodiscard]] Machine check_run(const Job& job);

[[nodiscard]] FitRun fit(Job job, const RunOptions& options);
// `machine`: from check_run. Throws InputError when a pose is out of the machine's reach.
[[nodiscard]] RunResult run(Job job, Machine machine, const RunOptions& options);

// The part's placement on the machine (post.setup): part frame -> work frame.
[[nodiscard]] ToolPose to_work(const PostJob& post, const ToolPose& p);
// Its inverse: work frame -> part frame (tip Rᵀ(p - t), axis Rᵀ axis).
[[nodiscard]] ToolPose from_work(const PostJob& post, const ToolPose& p);
// CL-data placed on the machine the same way (every move's pose).
[[nodiscard]] ClProgram to_work(const PostJob& post, ClProgram cl);
// A mesh (the part, the design surface) placed on the machine the same way.
[[nodiscard]] TriMesh to_work(const PostJob& post, TriMesh mesh);
// Spindle nose to tip: post.tool_length, else holder + shank + cutter lengths.
[[nodiscard]] double tool_length(const Job& job, const FittedPatch& p);

// `flankcam post`: APT files through a machine.
struct PostRequest {
  std::vector<std::string> apt;   // files, one program each
  std::string machine;            // file or shipped name
  std::string dialect;            // empty: the machine's
  std::string name = "all";       // the all-files program
  double tool_length_mm = 0, tolerance_mm = 0.005, safe_height_mm = 10;
  bool line_numbers = false;
};
struct PostRun {
  PostRequest request;
  Machine machine;
  PostSettings settings;
  std::vector<PostInput> inputs;
  std::vector<PostedProgram> programs;
};
// Refuses a bad machine, dialect, tool length or clashing output names before any APT is read.
[[nodiscard]] PostRun check_post(const PostRequest& request);
// Reads the APT files and posts them (`checked` from check_post).
[[nodiscard]] PostRun post_apt(PostRun checked);

}  // namespace flankcam::pipeline
