// Typed reading of YAML files (job and machine files) where every failure names the file, the
// line and the key path: "job.yaml:12: patches[0].line: expected 6 numbers". Header-only; users
// link yaml-cpp. `Error` is the exception thrown (InputError, MachineError).
#pragma once
#include <fmt/format.h>
#include <yaml-cpp/depthguard.h>
#include <yaml-cpp/yaml.h>

#include <Eigen/Core>
#include <cmath>
#include <cstddef>
#include <map>
#include <set>
#include <string>
#include <utility>

#include "core/message_text.h"

namespace flankcam {

template <class Error>
class YamlFields {
 public:
  // Messages quote the file's name escaped and cut (a fuzzed or pasted name stays one short line).
  explicit YamlFields(std::string file) : file_(std::move(file)), shown_(escaped(file_, 200)) {}

  // Parses the file; syntax errors name their line. Rejects what yaml-cpp accepts but a reader
  // would misread: duplicate keys (yaml-cpp keeps the first), keys that are lists or mappings.
  [[nodiscard]] YAML::Node load() const {
    YAML::Node root;
    try {
      root = YAML::LoadFile(file_);
    } catch (const YAML::DeepRecursion& e) {
      throw Error(fmt::format("{}:{}: nested too deeply (more than {} levels of lists and mappings)", shown_,
                              e.mark.line + 1, e.depth() - 1));
    } catch (const YAML::BadFile&) {
      throw Error(shown_ + ": cannot open the file");
    } catch (const YAML::ParserException& e) {
      throw Error(fmt::format("{}:{}: not valid YAML: {}", shown_, e.mark.line + 1, escaped(e.msg)));
    } catch (const YAML::Exception& e) {
      throw Error(shown_ + ": cannot read: " + escaped(e.what()));
    }
    std::set<std::size_t> seen;
    check_keys(root, "", seen);
    return root;
  }

  [[noreturn]] void fail(const YAML::Node& node, const std::string& key, const std::string& what) const {
    const YAML::Mark m = node.Mark();
    if (m.is_null()) throw Error(fmt::format("{}: {}: {}", shown_, key, what));
    throw Error(fmt::format("{}:{}: {}: {}", shown_, m.line + 1, key, what));
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
      const std::string k = key_name(kv.first, key);
      if (allowed.count(k)) continue;
      std::string known;
      for (const auto& a : allowed) known += (known.empty() ? "" : ", ") + a;
      fail(kv.first, escaped(key.empty() ? k : key + "." + k), "unknown key (known: " + known + ")");
    }
  }

  double number(const YAML::Node& n, const std::string& key) const {
    if (!n.IsScalar()) fail(n, key, "expected a number");
    double v = 0;
    try {
      v = n.as<double>();
    } catch (const YAML::Exception&) {
      fail(n, key, "expected a number, got " + in_quotes(n.Scalar()));
    }
    if (!std::isfinite(v)) fail(n, key, "must be finite, got " + in_quotes(n.Scalar()));
    return v;
  }
  // A number in [lo, hi] (a sane range; `unit` names the unit in the message).
  double number_in(const YAML::Node& n, const std::string& key, double lo, double hi, const std::string& unit) const {
    const double v = number(n, key);
    if (!(v >= lo && v <= hi)) fail(n, key, fmt::format("must be in {:g}..{:g} {}, got {}", lo, hi, unit, in_quotes(n.Scalar())));
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
  std::string key_name(const YAML::Node& k, const std::string& parent) const {
    if (!k.IsScalar()) fail(k, parent.empty() ? "top level" : parent, "a key must be a plain name, not a list or mapping");
    return k.Scalar();
  }
  // Every mapping in the document: scalar keys, each once. `seen` holds the positions of the
  // collections visited: an alias shares its anchor's node (and position), which may contain it.
  void check_keys(const YAML::Node& n, const std::string& path, std::set<std::size_t>& seen) const {
    if (!n.IsMap() && !n.IsSequence()) return;
    if (!seen.insert(n.Mark().pos).second) return;
    if (n.IsSequence()) {
      std::size_t i = 0;
      for (const auto& item : n) check_keys(item, fmt::format("{}[{}]", path, i++), seen);
      return;
    }
    std::map<std::string, int> lines;
    for (const auto& kv : n) {
      const std::string k = key_name(kv.first, path);
      const std::string key = path.empty() ? k : path + "." + k;
      const int line = kv.first.Mark().line + 1;
      if (const auto [it, fresh] = lines.emplace(k, line); !fresh)
        fail(kv.first, escaped(key), fmt::format("duplicate key (first at line {}, again at line {})", it->second, line));
      check_keys(kv.second, key, seen);
    }
  }

  std::string file_, shown_;
};

}  // namespace flankcam
