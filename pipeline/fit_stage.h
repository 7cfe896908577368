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

// `tool: {catalogue: NAME}`: the custom tool (general shape) fitted to the same patch, to compare.
struct CustomComparison {
  double eps_mm = 0, coverage = 0;  // ε (eq. 13) and share of the surface within the tolerance
  double diameter_min_mm = 0, diameter_max_mm = 0, length_mm = 0;
  std::string failed;  // why no custom tool came of those lines (its fit refused); the numbers are then unset
};

// `passes:` before the last one: the same tool's motion fitted to Φ offset by the pass's allowance.
struct PassMotion {
  double allowance_mm = 0;
  Rails rails;                               // unit frame
  double eps_mm = 0, coverage = 0;           // against the offset surface
  std::vector<ToolPose> poses;               // mm, like FittedPatch::poses
  std::vector<Eigen::Vector3d> contacts;
};

struct FittedPatch {
  const PatchJob* job = nullptr;
  PatchFit fit;                  // unit frame
  std::vector<ToolPose> poses;   // the fitted motion at its samples t_i, mm, part coordinates
  ToolAssembly assembly;         // cutter spheres from the fit, shank and holder from the job, mm
  std::vector<Eigen::Vector2d> profile_mm;  // the tool's meridian (z, r) from the tip with its end (tool.end), mm
  int end_points = 0;                       // profile_mm[0, end_points): the rounded end's arc (core/tool_end.h)
  double end_radius_mm = 0;                 // that arc's radius (0: flat end)
  std::vector<Eigen::Vector3d> contacts;    // per pose: the design surface nearest the middle of the cutter, mm
  CollisionReport collisions;    // against the whole part
  std::optional<CustomComparison> custom;  // catalogue jobs only
  std::vector<PassMotion> earlier_passes;  // `passes:`: every pass but the last (which is `fit`), in order
  int allowance_side = 0;        // allowance: +1/-1 the side of the design surface's normals the fit's target lies on
  // flankcam run: the motion shortened at an end whose lead had no clear point ("poses A-B of N kept
  // (t ..): no lead-out off ..."); empty: the whole motion is cut.
  std::string kept_for_leads;
  // The motion shortened to its longest stretch of poses clear of collisions ("poses A-B of N kept
  // (t ..): beyond them the shank would come ..."): shorten_to_clear; empty: not shortened.
  std::string kept_clear;
  // Not clear of the part after shorten_to_clear, collisions not allowed: no program, and not in the
  // cover's union (refuse_colliding).
  bool refused = false;
};

// `patches: auto`: the whole surface as the union of the detected patches (core/detect.h).
struct CoverResult {
  std::vector<int> owner;             // per surface vertex: index of the patch machining it, -1: none
  std::vector<double> deviation_mm;   // per surface vertex: the union's deviation, NaN: uncut
  double coverage = 0;                // share of the area within the tolerance
  double overcut_mm = 0;              // worst overcut of the union (>= 0)
  std::string stop;                   // coverage reached, max patches, no progress
  int seeds_tried = 0;
  int exchanged = 0;                  // patches replaced in exchange rounds (cover.exchanges)
  int regions_searched = 0;           // uncovered regions searched on their own (cover.regions)
  int from_regions = 0;               // patches kept that such a search found
  // tool: {shared: true} (or a catalogue tool): one tool for every patch. Shared: the coverage with
  // the held tool (core/detect.h), and whether the joint refit of all patches was kept.
  bool one_tool = false;
  double coverage_held_tool = 0;
  bool joint_refit = false;
};

struct FittedJob {
  LoadedMesh surface;  // mm
  Similarity frame;    // mm -> unit frame
  TriMesh unit_surface;
  std::vector<FittedPatch> patches;
  std::optional<TriMesh> part;  // the job's separate `part:` (mm) once checked; unset: the surface is the part
  // With `part:`: the part without the design surface's twin, faces out of the material (mm): the
  // fit's check surface and, with the design surface, what the collision check judges.
  std::optional<TriMesh> check_part;
  int check_twin_faces = 0;
  double check_twin_sag_mm = 0;  // CheckPart::twin_sag
  // `patches: auto`: the detected patches as jobs (init: lines), complete before any FittedPatch::job
  // points into it; a moved vector keeps its elements, so FittedJob stays movable.
  std::vector<PatchJob> detected;
  std::optional<CoverResult> cover;
};

// "whole surface: N patches[, one shared tool], C% within T mm (stopped: REASON)"; empty without `patches: auto`.
[[nodiscard]] std::string cover_summary(const Job& job, const FittedJob& fitted);
// `patches: auto` that found no patch: nothing to machine. Throws ProgramRefused ("patches: auto: no
// patch machines any of the surface within T mm (N candidate motions fitted); nothing written: ...") before
// any file is written; does nothing when a patch was found or the patches are listed.
void require_detected_patch(const Job& job, const FittedJob& fitted);
// The patch's tool as tables name it: the catalogue name, or the fitted shape ("general",
// "cone", ...; "shared" added when one tool serves every patch).
[[nodiscard]] std::string tool_label(const Job& job, const FittedPatch& p);
// The tables' tool column: as wide as the widest tool_label, at least 9 (a catalogue name is longer).
[[nodiscard]] size_t tool_label_width(const Job& job, const std::vector<FittedPatch>& patches);
// The "cover" entry of report.json (`patches: auto` only).
[[nodiscard]] nlohmann::ordered_json cover_report(const Job& job, const FittedJob& fitted);
// `patches: auto`: the job with the detected patches written out as `init: lines` (detected-job.yaml).
[[nodiscard]] std::string detected_job_yaml(const Job& job, const FittedJob& fitted);
// The name of that file in the output folder.
inline const std::string detected_job_name = "detected-job.yaml";
// `patches: auto`: the pictures of the whole surface (which patch machines each point; the union's deviation).
inline const std::string cover_owner_svg_name = "surface-patches.svg";
inline const std::string cover_deviation_svg_name = "surface-deviation.svg";

// Loads the design surface, fits every patch in the unit-diagonal frame (paper Sec. 4) and runs
// check_job. The OpenMP loops use however many threads the caller set (see run.h).
// The job's design surface (a mesh, or STEP/IGES faces tessellated at tolerance / 20 unless the
// job says otherwise) and its separate part (STEP/IGES at clearance / 10; unset: no `part:`), mm.
[[nodiscard]] LoadedMesh load_job_surface(const Job& job, const Progress& progress);
[[nodiscard]] std::optional<LoadedMesh> load_job_part(const Job& job);

[[nodiscard]] FittedJob fit_job(const Job& job, int threads, const Progress& progress);

// The job's shank and holder as the fit's check-surface body (CheckSurface::body): (u beyond the
// cutter's end, radius) in the frame `fr`, about every half of the smallest radius (at most 64
// samples); where the radius steps (a holder wider than its shank) both sides are samples at one u.
[[nodiscard]] std::vector<Eigen::Vector2d> body_samples(const HolderJob& holder, const Similarity& fr);

// Poses in mm, tool assembly, meridian, contact points and the collision and gouge checks of
// every fitted patch against the whole part (job.part, default the design surface).
void check_job(const Job& job, FittedJob& fitted, const Progress& progress);

// The grinding sheet of a patch's tool (NAME-tool-sheet.csv): dimensions, then the profile points
// with diameter and local half angle, mm and degrees.
[[nodiscard]] std::string tool_sheet(const Job& job, const FittedPatch& patch);

// Rounds a length in mm to 1 nm for reports (stable text, no spurious digits).
[[nodiscard]] double round_mm(double x);

// The "surface" and per-patch entries of report.json, lengths in mm, relative errors marked.
[[nodiscard]] nlohmann::ordered_json surface_report(const Job& job, const FittedJob& fitted);
[[nodiscard]] nlohmann::ordered_json patch_report(const Job& job, const FittedJob& fitted, const FittedPatch& patch);

// One line per collision interval: "patch P: holder collides at poses 12-17, 0.731 mm deep at (x, y, z)".
[[nodiscard]] std::vector<std::string> collision_summary(const FittedPatch& patch);

// Poses first..last (FittedPatch::poses indices, overtravel poses counted) of a patch kept, `why`.
struct KeptPoses {
  size_t first = 0, last = 0;
  std::string why;
};
// Each patch with a `keep` entry shortened to those poses (flankcam run: the cut entered and left
// where the link planner finds clear leads): its poses and contacts (and its earlier passes', their
// rails and coverage too), its rails trimmed to the same stretch, its machined surface and coverage anew, and with `patches: auto`
// the cover's union; one progress line each, the reason in `note`, the union's line saying they were
// shortened `shortened`.
void keep_poses(const Job& job, FittedJob& fitted, const std::vector<std::optional<KeptPoses>>& keep, std::string FittedPatch::*note,
                const std::string& shortened, const Progress& progress);

// Every patch the collision check found not clear (collisions, gouges or a shank or holder inside the
// clearance) whose longest stretch of clear poses is at least three quarters of its motion, shortened
// to that stretch (not with the job's overtravel, whose poses would be lost) (keep_poses; the reason in
// FittedPatch::kept_clear) and checked again: a program for what can be cut instead of none where the
// fit's check missed what the collision check sees near the ends of its motion. Not for
// `--allow-collisions` (the user posts the whole motion).
void shorten_to_clear(const Job& job, FittedJob& fitted, const Progress& progress);

// Every patch still not clear (after shorten_to_clear) marked refused (FittedPatch::refused): it
// gets no program, so with `patches: auto` the cover's union is judged anew without it (the surface
// it would machine is not machined) and a progress line says so.
void refuse_colliding(const Job& job, FittedJob& fitted, const Progress& progress);

// The patch's CL-data (APT model): approach, the fitted poses at the job's feed, retract; the tool's
// meridian in mm; a comment with the fitted error and one flagging allowed collisions.
[[nodiscard]] ClProgram patch_program(const Job& job, const FittedJob& fitted, const FittedPatch& patch, int tool);
// The CL-data of an earlier pass (PassMotion) of the patch, the same tool.
[[nodiscard]] ClProgram pass_program(const Job& job, const FittedJob& fitted, const FittedPatch& patch, const PassMotion& pass,
                                     int tool);

}  // namespace flankcam::pipeline
