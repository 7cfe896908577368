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

namespace flankcam::cli {

using Progress = std::function<void(const std::string&)>;  // one line of progress (stderr)

struct FittedPatch {
  const PatchJob* job = nullptr;
  PatchFit fit;                  // unit frame
  std::vector<ToolPose> poses;   // the fitted motion at its samples t_i, mm, part coordinates
  ToolAssembly assembly;         // cutter spheres from the fit, shank and holder from the job, mm
  CollisionReport collisions;    // against the whole part
};

struct FittedJob {
  LoadedMesh surface;  // mm
  Similarity frame;    // mm -> unit frame
  TriMesh unit_surface;
  std::vector<FittedPatch> patches;
};

[[nodiscard]] FittedJob fit_job(const Job& job, int threads, const Progress& progress);

// Deviation colours: green within the tolerance, red for undercut (material left, > 0),
// blue for overcut (< 0), saturated at 4x the tolerance; grey where undefined (NaN).
[[nodiscard]] std::vector<std::array<unsigned char, 3>> deviation_colors(const std::vector<double>& dev_mm, double tol_mm);

// Rounds a length in mm to 1 nm for reports (stable text, no spurious digits).
[[nodiscard]] double round_mm(double x);

// The "surface" and per-patch entries of report.json, lengths in mm, relative errors marked.
[[nodiscard]] nlohmann::ordered_json surface_report(const Job& job, const FittedJob& fitted);
[[nodiscard]] nlohmann::ordered_json patch_report(const Job& job, const FittedJob& fitted, const FittedPatch& patch);

// One line per collision interval: "patch P: holder collides at poses 12-17, 0.731 mm deep at (x, y, z)".
[[nodiscard]] std::vector<std::string> collision_summary(const FittedPatch& patch);

// Files of a fitted patch in `out`: NAME-envelope.ply (Ω with its deviation from Φ), NAME-deviation.ply
// (Φ with its deviation from Ω), NAME-tool.csv (meridian z, r in mm) and, when it collides,
// NAME-collisions.obj (the assembly at the worst pose of each interval). Returns the file names.
// With `program`, also NAME.apt (APT CL-data) and NAME-cl.csv (CL-data), flagged in a comment when
// the patch collides; NAME-tool.dxf always.
std::vector<std::string> write_patch_files(const std::filesystem::path& out, const Job& job, const FittedJob& fitted,
                                           const FittedPatch& patch, bool program);

}  // namespace flankcam::cli
