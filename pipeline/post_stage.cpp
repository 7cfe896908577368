#include "pipeline/post_stage.h"

#include <fmt/format.h>

#include <algorithm>
#include <cmath>

#include "core/errors.h"
#include "core/file_probe.h"
#include "pipeline/data_dir.h"
#include "postproc/gcode.h"
#include "postproc/verify.h"

namespace flankcam::pipeline {

Machine find_machine(const std::string& name_or_path, const std::filesystem::path& relative_to) {
  namespace fs = std::filesystem;
  const fs::path given(name_or_path);
  const auto load = [](const fs::path& p) {  // the dialect is postproc's to check
    Machine m = load_machine(p.string());
    (void)machine_dialect(m);
    return m;
  };
  for (const fs::path& p : {given, relative_to / given})
    if (!p.empty() && is_file(p)) return load(p);
  const fs::path dir = machines_dir();
  const fs::path shipped = dir / (name_or_path + ".yaml");
  if (is_file(shipped)) return load(shipped);
  std::vector<std::string> names;  // the shipped ones; an unreadable machines/ lists none (no exception)
  std::error_code ec;
  for (fs::directory_iterator it(dir, ec), end; !ec && it != end; it.increment(ec))
    if (it->path().extension() == ".yaml") names.push_back(it->path().stem().string());
  std::sort(names.begin(), names.end());
  throw InputError(fmt::format("machine '{}': no such file, and not one of the shipped machines ({})", name_or_path,
                               fmt::join(names, ", ")));
}

namespace {
PostedProgram summarize(Posted posted, const std::string& file, const std::string& patch, Dialect d) {
  PostedProgram w;
  w.file = file;
  w.patch = patch;
  w.dialect = d;
  w.posted = std::move(posted);
  w.rotary_range = {{{1e300, -1e300}, {1e300, -1e300}}};
  for (const PostedSection& s : w.posted.sections) {
    w.inserted += s.path.inserted;
    w.slowed += s.slowed_blocks;
    w.singular += int(s.path.singular.size());
    w.branch_changes += s.path.branch_changes;
    for (const SingularStretch& st : singular_stretches(s.path))
      w.singular_stretches.push_back({{"patch", s.patch}, {"poses", {st.first_pose, st.last_pose}},
                                      {"rotary_travel_deg", std::round(st.rotary_deg * 1e3) / 1e3},
                                      {"axis_turn_deg", std::round(st.axis_turn_deg * 1e3) / 1e3}});
    for (const Joints& j : s.path.joints)
      for (size_t k = 0; k < 2; ++k)
        w.rotary_range[k] = {std::min(w.rotary_range[k][0], j.rotary[k]), std::max(w.rotary_range[k][1], j.rotary[k])};
  }
  for (const NcBlock& b : w.posted.program.blocks)
    if (const auto* m = std::get_if<NcMove>(&b)) {
      ++w.moves;
      for (size_t k = 0; k < 2; ++k) w.rotary_deg[k].push_back(m->at.rotary[k]);
      if (!m->rapid) w.minutes += 1 / m->inverse_time;
    }
  return w;
}
}  // namespace

std::vector<Dialect> dialects_of(const Machine& m, const PostSettings& settings) {
  if (!settings.dialects.empty()) return settings.dialects;
  return {machine_dialect(m)};
}

std::vector<PostedProgram> post_programs(const Machine& m, const std::vector<PostInput>& inputs, const std::string& all_name,
                                         const PostSettings& settings, const std::vector<std::string>& header) {
  std::vector<PostedProgram> out;
  for (const Dialect d : dialects_of(m, settings)) {
    PostOptions o = settings.options;
    o.dialect = d;
    int number = 1;
    // One program per patch: its consecutive inputs (the passes of `passes:`) are its sections.
    bool several = false;
    for (size_t k = 0; k < inputs.size();) {
      size_t end = k + 1;
      while (end < inputs.size() && inputs[end].patch == inputs[k].patch) ++end;
      several = several || k > 0;
      Posted p = post(std::vector<PostInput>(inputs.begin() + long(k), inputs.begin() + long(end)), m, o, inputs[k].patch, header);
      p.program.number = number++;
      out.push_back(summarize(std::move(p), inputs[k].patch + file_extension(d), inputs[k].patch, d));
      k = end;
    }
    if (several) {
      Posted p = post(inputs, m, o, all_name, header);
      p.program.number = number;
      out.push_back(summarize(std::move(p), all_name + file_extension(d), "", d));
    }
  }
  for (const PostedProgram& p : out)
    if (!p.posted.refused.empty()) throw ProgramRefused(p.posted.refused + "; nothing written");
  return out;
}

nlohmann::ordered_json program_report(const PostedProgram& w, const Machine& m) {
  nlohmann::ordered_json j;
  j["file"] = w.file;
  j["dialect"] = to_string(w.dialect);
  j["moves"] = w.moves;
  j["inserted_by_linearisation"] = w.inserted;
  j["slowed_blocks"] = w.slowed;
  j["near_singular_poses"] = w.singular;
  j["near_singular_stretches"] = w.singular_stretches;  // rotary travel >> tool-axis turn
  j["branch_changes"] = w.branch_changes;
  for (size_t k = 0; k < 2; ++k)
    j["rotary_range_deg"][m.rotary[k].name] = {std::round(w.rotary_range[k][0] * 1e4) / 1e4,
                                               std::round(w.rotary_range[k][1] * 1e4) / 1e4};
  j["cut_minutes"] = std::round(w.minutes * 1e4) / 1e4;
  j["linearisation"] = {{"tolerance_mm", w.posted.tolerance_mm}, {"angle_tolerance_deg", w.posted.angle_tolerance_deg},
                        {"refined", w.posted.refined}};
  if (w.posted.refined > 0) j["linearisation"]["refined_for"] = w.posted.refined_for;
  if (w.posted.links_checked && std::isfinite(w.posted.min_link_clearance_mm))
    j["min_link_clearance_mm"] = std::round(w.posted.min_link_clearance_mm * 1e4) / 1e4;  // rapids, back-simulated
  return j;
}

}  // namespace flankcam::pipeline
