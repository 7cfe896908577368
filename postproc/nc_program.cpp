#include "postproc/nc_program.h"

#include <fmt/format.h>
#include <fmt/ranges.h>

#include <algorithm>
#include <cmath>

#include "core/errors.h"
#include "core/message_text.h"
#include "postproc/tool_export.h"

namespace flankcam {

const std::vector<DialectInfo>& dialect_table() {
  static const std::vector<DialectInfo> table = {
      {Dialect::Iso, "iso", {"fanuc"}, ".nc", "ISO/Fanuc G-code (G43.4 for TCP, G93 inverse time)"},
      {Dialect::LinuxCnc, "linuxcnc", {}, ".ngc", "LinuxCNC rs274ngc (joints, or tip + angles with trt kinematics)"},
      {Dialect::Heidenhain, "heidenhain", {}, ".h", "Heidenhain conversational (L blocks, M128 for TCP)"},
      {Dialect::Sinumerik, "sinumerik", {}, ".mpf", "Siemens Sinumerik (TRAORI for TCP)"},
  };
  return table;
}

const DialectInfo& dialect_info(Dialect d) {
  for (const DialectInfo& i : dialect_table())
    if (i.dialect == d) return i;
  throw InputError("dialect: not in the table");
}

std::string dialect_names() {
  std::string out;
  for (const DialectInfo& i : dialect_table()) {
    out += (out.empty() ? "" : ", ") + i.name;
    if (!i.aliases.empty()) out += fmt::format(" (or {})", fmt::join(i.aliases, ", "));
  }
  return out;
}

std::string to_string(Dialect d) { return dialect_info(d).name; }

namespace {
const DialectInfo* find_dialect(const std::string& name) {
  for (const DialectInfo& i : dialect_table())
    if (i.name == name || std::find(i.aliases.begin(), i.aliases.end(), name) != i.aliases.end()) return &i;
  return nullptr;
}
}  // namespace

Dialect parse_dialect(const std::string& name) {
  if (const DialectInfo* i = find_dialect(name)) return i->dialect;
  throw InputError(fmt::format("dialect: {} is not one of {}", in_quotes(name), dialect_names()));
}

std::string file_extension(Dialect d) { return dialect_info(d).extension; }

Dialect machine_dialect(const Machine& m) {
  if (const DialectInfo* i = find_dialect(m.controller.dialect)) return i->dialect;
  const std::string where = m.controller.dialect_line > 0 ? fmt::format("{}:{}", m.file, m.controller.dialect_line) : m.file;
  throw MachineError(fmt::format("{}: controller.dialect: {} is not one of {}", where,
                                 in_quotes(m.controller.dialect), dialect_names()));
}

std::string PostOptions::validate() const {
  if (std::string why = path.validate(); !why.empty()) return why;
  if (!(max_inverse_time > 0)) return "max_inverse_time: must be > 0";
  if (!(safe_height_mm >= 0) || !std::isfinite(safe_height_mm)) return "safe_height_mm: must be >= 0";
  return {};
}

namespace {

// Which CL move each output pose of a solved path belongs to: the input pose it ends at, or for an
// inserted pose the next input pose (the block it subdivides).
std::vector<int> owners(const JointPath& path) {
  std::vector<int> owner(path.joints.size(), -1);
  int next = -1;
  for (size_t j = path.joints.size(); j-- > 0;) {
    if (path.input_index[j] >= 0) next = path.input_index[j];
    owner[j] = next;
  }
  return owner;
}

bool same_rotaries(const Joints& a, const Joints& b) {
  return std::abs(a.rotary[0] - b.rotary[0]) < 1e-7 && std::abs(a.rotary[1] - b.rotary[1]) < 1e-7;
}

struct Solved {
  JointPath path;
  std::vector<Joints> at;  // programmed values per output pose
  std::vector<int> owner;
  double tool_length_mm = 0;
};

}  // namespace

Posted post(const std::vector<PostInput>& inputs, const Machine& m, const PostOptions& o, const std::string& name,
            const std::vector<std::string>& header) {
  if (std::string why = o.validate(); !why.empty()) throw InputError("post options: " + why);
  if (inputs.empty()) throw InputError("post: no CL-data");
  const bool tcp = m.controller.tcp || m.controller.linuxcnc_trt;
  if (o.dialect == Dialect::LinuxCnc && m.controller.tcp && !m.controller.linuxcnc_trt)
    throw MachineError(m.file + ": controller.tcp: LinuxCNC has no G43.4; set linuxcnc_trt when its trt kinematics is "
                                "active, or tcp: false to program joints");

  // Kinematics of every section first: the safe height depends on all of them.
  std::vector<Solved> solved;
  double top_z = -INFINITY;
  for (const PostInput& in : inputs) {
    if (in.cl.moves.empty()) throw InputError(fmt::format("patch '{}': the CL-data has no GOTO", in.patch));
    for (size_t k = 0; k < in.cl.moves.size(); ++k)
      if (!in.cl.moves[k].rapid && !(in.cl.moves[k].feed_mm_min > 0))
        throw InputError(fmt::format("patch '{}': CL move {} is a feed move without a feed rate (FEDRAT)", in.patch, k));
    std::vector<ToolPose> poses;
    for (const ClMove& mv : in.cl.moves) poses.push_back(mv.pose);
    PathOptions po = o.path;
    if (in.tool_length_mm > 0) po.tool_length_mm = in.tool_length_mm;
    Solved s;
    s.tool_length_mm = po.tool_length_mm;
    s.path = solve_path(m, poses, {}, po);
    require_reachable(s.path, poses, in.patch);
    s.owner = owners(s.path);
    for (size_t j = 0; j < s.path.joints.size(); ++j) {
      s.at.push_back(programmed(m, s.path.joints[j], s.path.poses[j]));
      top_z = std::max(top_z, s.at.back().linear.z());
    }
    solved.push_back(std::move(s));
  }

  Posted out;
  NcProgram& p = out.program;
  p.name = name;
  p.header = header;
  p.machine = m.name;
  p.rotary_names = {m.rotary[0].name, m.rotary[1].name};
  p.tcp = tcp;
  p.inverse_time = m.controller.inverse_time && o.dialect != Dialect::Heidenhain;
  // Joint values cannot go above the Z travel; the program's own highest point is below it.
  p.safe_z = top_z + o.safe_height_mm;
  if (!tcp) p.safe_z = std::max(top_z, std::min(p.safe_z, m.linear[2].max_mm));

  int tool = -1;
  bool have_position = false;
  Joints current;
  for (size_t i = 0; i < inputs.size(); ++i) {
    const PostInput& in = inputs[i];
    const Solved& s = solved[i];
    PostedSection sec;
    sec.patch = in.patch;
    sec.first_block = int(p.blocks.size());
    p.blocks.push_back(NcComment{"patch " + in.patch});
    for (const std::string& c : in.cl.comments) p.blocks.push_back(NcComment{c});
    if (in.cl.tool != tool) {
      tool = in.cl.tool;
      const ToolDimensions dim = tool_dimensions(in.cl.profile);
      p.blocks.push_back(NcToolChange{tool, in.cl.partno, dim.diameter_max_mm, dim.length_mm});
      have_position = false;  // after a tool change the spindle may be anywhere: approach from safe Z
    }
    p.blocks.push_back(NcSpindle{in.cl.spindle_rpm, in.cl.clockwise});
    p.blocks.push_back(NcCoolant{in.cl.coolant});

    // Feeds per output block: the CL move's feed; rapids get a nominal one (their F is not written).
    std::vector<double> feed(s.path.joints.size(), 1.0);
    for (size_t j = 1; j < feed.size(); ++j) {
      const ClMove& mv = in.cl.moves[size_t(s.owner[j])];
      if (!mv.rapid) feed[j] = mv.feed_mm_min;
    }
    const std::vector<BlockFeed> bf = block_feeds(m, s.path, feed);

    auto add_move = [&](bool rapid, unsigned axes, const Joints& at, const ToolPose& pose, int cl_move) {
      NcMove mv;
      mv.rapid = rapid;
      mv.axes = axes;
      mv.at = at;
      mv.pose = pose;
      mv.cl_move = cl_move;
      p.blocks.push_back(mv);
      current = at;
    };
    size_t j = 0;
    for (size_t k = 0; k < in.cl.moves.size(); ++k) {
      // Output poses j..jk end in CL move k (jk is the input pose itself).
      size_t jk = j;
      while (s.path.input_index[jk] != int(k)) ++jk;
      const ClMove& mv = in.cl.moves[k];
      const Joints& target = s.at[jk];
      if (mv.rapid || !have_position) {
        if (!have_position || !same_rotaries(current, target)) {
          // Safe approach: up to safe Z, turn the rotaries, over to X Y, down to the target.
          Joints up = have_position ? current : target;
          up.linear.z() = p.safe_z;
          add_move(true, AxisZ, up, programmed_pose(m, up, s.tool_length_mm), -1);
          up.rotary = target.rotary;
          add_move(true, AxesRotary, up, programmed_pose(m, up, s.tool_length_mm), -1);
          up.linear.x() = target.linear.x(), up.linear.y() = target.linear.y();
          add_move(true, AxisX | AxisY, up, programmed_pose(m, up, s.tool_length_mm), -1);
        }
        add_move(true, AxesLinear, target, s.path.poses[jk], int(k));
        have_position = true;
      } else {
        for (size_t q = j; q <= jk; ++q) {
          const BlockFeed& b = bf[q];
          double minutes = b.minutes;
          bool slowed = b.limiting_axis >= 0;
          if (1 / minutes > o.max_inverse_time) minutes = 1 / o.max_inverse_time, slowed = true;
          sec.slowed_blocks += slowed;
          NcMove nm;
          nm.rapid = false;
          nm.axes = AxesAll;
          nm.at = s.at[q];
          nm.pose = s.path.poses[q];
          nm.cl_move = q == jk ? int(k) : -1;
          nm.inverse_time = 1 / minutes;
          // G94: F is the path feed of the programmed linear axes, or deg/min for a rotary-only block.
          const Joints& a = q > 0 ? s.at[q - 1] : current;
          double dist = (nm.at.linear - a.linear).norm();
          if (dist < 1e-6) dist = std::hypot(nm.at.rotary[0] - a.rotary[0], nm.at.rotary[1] - a.rotary[1]);
          nm.feed_mm_min = dist > 0 ? dist / minutes : feed[q];
          p.blocks.push_back(nm);
          current = nm.at;
        }
      }
      j = jk + 1;
    }
    // Retract to safe Z: the next section (or the end) starts from there.
    Joints up = current;
    up.linear.z() = p.safe_z;
    add_move(true, AxisZ, up, programmed_pose(m, up, s.tool_length_mm), -1);
    sec.path = s.path;
    sec.end_block = int(p.blocks.size());
    out.sections.push_back(std::move(sec));
  }
  p.blocks.push_back(NcSpindle{0, true});
  p.blocks.push_back(NcCoolant{false});
  return out;
}

}  // namespace flankcam
