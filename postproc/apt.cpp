#include "postproc/apt.h"

#include <fmt/format.h>

#include <algorithm>
#include <cctype>
#include <cmath>
#include <filesystem>
#include <fstream>
#include <sstream>

#include "core/atomic_file.h"
#include "core/errors.h"
#include "core/message_text.h"
#include "core/number_format.h"

namespace flankcam {

AptCutter enveloping_cutter(const std::vector<Eigen::Vector2d>& all, int end_points, double end_radius) {
  if (all.size() < 2) throw InputError("tool profile: at least two points");
  if (end_points < 0 || size_t(end_points) + 2 > all.size()) throw InputError("tool profile: the end leaves no side");
  const std::vector<Eigen::Vector2d> p(all.begin() + end_points, all.end());  // the side
  const double z0 = p.front().x(), z1 = p.back().x();
  const double slope = (p.back().y() - p.front().y()) / (z1 - z0);
  double lift = 0;  // how far the profile bulges above the end-to-end cone
  for (const auto& q : p) lift = std::max(lift, q.y() - (p.front().y() + slope * (q.x() - z0)));
  AptCutter c;
  const double r_tip = p.front().y() + lift - slope * z0;  // the cone's radius at z = 0
  c.d = 2 * r_tip;
  c.beta_deg = std::atan(slope) * 180 / M_PI + 0.0;
  c.h = z1;
  if (end_points > 0) {  // the corner circle: tangent to the tip plane at all.front()'s height
    c.r = end_radius;
    c.e = all.front().y();
    c.f = all.front().x() + end_radius;
  }
  return c;
}

ClProgram flank_program(const std::string& partno, const std::vector<ToolPose>& poses, const std::vector<Eigen::Vector2d>& profile,
                        double feed, double spindle, double lead, double clearance) {
  if (poses.empty()) throw InputError("program " + partno + ": no poses");
  if (!(feed > 0)) throw InputError("feed: must be > 0 mm/min");
  if (!(lead >= 0) || !(clearance >= lead)) throw InputError("lead/clearance: need 0 <= lead <= clearance (mm)");
  ClProgram p;
  p.partno = partno;
  p.profile = profile;
  p.cutter = enveloping_cutter(profile);
  p.spindle_rpm = spindle;
  const ToolPose &first = poses.front(), &last = poses.back();
  p.moves.push_back({{first.tip + clearance * first.axis, first.axis}, true, 0});
  if (lead < clearance) p.moves.push_back({{first.tip + lead * first.axis, first.axis}, true, 0});
  for (const ToolPose& q : poses) p.moves.push_back({q, false, feed});
  p.moves.push_back({{last.tip + lead * last.axis, last.axis}, false, feed});
  if (lead < clearance) p.moves.push_back({{last.tip + clearance * last.axis, last.axis}, true, 0});
  return p;
}

namespace {
// One APT statement, wrapped with `$` so that no line passes column 72.
void statement(std::string& out, const std::string& major, const std::vector<std::string>& args) {
  std::string line = major + (args.empty() ? "" : "/");
  for (size_t k = 0; k < args.size(); ++k) {
    const std::string piece = args[k] + (k + 1 < args.size() ? "," : "");
    if (line.size() + piece.size() > 71) {
      out += line + "$\n";
      line = "  ";
    }
    line += piece;
  }
  out += line + "\n";
}
}  // namespace

std::string apt_text(const ClProgram& p) {
  std::string out;
  statement(out, "PARTNO", {p.partno});
  for (const auto& c : p.comments) statement(out, "PPRINT", {"'" + c + "'"});
  statement(out, "UNITS", {"MM"});
  statement(out, "MULTAX", {"ON"});
  const AptCutter& c = p.cutter;
  statement(out, "CUTTER", {fixed(c.d, 6), fixed(c.r, 6), fixed(c.e, 6), fixed(c.f, 6), fixed(c.alpha_deg, 6),
                            fixed(c.beta_deg, 6), fixed(c.h, 6)});
  statement(out, "PPRINT", {"'TOOL PROFILE Z R MM FROM THE TIP'"});
  for (const auto& q : p.profile) statement(out, "PPRINT", {"'PROFILE " + fixed(q.x(), 6) + " " + fixed(q.y(), 6) + "'"});
  statement(out, "LOADTL", {std::to_string(p.tool)});
  if (p.spindle_rpm > 0) statement(out, "SPINDL", {fixed(p.spindle_rpm, 1), "RPM", p.clockwise ? "CLW" : "CCLW"});
  if (p.coolant) statement(out, "COOLNT", {"ON"});
  double feed = -1;
  for (const ClMove& m : p.moves) {
    if (m.rapid) {
      statement(out, "RAPID", {});
    } else if (m.feed_mm_min != feed) {
      feed = m.feed_mm_min;
      statement(out, "FEDRAT", {fixed(feed, 3), "MMPM"});
    }
    const Eigen::Vector3d& t = m.pose.tip;
    const Eigen::Vector3d k = m.pose.axis.normalized();
    statement(out, "GOTO", {fixed(t.x(), 6), fixed(t.y(), 6), fixed(t.z(), 6), fixed(k.x(), 9), fixed(k.y(), 9), fixed(k.z(), 9)});
  }
  if (p.coolant) statement(out, "COOLNT", {"OFF"});
  if (p.spindle_rpm > 0) statement(out, "SPINDL", {"OFF"});
  statement(out, "END", {});
  statement(out, "FINI", {});
  return out;
}

void write_apt(const std::string& path, const ClProgram& p) {
  const std::string text = apt_text(p);
  write_file_atomically(path, [&](std::ostream& o) { o << text; });
}

ClProgram parse_apt(const std::string& text, const std::string& name) {
  ClProgram p;
  std::istringstream in(text);
  std::string raw, stmt;
  int line_no = 0, stmt_line = 0;
  bool rapid_next = false, finished = false;
  double feed = 0;
  Eigen::Vector3d axis = Eigen::Vector3d::UnitZ();
  const auto fail = [&](const std::string& what) -> void {
    throw InputError(fmt::format("{}:{}: {}", name, stmt_line, what));
  };
  const auto number = [&](const std::string& s, const std::string& what) {
    const std::optional<double> v = parse_number(s);
    if (!v) fail(what + ": " + in_quotes(s) + " is not a number");
    return *v;
  };
  // Every value has a sane range: beyond it a number is garbage (int(LOADTL/1e300) was undefined,
  // FEDRAT/1e-300 posted F0.0000, SPINDL/1e300 a 301-digit S word).
  const auto number_in = [&](const std::string& s, const std::string& what, double lo, double hi, const char* unit) {
    const double v = number(s, what);
    if (!(v >= lo && v <= hi))
      fail(fmt::format("{}: {} is outside {:g}..{:g}{}{}", what, in_quotes(s), lo, hi, *unit ? " " : "", unit));
    return v;
  };
  const auto handle = [&](std::string s) {
    s.erase(std::remove_if(s.begin(), s.end(), [](unsigned char ch) { return std::isspace(ch); }), s.end());
    if (s.empty()) return;
    std::string major = s, rest;
    if (const size_t slash = s.find('/'); slash != std::string::npos) major = s.substr(0, slash), rest = s.substr(slash + 1);
    std::transform(major.begin(), major.end(), major.begin(), [](unsigned char ch) { return char(std::toupper(ch)); });
    std::vector<std::string> args;
    for (size_t a = 0; !rest.empty();) {
      const size_t comma = rest.find(',', a);
      args.push_back(rest.substr(a, comma - a));
      if (comma == std::string::npos) break;
      a = comma + 1;
    }
    const auto upper = [](std::string x) {
      std::transform(x.begin(), x.end(), x.begin(), [](unsigned char ch) { return char(std::toupper(ch)); });
      return x;
    };
    if (major == "PARTNO") {
      p.partno = rest;
    } else if (major == "UNITS") {
      if (args.empty() || upper(args[0]) != "MM") fail("UNITS: only MM is supported, got '" + rest + "'");
    } else if (major == "LOADTL") {
      if (args.empty()) fail("LOADTL: tool number missing");
      const double t = number_in(args[0], "LOADTL", 0, AptRanges::tool_number, "");
      if (t != std::floor(t)) fail("LOADTL: " + in_quotes(args[0]) + " is not a whole number");
      p.tool = int(t);
    } else if (major == "CUTTER") {
      if (args.empty()) fail("CUTTER: diameter missing");
      double* fields[7] = {&p.cutter.d, &p.cutter.r, &p.cutter.e, &p.cutter.f, &p.cutter.alpha_deg, &p.cutter.beta_deg, &p.cutter.h};
      for (size_t k = 0; k < args.size() && k < 7; ++k)
        *fields[k] = k == 4 || k == 5 ? number_in(args[k], "CUTTER", -180, 180, "deg")
                                      : number_in(args[k], "CUTTER", 0, AptRanges::tool_size_mm, "mm");
    } else if (major == "FEDRAT") {
      bool got = false;
      for (const auto& a : args)
        if (upper(a) != "MMPM" && upper(a) != "MMPR")
          feed = number_in(a, "FEDRAT", AptRanges::feed_mm_min[0], AptRanges::feed_mm_min[1], "mm/min"), got = true;
      if (!got) fail("FEDRAT: no feed value");
    } else if (major == "SPINDL") {
      for (const auto& a : args) {
        const std::string u = upper(a);
        if (u == "OFF" || u == "RPM" || u == "SFM" || u == "SMM") continue;
        if (u == "CLW" || u == "CCLW") {
          p.clockwise = u == "CLW";
          continue;
        }
        p.spindle_rpm = number_in(a, "SPINDL", 0, AptRanges::spindle_rpm, "rpm");
      }
    } else if (major == "RAPID") {
      rapid_next = true;
    } else if (major == "GOTO") {
      if (args.size() != 3 && args.size() != 6) fail(fmt::format("GOTO: expected 3 or 6 values, got {}", args.size()));
      ClMove m;
      const double c = AptRanges::coordinate_mm;
      m.pose.tip = {number_in(args[0], "GOTO x", -c, c, "mm"), number_in(args[1], "GOTO y", -c, c, "mm"),
                    number_in(args[2], "GOTO z", -c, c, "mm")};
      if (args.size() == 6) {
        axis = {number_in(args[3], "GOTO i", -2, 2, ""), number_in(args[4], "GOTO j", -2, 2, ""),
                number_in(args[5], "GOTO k", -2, 2, "")};
        if (std::abs(axis.norm() - 1) > 1e-4) fail("GOTO: the tool axis (i, j, k) is not a unit vector");
        axis.normalize();
      }
      m.pose.axis = axis;
      m.rapid = rapid_next;
      m.feed_mm_min = rapid_next ? 0 : feed;
      if (!m.rapid && !(feed > 0)) fail("GOTO: a feed move before any FEDRAT");
      rapid_next = false;
      p.moves.push_back(m);
    } else if (major == "FINI") {
      finished = true;
    } else if (!std::all_of(major.begin(), major.end(), [](unsigned char ch) { return std::isalnum(ch); })) {
      fail("cannot read '" + s + "'");
    }
    // Other major words (MULTAX, COOLNT, END, FROM, MACHIN, ...) do not change the motion.
  };
  while (std::getline(in, raw)) {
    ++line_no;
    if (const size_t cc = raw.find("$$"); cc != std::string::npos) raw.erase(cc);
    if (!raw.empty() && raw.back() == '\r') raw.pop_back();
    if (stmt.empty()) stmt_line = line_no;
    const size_t end = raw.find_last_not_of(" \t");
    if (end != std::string::npos && raw[end] == '$') {
      stmt += raw.substr(0, end);
      continue;
    }
    stmt += raw;
    // PPRINT keeps its text (spaces included); the profile lines carry the tool's meridian.
    std::string head = stmt.substr(0, std::min<size_t>(stmt.size(), 7));
    std::transform(head.begin(), head.end(), head.begin(), [](unsigned char ch) { return char(std::toupper(ch)); });
    if (head.rfind("PPRINT/", 0) == 0) {
      const std::string text_part = stmt.substr(7);
      if (text_part.rfind("'PROFILE", 0) == 0) {
        std::istringstream q(text_part.substr(8));
        double z, r;
        if (q >> z >> r) {
          if (!(std::abs(z) <= AptRanges::tool_size_mm && std::abs(r) <= AptRanges::tool_size_mm))
            fail(fmt::format("PPRINT 'PROFILE: z {:g}, r {:g} outside +-{:g} mm", z, r, AptRanges::tool_size_mm));
          p.profile.emplace_back(z, r);
        }
      } else if (text_part.size() >= 2) {
        p.comments.push_back(text_part.substr(1, text_part.size() - 2));
      }
    } else {
      handle(stmt);
    }
    stmt.clear();
    if (finished) break;
  }
  if (!stmt.empty()) {
    stmt_line = line_no;
    fail("the file ends inside a statement continued with $");
  }
  if (p.moves.empty()) throw InputError(name + ": no GOTO moves");
  return p;
}

ClProgram read_apt(const std::string& path) {
  std::ifstream in(path, std::ios::binary);
  if (!in) throw InputError(path + ": cannot read the CL file");
  std::stringstream s;
  s << in.rdbuf();
  return parse_apt(s.str(), path);
}

std::string cl_csv(const ClProgram& p) {
  std::string out = "# flankcam CL data, mm, part coordinates; axis from the tip towards the spindle\n"
                    "index,motion,x,y,z,i,j,k,cx,cy,cz,feed_mm_min\n";
  for (size_t n = 0; n < p.moves.size(); ++n) {
    const ClMove& m = p.moves[n];
    const Eigen::Vector3d k = m.pose.axis.normalized();
    const bool known = m.contact.allFinite();
    out += fmt::format("{},{},{},{},{},{},{},{},{},{},{},{}\n", n, m.rapid ? "rapid" : "feed", fixed(m.pose.tip.x(), 6),
                       fixed(m.pose.tip.y(), 6), fixed(m.pose.tip.z(), 6), fixed(k.x(), 9), fixed(k.y(), 9), fixed(k.z(), 9),
                       known ? fixed(m.contact.x(), 6) : "", known ? fixed(m.contact.y(), 6) : "",
                       known ? fixed(m.contact.z(), 6) : "", fixed(m.feed_mm_min, 3));
  }
  return out;
}

}  // namespace flankcam
