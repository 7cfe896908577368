// Triangle meshes: reading (checked readers, core/mesh_io.cpp), cleaning, topology, normals,
// and the similarity that maps input millimetres to the paper's unit-diagonal frame.
#pragma once
#include <Eigen/Core>
#include <array>
#include <string>
#include <vector>

namespace flankcam {

struct TriMesh {
  std::vector<Eigen::Vector3d> vertices;  // input units (mm) unless stated otherwise
  std::vector<std::array<int, 3>> faces;  // counter-clockwise seen from the normal side
};

// What the reader did to make a clean triangle mesh.
struct MeshReadReport {
  int polygons_triangulated = 0;  // input faces with more than three corners
  int dropped_degenerate = 0;     // zero-area triangles (or repeated corners)
  int dropped_duplicate = 0;      // triangles on the same three vertices as an earlier one
  int flipped_to_orient = 0;      // faces turned to agree with their component's orientation
  int components = 0;             // edge-connected components
};

struct LoadedMesh {
  TriMesh mesh;
  MeshReadReport report;
};

// Reads OBJ, STL (ASCII/binary), OFF or PLY (ASCII, binary either endian) in double precision,
// fan-triangulates polygons, then cleans like clean_mesh (which also welds STL's unshared corners).
// Throws InputError "FILE:LINE: what" (text) or "FILE: byte N: what" (binary) for: a missing or
// unreadable file, an unknown format, a malformed header or token, counts the file cannot hold,
// a face index out of range, a coordinate that is NaN, infinite or beyond 1e15 mm; and
// "FILE: mesh has no ..." when no triangle is left.
[[nodiscard]] LoadedMesh load_mesh(const std::string& path);

// Cleans a mesh built in memory the same way the reader does: drops degenerate and
// duplicate triangles, removes unreferenced vertices, orients each component consistently.
// `what` names the mesh in errors.
[[nodiscard]] LoadedMesh clean_mesh(TriMesh mesh, const std::string& what);

struct BoundingBox {
  Eigen::Vector3d min, max;
  [[nodiscard]] double diagonal() const { return (max - min).norm(); }
  [[nodiscard]] Eigen::Vector3d center() const { return 0.5 * (min + max); }
};
[[nodiscard]] BoundingBox bounding_box(const std::vector<Eigen::Vector3d>& points);

// x_unit = (x_mm - origin) * scale. The paper works on Φ scaled to a unit bounding-box
// diagonal; every number shown to a user goes back through to_mm / length_to_mm.
struct Similarity {
  Eigen::Vector3d origin = Eigen::Vector3d::Zero();
  double scale = 1.0;
  [[nodiscard]] Eigen::Vector3d to_unit(const Eigen::Vector3d& x_mm) const { return (x_mm - origin) * scale; }
  [[nodiscard]] Eigen::Vector3d to_mm(const Eigen::Vector3d& x_unit) const { return x_unit / scale + origin; }
  [[nodiscard]] double length_to_mm(double l_unit) const { return l_unit / scale; }
  [[nodiscard]] double length_to_unit(double l_mm) const { return l_mm * scale; }
};
[[nodiscard]] Similarity unit_diagonal_frame(const TriMesh& mesh);
[[nodiscard]] TriMesh transformed(const TriMesh& mesh, const Similarity& s);

// Edge k of face f joins corners k and (k+1)%3.
struct MeshTopology {
  std::vector<std::array<bool, 3>> boundary_edge;  // per face, per edge
  std::vector<char> boundary_vertex;               // per vertex
  std::vector<int> component;                      // per face
  int components = 0;
  int boundary_edges = 0;
};
[[nodiscard]] MeshTopology mesh_topology(const TriMesh& mesh);

// Per vertex its one-ring neighbours (sharing an edge), sorted.
[[nodiscard]] std::vector<std::vector<int>> vertex_rings(const TriMesh& mesh);

[[nodiscard]] Eigen::Vector3d face_normal(const TriMesh& mesh, int face);  // unit, zero if degenerate
[[nodiscard]] double face_area(const TriMesh& mesh, int face);
[[nodiscard]] double surface_area(const TriMesh& mesh);
// Angle-weighted vertex normals, unit length, oriented like the faces.
[[nodiscard]] std::vector<Eigen::Vector3d> vertex_normals(const TriMesh& mesh);

// Writes OBJ (mm, 9 significant decimals after the point) through a temporary file.
void write_obj(const std::string& path, const TriMesh& mesh, const std::string& comment = {});
// Writes ASCII PLY with per-vertex colours and one scalar per vertex (e.g. signed deviation, mm).
void write_ply(const std::string& path, const TriMesh& mesh, const std::vector<std::array<unsigned char, 3>>& colors,
               const std::vector<double>& scalar, const std::string& scalar_name, const std::string& comment = {});

}  // namespace flankcam
