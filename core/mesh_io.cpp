// Checked mesh readers: OBJ, STL (ascii/binary), OFF, PLY (ascii/binary either endian).
// Every count is checked against the file size before anything is allocated, every
// numeric token is parsed whole (std::from_chars, double precision) and checked, every
// face index is range-checked. Errors name the file and line (text) or byte offset (binary).
#include <fmt/format.h>

#include <algorithm>
#include <charconv>
#include <cmath>
#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <filesystem>
#include <limits>
#include <string_view>
#include <system_error>

#include "core/errors.h"
#include "core/mesh.h"

namespace flankcam {
namespace {

constexpr double kMaxCoordinate_mm = 1e15;  // larger is a broken file, not a part
constexpr uint64_t kMaxVertices = uint64_t(std::numeric_limits<int>::max());

struct RawMesh {
  TriMesh mesh;
  int polygons = 0;  // faces with more than three corners, fan-triangulated
};

std::string lower_extension(const std::string& path) {
  std::string ext = std::filesystem::path(path).extension().string();
  std::transform(ext.begin(), ext.end(), ext.begin(), [](unsigned char c) { return char(std::tolower(c)); });
  return ext;
}

// A token as shown in an error: bounded, printable.
std::string shown(std::string_view tok) {
  std::string s(tok.substr(0, 40));
  for (char& c : s)
    if (static_cast<unsigned char>(c) < 32 || static_cast<unsigned char>(c) > 126) c = '?';
  return tok.size() > 40 ? s + "..." : s;
}

bool iequals(std::string_view a, std::string_view b) {
  if (a.size() != b.size()) return false;
  for (size_t i = 0; i < a.size(); ++i)
    if (std::tolower(static_cast<unsigned char>(a[i])) != std::tolower(static_cast<unsigned char>(b[i]))) return false;
  return true;
}

[[noreturn]] void fail_line(const std::string& path, size_t line, const std::string& what) {
  throw InputError(fmt::format("{}:{}: {}", path, line, what));
}
[[noreturn]] void fail_byte(const std::string& path, size_t byte, const std::string& what) {
  throw InputError(fmt::format("{}: byte {}: {}", path, byte, what));
}

std::string read_whole_file(const std::string& path) {
  namespace fs = std::filesystem;
  std::error_code ec;
  if (!fs::exists(path, ec)) throw InputError(path + ": file not found");
  if (fs::is_directory(path, ec)) throw InputError(path + ": is a directory, not a mesh file");
  if (!fs::is_regular_file(path, ec)) throw InputError(path + ": is not a regular file");
  std::FILE* f = std::fopen(path.c_str(), "rb");
  if (!f) throw InputError(path + ": cannot read file");
  std::string data;
  const auto size = fs::file_size(path, ec);
  if (!ec) data.reserve(size_t(size));
  char chunk[1 << 16];
  size_t n;
  while ((n = std::fread(chunk, 1, sizeof chunk, f)) > 0) data.append(chunk, n);
  const bool bad = std::ferror(f);
  std::fclose(f);
  if (bad) throw InputError(path + ": cannot read file");
  if (data.empty()) throw InputError(path + ": file is empty");
  return data;
}

// ---- numbers -------------------------------------------------------------------------

enum class Parsed { ok, not_a_number, out_of_range };

// The whole token as a double; a leading '+' is allowed. Underflow gives the rounded value.
Parsed parse_double(std::string_view tok, double& v) {
  const char* b = tok.data();
  const char* e = b + tok.size();
  if (b != e && *b == '+' && e - b > 1 && b[1] != '-' && b[1] != '+') ++b;
  const auto r = std::from_chars(b, e, v, std::chars_format::general);
  if (r.ptr != e || b == e) return Parsed::not_a_number;
  if (r.ec == std::errc::result_out_of_range) {
    const std::string s(b, e);
    v = std::strtod(s.c_str(), nullptr);  // ±HUGE_VAL on overflow, a tiny value or 0 on underflow
    return std::isfinite(v) && std::abs(v) < 1 ? Parsed::ok : Parsed::out_of_range;
  }
  return r.ec == std::errc() ? Parsed::ok : Parsed::not_a_number;
}

// The whole token as an integer.
bool parse_integer(std::string_view tok, long long& v) {
  const char* b = tok.data();
  const char* e = b + tok.size();
  if (b != e && *b == '+' && e - b > 1 && b[1] != '-') ++b;
  const auto r = std::from_chars(b, e, v);
  return b != e && r.ec == std::errc() && r.ptr == e;
}

// Why a coordinate is refused (not finite, beyond kMaxCoordinate_mm); empty when it is fine.
std::string check_coordinate(double v) {
  if (!std::isfinite(v)) return "vertex coordinate is NaN or infinite";
  if (std::abs(v) > kMaxCoordinate_mm) return fmt::format("vertex coordinate {:g} is beyond 1e15 mm in magnitude", v);
  return {};
}

double text_coordinate(std::string_view tok, const std::string& path, size_t line) {
  double v = 0;
  switch (parse_double(tok, v)) {
    case Parsed::not_a_number:
      fail_line(path, line, tok.empty() ? "missing vertex coordinate" : fmt::format("'{}' is not a number", shown(tok)));
    case Parsed::out_of_range:
      fail_line(path, line, fmt::format("vertex coordinate '{}' is beyond 1e15 mm in magnitude", shown(tok)));
    case Parsed::ok:
      break;
  }
  if (const std::string why = check_coordinate(v); !why.empty()) fail_line(path, line, why);
  return v;
}

// ---- text scanning -------------------------------------------------------------------

bool is_blank(char c) { return c == ' ' || c == '\t' || c == '\r' || c == '\f' || c == '\v'; }

// Next whitespace-separated token on the line [p, e); empty at the end of the line.
std::string_view next_token(const char*& p, const char* e) {
  while (p < e && is_blank(*p)) ++p;
  const char* b = p;
  while (p < e && !is_blank(*p)) ++p;
  return {b, size_t(p - b)};
}

// Values after those a line needs (a colour, w, a texture coordinate): numbers, not used.
// A '#' ends the line.
void check_trailing_numbers(const char* p, const char* e, const std::string& path, size_t line) {
  for (std::string_view t = next_token(p, e); !t.empty() && t[0] != '#'; t = next_token(p, e)) {
    double unused = 0;
    if (parse_double(t, unused) != Parsed::ok || !std::isfinite(unused))
      fail_line(path, line, fmt::format("'{}' is not a finite number", shown(t)));
  }
}

// Lines of a text buffer, numbered from 1, without their end of line.
struct LineReader {
  const char* p;
  const char* end;
  size_t number = 0;
  bool next(const char*& b, const char*& e) {
    if (p >= end) return false;
    b = p;
    const void* nl = std::memchr(p, '\n', size_t(end - p));
    e = nl ? static_cast<const char*>(nl) : end;
    p = nl ? e + 1 : end;
    ++number;
    return true;
  }
};

// Tokens across lines (PLY ascii bodies, ascii STL), tracking the line of the last token
// (at the end of the file, the line of the last token there is).
struct TokenReader {
  const char* p;
  const char* end;
  size_t line = 1;
  std::string_view next() {
    size_t newlines = 0;
    while (p < end && (is_blank(*p) || *p == '\n')) {
      if (*p == '\n') ++newlines;
      ++p;
    }
    const char* b = p;
    while (p < end && !is_blank(*p) && *p != '\n') ++p;
    if (p > b) line += newlines;
    return {b, size_t(p - b)};
  }
  void skip_line() {
    while (p < end && *p != '\n') ++p;
  }
};

void add_polygon(RawMesh& raw, const std::vector<int>& corners) {
  if (corners.size() > 3) ++raw.polygons;
  for (size_t k = 1; k + 1 < corners.size(); ++k) raw.mesh.faces.push_back({corners[0], corners[k], corners[k + 1]});
}

// ---- OBJ -----------------------------------------------------------------------------

// v x y z [w | r g b]; f with i, i/t, i//n, i/t/n corners, negative indices relative to
// the vertices read so far; every other statement (vt, vn, o, g, usemtl, l, ...) is ignored.
RawMesh read_obj(const std::string& path, const std::string& data) {
  RawMesh raw;
  LineReader lines{data.data(), data.data() + data.size()};
  std::vector<int> corners;
  long long max_index = 0;
  size_t max_index_line = 0;
  const char *b, *e;
  while (lines.next(b, e)) {
    const char* p = b;
    const std::string_view kw = next_token(p, e);
    if (kw == "v") {
      Eigen::Vector3d x;
      for (int k = 0; k < 3; ++k) x[k] = text_coordinate(next_token(p, e), path, lines.number);
      check_trailing_numbers(p, e, path, lines.number);  // w or a colour
      if (raw.mesh.vertices.size() >= kMaxVertices) fail_line(path, lines.number, "more than 2^31-1 vertices");
      raw.mesh.vertices.push_back(x);
    } else if (kw == "f") {
      corners.clear();
      for (std::string_view t = next_token(p, e); !t.empty() && t[0] != '#'; t = next_token(p, e)) {
        const size_t slash = t.find('/');
        long long i = 0;
        if (!parse_integer(t.substr(0, slash), i))
          fail_line(path, lines.number, fmt::format("face corner '{}' is not a vertex index", shown(t)));
        if (slash != std::string_view::npos) {  // texture and normal indices: checked, not used
          std::string_view rest = t.substr(slash + 1);
          const size_t slash2 = rest.find('/');
          long long unused;
          for (std::string_view part : {rest.substr(0, slash2), slash2 == std::string_view::npos ? std::string_view() : rest.substr(slash2 + 1)})
            if (!part.empty() && !parse_integer(part, unused))
              fail_line(path, lines.number, fmt::format("face corner '{}' is not of the form v, v/t, v//n or v/t/n", shown(t)));
        }
        const long long n = (long long)raw.mesh.vertices.size();
        if (i == 0) fail_line(path, lines.number, "face index 0 (OBJ indices start at 1)");
        if (i < 0) {
          if (n + i < 0)
            fail_line(path, lines.number, fmt::format("relative face index {} but only {} vertices precede it", i, n));
          i = n + i;
        } else {
          if (i > (long long)kMaxVertices) fail_line(path, lines.number, fmt::format("face index {} is out of range", i));
          if (i > max_index) max_index = i, max_index_line = lines.number;
          i -= 1;
        }
        corners.push_back(int(i));
      }
      if (corners.size() < 3) fail_line(path, lines.number, fmt::format("face has {} corners, at least 3 needed", corners.size()));
      add_polygon(raw, corners);
    }
  }
  if (max_index > (long long)raw.mesh.vertices.size())
    fail_line(path, max_index_line,
              fmt::format("face index {} is out of range (the file has {} vertices)", max_index, raw.mesh.vertices.size()));
  return raw;
}

// ---- STL -----------------------------------------------------------------------------

// Triangles are read as three fresh vertices each; clean_mesh welds exactly equal ones
// (first occurrence wins, so the result does not depend on anything but the file).
RawMesh read_binary_stl(const std::string& path, const std::string& data) {
  const size_t size = data.size();
  if (size < 84) fail_byte(path, size, fmt::format("binary STL is {} bytes, shorter than its 84-byte header", size));
  uint32_t n;
  std::memcpy(&n, data.data() + 80, 4);  // little-endian, as is the host (x86-64, aarch64)
  const uint64_t expected = 84 + 50 * uint64_t(n);
  if (expected != size)
    fail_byte(path, 80,
              fmt::format("binary STL header says {} triangles ({} bytes) but the file has {} bytes", n, expected, size));
  if (3 * uint64_t(n) > kMaxVertices) fail_byte(path, 80, fmt::format("{} triangles are too many", n));
  RawMesh raw;
  raw.mesh.vertices.resize(3 * size_t(n));
  raw.mesh.faces.resize(n);
  const char* p = data.data() + 84;
  for (uint32_t t = 0; t < n; ++t, p += 50) {
    float xyz[9];  // after the 12-byte normal, which is not used
    std::memcpy(xyz, p + 12, sizeof xyz);
    for (int k = 0; k < 9; ++k)
      if (const std::string why = check_coordinate(xyz[k]); !why.empty())
        fail_byte(path, size_t(p + 12 + 4 * k - data.data()), fmt::format("triangle {}: {}", t + 1, why));
    for (int c = 0; c < 3; ++c) raw.mesh.vertices[3 * size_t(t) + c] = Eigen::Vector3d(xyz[3 * c], xyz[3 * c + 1], xyz[3 * c + 2]);
    raw.mesh.faces[t] = {int(3 * t), int(3 * t + 1), int(3 * t + 2)};
  }
  return raw;
}

RawMesh read_ascii_stl(const std::string& path, const std::string& data) {
  RawMesh raw;
  TokenReader in{data.data(), data.data() + data.size()};
  auto expect = [&](std::string_view want) {
    const std::string_view t = in.next();
    if (!iequals(t, want))
      fail_line(path, in.line, t.empty() ? fmt::format("file ends where '{}' was expected", want)
                                         : fmt::format("'{}' where '{}' was expected", shown(t), want));
  };
  bool in_solid = false;
  for (std::string_view t = in.next(); !t.empty(); t = in.next()) {
    if (iequals(t, "solid") && !in_solid) {
      in.skip_line();  // the solid's name
      in_solid = true;
    } else if (iequals(t, "endsolid") && in_solid) {
      in.skip_line();
      in_solid = false;
    } else if (iequals(t, "facet") && in_solid) {
      expect("normal");
      for (int k = 0; k < 3; ++k) {  // the normal is not used, but it must be numbers
        const std::string_view c = in.next();
        double unused;
        if (parse_double(c, unused) == Parsed::not_a_number)
          fail_line(path, in.line, fmt::format("facet normal component '{}' is not a number", shown(c)));
      }
      expect("outer");
      expect("loop");
      const int first = int(raw.mesh.vertices.size());
      for (int c = 0; c < 3; ++c) {
        expect("vertex");
        Eigen::Vector3d x;
        for (int k = 0; k < 3; ++k) {
          const std::string_view tok = in.next();
          x[k] = text_coordinate(tok, path, in.line);
        }
        if (raw.mesh.vertices.size() >= kMaxVertices) fail_line(path, in.line, "more than 2^31-1 vertices");
        raw.mesh.vertices.push_back(x);
      }
      expect("endloop");
      expect("endfacet");
      raw.mesh.faces.push_back({first, first + 1, first + 2});
    } else {
      fail_line(path, in.line,
                fmt::format("'{}' where '{}' was expected", shown(t), in_solid ? "facet' or 'endsolid" : "solid"));
    }
  }
  if (in_solid) fail_line(path, in.line, "file ends inside a solid (no 'endsolid')");
  return raw;
}

RawMesh read_stl(const std::string& path, const std::string& data) {
  size_t i = 0;
  while (i < data.size() && std::isspace(static_cast<unsigned char>(data[i]))) ++i;
  const bool says_solid = data.size() - i >= 5 && iequals(std::string_view(data).substr(i, 5), "solid");
  bool textual = true;  // binary headers may start with "solid" too: their counts and floats are not text
  for (size_t k = 0; k < std::min<size_t>(data.size(), 1024); ++k) {
    const unsigned char c = data[k];
    if (!(std::isprint(c) || std::isspace(c))) textual = false;
  }
  return says_solid && textual ? read_ascii_stl(path, data) : read_binary_stl(path, data);
}

// ---- OFF -----------------------------------------------------------------------------

// Next line with content (comments after '#' removed); false at the end of the file.
bool content_line(LineReader& lines, const char*& b, const char*& e) {
  while (lines.next(b, e)) {
    if (const void* hash = std::memchr(b, '#', size_t(e - b))) e = static_cast<const char*>(hash);
    const char* p = b;
    while (p < e && is_blank(*p)) ++p;
    if (p < e) return true;
  }
  return false;
}

long long count_token(std::string_view tok, const char* what, const std::string& path, size_t line) {
  long long v = 0;
  if (tok.empty()) fail_line(path, line, fmt::format("missing {} count", what));
  if (!parse_integer(tok, v) || v < 0)
    fail_line(path, line, fmt::format("{} count '{}' is not a non-negative integer", what, shown(tok)));
  return v;
}

// [ST][C][N]OFF, one vertex per line (x y z, then colour/normal/texture values, ignored)
// and one face per line (n i1 .. in, then an optional colour, ignored).
RawMesh read_off(const std::string& path, const std::string& data) {
  RawMesh raw;
  LineReader lines{data.data(), data.data() + data.size()};
  const char *b, *e;
  if (!content_line(lines, b, e)) fail_line(path, 1, "no OFF header");
  const char* p = b;
  const std::string_view magic = next_token(p, e);
  if (magic.size() < 3 || magic.substr(magic.size() - 3) != "OFF" ||
      magic.substr(0, magic.size() - 3).find_first_not_of("STCN") != std::string_view::npos)
    fail_line(path, lines.number, fmt::format("'{}' is not an OFF header (OFF, COFF, NOFF, STOFF ...)", shown(magic)));
  std::string_view first = next_token(p, e);
  if (first.empty()) {  // the counts are on the next line
    if (!content_line(lines, b, e)) fail_line(path, lines.number, "file ends before the vertex and face counts");
    p = b;
    first = next_token(p, e);
  }
  const size_t count_line = lines.number;
  const long long nv = count_token(first, "vertex", path, count_line);
  const long long nf = count_token(next_token(p, e), "face", path, count_line);
  if (const std::string_view ne = next_token(p, e); !ne.empty()) count_token(ne, "edge", path, count_line);
  // A vertex line is at least "0 0 0\n" and a face line "3 0 1 2\n": check before allocating.
  const size_t left = size_t(data.data() + data.size() - lines.p);
  const long double need = 6.0L * nv + 8.0L * nf - 1;
  if (need > left)
    fail_line(path, count_line,
              fmt::format("header declares {} vertices and {} faces but only {} bytes follow", nv, nf, left));
  if (uint64_t(nv) > kMaxVertices) fail_line(path, count_line, "more than 2^31-1 vertices");
  raw.mesh.vertices.reserve(size_t(nv));
  raw.mesh.faces.reserve(size_t(nf));
  for (long long i = 0; i < nv; ++i) {
    if (!content_line(lines, b, e))
      fail_line(path, lines.number, fmt::format("file ends after {} of {} vertices", i, nv));
    p = b;
    Eigen::Vector3d x;
    for (int k = 0; k < 3; ++k) x[k] = text_coordinate(next_token(p, e), path, lines.number);
    check_trailing_numbers(p, e, path, lines.number);  // colour, normal, texture coordinates
    raw.mesh.vertices.push_back(x);
  }
  std::vector<int> corners;
  for (long long f = 0; f < nf; ++f) {
    if (!content_line(lines, b, e)) fail_line(path, lines.number, fmt::format("file ends after {} of {} faces", f, nf));
    p = b;
    const std::string_view nt = next_token(p, e);
    long long n = 0;
    if (!parse_integer(nt, n) || n < 3)
      fail_line(path, lines.number, fmt::format("face corner count '{}' is not an integer >= 3", shown(nt)));
    corners.clear();
    for (long long k = 0; k < n; ++k) {
      const std::string_view t = next_token(p, e);
      long long i = 0;
      if (t.empty()) fail_line(path, lines.number, fmt::format("face has {} of its {} corners", k, n));
      if (!parse_integer(t, i)) fail_line(path, lines.number, fmt::format("face index '{}' is not an integer", shown(t)));
      if (i < 0 || i >= nv)
        fail_line(path, lines.number, fmt::format("face index {} is out of range (the file has {} vertices)", i, nv));
      corners.push_back(int(i));
    }
    check_trailing_numbers(p, e, path, lines.number);  // a colour
    add_polygon(raw, corners);
  }
  return raw;
}

// ---- PLY -----------------------------------------------------------------------------

enum class PlyType { int8, uint8, int16, uint16, int32, uint32, float32, float64 };

bool ply_type(std::string_view name, PlyType& t) {
  static const std::pair<const char*, PlyType> names[] = {
      {"char", PlyType::int8},     {"int8", PlyType::int8},       {"uchar", PlyType::uint8},    {"uint8", PlyType::uint8},
      {"short", PlyType::int16},   {"int16", PlyType::int16},     {"ushort", PlyType::uint16},  {"uint16", PlyType::uint16},
      {"int", PlyType::int32},     {"int32", PlyType::int32},     {"uint", PlyType::uint32},    {"uint32", PlyType::uint32},
      {"float", PlyType::float32}, {"float32", PlyType::float32}, {"double", PlyType::float64}, {"float64", PlyType::float64}};
  for (const auto& [n, type] : names)
    if (name == n) {
      t = type;
      return true;
    }
  return false;
}

size_t ply_size(PlyType t) {
  switch (t) {
    case PlyType::int8: case PlyType::uint8: return 1;
    case PlyType::int16: case PlyType::uint16: return 2;
    case PlyType::int32: case PlyType::uint32: case PlyType::float32: return 4;
    case PlyType::float64: return 8;
  }
  return 0;
}

bool ply_is_float(PlyType t) { return t == PlyType::float32 || t == PlyType::float64; }

template <class T>
T load(const char* p, bool swap) {
  unsigned char bytes[sizeof(T)];
  std::memcpy(bytes, p, sizeof(T));
  if (swap) std::reverse(bytes, bytes + sizeof(T));
  T v;
  std::memcpy(&v, bytes, sizeof(T));
  return v;
}

double ply_binary_value(const char* p, PlyType t, bool swap) {
  switch (t) {
    case PlyType::int8: return load<int8_t>(p, swap);
    case PlyType::uint8: return load<uint8_t>(p, swap);
    case PlyType::int16: return load<int16_t>(p, swap);
    case PlyType::uint16: return load<uint16_t>(p, swap);
    case PlyType::int32: return load<int32_t>(p, swap);
    case PlyType::uint32: return load<uint32_t>(p, swap);
    case PlyType::float32: return load<float>(p, swap);
    case PlyType::float64: return load<double>(p, swap);
  }
  return 0;
}

struct PlyProperty {
  std::string name;
  PlyType type = PlyType::float32;  // the items' type for a list
  bool is_list = false;
  PlyType count_type = PlyType::uint8;
};

struct PlyElement {
  std::string name;
  uint64_t count = 0;
  size_t line = 0;
  std::vector<PlyProperty> properties;
};

enum class PlyFormat { ascii, binary_le, binary_be };

// Reads one value of `type`, as a double, from the ascii tokens or the binary bytes.
struct PlyBody {
  const std::string& path;
  const std::string& data;
  PlyFormat format;
  TokenReader tokens;  // ascii
  size_t at = 0;       // binary: offset of the next byte

  // `what` names the value in errors ("vertex 12 x"); integer types must hold integers in range.
  template <class What>
  double value(PlyType type, const What& what) {
    if (format != PlyFormat::ascii) {
      const size_t n = ply_size(type);
      if (data.size() - at < n) fail_byte(path, at, fmt::format("file ends in {}", what()));
      const double v = ply_binary_value(data.data() + at, type, format == PlyFormat::binary_be);
      at += n;
      return v;
    }
    const std::string_view tok = tokens.next();
    if (tok.empty()) fail_line(path, tokens.line, fmt::format("file ends before {}", what()));
    if (ply_is_float(type)) {
      double v = 0;
      const Parsed r = parse_double(tok, v);
      if (r == Parsed::not_a_number) fail_line(path, tokens.line, fmt::format("{} '{}' is not a number", what(), shown(tok)));
      if (r == Parsed::out_of_range) v = tok[0] == '-' ? -INFINITY : INFINITY;
      return v;
    }
    long long v = 0;
    if (!parse_integer(tok, v)) fail_line(path, tokens.line, fmt::format("{} '{}' is not an integer", what(), shown(tok)));
    static const long long lo[] = {-128, 0, -32768, 0, -2147483648LL, 0};
    static const long long hi[] = {127, 255, 32767, 65535, 2147483647LL, 4294967295LL};
    if (v < lo[int(type)] || v > hi[int(type)])
      fail_line(path, tokens.line, fmt::format("{} {} does not fit its declared type", what(), v));
    return double(v);
  }
  // Where the last value was, for errors about its meaning.
  [[noreturn]] void fail(const std::string& what, size_t value_start) const {
    if (format == PlyFormat::ascii) fail_line(path, tokens.line, what);
    fail_byte(path, value_start, what);
  }
};

RawMesh read_ply(const std::string& path, const std::string& data) {
  LineReader lines{data.data(), data.data() + data.size()};
  const char *b, *e;
  auto header_line = [&]() {
    if (!lines.next(b, e)) fail_line(path, lines.number, "file ends in the PLY header (no end_header)");
    if (e > b && e[-1] == '\r') --e;
  };
  header_line();
  const char* p = b;
  if (next_token(p, e) != "ply" || !next_token(p, e).empty()) fail_line(path, 1, "first line is not 'ply'");
  PlyFormat format = PlyFormat::ascii;
  bool have_format = false;
  std::vector<PlyElement> elements;
  for (;;) {
    header_line();
    p = b;
    const std::string_view kw = next_token(p, e);
    const size_t line = lines.number;
    if (kw == "end_header") break;
    if (kw.empty() || kw == "comment" || kw == "obj_info") continue;
    if (kw == "format") {
      const std::string_view f = next_token(p, e);
      if (f == "ascii") format = PlyFormat::ascii;
      else if (f == "binary_little_endian") format = PlyFormat::binary_le;
      else if (f == "binary_big_endian") format = PlyFormat::binary_be;
      else fail_line(path, line, fmt::format("unknown PLY format '{}'", shown(f)));
      have_format = true;
    } else if (kw == "element") {
      PlyElement el;
      el.name = std::string(next_token(p, e));
      const std::string_view count = next_token(p, e);
      if (el.name.empty() || count.empty()) fail_line(path, line, "element needs a name and a count");
      long long c = 0;
      if (!parse_integer(count, c) || c < 0)
        fail_line(path, line, fmt::format("element {} count '{}' is not a non-negative integer", shown(el.name), shown(count)));
      el.count = uint64_t(c);
      el.line = line;
      elements.push_back(std::move(el));
    } else if (kw == "property") {
      if (elements.empty()) fail_line(path, line, "property declared before any element");
      PlyProperty prop;
      std::string_view t = next_token(p, e);
      if (t == "list") {
        prop.is_list = true;
        const std::string_view ct = next_token(p, e);
        if (!ply_type(ct, prop.count_type) || ply_is_float(prop.count_type))
          fail_line(path, line, fmt::format("list count type '{}' is not an integer type", shown(ct)));
        t = next_token(p, e);
      }
      if (!ply_type(t, prop.type)) fail_line(path, line, fmt::format("unknown property type '{}'", shown(t)));
      prop.name = std::string(next_token(p, e));
      if (prop.name.empty()) fail_line(path, line, "property without a name");
      elements.back().properties.push_back(std::move(prop));
    } else {
      fail_line(path, line, fmt::format("unknown PLY header keyword '{}'", shown(kw)));
    }
  }
  const size_t header_end_line = lines.number;
  if (!have_format) fail_line(path, header_end_line, "PLY header has no format line");

  // Check every declared count against the bytes that follow before allocating anything:
  // binary entries need their scalars and list counts, ascii values at least 2 bytes each.
  const size_t body = size_t(lines.p - data.data());
  const unsigned __int128 left = data.size() - body;
  unsigned __int128 need = 0;
  for (const auto& el : elements) {
    size_t per = 0;
    for (const auto& prop : el.properties)
      per += format == PlyFormat::ascii ? 2 : ply_size(prop.is_list ? prop.count_type : prop.type);
    need += (unsigned __int128)el.count * per;
    if (need > left + (format == PlyFormat::ascii ? 1 : 0))  // ascii: the last value needs no separator
      fail_line(path, el.line,
                fmt::format("element {} declares {} entries but only {} bytes follow the header", shown(el.name), el.count,
                            uint64_t(left)));
  }

  const PlyElement* vertex_el = nullptr;
  for (const auto& el : elements)
    if (el.name == "vertex") {
      if (vertex_el) fail_line(path, el.line, "a second vertex element");
      vertex_el = &el;
    }
  const uint64_t nv = vertex_el ? vertex_el->count : 0;
  if (nv > kMaxVertices) fail_line(path, vertex_el->line, "more than 2^31-1 vertices");

  RawMesh raw;
  raw.mesh.vertices.reserve(size_t(nv));
  PlyBody in{path, data, format, TokenReader{data.data() + body, data.data() + data.size(), header_end_line + 1}, body};
  std::vector<int> corners;
  for (const auto& el : elements) {
    const bool is_vertex = &el == vertex_el;
    const bool is_face = el.name == "face";
    std::vector<int> axis(el.properties.size(), -1);  // vertex: 0,1,2 for x,y,z
    int index_list = -1;                              // face: the vertex index list
    if (is_vertex) {
      for (int k = 0; k < 3; ++k) {
        const char* want = k == 0 ? "x" : k == 1 ? "y" : "z";
        int found = -1;
        for (size_t i = 0; i < el.properties.size(); ++i)
          if (el.properties[i].name == want && found < 0) found = int(i);
        if (found < 0 || el.properties[size_t(found)].is_list)
          fail_line(path, el.line, fmt::format("vertex element has no scalar property {}", want));
        axis[size_t(found)] = k;
      }
    }
    if (is_face) {
      for (size_t i = 0; i < el.properties.size(); ++i)
        if (el.properties[i].is_list && (el.properties[i].name == "vertex_indices" || el.properties[i].name == "vertex_index"))
          index_list = int(i);
      if (index_list < 0) fail_line(path, el.line, "face element has no vertex_indices list");
      raw.mesh.faces.reserve(size_t(el.count));
    }
    if (el.properties.empty()) continue;  // nothing to read, however many entries it declares
    for (uint64_t i = 0; i < el.count; ++i) {
      Eigen::Vector3d x = Eigen::Vector3d::Zero();
      for (size_t k = 0; k < el.properties.size(); ++k) {
        const PlyProperty& prop = el.properties[k];
        auto what = [&]() { return fmt::format("{} {} {}", el.name, i, prop.name); };
        const size_t start = in.at;
        if (!prop.is_list) {
          const double v = in.value(prop.type, what);
          if (axis[k] >= 0) {
            if (const std::string why = check_coordinate(v); !why.empty()) in.fail(fmt::format("{}: {}", what(), why), start);
            x[axis[k]] = v;
          }
          continue;
        }
        const double n = in.value(prop.count_type, what);
        if (n < 0) in.fail(fmt::format("{} has a negative list length", what()), start);
        if (format != PlyFormat::ascii && n * ply_size(prop.type) > double(data.size() - in.at))
          in.fail(fmt::format("{} list of {} items runs past the end of the file", what(), n), start);
        const bool indices = is_face && int(k) == index_list;
        if (indices && n < 3) in.fail(fmt::format("{} has {} corners, at least 3 needed", what(), n), start);
        corners.clear();
        for (double j = 0; j < n; ++j) {
          const size_t item = in.at;
          const double v = in.value(prop.type, what);
          if (!indices) continue;
          if (!(v >= 0 && v < double(nv) && v == std::floor(v)))
            in.fail(fmt::format("{} index {} is out of range (the file has {} vertices)", what(), v, nv), item);
          corners.push_back(int(v));
        }
        if (indices) add_polygon(raw, corners);
      }
      if (is_vertex) raw.mesh.vertices.push_back(x);
    }
  }
  return raw;
}

}  // namespace

LoadedMesh load_mesh(const std::string& path) {
  namespace fs = std::filesystem;
  std::error_code ec;
  if (!fs::exists(path, ec)) throw InputError(path + ": file not found");
  if (fs::is_directory(path, ec)) throw InputError(path + ": is a directory, not a mesh file");
  const std::string ext = lower_extension(path);
  if (ext != ".obj" && ext != ".stl" && ext != ".off" && ext != ".ply")
    throw InputError(path + ": unknown mesh format '" + ext + "' (use .obj, .stl, .off or .ply)");
  const std::string data = read_whole_file(path);
  RawMesh raw = ext == ".obj"   ? read_obj(path, data)
                : ext == ".stl" ? read_stl(path, data)
                : ext == ".off" ? read_off(path, data)
                                : read_ply(path, data);
  if (raw.mesh.faces.empty()) throw InputError(path + ": mesh has no faces");
  if (raw.mesh.faces.size() > size_t(std::numeric_limits<int>::max()))
    throw InputError(path + ": more than 2^31-1 triangles");
  LoadedMesh out = clean_mesh(std::move(raw.mesh), path);
  out.report.polygons_triangulated = raw.polygons;
  return out;
}

}  // namespace flankcam
