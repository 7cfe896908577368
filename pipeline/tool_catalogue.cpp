#include "pipeline/tool_catalogue.h"

#include <fmt/format.h>
#include <yaml-cpp/yaml.h>

#include <algorithm>
#include <cmath>
#include <map>
#include <regex>
#include <set>

#include "core/errors.h"
#include "core/yaml_fields.h"

namespace flankcam::pipeline {

namespace {
using Reader = YamlFields<InputError>;
constexpr double max_tool_mm = 1000;  // a 1 m tool is a typo or a unit mistake
}  // namespace

std::vector<Eigen::Vector2d> CatalogueTool::meridian_mm(int points) const {
  std::vector<Eigen::Vector2d> zr;
  for (int k = 0; k < points; ++k) {
    const double z = length_mm * k / (points - 1);
    double r = diameter_mm / 2;
    if (family == "taper") r = tip_diameter_mm / 2 + z * std::tan(half_angle_deg * M_PI / 180);
    if (family == "barrel" || family == "lens" || family == "oval") {
      const double R = profile_radius_mm, dz = z - widest_at_mm;
      r = diameter_mm / 2 - (R - std::sqrt(R * R - dz * dz));
    }
    zr.emplace_back(z, r);
  }
  return zr;
}

std::vector<CatalogueTool> read_tool_file(const std::filesystem::path& file) {
  const Reader r(file.string());
  const YAML::Node root = r.load();
  r.only_keys(root, "", {"family", "tools"});
  const std::string family = r.text(r.need(root, "family", "family"), "family");
  static const std::map<std::string, std::vector<std::string>> keys = {
      {"cylinder", {"diameter", "length"}},
      {"taper", {"tip_diameter", "half_angle", "length"}},
      {"barrel", {"diameter", "profile_radius", "length"}},
      {"lens", {"diameter", "profile_radius", "length"}},
      {"oval", {"diameter", "profile_radius", "widest_at", "length"}}};
  const auto fam = keys.find(family);
  if (fam == keys.end()) r.fail(root["family"], "family", "unknown family '" + family + "' (cylinder, taper, barrel, lens, oval)");
  const YAML::Node list = r.need(root, "tools", "tools");
  if (!list.IsSequence() || list.size() == 0) r.fail(list, "tools", "expected a list of tools");
  std::vector<CatalogueTool> out;
  static const std::regex safe("[A-Za-z0-9_.-]+");
  for (size_t i = 0; i < list.size(); ++i) {
    const YAML::Node t = list[i];
    const std::string key = fmt::format("tools[{}]", i);
    std::set<std::string> allowed(fam->second.begin(), fam->second.end());
    allowed.insert("name");
    r.only_keys(t, key, allowed);
    CatalogueTool tool;
    tool.family = family;
    tool.file = file;
    tool.line = t.Mark().line + 1;
    tool.name = r.text(r.need(t, "name", key + ".name"), key + ".name");
    if (!std::regex_match(tool.name, safe)) r.fail(t["name"], key + ".name", "use letters, digits, '_', '-' and '.' only");
    for (const std::string& k : fam->second) {
      const YAML::Node n = r.need(t, k, key + "." + k);
      const std::string kk = key + "." + k;
      if (k == "half_angle") tool.half_angle_deg = r.number_in(n, kk, 0, 45, "deg");
      else if (k == "widest_at") tool.widest_at_mm = r.number_in(n, kk, 0, max_tool_mm, "mm");
      else {
        const double v = r.number_in(n, kk, 0, max_tool_mm, "mm");
        if (!(v > 0)) r.fail(n, kk, "must be > 0");
        if (k == "diameter") tool.diameter_mm = v;
        if (k == "tip_diameter") tool.tip_diameter_mm = v;
        if (k == "profile_radius") tool.profile_radius_mm = v;
        if (k == "length") tool.length_mm = v;
      }
    }
    if (family == "barrel") tool.widest_at_mm = tool.length_mm / 2;
    if (family == "lens") tool.widest_at_mm = tool.length_mm;
    if (family == "barrel" || family == "lens" || family == "oval") {
      const double reach = std::max(tool.widest_at_mm, tool.length_mm - tool.widest_at_mm);
      if (t["widest_at"] && tool.widest_at_mm > tool.length_mm) r.fail(t["widest_at"], key + ".widest_at", "beyond the cutting length");
      if (!(reach < tool.profile_radius_mm))
        r.fail(t["profile_radius"], key + ".profile_radius",
               fmt::format("{} mm is too small for the arc to span the cutting length ({} mm from the widest point)",
                           tool.profile_radius_mm, reach));
    }
    const std::vector<Eigen::Vector2d> zr = tool.meridian_mm();
    const double rmin = std::min_element(zr.begin(), zr.end(), [](auto& a, auto& b) { return a.y() < b.y(); })->y();
    if (!(rmin > 0)) r.fail(t, key, fmt::format("the flank reaches the axis (smallest radius {:.3f} mm)", rmin));
    out.push_back(std::move(tool));
  }
  return out;
}

std::vector<CatalogueTool> read_catalogue(const std::filesystem::path& dir) {
  std::vector<std::filesystem::path> files;
  std::error_code ec;
  for (const auto& e : std::filesystem::directory_iterator(dir, ec))
    if (e.is_regular_file() && e.path().extension() == ".yaml") files.push_back(e.path());
  if (ec) throw InputError(dir.string() + ": cannot read the tool catalogue folder");
  std::sort(files.begin(), files.end());
  std::vector<CatalogueTool> all;
  std::map<std::string, std::string> seen;
  for (const auto& f : files)
    for (CatalogueTool& t : read_tool_file(f)) {
      const std::string at = fmt::format("{}:{}", t.file.string(), t.line);
      if (const auto [it, fresh] = seen.emplace(t.name, at); !fresh)
        throw InputError(fmt::format("{}: name: tool '{}' is also defined at {}", at, t.name, it->second));
      all.push_back(std::move(t));
    }
  return all;
}

CatalogueTool find_catalogue_tool(const std::filesystem::path& dir, const std::string& name) {
  const std::vector<CatalogueTool> all = read_catalogue(dir);
  std::string known;
  for (const CatalogueTool& t : all) {
    if (t.name == name) return t;
    known += (known.empty() ? "" : ", ") + t.name;
  }
  throw InputError(fmt::format("no tool '{}' in the catalogue {} (known: {})", name, dir.string(), known));
}

}  // namespace flankcam::pipeline
