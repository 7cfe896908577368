#include "core/mesh.h"

#include <Eigen/Geometry>

// OpenMesh's property containers (VectorT default constructors) trip GCC 12's
// -Wmaybe-uninitialized when instantiated here; the warning is in OpenMesh, not ours.
#pragma GCC diagnostic ignored "-Wmaybe-uninitialized"
#include <OpenMesh/Core/IO/MeshIO.hh>
#include <OpenMesh/Core/Mesh/PolyMesh_ArrayKernelT.hh>
#include <fmt/format.h>
#include <fmt/os.h>

#include <algorithm>
#include <cmath>
#include <filesystem>
#include <fstream>
#include <map>
#include <numeric>
#include <set>
#include <sstream>
#include <tuple>
#include <unordered_map>

#include "core/atomic_file.h"
#include "core/errors.h"

namespace flankcam {
namespace {

struct DoubleTraits : OpenMesh::DefaultTraits {
  typedef OpenMesh::Vec3d Point;
  typedef OpenMesh::Vec3d Normal;
};
using OMPolyMesh = OpenMesh::PolyMesh_ArrayKernelT<DoubleTraits>;

std::string lower_extension(const std::string& path) {
  std::string ext = std::filesystem::path(path).extension().string();
  std::transform(ext.begin(), ext.end(), ext.begin(), [](unsigned char c) { return std::tolower(c); });
  return ext;
}

// OpenMesh reads "nan" in an OBJ as a stream failure; check the text ourselves for
// the textual formats so that a NaN is an error, not a silent zero.
void reject_textual_nonfinite(const std::string& path, const std::string& ext) {
  if (ext != ".obj" && ext != ".off") return;
  std::ifstream in(path);
  std::string line;
  int line_no = 0;
  while (std::getline(in, line)) {
    ++line_no;
    std::string lower = line;
    std::transform(lower.begin(), lower.end(), lower.begin(), [](unsigned char c) { return std::tolower(c); });
    if (ext == ".obj" && lower.rfind("v ", 0) != 0) continue;
    if (lower.find("nan") != std::string::npos || lower.find("inf") != std::string::npos)
      throw InputError(fmt::format("{}:{}: vertex coordinate is NaN or infinite", path, line_no));
  }
}

std::array<int, 3> sorted(std::array<int, 3> f) {
  std::sort(f.begin(), f.end());
  return f;
}

uint64_t edge_key(int a, int b) {
  if (a > b) std::swap(a, b);
  return (uint64_t(uint32_t(a)) << 32) | uint32_t(b);
}

// Faces sharing each undirected edge, in face order.
std::unordered_map<uint64_t, std::vector<std::pair<int, int>>> edge_faces(const TriMesh& m) {
  std::unordered_map<uint64_t, std::vector<std::pair<int, int>>> edges;
  edges.reserve(m.faces.size() * 2);
  for (int f = 0; f < int(m.faces.size()); ++f)
    for (int k = 0; k < 3; ++k) edges[edge_key(m.faces[f][k], m.faces[f][(k + 1) % 3])].push_back({f, k});
  return edges;
}

// Turns faces so that every manifold edge is used once in each direction; returns flips.
int orient_components(TriMesh& m) {
  const auto edges = edge_faces(m);
  std::vector<int> state(m.faces.size(), -1);  // -1 unvisited, else 0/1 flipped
  int flips = 0;
  std::vector<int> stack;
  for (int seed = 0; seed < int(m.faces.size()); ++seed) {
    if (state[seed] >= 0) continue;
    state[seed] = 0;
    stack.push_back(seed);
    while (!stack.empty()) {
      const int f = stack.back();
      stack.pop_back();
      for (int k = 0; k < 3; ++k) {
        int u = m.faces[f][k], v = m.faces[f][(k + 1) % 3];
        if (state[f]) std::swap(u, v);
        const auto& users = edges.at(edge_key(u, v));
        if (users.size() != 2) continue;
        const auto [g, kg] = users[0].first == f ? users[1] : users[0];
        if (state[g] >= 0) continue;
        // g runs its edge the same way as (the possibly flipped) f: g must be flipped.
        const bool same_direction = m.faces[g][kg] == u;
        state[g] = same_direction ? 1 : 0;
        stack.push_back(g);
      }
    }
  }
  for (size_t f = 0; f < m.faces.size(); ++f)
    if (state[f] == 1) {
      std::swap(m.faces[f][1], m.faces[f][2]);
      ++flips;
    }
  return flips;
}

}  // namespace

BoundingBox bounding_box(const std::vector<Eigen::Vector3d>& points) {
  BoundingBox b{Eigen::Vector3d::Constant(INFINITY), Eigen::Vector3d::Constant(-INFINITY)};
  for (const auto& p : points) {
    b.min = b.min.cwiseMin(p);
    b.max = b.max.cwiseMax(p);
  }
  return b;
}

Eigen::Vector3d face_normal(const TriMesh& m, int f) {
  const auto& F = m.faces[f];
  const Eigen::Vector3d n = (m.vertices[F[1]] - m.vertices[F[0]]).cross(m.vertices[F[2]] - m.vertices[F[0]]);
  const double len = n.norm();
  return len > 0 ? Eigen::Vector3d(n / len) : Eigen::Vector3d::Zero();
}

double face_area(const TriMesh& m, int f) {
  const auto& F = m.faces[f];
  return 0.5 * (m.vertices[F[1]] - m.vertices[F[0]]).cross(m.vertices[F[2]] - m.vertices[F[0]]).norm();
}

double surface_area(const TriMesh& m) {
  double a = 0;
  for (int f = 0; f < int(m.faces.size()); ++f) a += face_area(m, f);
  return a;
}

LoadedMesh clean_mesh(TriMesh mesh, const std::string& what) {
  LoadedMesh out;
  for (const auto& v : mesh.vertices)
    if (!v.allFinite()) throw InputError(what + ": vertex coordinate is NaN or infinite");

  // Weld exactly coincident vertices (readers split non-manifold fans and seams).
  std::map<std::tuple<double, double, double>, int> weld;
  std::vector<int> remap(mesh.vertices.size());
  for (size_t i = 0; i < mesh.vertices.size(); ++i) {
    const auto& v = mesh.vertices[i];
    remap[i] = weld.emplace(std::make_tuple(v.x(), v.y(), v.z()), int(i)).first->second;
  }
  const double diag = bounding_box(mesh.vertices).diagonal();
  const double min_area = 1e-14 * diag * diag;  // relative: zero area to rounding

  std::set<std::array<int, 3>> seen;
  std::vector<std::array<int, 3>> faces;
  faces.reserve(mesh.faces.size());
  for (auto f : mesh.faces) {
    for (int& i : f) i = remap[i];
    if (f[0] == f[1] || f[1] == f[2] || f[0] == f[2]) {
      ++out.report.dropped_degenerate;
      continue;
    }
    const double area = 0.5 * (mesh.vertices[f[1]] - mesh.vertices[f[0]])
                                  .cross(mesh.vertices[f[2]] - mesh.vertices[f[0]])
                                  .norm();
    if (!(area > min_area)) {
      ++out.report.dropped_degenerate;
      continue;
    }
    if (!seen.insert(sorted(f)).second) {
      ++out.report.dropped_duplicate;
      continue;
    }
    faces.push_back(f);
  }
  if (faces.empty()) throw InputError(what + ": mesh has no (non-degenerate) triangles");

  // Compact: keep referenced vertices in their original order.
  std::vector<int> new_index(mesh.vertices.size(), -1);
  for (const auto& f : faces)
    for (int i : f) new_index[i] = 0;
  int n = 0;
  for (size_t i = 0; i < new_index.size(); ++i)
    if (new_index[i] == 0) {
      new_index[i] = n++;
      out.mesh.vertices.push_back(mesh.vertices[i]);
    }
  for (auto f : faces) {
    for (int& i : f) i = new_index[i];
    out.mesh.faces.push_back(f);
  }
  out.report.flipped_to_orient = orient_components(out.mesh);
  out.report.components = mesh_topology(out.mesh).components;
  return out;
}

LoadedMesh load_mesh(const std::string& path) {
  namespace fs = std::filesystem;
  std::error_code ec;
  if (!fs::exists(path, ec)) throw InputError(path + ": file not found");
  if (fs::is_directory(path, ec)) throw InputError(path + ": is a directory, not a mesh file");
  {
    std::ifstream probe(path, std::ios::binary);
    if (!probe) throw InputError(path + ": cannot read file");
    if (probe.peek() == std::ifstream::traits_type::eof()) throw InputError(path + ": file is empty");
  }
  const std::string ext = lower_extension(path);
  if (ext != ".obj" && ext != ".stl" && ext != ".off" && ext != ".ply")
    throw InputError(path + ": unknown mesh format '" + ext + "' (use .obj, .stl, .off or .ply)");
  reject_textual_nonfinite(path, ext);

  OMPolyMesh om;
  OpenMesh::IO::Options opt;
  std::ostringstream messages;
  omerr().connect(messages);
  omerr().disable();
  const bool ok = OpenMesh::IO::read_mesh(om, path, opt);
  omerr().enable();
  omerr().disconnect(messages);
  if (!ok) throw InputError(path + ": cannot parse as " + ext.substr(1) + " mesh");

  TriMesh raw;
  raw.vertices.reserve(om.n_vertices());
  for (const auto& vh : om.vertices()) {
    const auto& p = om.point(vh);
    raw.vertices.emplace_back(p[0], p[1], p[2]);
  }
  int polygons = 0;
  for (const auto& fh : om.faces()) {
    std::vector<int> corners;
    for (const auto& vh : om.fv_range(fh)) corners.push_back(vh.idx());
    if (corners.size() > 3) ++polygons;
    for (size_t k = 1; k + 1 < corners.size(); ++k) raw.faces.push_back({corners[0], corners[k], corners[k + 1]});
  }
  if (raw.faces.empty()) throw InputError(path + ": mesh has no faces");
  LoadedMesh out = clean_mesh(std::move(raw), path);
  out.report.polygons_triangulated = polygons;
  // Faces OpenMesh refused outright (equal corners) count as degenerate.
  const std::string log = messages.str();
  for (size_t pos = log.find("equal vertices"); pos != std::string::npos; pos = log.find("equal vertices", pos + 1))
    ++out.report.dropped_degenerate;
  return out;
}

Similarity unit_diagonal_frame(const TriMesh& mesh) {
  const BoundingBox b = bounding_box(mesh.vertices);
  Similarity s;
  s.origin = b.center();
  s.scale = b.diagonal() > 0 ? 1.0 / b.diagonal() : 1.0;
  return s;
}

TriMesh transformed(const TriMesh& mesh, const Similarity& s) {
  TriMesh out = mesh;
  for (auto& v : out.vertices) v = s.to_unit(v);
  return out;
}

MeshTopology mesh_topology(const TriMesh& m) {
  MeshTopology t;
  t.boundary_edge.assign(m.faces.size(), {false, false, false});
  t.boundary_vertex.assign(m.vertices.size(), 0);
  t.component.assign(m.faces.size(), -1);
  const auto edges = edge_faces(m);
  for (const auto& [key, users] : edges) {
    if (users.size() != 1) continue;
    const auto [f, k] = users[0];
    t.boundary_edge[f][k] = true;
    t.boundary_vertex[m.faces[f][k]] = 1;
    t.boundary_vertex[m.faces[f][(k + 1) % 3]] = 1;
    ++t.boundary_edges;
  }
  std::vector<int> stack;
  for (int seed = 0; seed < int(m.faces.size()); ++seed) {
    if (t.component[seed] >= 0) continue;
    t.component[seed] = t.components;
    stack.push_back(seed);
    while (!stack.empty()) {
      const int f = stack.back();
      stack.pop_back();
      for (int k = 0; k < 3; ++k)
        for (const auto& [g, kg] : edges.at(edge_key(m.faces[f][k], m.faces[f][(k + 1) % 3])))
          if (t.component[g] < 0) {
            t.component[g] = t.components;
            stack.push_back(g);
          }
    }
    ++t.components;
  }
  return t;
}

std::vector<Eigen::Vector3d> vertex_normals(const TriMesh& m) {
  std::vector<Eigen::Vector3d> n(m.vertices.size(), Eigen::Vector3d::Zero());
  for (int f = 0; f < int(m.faces.size()); ++f) {
    const Eigen::Vector3d fn = face_normal(m, f);
    for (int k = 0; k < 3; ++k) {
      const Eigen::Vector3d e1 = m.vertices[m.faces[f][(k + 1) % 3]] - m.vertices[m.faces[f][k]];
      const Eigen::Vector3d e2 = m.vertices[m.faces[f][(k + 2) % 3]] - m.vertices[m.faces[f][k]];
      const double angle = std::atan2(e1.cross(e2).norm(), e1.dot(e2));
      n[m.faces[f][k]] += angle * fn;
    }
  }
  for (auto& v : n) {
    const double len = v.norm();
    if (len > 0) v /= len;
  }
  return n;
}

void write_obj(const std::string& path, const TriMesh& mesh, const std::string& comment) {
  write_file_atomically(path, [&](std::ostream& out) {
    fmt::memory_buffer buf;
    fmt::format_to(std::back_inserter(buf), "# flankcam{}{}\n", comment.empty() ? "" : ": ", comment);
    for (const auto& v : mesh.vertices) fmt::format_to(std::back_inserter(buf), "v {:.9f} {:.9f} {:.9f}\n", v.x(), v.y(), v.z());
    for (const auto& f : mesh.faces) fmt::format_to(std::back_inserter(buf), "f {} {} {}\n", f[0] + 1, f[1] + 1, f[2] + 1);
    out.write(buf.data(), std::streamsize(buf.size()));
  });
}

void write_ply(const std::string& path, const TriMesh& mesh, const std::vector<std::array<unsigned char, 3>>& colors,
               const std::vector<double>& scalar, const std::string& scalar_name, const std::string& comment) {
  write_file_atomically(path, [&](std::ostream& out) {
    fmt::memory_buffer buf;
    auto o = std::back_inserter(buf);
    fmt::format_to(o, "ply\nformat ascii 1.0\ncomment flankcam{}{}\n", comment.empty() ? "" : ": ", comment);
    fmt::format_to(o, "element vertex {}\nproperty double x\nproperty double y\nproperty double z\n", mesh.vertices.size());
    fmt::format_to(o, "property uchar red\nproperty uchar green\nproperty uchar blue\n");
    if (!scalar.empty()) fmt::format_to(o, "property double {}\n", scalar_name);
    fmt::format_to(o, "element face {}\nproperty list uchar int vertex_indices\nend_header\n", mesh.faces.size());
    for (size_t i = 0; i < mesh.vertices.size(); ++i) {
      const auto& v = mesh.vertices[i];
      const auto c = i < colors.size() ? colors[i] : std::array<unsigned char, 3>{200, 200, 200};
      fmt::format_to(o, "{:.9f} {:.9f} {:.9f} {} {} {}", v.x(), v.y(), v.z(), c[0], c[1], c[2]);
      if (!scalar.empty()) fmt::format_to(o, " {:.9f}", scalar[i]);  // "nan" where undefined
      fmt::format_to(o, "\n");
    }
    for (const auto& f : mesh.faces) fmt::format_to(o, "3 {} {} {}\n", f[0], f[1], f[2]);
    out.write(buf.data(), std::streamsize(buf.size()));
  });
}

}  // namespace flankcam
