#include "core/mesh.h"

#include <doctest/doctest.h>

#if !defined(__clang__)
#pragma GCC diagnostic ignored "-Wmaybe-uninitialized"  // in OpenMesh's headers, for the reference reading
#endif
#include <OpenMesh/Core/IO/MeshIO.hh>
#include <OpenMesh/Core/Mesh/PolyMesh_ArrayKernelT.hh>
#include <fmt/format.h>

#include <algorithm>
#include <cmath>
#include <cstring>
#include <fstream>
#include <random>

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
  // Coordinates are parsed in double precision: only the writer's 9 decimals are lost.
  for (size_t i = 0; i < grid.vertices.size(); ++i) CHECK((back.mesh.vertices[i] - grid.vertices[i]).cwiseAbs().maxCoeff() <= 5.1e-10);
  // No temporary file is left beside it.
  int files = 0;
  for ([[maybe_unused]] const auto& e : std::filesystem::directory_iterator(dir.path)) ++files;
  CHECK(files == 1);
}

// ---- checked readers ------------------------------------------------------------------

namespace {
template <class T>
void put(std::string& out, T v, bool big_endian = false) {
  char b[sizeof(T)];
  std::memcpy(b, &v, sizeof(T));
  if (big_endian) std::reverse(b, b + sizeof(T));
  out.append(b, sizeof(T));
}

// A binary PLY of `m` with extra properties and elements the reader must skip: a uchar
// before x, a float list inside each vertex, an int after the face list, an "edge" element.
std::string binary_ply(const TriMesh& m, bool big_endian) {
  std::string s = fmt::format(
      "ply\nformat {} 1.0\ncomment written by the flankcam tests\nelement vertex {}\nproperty uchar flag\n"
      "property double x\nproperty list ushort float extra\nproperty float64 y\nproperty double z\n"
      "element face {}\nproperty list uchar uint vertex_indices\nproperty int tag\n"
      "element edge 2\nproperty int vertex1\nproperty int vertex2\nend_header\n",
      big_endian ? "binary_big_endian" : "binary_little_endian", m.vertices.size(), m.faces.size());
  for (size_t i = 0; i < m.vertices.size(); ++i) {
    const auto& v = m.vertices[i];
    put<uint8_t>(s, uint8_t(i), big_endian);
    put<double>(s, v.x(), big_endian);
    put<uint16_t>(s, 2, big_endian);
    put<float>(s, 1.5f, big_endian);
    put<float>(s, NAN, big_endian);  // skipped properties may hold anything
    put<double>(s, v.y(), big_endian);
    put<double>(s, v.z(), big_endian);
  }
  for (const auto& f : m.faces) {
    put<uint8_t>(s, 3, big_endian);
    for (int i : f) put<uint32_t>(s, uint32_t(i), big_endian);
    put<int32_t>(s, -7, big_endian);
  }
  for (int e = 0; e < 2; ++e) {
    put<int32_t>(s, 0, big_endian);
    put<int32_t>(s, 1, big_endian);
  }
  return s;
}

std::string ascii_stl(const TriMesh& m) {
  std::string s = "solid grid\n";
  for (const auto& f : m.faces) {
    s += "  facet normal 0 0 1\n    outer loop\n";
    for (int i : f) s += fmt::format("      vertex {:.17g} {:.17g} {:.17g}\n", m.vertices[i].x(), m.vertices[i].y(), m.vertices[i].z());
    s += "    endloop\n  endfacet\n";
  }
  return s + "endsolid grid\n";
}

std::string off_text(const TriMesh& m) {
  std::string s = fmt::format("OFF\n# a comment\n{} {} 0\n", m.vertices.size(), m.faces.size());
  for (const auto& v : m.vertices) s += fmt::format("{:.17g} {:.17g} {:.17g}\n", v.x(), v.y(), v.z());
  for (const auto& f : m.faces) s += fmt::format("3 {} {} {}\n", f[0], f[1], f[2]);
  return s;
}

// Vertices equal to `tol` and faces equal, for meshes whose vertex order the reader keeps.
void check_same_mesh(const TriMesh& got, const TriMesh& want, double tol) {
  REQUIRE(got.vertices.size() == want.vertices.size());
  CHECK(got.faces == want.faces);
  double worst = 0;
  for (size_t i = 0; i < want.vertices.size(); ++i)
    worst = std::max(worst, (got.vertices[i] - want.vertices[i]).cwiseAbs().maxCoeff());
  CHECK(worst <= tol);
}

// STL has no shared vertices: the welded mesh keeps the first corner occurrences' order,
// so compare through the exact coordinates.
void check_same_welded_mesh(const TriMesh& got, const TriMesh& want, double tol) {
  REQUIRE(got.vertices.size() == want.vertices.size());
  REQUIRE(got.faces.size() == want.faces.size());
  std::vector<int> to_want(got.vertices.size(), -1);
  for (size_t f = 0; f < want.faces.size(); ++f)
    for (int k = 0; k < 3; ++k) to_want[size_t(got.faces[f][k])] = want.faces[f][k];
  double worst = 0;
  for (size_t i = 0; i < got.vertices.size(); ++i) {
    REQUIRE(to_want[i] >= 0);
    worst = std::max(worst, (got.vertices[i] - want.vertices[size_t(to_want[i])]).cwiseAbs().maxCoeff());
  }
  CHECK(worst <= tol);
  for (size_t f = 0; f < want.faces.size(); ++f)
    for (int k = 0; k < 3; ++k) CHECK(to_want[size_t(got.faces[f][k])] == want.faces[f][k]);
}

// The old reading through OpenMesh, kept here as the reference for well-formed files.
LoadedMesh openmesh_load(const std::string& path) {
  struct DoubleTraits : OpenMesh::DefaultTraits {
    typedef OpenMesh::Vec3d Point;
    typedef OpenMesh::Vec3d Normal;
  };
  OpenMesh::PolyMesh_ArrayKernelT<DoubleTraits> om;
  OpenMesh::IO::Options opt;
  REQUIRE(OpenMesh::IO::read_mesh(om, path, opt));
  TriMesh raw;
  for (const auto& vh : om.vertices()) raw.vertices.emplace_back(om.point(vh)[0], om.point(vh)[1], om.point(vh)[2]);
  for (const auto& fh : om.faces()) {
    std::vector<int> c;
    for (const auto& vh : om.fv_range(fh)) c.push_back(vh.idx());
    for (size_t k = 1; k + 1 < c.size(); ++k) raw.faces.push_back({c[0], c[k], c[k + 1]});
  }
  return clean_mesh(raw, path);
}
}  // namespace

TEST_CASE("every format reads back what was written, in double precision") {
  ScratchDir dir("roundtrip");
  TriMesh grid = test::wavy_grid(7, 6, 80, 60, 4);
  for (auto& v : grid.vertices) v += Eigen::Vector3d(123456.789012345678, -0.000123456789, 1e-7);  // needs doubles
  SUBCASE("OBJ through write_obj") {
    write_obj(dir.file("g.obj"), grid);
    check_same_mesh(load_mesh(dir.file("g.obj")).mesh, grid, 5.1e-10);  // the writer's 9 decimals
  }
  SUBCASE("ascii PLY through write_ply, with colours and a NaN scalar") {
    std::vector<double> scalar(grid.vertices.size(), 0.25);
    scalar[3] = NAN;
    write_ply(dir.file("g.ply"), grid, {}, scalar, "deviation_mm");
    check_same_mesh(load_mesh(dir.file("g.ply")).mesh, grid, 5.1e-10);
  }
  SUBCASE("binary PLY, both byte orders, with properties and elements to skip") {
    for (const bool big : {false, true}) {
      CAPTURE(big);
      write_text(dir.file("b.ply"), binary_ply(grid, big));
      check_same_mesh(load_mesh(dir.file("b.ply")).mesh, grid, 0.0);
    }
  }
  SUBCASE("OFF") {
    write_text(dir.file("g.off"), off_text(grid));
    check_same_mesh(load_mesh(dir.file("g.off")).mesh, grid, 0.0);
  }
  SUBCASE("ascii STL: corners are welded back to the grid's vertices") {
    write_text(dir.file("g.stl"), ascii_stl(grid));
    check_same_welded_mesh(load_mesh(dir.file("g.stl")).mesh, grid, 0.0);
  }
  SUBCASE("binary STL: single precision by the format, welded, deterministic") {
    TriMesh small = test::wavy_grid(7, 6, 80, 60, 4);
    std::vector<std::array<Eigen::Vector3f, 3>> tris;
    for (const auto& f : small.faces)
      tris.push_back({small.vertices[f[0]].cast<float>(), small.vertices[f[1]].cast<float>(), small.vertices[f[2]].cast<float>()});
    write_binary_stl(dir.file("g.stl"), tris);
    const LoadedMesh a = load_mesh(dir.file("g.stl")), b = load_mesh(dir.file("g.stl"));
    check_same_welded_mesh(a.mesh, small, 4e-6);  // float rounding of |x| <= 80
    CHECK(a.mesh.vertices == b.mesh.vertices);
    CHECK(a.mesh.faces == b.mesh.faces);
    CHECK(mesh_topology(a.mesh).components == 1);
    CHECK(mesh_topology(a.mesh).boundary_edges == 2 * (6 + 5));
  }
}

TEST_CASE("OBJ corners in every form, relative indices, polygons and ignored statements") {
  ScratchDir dir("objforms");
  write_text(dir.file("f.obj"),
             "# comment\nmtllib x.mtl\no thing\nv 0 0 0\nv +10 0 0 1\nv 10 10 0 0.5 0.5 0.5\nv 0 10 0\r\n"
             "vt 0 0\nvn 0 0 1\ng group\nusemtl m\ns off\n"
             "f 1/1/1 2/1/1 3//1 4/1\n"
             "v\t20 0 0\n"
             "f -4 -1 -3\n"
             "l 1 2\n");
  const LoadedMesh m = load_mesh(dir.file("f.obj"));
  CHECK(m.mesh.faces.size() == 3);
  CHECK(m.mesh.vertices.size() == 5);
  CHECK(m.report.polygons_triangulated == 1);
  CHECK(surface_area(m.mesh) == doctest::Approx(150.0));
  CHECK(mesh_topology(m.mesh).boundary_edges == 5);
}

TEST_CASE("the reader equals the old OpenMesh reading on the bundled example meshes") {
  for (const char* name : {"examples/blade/blade.obj", "examples/exact-envelope/envelope.obj"}) {
    CAPTURE(name);
    const std::string path = std::string(FLANKCAM_SOURCE_DIR) + "/" + name;
    const LoadedMesh ours = load_mesh(path), old = openmesh_load(path);
    REQUIRE(ours.mesh.vertices.size() == old.mesh.vertices.size());
    CHECK(ours.mesh.faces.size() == old.mesh.faces.size());
    CHECK(ours.mesh.faces == old.mesh.faces);
    double worst = 0;  // OpenMesh parsed OBJ coordinates as floats
    for (size_t i = 0; i < ours.mesh.vertices.size(); ++i)
      worst = std::max(worst, ((ours.mesh.vertices[i] - old.mesh.vertices[i]).array() /
                               (1.0 + ours.mesh.vertices[i].array().abs())).abs().maxCoeff());
    CHECK(worst <= 1.2e-7);
    CHECK(ours.report.dropped_degenerate == old.report.dropped_degenerate);
    CHECK(ours.report.dropped_duplicate == old.report.dropped_duplicate);
    CHECK(ours.report.components == old.report.components);
  }
}

// Each reproducer found by fuzzing (issue 12) ends in one line naming the file and the
// line (or byte) and what is wrong.
TEST_CASE("fuzzed PLY headers give a clear error") {
  ScratchDir dir("fuzzply");
  const std::string path = dir.file("x.ply");
  const std::string tail = "property float x\nproperty float y\nproperty float z\nelement face 1\n"
                           "property list uchar int vertex_indices\nend_header\n";
  SUBCASE("a property before any element, ascii and binary (was SIGSEGV)") {
    for (const char* format : {"ascii", "binary_little_endian"}) {
      CAPTURE(format);
      write_text(path, fmt::format("ply\nformat {} 1.0\nproperty float w\nelement vertex 3\n{}", format, tail) + "0 0 0\n");
      CHECK(error_of(path) == path + ":3: property declared before any element");
    }
  }
  SUBCASE("element vertex abc (was a hang)") {
    write_text(path, "ply\nformat ascii 1.0\nelement vertex abc\n" + tail + "0 0 0\n");
    CHECK(error_of(path) == path + ":3: element vertex count 'abc' is not a non-negative integer");
  }
  SUBCASE("a vertex token 0u5 (was a hang)") {
    write_text(path, "ply\nformat ascii 1.0\nelement vertex 3\n" + tail + "0 0 0\n1 0u5 0\n0 1 0\n3 0 1 2\n");
    CHECK(error_of(path) == path + ":11: vertex 1 y '0u5' is not a number");
  }
  SUBCASE("vertex count 4294967295 (was bad_alloc)") {
    write_text(path, "ply\nformat binary_little_endian 1.0\nelement vertex 4294967295\n" + tail + std::string(200, '\0'));
    CHECK(error_of(path) == path + ":3: element vertex declares 4294967295 entries but only 200 bytes follow the header");
  }
  SUBCASE("2e9 faces declared, 70 present (was accepted)") {
    std::string body = "0 0 0\n1 0 0\n0 1 0\n";
    for (int i = 0; i < 70; ++i) body += "3 0 1 2\n";
    write_text(path, "ply\nformat ascii 1.0\nelement vertex 3\nproperty float x\nproperty float y\nproperty float z\n"
                     "element face 2000000000\nproperty list uchar int vertex_indices\nend_header\n" + body);
    CHECK(error_of(path) == path + ":7: element face declares 2000000000 entries but only 578 bytes follow the header");
    write_text(path, "ply\nformat ascii 1.0\nelement vertex 3\nproperty float x\nproperty float y\nproperty float z\n"
                     "element face 2e9\nproperty list uchar int vertex_indices\nend_header\n" + body);
    CHECK(error_of(path) == path + ":7: element face count '2e9' is not a non-negative integer");
    write_text(path, "ply\nformat ascii 1.0\nelement vertex 3\nproperty float x\nproperty float y\nproperty float z\n"
                     "element face 71\nproperty list uchar int vertex_indices\nend_header\n" + body);
    CHECK(error_of(path) == path + ":82: file ends before face 70 vertex_indices");
  }
  SUBCASE("face indices out of range, ascii and binary") {
    write_text(path, "ply\nformat ascii 1.0\nelement vertex 3\n" + tail + "0 0 0\n1 0 0\n0 1 0\n3 0 1 3\n");
    CHECK(error_of(path) == path + ":13: face 0 vertex_indices index 3 is out of range (the file has 3 vertices)");
    std::string bin = "ply\nformat binary_big_endian 1.0\nelement vertex 3\n" + tail;
    const size_t header = bin.size();
    for (float c : {0.f, 0.f, 0.f, 1.f, 0.f, 0.f, 0.f, 1.f, 0.f}) put<float>(bin, c, true);
    put<uint8_t>(bin, 3);
    for (int i : {0, 1, -1}) put<int32_t>(bin, i, true);
    write_text(path, bin);
    CHECK(error_of(path) == path + ": byte " + std::to_string(header + 36 + 1 + 8) +
                                ": face 0 vertex_indices index -1 is out of range (the file has 3 vertices)");
  }
  SUBCASE("a binary NaN coordinate names its byte") {
    std::string bin = "ply\nformat binary_little_endian 1.0\nelement vertex 3\n" + tail;
    const size_t header = bin.size();
    for (float c : {0.f, 0.f, 0.f, 1.f, NAN, 0.f, 0.f, 1.f, 0.f}) put<float>(bin, c);
    put<uint8_t>(bin, 3);
    for (int i : {0, 1, 2}) put<int32_t>(bin, i);
    write_text(path, bin);
    CHECK(error_of(path) == path + ": byte " + std::to_string(header + 16) + ": vertex 1 y: vertex coordinate is NaN or infinite");
  }
}

TEST_CASE("fuzzed OFF files give a clear error") {
  ScratchDir dir("fuzzoff");
  const std::string path = dir.file("x.off");
  write_text(path, "OFF\n3 1 0\n0 0 0\n1 0 0\n0 1 0\n-1 0 1 2\n");  // was a hang
  CHECK(error_of(path) == path + ":6: face corner count '-1' is not an integer >= 3");
  write_text(path, "OFF\n3 2e9 0\n0 0 0\n1 0 0\n0 1 0\n3 0 1 2\n");  // was a hang
  CHECK(error_of(path) == path + ":2: face count '2e9' is not a non-negative integer");
  write_text(path, "OFF\n3 2000000000 0\n0 0 0\n1 0 0\n0 1 0\n3 0 1 2\n");
  CHECK(error_of(path) == path + ":2: header declares 3 vertices and 2000000000 faces but only 26 bytes follow");
  write_text(path, "OFF\n-5 1 0\n0 0 0\n1 0 0\n0 1 0\n3 0 1 2\n");  // was bad_alloc
  CHECK(error_of(path) == path + ":2: vertex count '-5' is not a non-negative integer");
  write_text(path, "OFF\n3 1 0\n0 0 0\n1 0 0\n0 1 0\n3 0 1 5\n");
  CHECK(error_of(path) == path + ":6: face index 5 is out of range (the file has 3 vertices)");
  write_text(path, "OFF\n3 2 0\n0 0 0\n1 0 0\n0 1 0\n3 0 1 2\n");  // 34 bytes needed at least
  CHECK(error_of(path) == path + ":2: header declares 3 vertices and 2 faces but only 26 bytes follow");
  write_text(path, "OFF\n3 2 0\n0.5 0.5 0.5\n1.5 0 0\n0 1.5 0\n3 0 1 2\n");
  CHECK(error_of(path) == path + ":6: file ends after 1 of 2 faces");
}

TEST_CASE("fuzzed OBJ files give a clear error") {
  ScratchDir dir("fuzzobj");
  const std::string path = dir.file("x.obj");
  write_text(path, "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\nf 1 2 4\n");  // was dropped uncounted
  CHECK(error_of(path) == path + ":5: face index 4 is out of range (the file has 3 vertices)");
  write_text(path, "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 -4\n");
  CHECK(error_of(path) == path + ":4: relative face index -4 but only 3 vertices precede it");
  write_text(path, "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 0 1 2\n");
  CHECK(error_of(path) == path + ":4: face index 0 (OBJ indices start at 1)");
  write_text(path, "v 0 0 0\nv 1e39 0 0\nv 0 1 0\nf 1 2 3\n");  // was changed silently
  CHECK(error_of(path) == path + ":2: vertex coordinate 1e+39 is beyond 1e15 mm in magnitude");
  write_text(path, "v 0 0 0\nv 1e400 0 0\nv 0 1 0\nf 1 2 3\n");
  CHECK(error_of(path) == path + ":2: vertex coordinate '1e400' is beyond 1e15 mm in magnitude");
  write_text(path, "v 0 0 0\nv 1 0 0\nv 0 1x 0\nf 1 2 3\n");
  CHECK(error_of(path) == path + ":3: '1x' is not a number");
  write_text(path, "v 0 0 0\nv 1 0\nv 0 1 0\nf 1 2 3\n");
  CHECK(error_of(path) == path + ":2: missing vertex coordinate");
  write_text(path, "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2\n");
  CHECK(error_of(path) == path + ":4: face has 2 corners, at least 3 needed");
  write_text(path, "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2/x 3\n");
  CHECK(error_of(path) == path + ":4: face corner '2/x' is not of the form v, v/t, v//n or v/t/n");
  // Within range, the value is kept to double precision, not rounded to a float.
  write_text(path, "v 0 0 0\nv 1e15 0 0\nv 0 -1e15 0.1234567890123\nf 1 2 3\n");
  const LoadedMesh m = load_mesh(path);
  CHECK(m.mesh.vertices[1].x() == 1e15);
  CHECK(m.mesh.vertices[2].y() == -1e15);
  CHECK(m.mesh.vertices[2].z() == 0.1234567890123);
}

TEST_CASE("fuzzed STL files give a clear error") {
  ScratchDir dir("fuzzstl");
  const std::string path = dir.file("x.stl");
  write_binary_stl(path, {{Eigen::Vector3f(0, 0, 0), Eigen::Vector3f(1, 0, 0), Eigen::Vector3f(0, 1, 0)},
                          {Eigen::Vector3f(0, 0, 0), Eigen::Vector3f(1, 0, 0), Eigen::Vector3f(0, 1, NAN)}});
  // was "mesh has no faces": the NaN is z of the second triangle's third corner
  CHECK(error_of(path) == path + ": byte " + std::to_string(84 + 50 + 12 + 32) + ": triangle 2: vertex coordinate is NaN or infinite");
  std::string data = test::read_text(path);
  write_text(path, data.substr(0, data.size() - 1));
  CHECK(error_of(path) == path + ": byte 80: binary STL header says 2 triangles (184 bytes) but the file has 183 bytes");
  write_text(path, data.substr(0, 40));
  CHECK(error_of(path) == path + ": byte 40: binary STL is 40 bytes, shorter than its 84-byte header");
  write_text(path, "solid x\nfacet normal 0 0 1\nouter loop\nvertex 0 0 0\nvertex 1 0 0\nendloop\nendfacet\nendsolid x\n");
  CHECK(error_of(path) == path + ":6: 'endloop' where 'vertex' was expected");
  write_text(path, "solid x\nfacet normal 0 0 1\nouter loop\nvertex 0 0 0\nvertex 1 0 0\nvertex 0 1 0\nendloop\nendfacet\n");
  CHECK(error_of(path) == path + ":8: file ends inside a solid (no 'endsolid')");
  write_text(path, "solid x\nfacet normal 0 0 1\nouter loop\nvertex 0 0 0\nvertex 1 0 0\nvertex 0 inf 0\nendloop\nendfacet\nendsolid\n");
  CHECK(error_of(path) == path + ":6: vertex coordinate is NaN or infinite");
}

TEST_CASE("truncated and mutated files load or give an InputError, never anything else") {
  ScratchDir dir("mutate");
  const TriMesh grid = test::wavy_grid(4, 3, 30, 20, 2);
  std::vector<std::array<Eigen::Vector3f, 3>> tris;
  for (const auto& f : grid.faces)
    tris.push_back({grid.vertices[f[0]].cast<float>(), grid.vertices[f[1]].cast<float>(), grid.vertices[f[2]].cast<float>()});
  write_binary_stl(dir.file("seed.stl"), tris);
  write_obj(dir.file("seed.obj"), grid);
  write_ply(dir.file("seed.ply"), grid, {}, {}, "");
  const std::vector<std::pair<std::string, std::string>> seeds = {
      {"obj", test::read_text(dir.file("seed.obj"))},      {"ply", test::read_text(dir.file("seed.ply"))},
      {"ply", binary_ply(grid, false)},                    {"ply", binary_ply(grid, true)},
      {"off", off_text(grid)},                             {"stl", ascii_stl(grid)},
      {"stl", test::read_text(dir.file("seed.stl"))}};
  std::mt19937 rng;
  int loaded = 0, refused = 0;
  const std::string bytes = " \n0123456789-+.eE/#nax\xff";
  for (size_t s = 0; s < seeds.size(); ++s) {
    const auto& [ext, text] = seeds[s];
    const std::string path = dir.file("m." + ext);
    std::vector<std::string> cases;
    for (size_t cut = 0; cut < text.size(); cut += 1 + text.size() / 150) cases.push_back(text.substr(0, cut));
    for (int i = 0; i < 300; ++i) {
      std::string m = text;
      for (int k = 0; k < 1 + int(rng() % 3); ++k) {
        const size_t at = rng() % m.size();
        if (rng() % 2) m[at] = bytes[rng() % bytes.size()];
        else m[at] = char(rng());
      }
      cases.push_back(m);
    }
    for (const auto& c : cases) {
      write_text(path, c);
      try {
        const LoadedMesh got = load_mesh(path);
        CHECK(!got.mesh.faces.empty());
        for (const auto& f : got.mesh.faces)
          for (int i : f) CHECK((i >= 0 && i < int(got.mesh.vertices.size())));
        for (const auto& v : got.mesh.vertices) CHECK((v.allFinite() && v.cwiseAbs().maxCoeff() <= 1e15));
        ++loaded;
      } catch (const InputError& e) {
        const std::string what = e.what();
        CHECK(what.rfind(path, 0) == 0);
        CHECK(what.find('\n') == std::string::npos);
        ++refused;
      }
    }
  }
  CHECK(loaded > 100);
  CHECK(refused > 100);
}

TEST_CASE("counts that need no bytes and values after the needed ones are checked too") {
  ScratchDir dir("extra");
  const std::string ply = dir.file("x.ply");
  // An element without properties reads nothing, however many entries it declares.
  write_text(ply, "ply\nformat ascii 1.0\nelement empty 9223372036854775807\nelement vertex 3\nproperty float x\n"
                  "property float y\nproperty float z\nelement face 1\nproperty list uchar int vertex_indices\nend_header\n"
                  "0 0 0\n1 0 0\n0 1 0\n3 0 1 2\n");
  CHECK(load_mesh(ply).mesh.faces.size() == 1);
  const std::string off = dir.file("x.off");
  write_text(off, "COFF\n3 1 0\n0 0 0 1 1 1 1\n1 0 0 1 1 1 1\n0 1 0 1 1 1 1\n3 0 1 2 255 0 0\n");
  CHECK(load_mesh(off).mesh.faces.size() == 1);
  write_text(off, "COFF\n3 1 0\n0 0 0 1 1 1 1\n1 0 0 1 x 1 1\n0 1 0 1 1 1 1\n3 0 1 2\n");
  CHECK(error_of(off) == off + ":4: 'x' is not a finite number");
  const std::string obj = dir.file("x.obj");
  write_text(obj, "v 0 0 0 # origin\nv 1 0 0 1 0 0\nv 0 1 0\nf 1 2 3 # one face\n");
  CHECK(load_mesh(obj).mesh.faces.size() == 1);
  write_text(obj, "v 0 0 0\nv 1 0 0 nan\nv 0 1 0\nf 1 2 3\n");
  CHECK(error_of(obj) == obj + ":2: 'nan' is not a finite number");
}
