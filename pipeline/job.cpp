#include "pipeline/job.h"

#include <fmt/format.h>
#include <yaml-cpp/yaml.h>

#include <Eigen/Geometry>
#include <cmath>
#include <regex>
#include <set>

#include "core/errors.h"
#include "core/file_probe.h"
#include "cad/cad_reader.h"
#include "core/yaml_fields.h"
#include "pipeline/data_dir.h"
#include "postproc/nc_program.h"

namespace flankcam::pipeline {

namespace {

using Reader = YamlFields<InputError>;

// Sane ranges of job values: beyond them a value is a typo or a unit mistake, and would post
// nonsense (F0.0000, a 301-digit S word) or make the fit run for hours.
constexpr double max_length_mm = 1e5;       // 100 m: lengths of tool, holder, moves
constexpr double max_coordinate_mm = 1e6;   // 1 km: line end points, setup translation
constexpr int max_samples_s = 200, max_samples_t = 2000, max_samples = 60000;  // 20x the paper's 30 x 100

// A number in [lo, hi] (unit for the message).
double in_range(const Reader& r, const YAML::Node& n, const std::string& key, double lo, double hi, const char* unit) {
  const double v = r.number(n, key);
  if (!(v >= lo && v <= hi)) r.fail(n, key, fmt::format("must be in {} .. {}{}{}, got {}", lo, hi, *unit ? " " : "", unit, n.Scalar()));
  return v;
}

std::array<double, 6> read_line(const Reader& r, const YAML::Node& n, const std::string& key) {
  if (!n.IsSequence() || n.size() != 6) r.fail(n, key, "expected 6 numbers [ax, ay, az, bx, by, bz] (mm)");
  std::array<double, 6> l{};
  for (size_t k = 0; k < 6; ++k)
    l[k] = in_range(r, n[k], fmt::format("{}[{}]", key, k), -max_coordinate_mm, max_coordinate_mm, "mm");
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
  if (p["length"]) job.length_mm = in_range(r, p["length"], key + ".length", 1e-3, max_length_mm, "mm");
  return job;
}

void read_post(const Reader& r, const YAML::Node& p, PostJob& post) {
  r.only_keys(p, "post", {"dialects", "apt", "cl", "tool", "line_numbers", "tolerance", "angle_tolerance", "tool_length",
                          "safe_height", "setup"});
  if (const YAML::Node s = p["setup"]) {
    if (s.IsScalar() && s.Scalar() == "auto") {
      post.setup_auto = true;
    } else {
    if (!s.IsMap()) r.fail(s, "post.setup", "expected auto or {rotate: [a, b, c], translate: [x, y, z]}");
    r.only_keys(s, "post.setup", {"rotate", "translate"});
    const auto vec = [&](const char* key, std::array<double, 3>& v) {
      const YAML::Node n = s[key];
      if (!n) return;
      if (std::string(key) == "rotate" && n.IsScalar() && n.Scalar() == "auto") {
        post.setup_auto = true;
        return;
      }
      if (!n.IsSequence() || n.size() != 3) r.fail(n, std::string("post.setup.") + key, "expected 3 numbers");
      const double bound = std::string(key) == "rotate" ? 360 : max_coordinate_mm;
      for (size_t k = 0; k < 3; ++k)
        v[k] = in_range(r, n[k], fmt::format("post.setup.{}[{}]", key, k), -bound, bound, key == std::string("rotate") ? "deg" : "mm");
    };
    vec("rotate", post.setup_rotate_deg);
    vec("translate", post.setup_translate_mm);
    }
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
  if (p["tolerance"]) post.tolerance_mm = in_range(r, p["tolerance"], "post.tolerance", 1e-5, 10, "mm");
  if (p["angle_tolerance"]) post.angle_tolerance_deg = in_range(r, p["angle_tolerance"], "post.angle_tolerance", 1e-4, 10, "deg");
  if (p["tool_length"]) post.tool_length_mm = in_range(r, p["tool_length"], "post.tool_length", 1e-3, max_length_mm, "mm");
  if (p["safe_height"]) post.safe_height_mm = in_range(r, p["safe_height"], "post.safe_height", 0, max_length_mm, "mm");
}

// tool.end: flat | ball | {corner: R} (mm).
ToolEnd read_end(const Reader& r, const YAML::Node& e) {
  const char* expected = "expected flat, ball or {corner: R} (R in mm)";
  if (e.IsScalar()) {
    if (e.Scalar() == "flat") return {};
    if (e.Scalar() == "ball") return {EndKind::Ball, 0, 1};
    if (e.Scalar() == "corner") r.fail(e, "tool.end", "corner needs its radius: {corner: R} (mm)");
    r.fail(e, "tool.end", fmt::format("unknown end '{}': {}", e.Scalar(), expected));
  }
  if (!e.IsMap()) r.fail(e, "tool.end", expected);
  r.only_keys(e, "tool.end", {"corner"});
  const YAML::Node c = r.need(e, "corner", "tool.end.corner");
  const double R = r.positive(c, "tool.end.corner");
  if (R > max_length_mm) r.fail(c, "tool.end.corner", fmt::format("must be at most {} mm", max_length_mm));
  return {EndKind::Corner, R, 1};
}

// tool: {shape, control_points, min_diameter, max_diameter, max_length, min_tip_diameter,
// max_tip_diameter, max_cone_angle, convex, catalogue, shared, end}.
void read_tool(const Reader& r, const YAML::Node& t, Job& job) {
  r.only_keys(t, "tool", {"shape", "control_points", "min_diameter", "max_diameter", "max_length", "min_tip_diameter",
                          "max_tip_diameter", "max_cone_angle", "convex", "catalogue", "shared", "end"});
  if (t["shape"]) job.fit.shape = read_shape(r, t["shape"]);
  if (t["control_points"]) job.fit.meridian_control_points = r.integer(t["control_points"], "tool.control_points", 4, max_samples_s);
  ToolJob& tj = job.tool;
  const auto mm = [&](const char* key, double& v, double lo) {
    if (t[key]) v = in_range(r, t[key], std::string("tool.") + key, lo, max_length_mm, "mm");
  };
  mm("min_diameter", tj.min_diameter_mm, 0);
  mm("max_diameter", tj.max_diameter_mm, 1e-3);
  mm("max_length", tj.max_length_mm, 1e-3);
  mm("min_tip_diameter", tj.min_tip_diameter_mm, 0);
  mm("max_tip_diameter", tj.max_tip_diameter_mm, 1e-3);
  if (t["max_cone_angle"]) tj.max_cone_angle_deg = in_range(r, t["max_cone_angle"], "tool.max_cone_angle", 0, 90, "deg");
  if (t["convex"]) tj.convex = r.boolean(t["convex"], "tool.convex");
  if (t["shared"]) tj.shared = r.boolean(t["shared"], "tool.shared");
  if (tj.min_diameter_mm > tj.max_diameter_mm)
    r.fail(t["min_diameter"], "tool.min_diameter", fmt::format("{} mm is larger than tool.max_diameter", tj.min_diameter_mm));
  if (tj.min_tip_diameter_mm > tj.max_diameter_mm)
    r.fail(t["min_tip_diameter"], "tool.min_tip_diameter", fmt::format("{} mm is larger than tool.max_diameter", tj.min_tip_diameter_mm));
  if (tj.min_tip_diameter_mm > tj.max_tip_diameter_mm)
    r.fail(t["min_tip_diameter"], "tool.min_tip_diameter", fmt::format("{} mm is larger than tool.max_tip_diameter", tj.min_tip_diameter_mm));
  if (tj.min_diameter_mm > tj.max_tip_diameter_mm)
    r.fail(t["min_diameter"], "tool.min_diameter", fmt::format("{} mm is larger than tool.max_tip_diameter", tj.min_diameter_mm));
  if (const YAML::Node c = t["catalogue"]) {
    for (const char* k : {"shape", "control_points", "min_diameter", "max_diameter", "max_length", "min_tip_diameter",
                          "max_tip_diameter", "max_cone_angle", "convex"})
      if (t[k]) r.fail(t[k], std::string("tool.") + k, "not with tool.catalogue (a catalogue tool is fixed; only its motion is fitted)");
    const std::string name = r.text(c, "tool.catalogue");
    try {
      tj.catalogue = find_catalogue_tool(tools_dir(), name);
    } catch (const InputError& e) {
      r.fail(c, "tool.catalogue", e.what());
    }
  }
  if (const YAML::Node e = t["end"]) {
    tj.end = read_end(r, e);
    // A catalogue tool is known now: its corner radius must fit it. A fitted tool is held to fit it
    // in the fit (its tip's ball radius at least R), which max_diameter must leave room for.
    if (tj.end.kind == EndKind::Corner && !tj.catalogue && 2 * tj.end.corner_radius > tj.max_diameter_mm)
      r.fail(e["corner"], "tool.end.corner",
             fmt::format("{} mm does not fit a tool of tool.max_diameter {} mm (at most half of it)", tj.end.corner_radius,
                         tj.max_diameter_mm));
    if (tj.catalogue && tj.end.kind == EndKind::Corner) try {
        (void)end_profile(tj.catalogue->meridian_mm(), tj.end);
      } catch (const InputError& x) {
        std::string why = x.what();
        for (const std::string prefix : {"tool.end.corner: ", "tool.end: "})
          if (why.rfind(prefix, 0) == 0) why = why.substr(prefix.size());
        r.fail(e["corner"], "tool.end.corner", why);
      }
  }
}

// KEY: FILE | {file: FILE, faces: [N, ...], deflection: MM}; faces and deflection only for STEP/IGES.
struct FileKey {
  std::filesystem::path path;
  std::vector<int> faces;
  std::optional<double> deflection_mm;
};
FileKey read_file_key(const Reader& r, const YAML::Node& n, const std::string& key, const std::filesystem::path& base,
                      bool with_faces) {
  FileKey out;
  YAML::Node file = n;
  std::string file_key = key;
  if (n.IsMap()) {
    r.only_keys(n, key, with_faces ? std::set<std::string>{"file", "faces", "deflection"} : std::set<std::string>{"file", "deflection"});
    if (!n["file"]) r.fail(n, key + ".file", "missing");
    file.reset(n["file"]);  // not `file = ...`: yaml-cpp would overwrite n itself with the scalar
    file_key = key + ".file";
    if (const YAML::Node f = n["faces"]) {
      if (!f.IsSequence() || f.size() == 0) r.fail(f, key + ".faces", "expected a list of face numbers from `flankcam faces`, e.g. [132]");
      for (const YAML::Node& x : f) out.faces.push_back(r.integer(x, key + ".faces", 1, 10000000));
    }
    if (n["deflection"]) out.deflection_mm = r.positive(n["deflection"], key + ".deflection");
  }
  const std::filesystem::path p = r.text(file, file_key);
  out.path = p.is_absolute() ? p : base / p;
  if (!is_file(out.path)) r.fail(file, file_key, "file not found: " + escaped(out.path.string(), 200));
  const bool cad = is_cad_file(out.path.string());
  if (!out.faces.empty() && !cad) r.fail(n["faces"], key + ".faces", "only STEP/IGES models have faces");
  if (out.deflection_mm && !cad) r.fail(n["deflection"], key + ".deflection", "only STEP/IGES models are tessellated by flankcam");
  return out;
}

}  // namespace

Eigen::Matrix3d setup_rotation(const PostJob& post) {
  constexpr double deg = M_PI / 180;
  return (Eigen::AngleAxisd(post.setup_rotate_deg[2] * deg, Eigen::Vector3d::UnitZ()) *
          Eigen::AngleAxisd(post.setup_rotate_deg[1] * deg, Eigen::Vector3d::UnitY()) *
          Eigen::AngleAxisd(post.setup_rotate_deg[0] * deg, Eigen::Vector3d::UnitX()))
      .toRotationMatrix();
}

Job read_job(const std::filesystem::path& file) {
  const std::string name = escaped(file.string(), 200);  // as messages quote it
  if (!is_file(file)) throw InputError(name + ": job file not found");
  const Reader r(file.string());
  const YAML::Node root = r.load();
  if (!root.IsMap()) throw InputError(name + ": expected a mapping with surface:, patches:, ...");
  r.only_keys(root, "", {"surface", "part", "holder", "clearance", "check_tolerance", "feed", "spindle", "lead_in", "retract", "tool", "tolerance", "sampling", "weights", "fit", "patches", "cover", "machine", "post", "allowance", "passes", "overtravel", "depth_cuts"});

  Job job;
  job.file = file;
  if (!root["surface"]) throw InputError(name + ": surface: missing (the design surface mesh, mm)");
  const std::filesystem::path base = file.parent_path();
  const FileKey s = read_file_key(r, root["surface"], "surface", base, true);
  job.surface = s.path, job.surface_faces = s.faces, job.surface_deflection_mm = s.deflection_mm;
  job.part = job.surface;
  if (root["part"]) {
    const FileKey p = read_file_key(r, root["part"], "part", base, false);
    job.part = p.path, job.part_deflection_mm = p.deflection_mm, job.part_given = true;
  }
  if (const YAML::Node h = root["holder"]) {
    r.only_keys(h, "holder", {"shank_length", "shank_diameter", "length", "diameter", "diameter_far", "cylinder_length"});
    HolderJob& hj = job.holder;
    const auto get = [&](const char* key, double& v) {
      if (h[key]) v = in_range(r, h[key], std::string("holder.") + key, 0, max_length_mm, "mm");
    };
    get("shank_length", hj.shank_length), get("shank_diameter", hj.shank_diameter), get("length", hj.length);
    get("diameter", hj.diameter), get("diameter_far", hj.diameter_far), get("cylinder_length", hj.cylinder_length);
    if (!h["diameter_far"]) hj.diameter_far = hj.diameter;
    if (hj.shank_length > 0 && !(hj.shank_diameter > 0)) r.fail(h, "holder.shank_diameter", "must be > 0 with a shank");
    if (hj.length + hj.cylinder_length > 0 && !(hj.diameter > 0)) r.fail(h, "holder.diameter", "must be > 0 with a holder");
  }
  if (root["clearance"]) job.clearance_mm = in_range(r, root["clearance"], "clearance", 0.01, 1000, "mm");
  if (root["check_tolerance"]) {
    if (!root["part"]) r.fail(root["check_tolerance"], "check_tolerance", "needs part: (the part the fit keeps the tool out of)");
    job.check_tolerance_mm = in_range(r, root["check_tolerance"], "check_tolerance", 1e-4, 10, "mm");
  }
  if (root["feed"]) job.feed_mm_min = in_range(r, root["feed"], "feed", 0.01, 1e5, "mm/min");
  if (root["spindle"]) job.spindle_rpm = in_range(r, root["spindle"], "spindle", 1, 2e5, "rpm");
  if (root["lead_in"]) job.lead_in_mm = in_range(r, root["lead_in"], "lead_in", 0, max_length_mm, "mm");
  if (root["retract"]) job.retract_mm = in_range(r, root["retract"], "retract", 1e-3, max_length_mm, "mm");
  if (job.retract_mm < job.lead_in_mm) r.fail(root["retract"] ? root["retract"] : root, "retract", "must be >= lead_in");
  if (const YAML::Node t = root["tool"]) read_tool(r, t, job);
  if (root["allowance"]) job.allowance_mm = in_range(r, root["allowance"], "allowance", 0, 100, "mm");
  if (const YAML::Node ps = root["passes"]) {
    if (root["allowance"]) r.fail(root["allowance"], "allowance", "not with passes: (give each pass its allowance)");
    if (!ps.IsSequence() || ps.size() == 0 || ps.size() > 20)
      r.fail(ps, "passes", "expected a list of 1 to 20 passes such as [{allowance: 0.3}, {allowance: 0}]");
    for (size_t k = 0; k < ps.size(); ++k) {
      const std::string key = fmt::format("passes[{}]", k);
      r.only_keys(ps[k], key, {"allowance"});
      job.passes_mm.push_back(in_range(r, r.need(ps[k], "allowance", key + ".allowance"), key + ".allowance", 0, 100, "mm"));
    }
  }
  if (root["overtravel"]) job.overtravel_mm = in_range(r, root["overtravel"], "overtravel", 0, 1000, "mm");
  if (root["depth_cuts"]) job.depth_cuts = r.integer(root["depth_cuts"], "depth_cuts", 1, 50);
  if (root["tolerance"]) job.tolerance_mm = in_range(r, root["tolerance"], "tolerance", 1e-5, 100, "mm");
  if (const YAML::Node s = root["sampling"]) {
    r.only_keys(s, "sampling", {"s", "t"});
    if (s["s"]) job.fit.samples_s = r.integer(s["s"], "sampling.s", 4, max_samples_s);
    if (s["t"]) job.fit.samples_t = r.integer(s["t"], "sampling.t", 8, max_samples_t);
    if (job.fit.samples_s * job.fit.samples_t > max_samples)
      r.fail(s, "sampling", fmt::format("s x t = {} samples, at most {} (the fit's time grows with it; the paper uses 30 x 100)",
                                        job.fit.samples_s * job.fit.samples_t, max_samples));
  }
  if (const YAML::Node w = root["weights"]) {
    r.only_keys(w, "weights", {"plane", "fair", "point", "rigid", "anchor"});
    if (w["plane"]) job.fit.w_plane = in_range(r, w["plane"], "weights.plane", 0, 1e6, "");
    if (w["fair"]) job.fit.w_fair = in_range(r, w["fair"], "weights.fair", 0, 1e6, "");
    if (w["point"]) job.fit.w_point = in_range(r, w["point"], "weights.point", 0, 1e6, "");
    if (w["rigid"]) job.fit.w_rigid = in_range(r, w["rigid"], "weights.rigid", 0, 1e6, "");
    if (w["anchor"]) job.fit.w_anchor = in_range(r, w["anchor"], "weights.anchor", 0, 1e6, "");
  }
  if (const YAML::Node f = root["fit"]) {
    r.only_keys(f, "fit", {"iterations", "rail_control_points", "robust"});
    if (f["iterations"]) job.fit.max_iterations = r.integer(f["iterations"], "fit.iterations", 1, 1000);
    if (f["rail_control_points"])
      job.fit.rail_control_points = r.integer(f["rail_control_points"], "fit.rail_control_points", 4, 1000);
    if (f["robust"]) job.robust_mm = in_range(r, f["robust"], "fit.robust", 0, max_length_mm, "mm");
  }
  // Limits that tie two keys together, reported at the key the user would change.
  if (const YAML::Node w = root["weights"]; w && !(job.fit.w_plane > 0 || job.fit.w_point > 0))
    r.fail(w, "weights", "plane or point must be > 0 (otherwise nothing pulls the tool to the surface)");
  const YAML::Node sampling = root["sampling"];
  if (root["tool"] && root["tool"]["control_points"] && job.fit.meridian_control_points > job.fit.samples_s)
    r.fail(root["tool"]["control_points"], "tool.control_points",
           fmt::format("{} is more than sampling.s = {} (one sample per control point at least)",
                       job.fit.meridian_control_points, job.fit.samples_s));
  if (job.fit.meridian_control_points > job.fit.samples_s)
    r.fail(sampling ? sampling : root, "sampling.s",
           fmt::format("{} is less than tool.control_points = {}", job.fit.samples_s, job.fit.meridian_control_points));
  if (2 * job.fit.rail_control_points > job.fit.samples_t) {
    if (root["fit"] && root["fit"]["rail_control_points"])
      r.fail(root["fit"]["rail_control_points"], "fit.rail_control_points",
             fmt::format("{} is more than half of sampling.t = {}", job.fit.rail_control_points, job.fit.samples_t));
    r.fail(sampling ? sampling : root, "sampling.t",
           fmt::format("{} is less than twice fit.rail_control_points = {} (default 16)", job.fit.samples_t,
                       job.fit.rail_control_points));
  }
  if (auto err = job.fit.validate(); !err.empty()) throw InputError(name + ": " + err);
  if (root["machine"]) job.machine = r.text(root["machine"], "machine");
  if (const YAML::Node p = root["post"]) read_post(r, p, job.post);

  const YAML::Node ps = root["patches"];
  if (!ps) throw InputError(name + ": patches: missing (a list of patches with their initialisation, or auto)");
  if (ps.IsScalar() && ps.Scalar() == "auto") {
    // Detection fits its own motions and tools patch by patch; with `shared: true` one custom tool
    // for all of them (the first patch's held for the others, then refitted jointly); with a
    // catalogue tool the motions alone, that tool held. Detection fits Φ itself: an allowance is for
    // listed patches (detected-job.yaml takes both), passes leave stock before a last pass on Φ.
    if (root["allowance"])
      r.fail(root["allowance"], "allowance",
             "not with patches: auto (list the patches, e.g. from detected-job.yaml; or passes: [{allowance: 0.3}, {allowance: 0}])");
    if (!job.passes_mm.empty() && job.passes_mm.back() > 0)
      r.fail(root["passes"], "passes",
             "with patches: auto the last pass must have allowance 0 (detection fits the design surface itself; list the "
             "patches, e.g. from detected-job.yaml, to finish with stock left)");
    CoverJob& c = job.cover.emplace();
    if (const YAML::Node cv = root["cover"]) {
      if (!cv.IsMap()) r.fail(cv, "cover", "expected {coverage: 0.95, max_patches: 8, exchanges: 3, regions: 2}");
      r.only_keys(cv, "cover", {"coverage", "max_patches", "exchanges", "regions", "floor_tip_diameter"});
      if (cv["coverage"]) {
        c.coverage = r.number(cv["coverage"], "cover.coverage");
        if (!(c.coverage > 0 && c.coverage <= 1))
          r.fail(cv["coverage"], "cover.coverage", fmt::format("must be in (0, 1], got {}", cv["coverage"].Scalar()));
      }
      if (cv["max_patches"]) c.max_patches = r.integer(cv["max_patches"], "cover.max_patches", 1, 32);
      if (cv["exchanges"]) c.exchanges = r.integer(cv["exchanges"], "cover.exchanges", 0, 16);
      if (cv["regions"]) c.regions = r.integer(cv["regions"], "cover.regions", 0, 8);
      if (const YAML::Node f = cv["floor_tip_diameter"]) {
        c.floor_tip_diameter_mm = in_range(r, f, "cover.floor_tip_diameter", 1e-3, max_length_mm, "mm");
        if (!job.part_given) r.fail(f, "cover.floor_tip_diameter", "needs part: (the floor the tips stand on)");
        if (c.floor_tip_diameter_mm >= std::min(job.tool.max_tip_diameter_mm, job.tool.max_diameter_mm))
          r.fail(f, "cover.floor_tip_diameter", fmt::format("{} mm is not narrower than the tool's tip may be (tool.max_diameter, tool.max_tip_diameter)", c.floor_tip_diameter_mm));
        if (c.floor_tip_diameter_mm < std::max(job.tool.min_tip_diameter_mm, job.tool.min_diameter_mm))
          r.fail(f, "cover.floor_tip_diameter", fmt::format("{} mm is narrower than tool.min_diameter or tool.min_tip_diameter", c.floor_tip_diameter_mm));
        if (job.tool.end.kind != EndKind::Flat)
          r.fail(f, "cover.floor_tip_diameter", "only with a flat end (tool.end)");
      }
    }
    return job;
  }
  if (root["cover"]) r.fail(root["cover"], "cover", "only with patches: auto");
  if (!ps.IsSequence() || ps.size() == 0) r.fail(ps, "patches", "expected a list of at least one patch, or auto");
  std::set<std::string> names;
  for (size_t k = 0; k < ps.size(); ++k) job.patches.push_back(read_patch(r, ps[k], fmt::format("patches[{}]", k), names));
  return job;
}

CutJudgement cut_judgement(const Job& job, double twin_sag_mm) {
  return {job.check_tolerance_mm.value_or(job.tolerance_mm), job.tolerance_mm, twin_sag_mm + job.tolerance_mm};
}

}  // namespace flankcam::pipeline
