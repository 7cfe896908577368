// The one writer: every file of a fit, run or post goes through here into an OutputDir, which
// moves them into the output folder only when all are written (nothing is left on failure).
#pragma once
#include <string>
#include <vector>

#include "pipeline/output_dir.h"
#include "pipeline/run.h"

namespace flankcam::pipeline {

// `flankcam fit`: per patch NAME-envelope.ply (Ω with its deviation from Φ), NAME-deviation.ply
// (Φ with its deviation from Ω), NAME-tool.csv/.dxf/.stl (meridian), with CL-data NAME.apt and
// NAME-cl.csv, when it collides NAME-collisions.obj; report.json. Commits `out`. Returns the file
// names per patch.
std::vector<std::vector<std::string>> write_fit(const FitRun& fit, OutputDir& out);

// `flankcam run`: the fit's files (post.apt/cl/tool choose), NAME-deviation.svg, NAME-tool.svg,
// NAME-angles.svg, the NC programs, report.json and report.html. Commits `out`. Returns the file
// names per patch.
std::vector<std::vector<std::string>> write_run(const RunResult& run, OutputDir& out);

// `flankcam post`: the NC programs and, for CL-data that carries the tool's profile, NAME-tool.stl.
// Commits `out`.
void write_post(const PostRun& post, OutputDir& out);

}  // namespace flankcam::pipeline
