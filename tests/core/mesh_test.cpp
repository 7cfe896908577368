#include "core/mesh.h"

#include <doctest/doctest.h>

#include <cstring>
#include <fstream>

#include "core/errors.h"
#include "tests/test_util.h"

using namespace flankcam;
using flankcam::test::ScratchDir;
using flankcam::test::write_text;

namespace {
const char* kQuadObj =
    "v 0 0 0\nv 10 0 0\nv 10 10 0\nv 0 10 0\nv 20 0 0\n"
    "f 1 2 3 4\nf 2 5 3\n";

void write_binary_stl(const std::string& path, const std::vector<std::array<Eigen::Vector3f, 3>>& tris) {
  std::ofstream out(path, std::ios::binary);
  char header[80] = "binary stl written by the flankcam tests";
  out.write(header, 80);
  const uint32_t n = uint32_t(tris.size());
  out.write(reinterpret_cast<const char*>(&n), 4);
  for (const auto& t : tris) {
    const float normal[3] = {0, 0, 1};
    out.write(reinterpret_cast<const char*>(normal), 12);
    for (const auto& v : t) out.write(reinterpret_cast<const char*>(v.data()), 12);
    const uint16_t attr = 0;
    out.write(reinterpret_cast<const char*>(&attr), 2);
  }
}

std::string error_of(const std::string& path) {
  try {
    (void)load_mesh(path);
  } catch (const InputError& e) {
    return e.what();
  }
  return "";
}
}  // namespace

TEST_CASE("OBJ polygons are triangulated and the mesh keeps its area") {
  ScratchDir dir("mesh");
  write_text(dir.file("quad.obj"), kQuadObj);
  const LoadedMesh m = load_mesh(dir.file("quad.obj"));
  CHECK(m.mesh.faces.size() == 3);
  CHECK(m.mesh.vertices.size() == 5);
  CHECK(m.report.polygons_triangulated == 1);
  CHECK(surface_area(m.mesh) == doctest::Approx(150.0));
  const MeshTopology t = mesh_topology(m.mesh);
  CHECK(t.boundary_edges == 5);
  CHECK(t.components == 1);
}

TEST_CASE("STL ascii and binary, OFF and PLY read to the same geometry") {
  ScratchDir dir("formats");
  write_text(dir.file("a.stl"),
             "solid t\nfacet normal 0 0 1\nouter loop\nvertex 0 0 0\nvertex 10 0 0\nvertex 10 10 0\nendloop\nendfacet\n"
             "facet normal 0 0 1\nouter loop\nvertex 0 0 0\nvertex 10 10 0\nvertex 0 10 0\nendloop\nendfacet\nendsolid t\n");
  write_binary_stl(dir.file("b.stl"), {{Eigen::Vector3f(0, 0, 0), Eigen::Vector3f(10, 0, 0), Eigen::Vector3f(10, 10, 0)},
                                       {Eigen::Vector3f(0, 0, 0), Eigen::Vector3f(10, 10, 0), Eigen::Vector3f(0, 10, 0)}});
  write_text(dir.file("c.off"), "OFF\n4 1 0\n0 0 0\n10 0 0\n10 10 0\n0 10 0\n4 0 1 2 3\n");
  write_text(dir.file("d.ply"),
             "ply\nformat ascii 1.0\nelement vertex 4\nproperty float x\nproperty float y\nproperty float z\n"
             "element face 2\nproperty list uchar int vertex_indices\nend_header\n"
             "0 0 0\n10 0 0\n10 10 0\n0 10 0\n3 0 1 2\n3 0 2 3\n");
  for (const char* name : {"a.stl", "b.stl", "c.off", "d.ply"}) {
    CAPTURE(name);
    const LoadedMesh m = load_mesh(dir.file(name));
    CHECK(m.mesh.faces.size() == 2);
    CHECK(m.mesh.vertices.size() == 4);  // STL corners are welded
    CHECK(surface_area(m.mesh) == doctest::Approx(100.0));
    CHECK(mesh_topology(m.mesh).boundary_edges == 4);
  }
}

TEST_CASE("bad mesh files give one clear error naming the file") {
  ScratchDir dir("bad");
  CHECK(error_of(dir.file("missing.obj")).find("missing.obj: file not found") != std::string::npos);
  write_text(dir.file("x.xyz"), "1 2 3\n");
  CHECK(error_of(dir.file("x.xyz")).find("unknown mesh format") != std::string::npos);
  write_text(dir.file("empty.obj"), "");
  CHECK(error_of(dir.file("empty.obj")).find("empty.obj: file is empty") != std::string::npos);
  write_text(dir.file("nan.obj"), "v 0 0 0\nv 1 0 nan\nv 0 1 0\nf 1 2 3\n");
  CHECK(error_of(dir.file("nan.obj")).find("nan.obj:2: vertex coordinate is NaN") != std::string::npos);
  write_text(dir.file("inf.off"), "OFF\n3 1 0\n0 0 0\ninf 0 0\n0 1 0\n3 0 1 2\n");
  CHECK(error_of(dir.file("inf.off")).find("NaN or infinite") != std::string::npos);
  write_text(dir.file("points.obj"), "v 0 0 0\nv 1 0 0\nv 0 1 0\n");
  CHECK(error_of(dir.file("points.obj")).find("points.obj: mesh has no") != std::string::npos);
  write_text(dir.file("flat.obj"), "v 0 0 0\nv 1 0 0\nv 2 0 0\nf 1 2 3\n");
  CHECK(error_of(dir.file("flat.obj")).find("no (non-degenerate) triangles") != std::string::npos);
  std::filesystem::create_directories(dir.file("dir.obj"));
  CHECK(error_of(dir.file("dir.obj")).find("is a directory") != std::string::npos);
}

TEST_CASE("degenerate and duplicate triangles are dropped and counted") {
  TriMesh m;
  m.vertices = {{0, 0, 0}, {10, 0, 0}, {10, 10, 0}, {0, 10, 0}, {20, 0, 0}, {10, 0, 0}};
  m.faces = {{0, 1, 2}, {0, 2, 3}, {2, 0, 1}, {0, 1, 4}, {1, 5, 2}};
  // {2,0,1} duplicates {0,1,2}; {0,1,4} is collinear; vertex 5 welds onto 1, so {1,5,2} repeats a corner.
  const LoadedMesh c = clean_mesh(m, "memory");
  CHECK(c.mesh.faces.size() == 2);
  CHECK(c.report.dropped_duplicate == 1);
  CHECK(c.report.dropped_degenerate == 2);
  CHECK(c.mesh.vertices.size() == 4);  // unreferenced vertices removed
}

TEST_CASE("each component is oriented consistently and normals follow it") {
  TriMesh m;
  m.vertices = {{0, 0, 0}, {10, 0, 0}, {10, 10, 0}, {0, 10, 0}};
  m.faces = {{0, 1, 2}, {0, 3, 2}};  // second face runs against the first
  const LoadedMesh c = clean_mesh(m, "memory");
  CHECK(c.report.flipped_to_orient == 1);
  CHECK(face_normal(c.mesh, 0).dot(face_normal(c.mesh, 1)) == doctest::Approx(1.0));
  for (const auto& n : vertex_normals(c.mesh)) CHECK(n.z() == doctest::Approx(1.0));
}

TEST_CASE("holes and several components are seen in the topology") {
  TriMesh grid = test::wavy_grid(12, 10, 110, 90, 3);
  // Cut a 2x2-cell hole in the middle and add a separate triangle.
  std::vector<std::array<int, 3>> kept;
  for (const auto& f : grid.faces) {
    const Eigen::Vector3d c = (grid.vertices[f[0]] + grid.vertices[f[1]] + grid.vertices[f[2]]) / 3;
    if (c.x() > 40 && c.x() < 60 && c.y() > 40 && c.y() < 60) continue;
    kept.push_back(f);
  }
  grid.faces = kept;
  const int base = int(grid.vertices.size());
  grid.vertices.insert(grid.vertices.end(), {{200, 0, 0}, {210, 0, 0}, {200, 10, 0}});
  grid.faces.push_back({base, base + 1, base + 2});
  const LoadedMesh c = clean_mesh(grid, "memory");
  const MeshTopology t = mesh_topology(c.mesh);
  CHECK(t.components == 2);
  // Outer rim 2*(11+9) edges, the hole's rim 8 edges, the lone triangle 3.
  CHECK(t.boundary_edges == 40 + 8 + 3);
}

TEST_CASE("the unit-diagonal frame maps the bounding box diagonal to 1 and back") {
  const TriMesh grid = test::wavy_grid(8, 8, 300, 120, 10);
  const Similarity s = unit_diagonal_frame(grid);
  const TriMesh unit = transformed(grid, s);
  CHECK(bounding_box(unit.vertices).diagonal() == doctest::Approx(1.0));
  CHECK(bounding_box(unit.vertices).center().norm() < 1e-12);
  for (size_t i = 0; i < grid.vertices.size(); ++i) CHECK((s.to_mm(unit.vertices[i]) - grid.vertices[i]).norm() < 1e-12);
  CHECK(s.length_to_mm(s.length_to_unit(0.01)) == doctest::Approx(0.01));
}

TEST_CASE("written OBJ reads back to the same mesh") {
  ScratchDir dir("write");
  const TriMesh grid = test::wavy_grid(9, 7, 80, 60, 4);
  write_obj(dir.file("g.obj"), grid, "test");
  const LoadedMesh back = load_mesh(dir.file("g.obj"));
  REQUIRE(back.mesh.vertices.size() == grid.vertices.size());
  REQUIRE(back.mesh.faces == grid.faces);
  // OpenMesh parses coordinates in single precision: 6e-8 relative.
  for (size_t i = 0; i < grid.vertices.size(); ++i)
    CHECK((back.mesh.vertices[i] - grid.vertices[i]).norm() < 2e-7 * (1 + grid.vertices[i].norm()));
  // No temporary file is left beside it.
  int files = 0;
  for ([[maybe_unused]] const auto& e : std::filesystem::directory_iterator(dir.path)) ++files;
  CHECK(files == 1);
}
