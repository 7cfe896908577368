#include "core/mesh.h"

#include <Eigen/Geometry>
#include <fmt/format.h>

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <cstring>

#include "core/atomic_file.h"
#include "core/errors.h"

namespace flankcam {
namespace {

std::array<int, 3> sorted(std::array<int, 3> f) {
  std::sort(f.begin(), f.end());
  return f;
}

uint64_t mix(uint64_t h) {  // murmur3's finaliser
  h ^= h >> 33;
  h *= 0xff51afd7ed558ccdULL;
  h ^= h >> 33;
  h *= 0xc4ceb9fe1a85ec53ULL;
  return h ^ (h >> 33);
}

uint64_t bits(double v) {
  v += 0.0;  // -0 and +0 are equal coordinates: one hash
  uint64_t b;
  std::memcpy(&b, &v, sizeof b);
  return b;
}

// For each i < n in order, the first j <= i whose key equals i's. Open addressing over
// indices: the answer depends only on the order of the keys, never on a hash map's iteration.
template <class Hash, class Equal>
std::vector<int> first_occurrence(int n, const Hash& hash, const Equal& equal) {
  size_t capacity = 16;
  while (capacity < 2 * size_t(n)) capacity *= 2;
  const size_t mask = capacity - 1;
  std::vector<int> slot(capacity, -1);
  std::vector<int> first(static_cast<size_t>(n));
  for (int i = 0; i < n; ++i) {
    size_t h = hash(i) & mask;
    while (slot[h] >= 0 && !equal(slot[h], i)) h = (h + 1) & mask;
    if (slot[h] < 0) slot[h] = i;
    first[size_t(i)] = slot[h];
  }
  return first;
}

// Each undirected edge's faces, in face order: half-edges grouped by their smaller vertex
// (counting sort, O(n)), sorted by the other vertex within a group for a binary search.
struct EdgeFaces {
  struct Use {
    int other, face, k;  // edge k of `face` joins its smaller vertex to `other`
  };
  std::vector<int> start;  // per vertex, into uses; one past the end at the back
  std::vector<Use> uses;

  explicit EdgeFaces(const TriMesh& m) : start(m.vertices.size() + 1, 0), uses(3 * m.faces.size()) {
    for (const auto& f : m.faces)
      for (int k = 0; k < 3; ++k) ++start[size_t(std::min(f[k], f[(k + 1) % 3])) + 1];
    for (size_t v = 1; v < start.size(); ++v) start[v] += start[v - 1];
    std::vector<int> fill(start.begin(), start.end() - 1);
    for (int f = 0; f < int(m.faces.size()); ++f)
      for (int k = 0; k < 3; ++k) {
        const int a = m.faces[f][k], b = m.faces[f][(k + 1) % 3];
        uses[size_t(fill[size_t(std::min(a, b))]++)] = {std::max(a, b), f, k};
      }
    const long nv = long(start.size()) - 1;
#pragma omp parallel for schedule(dynamic, 8192) if (nv > 20000)
    for (long v = 0; v < nv; ++v)
      std::sort(uses.begin() + start[size_t(v)], uses.begin() + start[size_t(v) + 1],
                [](const Use& x, const Use& y) { return std::tie(x.other, x.face, x.k) < std::tie(y.other, y.face, y.k); });
  }
  // The uses of edge {a, b}: [first, last), in face order.
  [[nodiscard]] std::pair<const Use*, const Use*> of(int a, int b) const {
    if (a > b) std::swap(a, b);
    const Use* lo = uses.data() + start[size_t(a)];
    const Use* hi = uses.data() + start[size_t(a) + 1];
    return std::equal_range(lo, hi, Use{b, 0, 0}, [](const Use& x, const Use& y) { return x.other < y.other; });
  }
};

// Turns faces so that every manifold edge is used once in each direction; returns flips.
// Afterwards `edges` still tells which faces share an edge, but its `k` is stale for flipped faces.
int orient_components(TriMesh& m, const EdgeFaces& edges) {
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
        const auto [first, last] = edges.of(u, v);
        if (last - first != 2) continue;
        const EdgeFaces::Use& other = first->face == f ? first[1] : first[0];
        const int g = other.face, kg = other.k;
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

// Edge-connected components, numbered in the order of their lowest face: union-find over the
// faces sharing each edge (one pass over the edge uses), then labels in face order.
struct Components {
  std::vector<int> of_face;
  int count = 0;
};
Components label_components(const TriMesh& m, const EdgeFaces& edges) {
  std::vector<int> parent(m.faces.size());
  for (size_t f = 0; f < parent.size(); ++f) parent[f] = int(f);
  const auto find = [&](int f) {
    while (parent[size_t(f)] != f) f = parent[size_t(f)] = parent[size_t(parent[size_t(f)])];
    return f;
  };
  for (size_t v = 0; v + 1 < edges.start.size(); ++v)
    for (int i = edges.start[v] + 1; i < edges.start[v + 1]; ++i) {
      const auto &u = edges.uses[size_t(i)], &prev = edges.uses[size_t(i) - 1];
      if (u.other != prev.other) continue;  // a different edge
      const int a = find(prev.face), b = find(u.face);
      if (a != b) parent[size_t(std::max(a, b))] = std::min(a, b);
    }
  Components c;
  c.of_face.assign(m.faces.size(), -1);
  std::vector<int> label(m.faces.size(), -1);
  for (size_t f = 0; f < m.faces.size(); ++f) {
    const int r = find(int(f));
    if (label[size_t(r)] < 0) label[size_t(r)] = c.count++;
    c.of_face[f] = label[size_t(r)];
  }
  return c;
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

std::vector<std::vector<int>> vertex_rings(const TriMesh& m) {
  std::vector<std::vector<int>> ring(m.vertices.size());
  for (const auto& f : m.faces)
    for (int c = 0; c < 3; ++c) {
      ring[size_t(f[size_t(c)])].push_back(f[size_t((c + 1) % 3)]);
      ring[size_t(f[size_t(c)])].push_back(f[size_t((c + 2) % 3)]);
    }
  for (auto& r : ring) {
    std::sort(r.begin(), r.end());
    r.erase(std::unique(r.begin(), r.end()), r.end());
  }
  return ring;
}

LoadedMesh clean_mesh(TriMesh mesh, const std::string& what) {
  LoadedMesh out;
  for (const auto& v : mesh.vertices)
    if (!v.allFinite()) throw InputError(what + ": vertex coordinate is NaN or infinite");

  // Weld exactly coincident vertices (readers split non-manifold fans and seams; STL
  // has no shared vertices at all): each goes to its first occurrence.
  const auto& V = mesh.vertices;
  const std::vector<int> remap = first_occurrence(
      int(V.size()), [&](int i) { return mix(bits(V[i].x()) ^ mix(bits(V[i].y()) ^ mix(bits(V[i].z())))); },
      [&](int i, int j) { return V[i] == V[j]; });
  const double diag = bounding_box(mesh.vertices).diagonal();
  const double min_area = 1e-14 * diag * diag;  // relative: zero area to rounding

  std::vector<std::array<int, 3>> candidates, keys;
  candidates.reserve(mesh.faces.size());
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
    candidates.push_back(f);
  }
  // A triangle on the same three vertices as an earlier one is a duplicate.
  keys.reserve(candidates.size());
  for (const auto& f : candidates) keys.push_back(sorted(f));
  const std::vector<int> first_face = first_occurrence(
      int(keys.size()), [&](int i) { return mix(uint64_t(uint32_t(keys[i][0])) << 32 | uint32_t(keys[i][1])) ^ mix(uint64_t(keys[i][2])); },
      [&](int i, int j) { return keys[i] == keys[j]; });
  std::vector<std::array<int, 3>> faces;
  faces.reserve(candidates.size());
  for (size_t i = 0; i < candidates.size(); ++i) {
    if (first_face[i] != int(i)) {
      ++out.report.dropped_duplicate;
      continue;
    }
    faces.push_back(candidates[i]);
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
  const EdgeFaces edges(out.mesh);  // flipping keeps which faces share an edge
  out.report.flipped_to_orient = orient_components(out.mesh, edges);
  out.report.components = label_components(out.mesh, edges).count;
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
  const EdgeFaces edges(m);
  for (size_t v = 0; v + 1 < edges.start.size(); ++v)  // an edge with one use is a boundary edge
    for (int i = edges.start[v]; i < edges.start[v + 1]; ++i) {
      const auto& u = edges.uses[size_t(i)];
      if ((i > edges.start[v] && edges.uses[size_t(i) - 1].other == u.other) ||
          (i + 1 < edges.start[v + 1] && edges.uses[size_t(i) + 1].other == u.other))
        continue;
      t.boundary_edge[u.face][u.k] = true;
      t.boundary_vertex[m.faces[u.face][u.k]] = 1;
      t.boundary_vertex[m.faces[u.face][(u.k + 1) % 3]] = 1;
      ++t.boundary_edges;
    }
  Components c = label_components(m, edges);
  t.component = std::move(c.of_face);
  t.components = c.count;
  return t;
}

std::vector<Eigen::Vector3d> vertex_normals(const TriMesh& m) {
  // Each face's three weighted normals in parallel, then summed per vertex in face order (the
  // order of a serial loop: the same bits at any thread count).
  const long nf = long(m.faces.size());
  std::vector<std::array<Eigen::Vector3d, 3>> part(m.faces.size());
#pragma omp parallel for schedule(static) if (nf > 20000)
  for (long f = 0; f < nf; ++f) {
    const Eigen::Vector3d fn = face_normal(m, int(f));
    const auto& F = m.faces[size_t(f)];
    for (int k = 0; k < 3; ++k) {
      const Eigen::Vector3d e1 = m.vertices[size_t(F[size_t((k + 1) % 3)])] - m.vertices[size_t(F[size_t(k)])];
      const Eigen::Vector3d e2 = m.vertices[size_t(F[size_t((k + 2) % 3)])] - m.vertices[size_t(F[size_t(k)])];
      const double angle = std::atan2(e1.cross(e2).norm(), e1.dot(e2));
      part[size_t(f)][size_t(k)] = angle * fn;
    }
  }
  std::vector<Eigen::Vector3d> n(m.vertices.size(), Eigen::Vector3d::Zero());
  for (size_t f = 0; f < part.size(); ++f)
    for (int k = 0; k < 3; ++k) n[size_t(m.faces[f][size_t(k)])] += part[f][size_t(k)];
  const long nv = long(n.size());
#pragma omp parallel for schedule(static) if (nv > 20000)
  for (long v = 0; v < nv; ++v) {
    const double len = n[size_t(v)].norm();
    if (len > 0) n[size_t(v)] /= len;
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
