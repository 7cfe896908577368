#include "core/check_surface.h"

#include <Eigen/Geometry>
#include <algorithm>
#include <cmath>
#include <utility>

namespace flankcam {

double signed_volume(const TriMesh& m) {
  double v = 0;
  for (const auto& f : m.faces) v += m.vertices[size_t(f[0])].dot(m.vertices[size_t(f[1])].cross(m.vertices[size_t(f[2])]));
  return v / 6;
}

CheckPart check_part(const TriMesh& part, const SurfaceIndex& design, double within) {
  CheckPart out;
  const bool flip = mesh_topology(part).boundary_edges == 0 && signed_volume(part) < 0;
  out.turned_outward = flip;
  const std::vector<Footpoint> fp = design.closest(part.vertices);
  // Candidates: all three corners on Φ. Φ's orientation relative to the part's is the sign of the
  // area-weighted agreement of their normals; a twin face agrees with it (the other side of a blade
  // thinner than `within` does not).
  std::vector<double> agree(part.faces.size(), 0.0);
  std::vector<char> candidate(part.faces.size(), 0);
  double sum = 0;
  for (size_t f = 0; f < part.faces.size(); ++f) {
    bool on = true;
    Eigen::Vector3d phi_normal = Eigen::Vector3d::Zero();
    for (int k = 0; k < 3 && on; ++k) {
      const Footpoint& q = fp[size_t(part.faces[f][size_t(k)])];
      on = q.face >= 0 && q.distance <= within;
      phi_normal += q.normal;
    }
    if (!on) continue;
    candidate[f] = 1;
    agree[f] = face_normal(part, int(f)).dot(phi_normal.normalized());
    sum += face_area(part, int(f)) * agree[f];
  }
  const double sign = sum < 0 ? -1.0 : 1.0;
  out.twin.assign(part.faces.size(), 0);
  std::vector<Eigen::Vector3d> between;  // twin faces' centroids and edge midpoints
  for (size_t f = 0; f < part.faces.size(); ++f) {
    std::array<int, 3> face = part.faces[f];
    if (candidate[f] && sign * agree[f] > 0.5) {
      ++out.twin_faces;
      out.twin[f] = 1;
      const Eigen::Vector3d &a = part.vertices[size_t(face[0])], &b = part.vertices[size_t(face[1])],
                            &c = part.vertices[size_t(face[2])];
      between.insert(between.end(), {(a + b + c) / 3, (a + b) / 2, (b + c) / 2, (c + a) / 2});
      continue;
    }
    if (flip) std::swap(face[1], face[2]);
    out.mesh.faces.push_back(face);
  }
  for (const Footpoint& q : design.closest(between)) out.twin_sag = std::max(out.twin_sag, q.distance);
  // Only the vertices the kept faces use.
  std::vector<int> index(part.vertices.size(), -1);
  std::vector<Eigen::Vector3d> used;
  for (auto& face : out.mesh.faces)
    for (int& v : face) {
      if (index[size_t(v)] < 0) {
        index[size_t(v)] = int(used.size());
        used.push_back(part.vertices[size_t(v)]);
      }
      v = index[size_t(v)];
    }
  out.mesh.vertices = std::move(used);
  return out;
}

TriMesh merged(const TriMesh& a, const TriMesh& b) {
  TriMesh out = a;
  const int n = int(a.vertices.size());
  out.vertices.insert(out.vertices.end(), b.vertices.begin(), b.vertices.end());
  for (auto f : b.faces) out.faces.push_back({f[0] + n, f[1] + n, f[2] + n});
  return out;
}

}  // namespace flankcam
