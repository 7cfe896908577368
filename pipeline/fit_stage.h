// The fitting stage of a job, shared by `flankcam fit` and `flankcam run`: load the design surface,
// fit every patch in the unit-diagonal frame, and turn the results back into millimetres
// (report entries and per-patch files).
#pragma once
#include <filesystem>
#include <functional>
#include <nlohmann/json.hpp>
#include <string>
#include <vector>

#include "cli/job.h"
#include "core/mesh.h"
#include "core/collision.h"
#include "core/patch.h"
#include "postproc/apt.h"

namespace flankcam::cli {

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
};

[[nodiscard]] FittedJob fit_job(const Job& job, int threads, const Progress& progress);

// Per-vertex deviation colours (postproc's deviation_color).
[[nodiscard]] std::vector<std::array<unsigned char, 3>> deviation_colors(const std::vector<double>& dev_mm, double tol_mm);

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

struct PatchOutputs {
  const ClProgram* program = nullptr;  // CL-data (none for a colliding patch unless collisions are allowed)
  bool apt = true, cl = true, tool = true;
};
// Files of a fitted patch in `out`: NAME-envelope.ply (Ω with its deviation from Φ), NAME-deviation.ply
// (Φ with its deviation from Ω); with `tool`, NAME-tool.csv (meridian z, r in mm), NAME-tool.dxf and
// NAME-tool.stl; with a `program`, NAME.apt (APT CL-data) and NAME-cl.csv; when it collides,
// NAME-collisions.obj (the assembly at the worst pose of each interval). Returns the file names.
std::vector<std::string> write_patch_files(const std::filesystem::path& out, const Job& job, const FittedJob& fitted,
                                           const FittedPatch& patch, const PatchOutputs& what);

}  // namespace flankcam::cli
