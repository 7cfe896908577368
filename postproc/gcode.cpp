#include "postproc/gcode.h"

#include <fmt/format.h>

#include <cctype>
#include <cmath>
#include <memory>
#include <sstream>

#include "core/atomic_file.h"
#include "core/errors.h"
#include "core/message_text.h"
#include "core/number_format.h"

namespace flankcam {

namespace {

std::string mm(double x) { return fixed(x, 4); }
// Heidenhain writes every coordinate with its sign.
std::string signed_mm(double x) {
  const std::string s = fixed(x, 4);
  return s[0] == '-' ? s : "+" + s;
}
std::string rpm(double x) { return fixed(x, 0); }
// A mm/min (or deg/min) feed rounded down to 0.001, never up: a block slowed to an axis' top speed
// stays within it. Trailing zeros go (F600.0, F1234.567).
std::string feed_mm_min(double x) {
  std::string s = fixed(std::floor(x * 1000 + 1e-6) / 1000, 3);
  while (s.size() > 2 && s.back() == '0' && s[s.size() - 2] != '.') s.pop_back();
  return s;
}

// Comment text without the characters that would end or nest the comment.
std::string comment_text(const std::string& s) {
  std::string out;
  for (char c : s) out += (c == '(' ? '[' : c == ')' ? ']' : c == ';' ? ',' : (c == '\n' || c == '\r') ? ' ' : c);
  return out;
}

// Program names the controllers accept: letters, digits, '_' and '-'.
std::string program_name(const std::string& s) {
  std::string out;
  for (char c : s) out += std::isalnum(static_cast<unsigned char>(c)) || c == '_' || c == '-' ? c : '_';
  return out.empty() ? "FLANKCAM" : out;
}

// The lines of a program, numbered when asked.
class Lines {
 public:
  explicit Lines(bool numbered, std::string prefix = "N", int first = 10, int step = 10)
      : numbered_(numbered), prefix_(std::move(prefix)), n_(first), step_(step) {}
  void add(const std::string& block) {
    if (numbered_) {
      text_ += fmt::format("{}{} ", prefix_, n_);
      n_ += step_;
    }
    text_ += block + "\n";
  }
  void raw(const std::string& line) { text_ += line + "\n"; }  // unnumbered (%, O-number)
  [[nodiscard]] const std::string& text() const { return text_; }

 private:
  bool numbered_;
  std::string prefix_;
  int n_, step_;
  std::string text_;
};

// The parts a dialect decides; the walk over the blocks is shared (emit()).
class Emitter {
 public:
  virtual ~Emitter() = default;
  virtual void begin(const NcProgram& p) = 0;
  virtual void comment(const std::string& text) = 0;
  virtual void tool_change(const NcProgram& p, const NcToolChange& t, double next_rpm) = 0;
  virtual void spindle(const NcSpindle& s) = 0;
  virtual void coolant(const NcCoolant& c) = 0;
  virtual void move(const NcProgram& p, const NcMove& m) = 0;
  virtual void end(const NcProgram& p) = 0;
  [[nodiscard]] virtual std::string text() const = 0;

 protected:
  // What the operator checks at the tool change: number, name, diameter and length (mm).
  static std::string tool_comment(const NcToolChange& t) {
    return fmt::format("T{} {} D{} L{}", t.number, t.name, fixed(t.diameter_mm, 3), fixed(t.length_mm, 3));
  }
};

// Fanuc-style G-code, shared by iso, linuxcnc and sinumerik: G0/G1 modal, G93 inverse time with F on
// every feed block, G94 mm/min with F when it changes.
class GcodeEmitter : public Emitter {
 public:
  explicit GcodeEmitter(const EmitOptions& o) : o_(o), lines_(o.line_numbers) {}
  void coolant(const NcCoolant& c) override { lines_.add(c.on ? "M8" : "M9"); }
  void spindle(const NcSpindle& s) override {
    lines_.add(s.rpm > 0 ? fmt::format("S{} {}", rpm(s.rpm), s.clockwise ? "M3" : "M4") : "M5");
  }
  void move(const NcProgram& p, const NcMove& m) override {
    std::string b;
    const int motion = m.rapid ? 0 : 1;
    if (!m.rapid && p.inverse_time && !g93_) b += "G93 ", g93_ = true;
    if (motion != motion_) b += m.rapid ? "G0 " : "G1 ", motion_ = motion;
    static constexpr const char* kLinear[3] = {"X", "Y", "Z"};
    for (int k = 0; k < 3; ++k)
      if (m.axes & (1u << k)) b += fmt::format("{}{} ", kLinear[k], mm(m.at.linear[k]));
    for (int k = 0; k < 2; ++k)
      if (m.axes & (8u << k)) b += rotary_word(p.rotary_names[size_t(k)], m.at.rotary[size_t(k)]) + " ";
    if (!m.rapid) {
      if (p.inverse_time) {
        b += "F" + fixed(m.inverse_time, 4);
      } else if (const std::string f = feed_mm_min(m.feed_mm_min); f != feed_) {
        b += "F" + f;
        feed_ = f;
      }
    }
    while (!b.empty() && b.back() == ' ') b.pop_back();
    lines_.add(b);
  }
  [[nodiscard]] std::string text() const override { return lines_.text(); }

 protected:
  virtual std::string rotary_word(const std::string& name, double deg) const { return name + mm(deg); }
  // Back to mm/min before the program ends (G93 is modal and survives the program on some controls).
  void feed_mode_off() {
    if (g93_) lines_.add("G94"), g93_ = false;
  }
  EmitOptions o_;
  Lines lines_;
  int motion_ = -1;
  bool g93_ = false;
  std::string feed_;
};

class IsoEmitter final : public GcodeEmitter {
 public:
  using GcodeEmitter::GcodeEmitter;
  void begin(const NcProgram& p) override {
    lines_.raw("%");
    lines_.raw(fmt::format("O{:04d} ({})", p.number, comment_text(program_name(p.name))));
    for (const auto& h : p.header) comment(h);
    lines_.add("G21 G90 G17 G40 G49 G80 G94");
    lines_.add("G54");
  }
  void comment(const std::string& text) override { lines_.add("(" + comment_text(text) + ")"); }
  void tool_change(const NcProgram& p, const NcToolChange& t, double) override {
    comment(tool_comment(t));
    lines_.add(fmt::format("T{} M6", t.number));
    // TCP (G43.4) carries the tool length compensation; joints need G43.
    lines_.add(fmt::format("{} H{}", p.tcp ? "G43.4" : "G43", t.number));
  }
  void end(const NcProgram&) override {
    feed_mode_off();
    lines_.add("G49");
    lines_.add("M30");
    lines_.raw("%");
  }
};

class LinuxCncEmitter final : public GcodeEmitter {
 public:
  using GcodeEmitter::GcodeEmitter;
  void begin(const NcProgram& p) override {
    comment(program_name(p.name));
    for (const auto& h : p.header) comment(h);
    lines_.add("G21 G90 G17 G40 G49 G94 G54");
    // Blending: the controller may round corners by at most the linearisation tolerance.
    lines_.add("G64 P" + mm(o_.blend_tolerance_mm));
  }
  void comment(const std::string& text) override { lines_.add("(" + comment_text(text) + ")"); }
  void tool_change(const NcProgram&, const NcToolChange& t, double) override {
    comment(tool_comment(t));
    lines_.add(fmt::format("T{} M6", t.number));
    lines_.add(fmt::format("G43 H{}", t.number));
  }
  void end(const NcProgram&) override {
    feed_mode_off();
    lines_.add("M2");
  }
};

class SinumerikEmitter final : public GcodeEmitter {
 public:
  using GcodeEmitter::GcodeEmitter;
  void begin(const NcProgram& p) override {
    comment(program_name(p.name));
    for (const auto& h : p.header) comment(h);
    lines_.add("G17 G90 G71 G40 G54 G94");
    // High-speed settings for finishing: contour tolerance = the linearisation tolerance.
    lines_.add(fmt::format("CYCLE832({},_FINISH,1)", mm(o_.blend_tolerance_mm)));
  }
  void comment(const std::string& text) override { lines_.add("; " + comment_text(text)); }
  void tool_change(const NcProgram& p, const NcToolChange& t, double) override {
    if (tcp_) lines_.add("TRAFOOF"), tcp_ = false;
    comment(tool_comment(t));
    lines_.add(fmt::format("T{} M6", t.number));
    lines_.add("D1");
    if (p.tcp) lines_.add("TRAORI"), tcp_ = true;
  }
  void end(const NcProgram&) override {
    feed_mode_off();
    if (tcp_) lines_.add("TRAFOOF"), tcp_ = false;
    lines_.add("M30");
  }

 private:
  std::string rotary_word(const std::string& name, double deg) const override { return name + "=" + mm(deg); }
  bool tcp_ = false;
};

// Heidenhain conversational: numbered blocks, L with signed coordinates, FMAX for rapids, F in mm/min
// (tip feed under FUNCTION TCPM, the linear axes' feed otherwise), S in TOOL CALL.
class HeidenhainEmitter final : public Emitter {
 public:
  explicit HeidenhainEmitter(const EmitOptions&) : lines_(true, "", 0, 1) {}
  void begin(const NcProgram& p) override {
    name_ = program_name(p.name);
    lines_.add("BEGIN PGM " + name_ + " MM");
    for (const auto& h : p.header) comment(h);
  }
  void comment(const std::string& text) override { lines_.add("; " + comment_text(text)); }
  void tool_change(const NcProgram& p, const NcToolChange& t, double next_rpm) override {
    if (tcp_) lines_.add("FUNCTION RESET TCPM"), tcp_ = false;
    comment(tool_comment(t));
    lines_.add(fmt::format("TOOL CALL {} Z S{}", t.number, rpm(next_rpm)));
    rpm_ = next_rpm;
    if (p.tcp) lines_.add("FUNCTION TCPM F TCP AXIS POS PATHCTRL AXIS"), tcp_ = true;
  }
  void spindle(const NcSpindle& s) override {
    if (s.rpm > 0 && s.rpm != rpm_) lines_.add("TOOL CALL Z S" + rpm(s.rpm)), rpm_ = s.rpm;
    lines_.add(s.rpm > 0 ? (s.clockwise ? "M3" : "M4") : "M5");
  }
  void coolant(const NcCoolant& c) override { lines_.add(c.on ? "M8" : "M9"); }
  void move(const NcProgram& p, const NcMove& m) override {
    std::string b = "L";
    static constexpr const char* kLinear[3] = {"X", "Y", "Z"};
    for (int k = 0; k < 3; ++k)
      if (m.axes & (1u << k)) b += fmt::format(" {}{}", kLinear[k], signed_mm(m.at.linear[k]));
    for (int k = 0; k < 2; ++k)
      if (m.axes & (8u << k)) b += fmt::format(" {}{}", p.rotary_names[size_t(k)], signed_mm(m.at.rotary[size_t(k)]));
    b += m.rapid ? " R0 FMAX" : " R0 F" + feed_mm_min(m.feed_mm_min);
    lines_.add(b);
  }
  void end(const NcProgram&) override {
    if (tcp_) lines_.add("FUNCTION RESET TCPM"), tcp_ = false;
    lines_.add("M30");
    lines_.add("END PGM " + name_ + " MM");
  }
  [[nodiscard]] std::string text() const override { return lines_.text(); }

 private:
  Lines lines_;
  std::string name_;
  bool tcp_ = false;
  double rpm_ = -1;
};

std::unique_ptr<Emitter> make_emitter(const EmitOptions& o) {
  switch (o.dialect) {
    case Dialect::Iso: return std::make_unique<IsoEmitter>(o);
    case Dialect::LinuxCnc: return std::make_unique<LinuxCncEmitter>(o);
    case Dialect::Heidenhain: return std::make_unique<HeidenhainEmitter>(o);
    case Dialect::Sinumerik: return std::make_unique<SinumerikEmitter>(o);
  }
  throw InputError("unknown dialect");
}

}  // namespace

std::string nc_text(const NcProgram& p, const EmitOptions& o) {
  const std::unique_ptr<Emitter> e = make_emitter(o);
  e->begin(p);
  for (size_t i = 0; i < p.blocks.size(); ++i) {
    const NcBlock& b = p.blocks[i];
    if (const auto* c = std::get_if<NcComment>(&b)) e->comment(c->text);
    if (const auto* t = std::get_if<NcToolChange>(&b)) {
      double next_rpm = 0;  // the speed the tool will turn at (Heidenhain states it in TOOL CALL)
      for (size_t j = i + 1; j < p.blocks.size() && next_rpm == 0; ++j)
        if (const auto* s = std::get_if<NcSpindle>(&p.blocks[j])) next_rpm = s->rpm;
      e->tool_change(p, *t, next_rpm);
    }
    if (const auto* s = std::get_if<NcSpindle>(&b)) e->spindle(*s);
    if (const auto* c = std::get_if<NcCoolant>(&b)) e->coolant(*c);
    if (const auto* m = std::get_if<NcMove>(&b)) e->move(p, *m);
  }
  e->end(p);
  return e->text();
}

void write_nc(const std::string& path, const NcProgram& p, const EmitOptions& o) {
  const std::string text = nc_text(p, o);
  write_file_atomically(path, [&](std::ostream& out) { out << text; });
}

// ---- Reading back ----------------------------------------------------------------------------

namespace {

struct ReaderState {
  NcPoint point;
  int motion = -1;
  bool ended = false;  // M2 / M30 / END PGM seen
};

[[noreturn]] void fail(const std::string& file, int line, const std::string& what) {
  throw InputError(fmt::format("{}:{}: {}", file, line, what));
}

double number(const std::string& s, const std::string& file, int line) {
  const std::optional<double> v = parse_number(s);
  if (!v) fail(file, line, in_quotes(s) + " is not a number");
  return *v;
}

// What a program may say (beyond it a value is garbage, and int(T1e30) would be undefined).
constexpr double kMaxCoordinate = 1e6;  // mm, and degrees of unwound rotary axes
constexpr double kMaxFeed = 1e7;        // mm/min, or 1/min under G93
constexpr int kMaxTool = 99999;

double number_in(const std::string& s, const std::string& what, double lo, double hi, const std::string& file, int line) {
  const double v = number(s, file, line);
  if (!(v >= lo && v <= hi)) fail(file, line, fmt::format("{} {} is outside {:g}..{:g}", what, in_quotes(s), lo, hi));
  return v;
}
int tool_number(const std::string& s, const std::string& file, int line) {
  const double v = number_in(s, "tool number", 0, kMaxTool, file, line);
  if (v != std::floor(v)) fail(file, line, "tool number " + in_quotes(s) + " is not a whole number");
  return int(v);
}

// Index of an axis letter in the programmed values: 0..2 linear, 3..4 rotary, -1 none.
int axis_index(const std::string& word, const std::array<std::string, 2>& rotary) {
  if (word == "X") return 0;
  if (word == "Y") return 1;
  if (word == "Z") return 2;
  if (word == rotary[0]) return 3;
  if (word == rotary[1]) return 4;
  return -1;
}

void set_axis(NcPoint& p, int k, double v) {
  if (k < 3)
    p.at.linear[k] = v;
  else
    p.at.rotary[size_t(k - 3)] = v;
  p.known |= 1u << k;
  p.stated |= 1u << k;
}

// One G-code line (iso, linuxcnc, sinumerik) without its comments; appends a point for a motion block.
void gcode_line(std::string s, Dialect d, const std::array<std::string, 2>& rotary, const std::string& file, int line,
                ReaderState& st, std::vector<NcPoint>& out) {
  // Upper case; sinumerik writes A=10.0, the others A10.0.
  for (char& c : s) c = char(std::toupper(static_cast<unsigned char>(c)));
  std::istringstream words(s);
  std::string w;
  bool moved = false;
  st.point.stated = 0;
  while (words >> w) {
    if (d == Dialect::Sinumerik) {
      if (w == "TRAORI") { st.point.tcp = true; continue; }
      if (w == "TRAFOOF") { st.point.tcp = false; continue; }
      if (w.rfind("CYCLE832(", 0) == 0) {
        while (w.back() != ')' && words >> w) {}
        continue;
      }
    }
    const size_t eq = w.find('=');
    std::string letter, value;
    if (eq != std::string::npos) {
      letter = w.substr(0, eq), value = w.substr(eq + 1);
    } else {
      size_t k = 0;
      while (k < w.size() && std::isalpha(static_cast<unsigned char>(w[k]))) ++k;
      letter = w.substr(0, k), value = w.substr(k);
    }
    if (letter.empty()) fail(file, line, in_quotes(w) + " is not a word");
    if (letter == "M") {
      const double m = number(value, file, line);
      if (m == 2 || m == 30) st.ended = true;
      continue;
    }
    if (letter == "N" || letter == "S" || letter == "D" || letter == "H" || letter == "P") {
      number(value, file, line);
      continue;
    }
    const double v = number(value, file, line);
    if (letter == "G") {
      if (v == 0 || v == 1) st.motion = int(v);
      else if (v == 93) st.point.inverse_time = true;
      else if (v == 94) st.point.inverse_time = false;
      else if (value == "43.4") st.point.tcp = true;
      else if (v == 49) st.point.tcp = false;
      else if (v == 21 || v == 71 || v == 90 || v == 17 || v == 40 || v == 80 || v == 54 || v == 64 || v == 43) {}
      else fail(file, line, "G" + value + " is not a code flankcam writes");
      continue;
    }
    if (letter == "T") { st.point.tool = tool_number(value, file, line); continue; }
    if (letter == "F") { st.point.f = number_in(value, "F", 0, kMaxFeed, file, line); continue; }
    const int k = axis_index(letter, rotary);
    if (k < 0) fail(file, line, in_quotes(w) + ": no such axis on this machine");
    set_axis(st.point, k, number_in(value, letter, -kMaxCoordinate, kMaxCoordinate, file, line));
    moved = true;
  }
  if (!moved) return;
  if (st.motion < 0) fail(file, line, "a move before any G0/G1");
  st.point.line = line;
  st.point.rapid = st.motion == 0;
  out.push_back(st.point);
}

void heidenhain_line(const std::string& s, const std::array<std::string, 2>& rotary, const std::string& file, int line,
                     ReaderState& st, std::vector<NcPoint>& out) {
  std::istringstream words(s);
  std::string w;
  words >> w;  // block number
  if (w.empty() || !std::isdigit(static_cast<unsigned char>(w[0]))) fail(file, line, "a Heidenhain block starts with its number");
  std::string rest;
  std::getline(words, rest);
  rest.erase(0, rest.find_first_not_of(' '));
  if (rest.empty() || rest[0] == ';' || rest.rfind("BEGIN PGM", 0) == 0 || rest.rfind("END PGM", 0) == 0) return;
  if (rest.rfind("FUNCTION TCPM", 0) == 0) { st.point.tcp = true; return; }
  if (rest.rfind("FUNCTION RESET TCPM", 0) == 0) { st.point.tcp = false; return; }
  if (rest.rfind("TOOL CALL", 0) == 0) {
    std::istringstream t(rest.substr(9));
    std::string first;
    if (t >> first && std::isdigit(static_cast<unsigned char>(first[0]))) st.point.tool = tool_number(first, file, line);
    return;
  }
  if (rest[0] == 'M') return;
  if (rest.rfind("L ", 0) != 0) fail(file, line, in_quotes(rest) + " is not a block flankcam writes");
  std::istringstream lw(rest.substr(2));
  bool rapid = false;
  st.point.stated = 0;
  while (lw >> w) {
    if (w == "FMAX") { rapid = true; continue; }
    if (w == "R0") continue;
    if (w[0] == 'F') { st.point.f = number_in(w.substr(1), "F", 0, kMaxFeed, file, line); continue; }
    if (w[0] == 'M') continue;
    const int k = axis_index(w.substr(0, 1), rotary);
    if (k < 0) fail(file, line, in_quotes(w) + ": no such axis on this machine");
    if (w.size() < 2 || (w[1] != '+' && w[1] != '-')) fail(file, line, in_quotes(w) + ": Heidenhain coordinates carry a sign");
    set_axis(st.point, k, number_in(w.substr(1), w.substr(0, 1), -kMaxCoordinate, kMaxCoordinate, file, line));
  }
  st.point.line = line;
  st.point.rapid = rapid;
  out.push_back(st.point);
}

}  // namespace

std::vector<NcPoint> parse_nc(const std::string& text, Dialect d, const std::array<std::string, 2>& rotary_names,
                              const std::string& file) {
  std::vector<NcPoint> out;
  ReaderState st;
  std::istringstream in(text);
  std::string raw;
  int line = 0;
  while (std::getline(in, raw)) {
    ++line;
    if (!raw.empty() && raw.back() == '\r') raw.pop_back();
    if (d == Dialect::Heidenhain) {
      if (!raw.empty()) heidenhain_line(raw, rotary_names, file, line, st, out);
      if (raw.find("END PGM") != std::string::npos) st.ended = true;
      continue;
    }
    // Comments: (...) in iso and linuxcnc, ';' to the end of the line in sinumerik and linuxcnc.
    std::string s;
    int depth = 0;
    for (char c : raw) {
      if (c == ';' && d != Dialect::Iso && depth == 0) break;
      if (c == '(' && d != Dialect::Sinumerik) ++depth;
      else if (c == ')' && d != Dialect::Sinumerik) --depth;
      else if (depth == 0) s += c;
    }
    if (depth != 0) fail(file, line, "unbalanced parentheses");
    const size_t first = s.find_first_not_of(" \t");
    if (first == std::string::npos) continue;
    s = s.substr(first);
    if (s[0] == '%') continue;
    if (d == Dialect::Iso && (s[0] == 'O' || s[0] == 'o')) continue;
    gcode_line(s, d, rotary_names, file, line, st, out);
  }
  if (!st.ended) fail(file, line, "the program has no end (M2, M30 or END PGM)");
  return out;
}

}  // namespace flankcam
