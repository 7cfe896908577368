// The fitting stage of a job, shared by `flankcam fit` and `flankcam run`: load the design surface,
// fit every patch in the unit-diagonal frame, check it against the part, and turn the results back
// into millimetres (report entries, CL-data). Files are written by outputs.h.
#pragma once
#include <functional>
#include <optional>
#include <nlohmann/json.hpp>
#include <string>
#include <vector>

#include "pipeline/job.h"
#include "core/mesh.h"
#include "core/collision.h"
#include "core/patch.h"
#include "postproc/apt.h"

namespace flankcam::pipeline {

using Progress = std::function<void(const std::string&)>;  // one line of progress (stderr)

struct FittedPatch {
  const PatchJob* job = nullptr;
  PatchFit fit;                  // unit frame
  std::vector<ToolPose> poses;   // the fitted motion at its samples t_i, mm, part coordinates
  ToolAssembly assembly;         // cutter spheres from the fit, shank and holder from the job, mm
  std::vector<Eigen::Vector2d> profile_mm;  // the tool's meridian (z, r) from the tip, mm
  std::vector<Eigen::Vector3d> contacts;    // per pose: the design surface nearest the middle of the cutter, mm
  CollisionReport collisions;    // against the whole part
};

struct FittedJob {
  LoadedMesh surface;  // mm
  Similarity frame;    // mm -> unit frame
  TriMesh unit_surface;
  std::vector<FittedPatch> patches;
  std::optional<TriMesh> part;  // the job's separate `part:` (mm) once checked; unset: the surface is the part
};

// Loads the design surface, fits every patch in the unit-diagonal frame (paper Sec. 4) and runs
// check_job. The OpenMP loops use however many threads the caller set (see run.h).
[[nodiscard]] FittedJob fit_job(const Job& job, int threads, const Progress& progress);

// Poses in mm, tool assembly, meridian, contact points and the collision and gouge checks of
// every fitted patch against the whole part (job.part, default the design surface).
void check_job(const Job& job, FittedJob& fitted, const Progress& progress);

// Rounds a length in mm to 1 nm for reports (stable text, no spurious digits).
[[nodiscard]] double round_mm(double x);

// The "surface" and per-patch entries of report.json, lengths in mm, relative errors marked.
[[nodiscard]] nlohmann::ordered_json surface_report(const Job& job, const FittedJob& fitted);
[[nodiscard]] nlohmann::ordered_json patch_report(const Job& job, const FittedJob& fitted, const FittedPatch& patch);

// One line per collision interval: "patch P: holder collides at poses 12-17, 0.731 mm deep at (x, y, z)".
[[nodiscard]] std::vector<std::string> collision_summary(const FittedPatch& patch);

// The patch's CL-data (APT model): approach, the fitted poses at the job's feed, retract; the tool's
// meridian in mm; a comment with the fitted error and one flagging allowed collisions.
[[nodiscard]] ClProgram patch_program(const Job& job, const FittedJob& fitted, const FittedPatch& patch, int tool);

}  // namespace flankcam::pipeline
