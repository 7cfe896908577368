#include "cli/post_stage.h"

#include <fmt/format.h>

#include <algorithm>

#include "core/errors.h"
#include "postproc/gcode.h"
#include "postproc/verify.h"

namespace flankcam::cli {

Machine find_machine(const std::string& name_or_path, const std::filesystem::path& relative_to) {
  namespace fs = std::filesystem;
  const fs::path given(name_or_path);
  for (const fs::path& p : {given, relative_to / given})
    if (!p.empty() && fs::is_regular_file(p)) return load_machine(p.string());
  const fs::path shipped = fs::path(FLANKCAM_MACHINES_DIR) / (name_or_path + ".yaml");
  if (fs::is_regular_file(shipped)) return load_machine(shipped.string());
  std::vector<std::string> names;
  for (const auto& e : fs::directory_iterator(FLANKCAM_MACHINES_DIR))
    if (e.path().extension() == ".yaml") names.push_back(e.path().stem().string());
  std::sort(names.begin(), names.end());
  throw InputError(fmt::format("machine '{}': no such file, and not one of the shipped machines ({})", name_or_path,
                               fmt::join(names, ", ")));
}

namespace {
WrittenProgram summarize(const Posted& posted, const std::string& file, const std::string& patch, Dialect d) {
  WrittenProgram w;
  w.file = file;
  w.patch = patch;
  w.dialect = d;
  w.rotary_range = {{{1e300, -1e300}, {1e300, -1e300}}};
  for (const PostedSection& s : posted.sections) {
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
  for (const NcBlock& b : posted.program.blocks)
    if (const auto* m = std::get_if<NcMove>(&b)) {
      ++w.moves;
      for (size_t k = 0; k < 2; ++k) w.rotary_deg[k].push_back(m->at.rotary[k]);
      if (!m->rapid) w.minutes += 1 / m->inverse_time;
    }
  return w;
}
}  // namespace

std::vector<WrittenProgram> write_programs(const std::filesystem::path& out, const Machine& m,
                                           const std::vector<PostInput>& inputs, const std::string& all_name,
                                           const PostSettings& settings, const std::vector<std::string>& header) {
  std::vector<Dialect> dialects = settings.dialects;
  if (dialects.empty()) dialects.push_back(parse_dialect(m.controller.dialect));
  // Build every program before writing any, so an unreachable patch leaves no files behind.
  struct Pending {
    std::string file, patch;
    Dialect dialect;
    Posted posted;
  };
  std::vector<Pending> pending;
  for (const Dialect d : dialects) {
    PostOptions o = settings.options;
    o.dialect = d;
    int number = 1;
    for (const PostInput& in : inputs) {
      Posted p = post({in}, m, o, in.patch, header);
      p.program.number = number++;
      pending.push_back({in.patch + file_extension(d), in.patch, d, std::move(p)});
    }
    if (inputs.size() > 1) {
      Posted p = post(inputs, m, o, all_name, header);
      p.program.number = number;
      pending.push_back({all_name + file_extension(d), "", d, std::move(p)});
    }
  }
  for (const Pending& p : pending)
    if (!p.posted.refused.empty()) throw ProgramRefused("back-simulation: " + p.posted.refused + "; nothing written");
  std::vector<WrittenProgram> written;
  for (const Pending& p : pending) {
    write_nc((out / p.file).string(), p.posted.program, {p.dialect, settings.line_numbers, settings.options.path.tolerance_mm});
    written.push_back(summarize(p.posted, p.file, p.patch, p.dialect));
  }
  return written;
}

nlohmann::ordered_json program_report(const WrittenProgram& w, const Machine& m) {
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
  return j;
}

}  // namespace flankcam::cli
