#include "kinematics/machine.h"

#include <fmt/format.h>
#include <yaml-cpp/yaml.h>

#include <Eigen/Geometry>
#include <cmath>
#include <filesystem>
#include <set>
#include <tuple>

#include "core/errors.h"
#include "core/file_probe.h"
#include "core/yaml_fields.h"

namespace flankcam {

std::string Machine::kind() const {
  const int t = tables();
  return t == 2 ? "table-table" : t == 1 ? "head-table" : "head-head";
}

int Machine::tables() const {
  return int(rotary[0].carries == Carrier::Table) + int(rotary[1].carries == Carrier::Table);
}

namespace {
using Fields = YamlFields<MachineError>;

Eigen::Vector3d direction(const Fields& f, const YAML::Node& n, const std::string& key) {
  const Eigen::Vector3d d = f.vec3(n, key);
  if (!(d.norm() > 1e-9)) f.fail(n, key, "zero direction");
  return d.normalized();
}
}  // namespace

void validate(const Machine& m) {
  const auto fail = [&](const std::string& what) { throw MachineError(m.file + ": " + what); };
  using R = MachineRanges;
  const auto within = [](double v, double lo, double hi) { return v >= lo && v <= hi; };
  for (const auto& l : m.linear) {
    if (!(l.min_mm < l.max_mm)) fail("linear." + l.name + ".limits: min must be below max");
    if (!within(l.max_speed_mm_min, R::linear_speed_mm_min[0], R::linear_speed_mm_min[1]))
      fail(fmt::format("linear.{}.speed: must be in {:g}..{:g} mm/min", l.name, R::linear_speed_mm_min[0],
                       R::linear_speed_mm_min[1]));
  }
  std::set<std::string> names;
  for (const auto& r : m.rotary) {
    if (r.name != "A" && r.name != "B" && r.name != "C") fail("rotary." + r.name + ".name: must be A, B or C");
    if (!names.insert(r.name).second) fail("rotary." + r.name + ": two rotary axes with the same name");
    if (!(std::abs(r.direction.norm() - 1) < 1e-9)) fail("rotary." + r.name + ".direction: zero direction");
    if (!r.continuous && !(r.min_deg < r.max_deg)) fail("rotary." + r.name + ".limits: min must be below max");
    if (!within(r.max_speed_deg_min, R::rotary_speed_deg_min[0], R::rotary_speed_deg_min[1]))
      fail(fmt::format("rotary.{}.speed: must be in {:g}..{:g} deg/min", r.name, R::rotary_speed_deg_min[0],
                       R::rotary_speed_deg_min[1]));
    if (!r.pivot.allFinite() || r.pivot.cwiseAbs().maxCoeff() > R::position_mm)
      fail(fmt::format("rotary.{}.pivot: coordinates must be within +-{:g} mm", r.name, R::position_mm));
  }
  if (m.rotary[0].direction.cross(m.rotary[1].direction).norm() < 1e-6)
    fail("rotary: the two rotary axes are parallel (no 5-axis orientation range)");
  if (!(std::abs(m.spindle_direction.norm() - 1) < 1e-9)) fail("spindle.direction: zero direction");
  if (!within(m.gauge_length_mm, 0, R::gauge_length_mm))
    fail(fmt::format("gauge_length: must be in 0..{:g} mm", R::gauge_length_mm));
  if (m.controller.dialect.empty()) fail("controller.dialect: empty");
}

Machine load_machine(const std::string& path) {
  if (!is_file(path)) throw MachineError(path + ": machine file not found");
  const Fields f(path);
  const YAML::Node root = f.load();
  if (!root.IsMap()) throw MachineError(path + ": expected a mapping (name:, linear:, rotary:, ...)");
  f.only_keys(root, "", {"name", "description", "linear", "rotary", "spindle", "gauge_length", "controller",
                          "tool_change"});
  using R = MachineRanges;
  Machine m;
  m.file = path;
  m.name = f.text(f.need(root, "name", "name"), "name");
  if (root["description"]) m.description = f.text(root["description"], "description");

  const YAML::Node lin = f.need(root, "linear", "linear");
  f.only_keys(lin, "linear", {"X", "Y", "Z"});
  const char* lnames[3] = {"X", "Y", "Z"};
  for (int k = 0; k < 3; ++k) {
    const std::string key = std::string("linear.") + lnames[k];
    const YAML::Node a = f.need(lin, lnames[k], key);
    f.only_keys(a, key, {"limits", "speed"});
    LinearAxis& l = m.linear[size_t(k)];
    l.name = lnames[k];
    const YAML::Node lim = f.need(a, "limits", key + ".limits");
    std::tie(l.min_mm, l.max_mm) = f.range(lim, key + ".limits", "mm");
    f.number_in(lim[0], key + ".limits[0]", -R::position_mm, R::position_mm, "mm");
    f.number_in(lim[1], key + ".limits[1]", -R::position_mm, R::position_mm, "mm");
    l.max_speed_mm_min = f.number_in(f.need(a, "speed", key + ".speed"), key + ".speed", R::linear_speed_mm_min[0],
                                     R::linear_speed_mm_min[1], "mm/min");
  }

  const YAML::Node rot = f.need(root, "rotary", "rotary");
  if (!rot.IsSequence() || rot.size() != 2) f.fail(rot, "rotary", "expected a list of exactly two rotary axes");
  for (size_t k = 0; k < 2; ++k) {
    const YAML::Node a = rot[k];
    std::string key = fmt::format("rotary[{}]", k);
    f.only_keys(a, key, {"name", "carries", "direction", "pivot", "limits", "speed"});
    RotaryAxis& r = m.rotary[k];
    r.name = f.text(f.need(a, "name", key + ".name"), key + ".name");
    if (r.name != "A" && r.name != "B" && r.name != "C") f.fail(a["name"], key + ".name", "must be A, B or C");
    key = "rotary." + r.name;
    const std::string carries = f.text(f.need(a, "carries", key + ".carries"), key + ".carries");
    if (carries == "table")
      r.carries = Carrier::Table;
    else if (carries == "head")
      r.carries = Carrier::Head;
    else
      f.fail(a["carries"], key + ".carries", "must be table or head");
    r.direction = direction(f, f.need(a, "direction", key + ".direction"), key + ".direction");
    if (const YAML::Node pv = a["pivot"]) {
      r.pivot = f.vec3(pv, key + ".pivot");
      for (int i = 0; i < 3; ++i)
        f.number_in(pv[i], fmt::format("{}.pivot[{}]", key, i), -R::position_mm, R::position_mm, "mm");
    }
    const YAML::Node lim = f.need(a, "limits", key + ".limits");
    if (lim.IsScalar() && lim.Scalar() == "continuous") {
      r.continuous = true;
    } else {
      std::tie(r.min_deg, r.max_deg) = f.range(lim, key + ".limits", "degrees, or continuous");
      f.number_in(lim[0], key + ".limits[0]", -R::rotary_deg, R::rotary_deg, "deg");
      f.number_in(lim[1], key + ".limits[1]", -R::rotary_deg, R::rotary_deg, "deg");
    }
    r.max_speed_deg_min = f.number_in(f.need(a, "speed", key + ".speed"), key + ".speed", R::rotary_speed_deg_min[0],
                                      R::rotary_speed_deg_min[1], "deg/min");
  }
  if (m.rotary[0].name == m.rotary[1].name) f.fail(rot[1]["name"], "rotary[1].name", "both rotary axes are " + m.rotary[0].name);
  if (m.rotary[0].carries == Carrier::Head && m.rotary[1].carries == Carrier::Table) std::swap(m.rotary[0], m.rotary[1]);

  const YAML::Node sp = f.need(root, "spindle", "spindle");
  f.only_keys(sp, "spindle", {"direction"});
  m.spindle_direction = direction(f, f.need(sp, "direction", "spindle.direction"), "spindle.direction");
  if (root["gauge_length"]) {
    m.gauge_length_mm = f.number_in(root["gauge_length"], "gauge_length", 0, R::gauge_length_mm, "mm");
  }
  if (const YAML::Node c = root["controller"]) {
    f.only_keys(c, "controller", {"tcp", "dialect", "inverse_time", "linuxcnc_trt"});
    if (c["tcp"]) m.controller.tcp = f.boolean(c["tcp"], "controller.tcp");
    if (const YAML::Node d = c["dialect"]) {
      m.controller.dialect = f.text(d, "controller.dialect");
      m.controller.dialect_line = d.Mark().line + 1;
      if (m.controller.dialect.empty()) f.fail(d, "controller.dialect", "empty");
    }
    if (c["inverse_time"]) m.controller.inverse_time = f.boolean(c["inverse_time"], "controller.inverse_time");
    if (c["linuxcnc_trt"]) m.controller.linuxcnc_trt = f.boolean(c["linuxcnc_trt"], "controller.linuxcnc_trt");
  }
  if (const YAML::Node tc = root["tool_change"]) {
    // Joint values by axis name; rotaries after the rotary axes are known (and ordered).
    f.only_keys(tc, "tool_change", {"X", "Y", "Z", m.rotary[0].name, m.rotary[1].name});
    m.tool_change.line = tc.Mark().line + 1;
    const char* lnames[3] = {"X", "Y", "Z"};
    for (size_t k = 0; k < 5; ++k) {
      const std::string name = k < 3 ? lnames[k] : m.rotary[k - 3].name;
      if (const YAML::Node v = tc[name]) {
        const bool lin = k < 3;
        const double lo = lin ? m.linear[k].min_mm : m.rotary[k - 3].continuous ? -R::rotary_deg : m.rotary[k - 3].min_deg;
        const double hi = lin ? m.linear[k].max_mm : m.rotary[k - 3].continuous ? R::rotary_deg : m.rotary[k - 3].max_deg;
        m.tool_change.joints[k] = f.number_in(v, "tool_change." + name, lo, hi, lin ? "mm" : "deg");
      }
    }
  }
  validate(m);
  return m;
}

}  // namespace flankcam
