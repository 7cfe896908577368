// Typed reading of YAML files (job and machine files) where every failure names the file, the
// line and the key path: "job.yaml:12: patches[0].line: expected 6 numbers". Header-only; users
// link yaml-cpp. `Error` is the exception thrown (InputError, MachineError).
#pragma once
#include <fmt/format.h>
#include <yaml-cpp/yaml.h>

#include <Eigen/Core>
#include <cmath>
#include <set>
#include <string>
#include <utility>

namespace flankcam {

template <class Error>
class YamlFields {
 public:
  explicit YamlFields(std::string file) : file_(std::move(file)) {}

  // Parses the file; syntax errors name their line.
  [[nodiscard]] YAML::Node load() const {
    try {
      return YAML::LoadFile(file_);
    } catch (const YAML::ParserException& e) {
      throw Error(fmt::format("{}:{}: not valid YAML: {}", file_, e.mark.line + 1, e.msg));
    } catch (const YAML::Exception& e) {
      throw Error(file_ + ": cannot read: " + e.what());
    }
  }

  [[noreturn]] void fail(const YAML::Node& node, const std::string& key, const std::string& what) const {
    const YAML::Mark m = node.Mark();
    if (m.is_null()) throw Error(fmt::format("{}: {}: {}", file_, key, what));
    throw Error(fmt::format("{}:{}: {}: {}", file_, m.line + 1, key, what));
  }

  YAML::Node need(const YAML::Node& parent, const std::string& child, const std::string& key) const {
    const YAML::Node n = parent[child];
    if (!n) fail(parent, key, "missing");
    return n;
  }

  // Rejects keys outside `allowed` (and non-mappings), listing the known ones.
  void only_keys(const YAML::Node& map, const std::string& key, const std::set<std::string>& allowed) const {
    if (!map.IsMap()) fail(map, key.empty() ? "top level" : key, "expected a mapping of keys");
    for (const auto& kv : map) {
      const std::string k = kv.first.as<std::string>();
      if (allowed.count(k)) continue;
      std::string known;
      for (const auto& a : allowed) known += (known.empty() ? "" : ", ") + a;
      fail(kv.first, key.empty() ? k : key + "." + k, "unknown key (known: " + known + ")");
    }
  }

  double number(const YAML::Node& n, const std::string& key) const {
    if (!n.IsScalar()) fail(n, key, "expected a number");
    double v = 0;
    try {
      v = n.as<double>();
    } catch (const YAML::Exception&) {
      fail(n, key, "expected a number, got '" + n.Scalar() + "'");
    }
    if (!std::isfinite(v)) fail(n, key, "must be finite, got '" + n.Scalar() + "'");
    return v;
  }
  double positive(const YAML::Node& n, const std::string& key) const {
    const double v = number(n, key);
    if (!(v > 0)) fail(n, key, "must be > 0");
    return v;
  }
  double non_negative(const YAML::Node& n, const std::string& key) const {
    const double v = number(n, key);
    if (!(v >= 0)) fail(n, key, "must be >= 0");
    return v;
  }
  int integer(const YAML::Node& n, const std::string& key, int lo, int hi) const {
    const double v = number(n, key);
    if (v != std::floor(v) || v < lo || v > hi) fail(n, key, fmt::format("expected a whole number in {}..{}", lo, hi));
    return int(v);
  }
  bool boolean(const YAML::Node& n, const std::string& key) const {
    try {
      return n.as<bool>();
    } catch (const YAML::Exception&) {
      fail(n, key, "expected true or false");
    }
  }
  std::string text(const YAML::Node& n, const std::string& key) const {
    if (!n.IsScalar()) fail(n, key, "expected a string");
    return n.Scalar();
  }
  Eigen::Vector3d vec3(const YAML::Node& n, const std::string& key) const {
    if (!n.IsSequence() || n.size() != 3) fail(n, key, "expected 3 numbers [x, y, z]");
    return {number(n[0], key + "[0]"), number(n[1], key + "[1]"), number(n[2], key + "[2]")};
  }
  // [min, max] with min < max; `unit` names the unit in the message.
  std::pair<double, double> range(const YAML::Node& n, const std::string& key, const std::string& unit) const {
    if (!n.IsSequence() || n.size() != 2) fail(n, key, "expected [min, max] in " + unit);
    const double lo = number(n[0], key + "[0]"), hi = number(n[1], key + "[1]");
    if (!(lo < hi)) fail(n, key, "min must be below max");
    return {lo, hi};
  }

 private:
  std::string file_;
};

}  // namespace flankcam
