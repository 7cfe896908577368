// `flankcam verify` as a library: back-simulates NC programs (any of the four dialects, by
// extension) or APT CL-data through the job's machine against its part placed on the machine
// (post.setup), with each tool's cutter from its meridian and shank and holder from the job.
// verify() reads everything and simulates; write_verify() writes verify.json and verify.html
// through an OutputDir. Nothing here prints.
#pragma once
#include <Eigen/Core>
#include <array>
#include <string>
#include <vector>

#include "core/closest_point.h"
#include "kinematics/machine.h"
#include "pipeline/fit_stage.h"
#include "pipeline/job.h"
#include "pipeline/output_dir.h"
#include "postproc/verify.h"

namespace flankcam::pipeline {

struct VerifyRequest {
  std::string job;                    // job file (YAML): machine, part, holder, setup, tolerance
  std::vector<std::string> programs;  // .nc .ngc .h .mpf programs or .apt CL-data
  // "T=FILE": tool T's meridian CSV (z_mm,r_mm); T=0 for every tool. Default: NAME-tool.csv
  // beside the program, NAME from the program's tool-change comment (or the file's stem).
  std::vector<std::string> tools;
  // "PROGRAM=FILE": the APT CL-data PROGRAM was posted from (several for several tools, matched by
  // their LOADTL). Default: NAME.apt beside the program for each tool NAME of its tool-change comments.
  std::vector<std::string> cl;
};

struct VerifiedProgram {
  std::string file;
  VerifyReport report;
  std::vector<Eigen::Vector2d> meridian;             // the (first) tool's cutter, mm
  std::vector<VerifyTool> tools;                     // as simulated (verify.html's 3D view draws them)
  bool cl_data = false;                              // APT CL-data: poses only, no machine axes
  std::array<double, 3> min_rapid_mm{}, min_feed_mm{};  // cutter, shank, holder clearance; +inf without blocks
  [[nodiscard]] double min_rapid_all_mm() const;
  std::vector<std::string> cl_files;  // the CL-data the cutting blocks were compared with
  std::string cl_note;                // why (some) blocks were not compared with CL-data, "" when all were
};

// Move-only (SurfaceIndex).
struct VerifyRun {
  Job job;
  Machine machine;
  VerifyOptions options;
  SurfaceIndex design;  // the job's surface in the work frame (the coverage and the deviation map)
  TriMesh part_mm;      // the job's separate part in the work frame; empty: the surface is the part
  std::vector<VerifiedProgram> programs;  // in the order requested
  // Programs that are not clean: they collide, gouge, keep a rapid inside the clearance or leave the CL-data.
  [[nodiscard]] int failing() const;
};

// NAME-tool.csv: "# comment", "z_mm,r_mm", then z,r rows (mm). Throws InputError with file:line.
[[nodiscard]] std::vector<Eigen::Vector2d> read_meridian(const std::string& path);

// Reads the job, machine, tools, part and programs (all before anything is written) and
// back-simulates each program. Throws InputError on bad input. `progress`: one line per program.
[[nodiscard]] VerifyRun verify(const VerifyRequest& request, const Progress& progress = [](const std::string&) {});

// verify.json and verify.html (with the 3D view of the simulation, postproc/verify_view.h). Commits `out`.
void write_verify(const VerifyRun& run, OutputDir& out);

}  // namespace flankcam::pipeline
