#include "cli/job.h"

#include <fmt/format.h>
#include <yaml-cpp/yaml.h>

#include <cmath>
#include <regex>
#include <set>

#include "core/errors.h"
#include "core/yaml_fields.h"
#include "postproc/nc_program.h"

namespace flankcam::cli {

namespace {

using Reader = YamlFields<InputError>;

std::array<double, 6> read_line(const Reader& r, const YAML::Node& n, const std::string& key) {
  if (!n.IsSequence() || n.size() != 6) r.fail(n, key, "expected 6 numbers [ax, ay, az, bx, by, bz] (mm)");
  std::array<double, 6> l{};
  for (size_t k = 0; k < 6; ++k) l[k] = r.number(n[k], fmt::format("{}[{}]", key, k));
  return l;
}

ToolShape read_shape(const Reader& r, const YAML::Node& n) {
  const std::string s = r.text(n, "tool.shape");
  if (s == "general") return ToolShape::General;
  if (s == "cone") return ToolShape::Cone;
  if (s == "cylinder") return ToolShape::Cylinder;
  r.fail(n, "tool.shape", "unknown shape '" + s + "' (general, cone, cylinder)");
}

PatchJob read_patch(const Reader& r, const YAML::Node& p, const std::string& key, std::set<std::string>& names) {
  r.only_keys(p, key, {"name", "init", "lines", "line", "rail", "length"});
  PatchJob job;
  if (!p["name"]) r.fail(p, key + ".name", "missing");
  job.name = r.text(p["name"], key + ".name");
  static const std::regex safe("[A-Za-z0-9_.-]+");
  if (!std::regex_match(job.name, safe) || job.name.front() == '.')
    r.fail(p["name"], key + ".name", "use letters, digits, '_', '-' and '.' only (it names the output files)");
  if (!names.insert(job.name).second) r.fail(p["name"], key + ".name", "duplicate patch name '" + job.name + "'");
  if (!p["init"]) r.fail(p, key + ".init", "missing (lines | line)");
  const std::string init = r.text(p["init"], key + ".init");
  if (init == "lines") {
    job.init = PatchInit::Lines;
    if (!p["lines"]) r.fail(p, key + ".lines", "missing: init: lines needs ordered axis positions");
    if (p["line"]) r.fail(p["line"], key + ".line", "not used with init: lines (use lines:)");
    const YAML::Node ls = p["lines"];
    if (!ls.IsSequence() || ls.size() < 2) r.fail(ls, key + ".lines", "expected a list of at least 2 lines");
    for (size_t k = 0; k < ls.size(); ++k) job.lines_mm.push_back(read_line(r, ls[k], fmt::format("{}.lines[{}]", key, k)));
  } else if (init == "line") {
    job.init = PatchInit::Line;
    if (!p["line"]) r.fail(p, key + ".line", "missing: init: line needs one user line");
    if (p["lines"]) r.fail(p["lines"], key + ".lines", "not used with init: line (use line:)");
    if (p["rail"]) r.fail(p["rail"], key + ".rail", "only for init: lines");
    if (p["length"]) r.fail(p["length"], key + ".length", "only for init: lines (the user line's length is kept)");
    job.lines_mm.push_back(read_line(r, p["line"], key + ".line"));
  } else {
    r.fail(p["init"], key + ".init", "unknown initialisation '" + init + "' (lines, line)");
  }
  for (size_t k = 0; k < job.lines_mm.size(); ++k) {
    const auto& l = job.lines_mm[k];
    if (std::hypot(l[3] - l[0], l[4] - l[1], l[5] - l[2]) < 1e-6)
      r.fail(job.init == PatchInit::Line ? p["line"] : p["lines"][k], key, "a line has zero length (a = b)");
  }
  if (p["rail"]) job.rail = r.integer(p["rail"], key + ".rail", 0, 1);
  if (p["length"]) job.length_mm = r.positive(p["length"], key + ".length");
  return job;
}

void read_post(const Reader& r, const YAML::Node& p, PostJob& post) {
  r.only_keys(p, "post", {"dialects", "apt", "cl", "tool", "line_numbers", "tolerance", "angle_tolerance", "tool_length",
                          "safe_height", "setup"});
  if (const YAML::Node s = p["setup"]) {
    r.only_keys(s, "post.setup", {"rotate", "translate"});
    const auto vec = [&](const char* key, std::array<double, 3>& v) {
      const YAML::Node n = s[key];
      if (!n) return;
      if (!n.IsSequence() || n.size() != 3) r.fail(n, std::string("post.setup.") + key, "expected 3 numbers");
      for (size_t k = 0; k < 3; ++k) v[k] = r.number(n[k], fmt::format("post.setup.{}[{}]", key, k));
    };
    vec("rotate", post.setup_rotate_deg);
    vec("translate", post.setup_translate_mm);
  }
  if (const YAML::Node d = p["dialects"]) {
    if (!d.IsSequence() || d.size() == 0) r.fail(d, "post.dialects", "expected a list such as [linuxcnc, iso]");
    for (size_t k = 0; k < d.size(); ++k) {
      const std::string key = fmt::format("post.dialects[{}]", k);
      const std::string name = r.text(d[k], key);
      try {
        (void)parse_dialect(name);
      } catch (const InputError& e) {
        r.fail(d[k], key, e.what());
      }
      post.dialects.push_back(name);
    }
  }
  if (p["apt"]) post.apt = r.boolean(p["apt"], "post.apt");
  if (p["cl"]) post.cl = r.boolean(p["cl"], "post.cl");
  if (p["tool"]) post.tool = r.boolean(p["tool"], "post.tool");
  if (p["line_numbers"]) post.line_numbers = r.boolean(p["line_numbers"], "post.line_numbers");
  if (p["tolerance"]) post.tolerance_mm = r.positive(p["tolerance"], "post.tolerance");
  if (p["angle_tolerance"]) post.angle_tolerance_deg = r.positive(p["angle_tolerance"], "post.angle_tolerance");
  if (p["tool_length"]) post.tool_length_mm = r.positive(p["tool_length"], "post.tool_length");
  if (p["safe_height"]) post.safe_height_mm = r.non_negative(p["safe_height"], "post.safe_height");
}

}  // namespace

Job read_job(const std::filesystem::path& file) {
  const std::string name = file.string();
  if (!std::filesystem::is_regular_file(file)) throw InputError(name + ": job file not found");
  const Reader r(name);
  const YAML::Node root = r.load();
  if (!root.IsMap()) throw InputError(name + ": expected a mapping with surface:, patches:, ...");
  r.only_keys(root, "", {"surface", "part", "holder", "clearance", "feed", "spindle", "lead_in", "retract", "tool", "tolerance", "sampling", "weights", "fit", "patches", "machine", "post"});

  Job job;
  job.file = file;
  if (!root["surface"]) throw InputError(name + ": surface: missing (the design surface mesh, mm)");
  const std::filesystem::path base = file.parent_path();
  const std::filesystem::path surface = r.text(root["surface"], "surface");
  job.surface = surface.is_absolute() ? surface : base / surface;
  if (!std::filesystem::is_regular_file(job.surface))
    r.fail(root["surface"], "surface", "file not found: " + job.surface.string());

  job.part = job.surface;
  if (root["part"]) {
    const std::filesystem::path part = r.text(root["part"], "part");
    job.part = part.is_absolute() ? part : base / part;
    if (!std::filesystem::is_regular_file(job.part)) r.fail(root["part"], "part", "file not found: " + job.part.string());
  }
  if (const YAML::Node h = root["holder"]) {
    r.only_keys(h, "holder", {"shank_length", "shank_diameter", "length", "diameter", "diameter_far", "cylinder_length"});
    HolderJob& hj = job.holder;
    const auto get = [&](const char* key, double& v) {
      if (h[key]) v = r.non_negative(h[key], std::string("holder.") + key);
    };
    get("shank_length", hj.shank_length), get("shank_diameter", hj.shank_diameter), get("length", hj.length);
    get("diameter", hj.diameter), get("diameter_far", hj.diameter_far), get("cylinder_length", hj.cylinder_length);
    if (!h["diameter_far"]) hj.diameter_far = hj.diameter;
    if (hj.shank_length > 0 && !(hj.shank_diameter > 0)) r.fail(h, "holder.shank_diameter", "must be > 0 with a shank");
    if (hj.length + hj.cylinder_length > 0 && !(hj.diameter > 0)) r.fail(h, "holder.diameter", "must be > 0 with a holder");
  }
  if (root["clearance"]) job.clearance_mm = r.positive(root["clearance"], "clearance");
  if (root["feed"]) job.feed_mm_min = r.positive(root["feed"], "feed");
  if (root["spindle"]) job.spindle_rpm = r.positive(root["spindle"], "spindle");
  if (root["lead_in"]) job.lead_in_mm = r.non_negative(root["lead_in"], "lead_in");
  if (root["retract"]) job.retract_mm = r.positive(root["retract"], "retract");
  if (job.retract_mm < job.lead_in_mm) r.fail(root["retract"] ? root["retract"] : root, "retract", "must be >= lead_in");
  if (const YAML::Node t = root["tool"]) {
    r.only_keys(t, "tool", {"shape", "control_points"});
    if (t["shape"]) job.fit.shape = read_shape(r, t["shape"]);
    if (t["control_points"]) job.fit.meridian_control_points = r.integer(t["control_points"], "tool.control_points", 4, 100);
  }
  if (root["tolerance"]) job.tolerance_mm = r.positive(root["tolerance"], "tolerance");
  if (const YAML::Node s = root["sampling"]) {
    r.only_keys(s, "sampling", {"s", "t"});
    if (s["s"]) job.fit.samples_s = r.integer(s["s"], "sampling.s", 4, 1000);
    if (s["t"]) job.fit.samples_t = r.integer(s["t"], "sampling.t", 8, 100000);
  }
  if (const YAML::Node w = root["weights"]) {
    r.only_keys(w, "weights", {"plane", "fair", "point", "rigid", "anchor"});
    if (w["plane"]) job.fit.w_plane = r.non_negative(w["plane"], "weights.plane");
    if (w["fair"]) job.fit.w_fair = r.non_negative(w["fair"], "weights.fair");
    if (w["point"]) job.fit.w_point = r.non_negative(w["point"], "weights.point");
    if (w["rigid"]) job.fit.w_rigid = r.non_negative(w["rigid"], "weights.rigid");
    if (w["anchor"]) job.fit.w_anchor = r.non_negative(w["anchor"], "weights.anchor");
  }
  if (const YAML::Node f = root["fit"]) {
    r.only_keys(f, "fit", {"iterations", "rail_control_points", "robust"});
    if (f["iterations"]) job.fit.max_iterations = r.integer(f["iterations"], "fit.iterations", 1, 1000);
    if (f["rail_control_points"])
      job.fit.rail_control_points = r.integer(f["rail_control_points"], "fit.rail_control_points", 4, 1000);
    if (f["robust"]) job.robust_mm = r.non_negative(f["robust"], "fit.robust");
  }
  if (auto err = job.fit.validate(); !err.empty()) throw InputError(name + ": " + err);
  if (root["machine"]) job.machine = r.text(root["machine"], "machine");
  if (const YAML::Node p = root["post"]) read_post(r, p, job.post);

  const YAML::Node ps = root["patches"];
  if (!ps) throw InputError(name + ": patches: missing (at least one patch with its initialisation)");
  if (!ps.IsSequence() || ps.size() == 0) r.fail(ps, "patches", "expected a list of at least one patch");
  std::set<std::string> names;
  for (size_t k = 0; k < ps.size(); ++k) job.patches.push_back(read_patch(r, ps[k], fmt::format("patches[{}]", k), names));
  return job;
}

}  // namespace flankcam::cli
