#include "core/patch.h"

#include <chrono>

#include "core/errors.h"

namespace flankcam {

const char* to_string(PatchInit i) { return i == PatchInit::Lines ? "lines" : "line"; }

namespace {
double seconds_since(std::chrono::steady_clock::time_point t0) {
  return std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
}
}  // namespace

PatchFit fit_patch(const SurfaceIndex& surface, const PatchSpec& spec, const PatchOptions& o) {
  const std::string where = "patch '" + spec.name + "': ";
  const auto stage = [&](const std::string& what) {
    if (o.on_stage) o.on_stage(what);
  };
  if (spec.init == PatchInit::Lines && spec.lines.size() < 2)
    throw InputError(where + "init: lines needs at least 2 lines");
  if (spec.init == PatchInit::Line && spec.lines.size() != 1) throw InputError(where + "init: line needs exactly one line");
  for (size_t k = 0; k < spec.lines.size(); ++k)
    if (!((spec.lines[k].b - spec.lines[k].a).norm() > 1e-9))
      throw InputError(where + "line " + std::to_string(k) + " has zero length");
  if (spec.rail != 0 && spec.rail != 1) throw InputError(where + "rail: must be 0 (tool tip, a) or 1 (b)");

  PatchFit out;
  const auto t0 = std::chrono::steady_clock::now();
  try {
    if (spec.init == PatchInit::Lines) {
      stage("surface-driven rails through " + std::to_string(spec.lines.size()) + " lines");
      out.initial = rails_from_lines(spec.lines, spec.rail, spec.length, o.fit);
    } else {
      stage("exploring the user line");
      out.explored = explore_line(surface, spec.lines[0].a, spec.lines[0].b, o.exploration);
      stage("propagating the line");
      out.trajectory = propagate_line(surface, out.explored->a, out.explored->b, o.propagation);
      out.initial = rails_from_trajectory(*out.trajectory, o.fit);
    }
    out.seconds_init = seconds_since(t0);
    stage("optimising rails and radii");
    const auto t1 = std::chrono::steady_clock::now();
    out.fit = optimize_motion(surface, out.initial, o.fit);
    out.seconds_opt = seconds_since(t1);
  } catch (const InputError& e) {
    throw InputError(where + e.what());
  }
  stage("machined envelope and deviation");
  out.machined = machined_surface(surface, out.fit.rails, out.fit.tool, o.machined);
  out.coverage = coverage(surface.mesh(), out.machined.design_deviation, o.tolerance);
  return out;
}

}  // namespace flankcam
