// The interactive 3D view of report.html and verify.html (one viewer, two pages): the data it shows
// (design surface with its deviation bands, the part, each patch's machined envelope Ω, the axis
// ruled surface, the tool assemblies, the motion of programs with their programmed axis values,
// collision and gouge markers) and the HTML fragment that draws it with three.js (Debian's
// libjs-three, inlined at build time: one offline file). report.html builds its scene from the fit
// and the posted programs (pipeline/outputs.cpp), verify.html from the back-simulation
// (postproc/verify_view.h). Meshes are decimated to a triangle budget and written as base64
// little-endian Float32/Uint32 arrays with fixed-decimal JSON around them, so the same scene gives
// the same bytes.
#pragma once
#include <Eigen/Core>
#include <array>
#include <cstdint>
#include <optional>
#include <string>
#include <vector>

#include "core/collision.h"
#include "core/mesh.h"
#include "core/pose.h"
#include "kinematics/machine.h"
#include "postproc/nc_program.h"

namespace flankcam {

// Signed deviation in discrete bands (the legend): undercut > 0 (material left), overcut < 0.
enum class DeviationBand : std::uint8_t { None = 0, Within = 1, Over = 2, Under = 3 };
[[nodiscard]] DeviationBand deviation_band(double dev_mm, double tol_mm);  // NaN: None

struct ViewerMarker {
  Eigen::Vector3d at_mm = Eigen::Vector3d::Zero();  // the part point of the collision or gouge
  int pose = 0;                                     // index into ViewerPatch::poses (the worst one)
  std::string label;                                // "holder collides at poses 12-17, 0.731 mm deep"
  // Per track, the frame the marker jumps to (-1: not in that track). Empty: the frame of this
  // patch nearest `pose` (report.html); verify.html knows the simulated position of each hit.
  std::vector<int> frames;
};

struct ViewerPatch {
  std::string name;
  std::vector<Eigen::Vector2d> meridian;    // cutter (z, r) from the tip, mm
  ToolAssembly assembly;                    // shank and holder above the cutter, mm
  std::vector<double> design_deviation_mm;  // per design-surface vertex; NaN where Ω does not reach; empty: none
  TriMesh envelope_mm;                      // Ω
  std::vector<ToolPose> poses;              // the fitted poses (part frame): the axis ruled surface; may be empty
  std::vector<ViewerMarker> markers;
};

// One step of a motion: the pose (part frame) and what the program states for it.
struct ViewerFrame {
  ToolPose pose;
  std::array<double, 5> values{};  // X Y Z and the two rotary axes as programmed (mm, degrees)
  bool rapid = false;
  int patch = 0;                   // index into ViewerScene::patches: whose tool is in the spindle
  int line = 0;                    // the program's line (1-based) the frame belongs to; 0: not known
};

struct ViewerTrack {
  std::string name;                                    // "cone-1.ngc", "all-patches.ngc", "cone-1 (fitted poses)"
  std::array<std::string, 5> axis_names{"X", "Y", "Z", "A", "C"};
  bool has_values = true;                              // false: fitted poses only, no program
  std::vector<ViewerFrame> frames;
};

// A further "colour by" choice of the design surface (verify.html: the deviation one program machines).
struct ViewerColouring {
  std::string name;
  std::vector<double> deviation_mm;  // per design-surface vertex, NaN where not reached
};

// The machine for the view's machine mode: the tables turn the part and the heads tilt the tool by
// the rotary values of a track's frames, through the machine's chain (kinematics/kinematics.h),
// drawn as simple bodies (a rotary table, a trunnion cradle, head housings).
struct ViewerMachine {
  Machine machine;
  std::vector<double> tool_length_mm;  // per patch: spindle nose to tip as the program is posted
};

struct ViewerScene {
  double tolerance_mm = 0.01;
  std::string combined_name = "all patches";  // the surface coloured by the smallest deviation of all
  TriMesh surface_mm;        // the design surface Φ
  TriMesh part_mm;           // the whole part, drawn translucent; empty: Φ is the part
  std::vector<ViewerPatch> patches;
  std::vector<ViewerTrack> tracks;
  std::vector<ViewerColouring> colourings;
  std::optional<ViewerMachine> machine;  // none: no machine mode
  std::string validate() const;  // empty when valid: sizes agree, indices in range
};

struct ViewerOptions {
  int max_surface_triangles = 300000;   // Φ beyond this is decimated (vertex clustering)
  int max_part_triangles = 150000;
  int max_envelope_triangles = 60000;   // per patch
  int max_frames = 20000;               // per track; longer tracks are subsampled (ends and marker frames kept)
  int max_total_frames = 60000;         // all tracks together (~4 MB): beyond it each track's share shrinks in proportion
  std::string validate() const;
};

// The motion of a posted program: one frame per NcMove, its pose taken back to the part frame by
// `T_part_work` (inverse of the setup), the tool of the section's patch (by name in `patch_names`;
// blocks after the last section keep its tool).
[[nodiscard]] ViewerTrack viewer_track(const Posted& posted, const std::string& name,
                                       const std::array<std::string, 2>& rotary_names,
                                       const Eigen::Matrix3d& R_part_work, const Eigen::Vector3d& t_part_work,
                                       const std::vector<std::string>& patch_names);

// Vertex clustering on a uniform grid, the cell grown until at most `max_triangles` remain.
// `vertex_map[i]`: the output vertex of input vertex i. Deterministic; the input when small enough.
struct Decimated {
  TriMesh mesh;
  std::vector<int> vertex_map;
};
[[nodiscard]] Decimated decimate(const TriMesh& mesh, int max_triangles);

// The view's <section> (canvas, controls, legend, data and scripts) for HtmlReport::viewer. Throws
// InputError when the scene or the options are invalid.
[[nodiscard]] std::string viewer_html(const ViewerScene& scene, const ViewerOptions& options = {});

// The scene's JSON alone (what viewer_html embeds), for tests and tools.
[[nodiscard]] std::string viewer_json(const ViewerScene& scene, const ViewerOptions& options = {});

// True when three.js was found at build time (libjs-three); without it the view says so.
[[nodiscard]] bool viewer_available();

}  // namespace flankcam
