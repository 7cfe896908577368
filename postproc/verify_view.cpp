#include "postproc/verify_view.h"

#include <fmt/format.h>

#include <map>

#include "core/errors.h"

namespace flankcam {

namespace {

// The tool a block's T number selects, as verify_program chooses it: its own entry, else number 0,
// else the only tool.
size_t tool_index(const std::vector<VerifyTool>& tools, int number) {
  for (size_t k = 0; k < tools.size(); ++k)
    if (tools[k].number == number) return k;
  for (size_t k = 0; k < tools.size(); ++k)
    if (tools[k].number == 0) return k;
  return 0;
}

}  // namespace

ViewerScene verify_view(const TriMesh& surface_mm, const TriMesh& part_mm, double tolerance_mm,
                        const std::vector<VerifyViewProgram>& programs, const Machine* machine) {
  ViewerScene v;
  std::vector<double> tool_length_mm;  // per patch
  v.tolerance_mm = tolerance_mm;
  v.surface_mm = surface_mm;
  v.part_mm = part_mm;
  v.combined_name = programs.size() == 1 ? programs.front().name : "all programs (smallest deviation)";
  const bool whole_run = programs.size() > 1;
  ViewerTrack all;
  all.name = fmt::format("all {} programs", programs.size());
  std::vector<size_t> offset;  // per program: its first frame in the whole run's track
  for (const VerifyViewProgram& p : programs) {
    if (!p.report || p.tools.empty()) throw InputError("verify view: program '" + p.name + "' has no report or no tool");
    const VerifyReport& r = *p.report;
    // One patch per tool the program uses, in the order of first use.
    std::map<size_t, int> patch_of_tool;
    const auto patch_of_block = [&](int block) {
      const size_t k = tool_index(p.tools, r.blocks.at(size_t(block)).tool);
      const auto [it, added] = patch_of_tool.emplace(k, int(v.patches.size()));
      if (added) {
        const VerifyTool& t = p.tools[k];
        ViewerPatch vp;
        vp.name = t.number > 0 ? fmt::format("{} T{}", p.name, t.number) : p.name;
        vp.meridian = t.assembly.cutter;
        vp.assembly = t.assembly;
        v.patches.push_back(std::move(vp));
        tool_length_mm.push_back(t.length_mm);
      }
      return it->second;
    };
    ViewerTrack t;
    t.name = p.name;
    t.axis_names = p.axis_names;
    t.has_values = p.has_values;
    for (const VerifiedPosition& q : r.motion) {
      const VerifiedBlock& b = r.blocks.at(size_t(q.block));
      t.frames.push_back({q.pose,
                          {q.programmed.linear.x(), q.programmed.linear.y(), q.programmed.linear.z(), q.programmed.rotary[0],
                           q.programmed.rotary[1]},
                          b.rapid,
                          patch_of_block(q.block),
                          b.line});
    }
    offset.push_back(all.frames.size());
    all.axis_names = p.axis_names;
    all.has_values = (offset.size() == 1 || all.has_values) && p.has_values;
    all.frames.insert(all.frames.end(), t.frames.begin(), t.frames.end());
    v.tracks.push_back(std::move(t));
    if (r.design.deviation_mm.size() == surface_mm.vertices.size()) v.colourings.push_back({p.name, r.design.deviation_mm});
  }
  if (whole_run) v.tracks.push_back(std::move(all));
  if (machine) v.machine = ViewerMachine{*machine, tool_length_mm};

  for (size_t k = 0; k < programs.size(); ++k) {
    const VerifyViewProgram& p = programs[k];
    const VerifyReport& r = *p.report;
    for (const VerifyHit& h : r.hits) {
      ViewerMarker m;
      m.at_mm = h.point;
      m.label = fmt::format("{} line {}: {} ({})", p.name, h.line, h.what(r.link_clearance_mm), h.rapid ? "rapid" : "feed");
      m.frames.assign(v.tracks.size(), -1);
      const bool known = h.position >= 0 && size_t(h.position) < r.motion.size();
      if (known) {
        m.frames[k] = h.position;
        if (whole_run) m.frames.back() = int(offset[k]) + h.position;
      }
      const int patch = known ? v.tracks[k].frames[size_t(h.position)].patch : 0;
      if (v.patches.empty()) break;  // no motion: nothing to jump to
      v.patches[size_t(patch)].markers.push_back(std::move(m));
    }
  }
  return v;
}

}  // namespace flankcam
