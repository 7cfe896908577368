// Mesh loading speed (issue 16 goal: >= 50 MB/s for OBJ and STL). Writes a 1000 x 1000-vertex
// wavy grid (1,000,000 vertices, 1,996,002 triangles) as OBJ (~85 MB) and binary STL (~100 MB)
// into a temporary folder, loads each with load_mesh (parse, check, weld, clean, orient) and,
// as the named peer, with OpenMesh's reader (parse only, into its PolyMesh), on the same file.
// With file arguments, it loads those instead: mesh_load_bench /work/shared/data/*/*.obj
#include <fmt/format.h>

#pragma GCC diagnostic ignored "-Wmaybe-uninitialized"  // in OpenMesh's headers
#include <OpenMesh/Core/IO/MeshIO.hh>
#include <OpenMesh/Core/Mesh/PolyMesh_ArrayKernelT.hh>

#include <Eigen/Geometry>
#include <chrono>
#include <cmath>
#include <cstring>
#include <ctime>
#include <filesystem>
#include <fstream>
#include <functional>
#include <unistd.h>

#include "core/mesh.h"

using namespace flankcam;

namespace {

double cpu_seconds() {
  timespec t{};
  clock_gettime(CLOCK_PROCESS_CPUTIME_ID, &t);
  return double(t.tv_sec) + 1e-9 * double(t.tv_nsec);
}

struct Timing {
  double cpu_s, wall_s;
};

Timing timed(const std::function<void()>& f) {
  const double c0 = cpu_seconds();
  const auto w0 = std::chrono::steady_clock::now();
  f();
  return {cpu_seconds() - c0, std::chrono::duration<double>(std::chrono::steady_clock::now() - w0).count()};
}

void write_binary_stl(const std::string& path, const TriMesh& m) {
  std::string data(84 + 50 * m.faces.size(), '\0');
  std::memcpy(data.data(), "binary STL written by mesh_load_bench", 37);
  const uint32_t n = uint32_t(m.faces.size());
  std::memcpy(data.data() + 80, &n, 4);
  char* p = data.data() + 84;
  for (const auto& f : m.faces) {
    const Eigen::Vector3f n_f = (m.vertices[f[1]] - m.vertices[f[0]]).cross(m.vertices[f[2]] - m.vertices[f[0]]).normalized().cast<float>();
    std::memcpy(p, n_f.data(), 12);
    for (int k = 0; k < 3; ++k) {
      const Eigen::Vector3f v = m.vertices[f[k]].cast<float>();
      std::memcpy(p + 12 + 12 * k, v.data(), 12);
    }
    p += 50;
  }
  std::ofstream(path, std::ios::binary).write(data.data(), std::streamsize(data.size()));
}

struct OMTraits : OpenMesh::DefaultTraits {
  typedef OpenMesh::Vec3d Point;
  typedef OpenMesh::Vec3d Normal;
};

void load_given(const std::string& path) {
  const double mb = double(std::filesystem::file_size(path)) / 1e6;
  LoadedMesh m;
  std::string error;
  const Timing t = timed([&] {
    try {
      m = load_mesh(path);
    } catch (const std::exception& e) {
      error = e.what();
    }
  });
  if (!error.empty()) {
    fmt::print("{}: error: {}\n", path, error);
    return;
  }
  OpenMesh::PolyMesh_ArrayKernelT<OMTraits> om;
  const Timing p = timed([&] {
    OpenMesh::IO::Options opt;
    (void)OpenMesh::IO::read_mesh(om, path, opt);
  });
  const auto& r = m.report;
  fmt::print("{}: {:.1f} MB, {} vertices, {} triangles ({} polygons triangulated, {} degenerate and {} duplicate dropped, "
             "{} flipped, {} components): {:.3f} CPU-s = {:.0f} MB/s; OpenMesh {:.3f} CPU-s = {:.0f} MB/s\n",
             path, mb, m.mesh.vertices.size(), m.mesh.faces.size(), r.polygons_triangulated, r.dropped_degenerate,
             r.dropped_duplicate, r.flipped_to_orient, r.components, t.cpu_s, mb / t.cpu_s, p.cpu_s, mb / p.cpu_s);
}

}  // namespace

int main(int argc, char** argv) {
  if (argc > 1) {
    for (int i = 1; i < argc; ++i) load_given(argv[i]);
    return 0;
  }
  const int n = 1000;
  TriMesh grid;
  for (int j = 0; j < n; ++j)
    for (int i = 0; i < n; ++i) {
      const double x = 2000.0 * i / (n - 1) - 1000.0, y = 1500.0 * j / (n - 1) - 700.0;
      grid.vertices.emplace_back(x, y, 40 * std::sin(0.011 * x) * std::cos(0.007 * y + 0.3 * std::sin(0.005 * x)));
    }
  for (int j = 0; j + 1 < n; ++j)
    for (int i = 0; i + 1 < n; ++i) {
      const int v = j * n + i;
      grid.faces.push_back({v, v + 1, v + n + 1});
      grid.faces.push_back({v, v + n + 1, v + n});
    }
  namespace fs = std::filesystem;
  const fs::path dir = fs::temp_directory_path() / ("flankcam-mesh-load-bench-" + std::to_string(::getpid()));
  fs::create_directories(dir);
  const std::string obj = (dir / "grid.obj").string(), stl = (dir / "grid.stl").string();
  write_obj(obj, grid, "mesh_load_bench");
  write_binary_stl(stl, grid);

  for (const std::string& path : {obj, stl}) {
    const double mb = double(fs::file_size(path)) / 1e6;
    const std::string name = fs::path(path).extension().string() == ".obj" ? "OBJ" : "binary STL";
    LoadedMesh ours;
    const Timing t = timed([&] { ours = load_mesh(path); });
    OpenMesh::PolyMesh_ArrayKernelT<OMTraits> om;
    bool om_ok = false;
    const Timing p = timed([&] {
      OpenMesh::IO::Options opt;
      om_ok = OpenMesh::IO::read_mesh(om, path, opt);
    });
    fmt::print("{:<10} {:6.1f} MB, {} vertices, {} triangles: flankcam load_mesh {:.2f} CPU-s {:.2f} s = {:.0f} MB/s "
               "[goal >= 50 MB/s]; OpenMesh read_mesh {}{} vertices, {} faces: {:.2f} CPU-s = {:.0f} MB/s; ratio {:.1f}x\n",
               name, mb, ours.mesh.vertices.size(), ours.mesh.faces.size(), t.cpu_s, t.wall_s, mb / t.cpu_s,
               om_ok ? "" : "(failed) ", om.n_vertices(), om.n_faces(), p.cpu_s, mb / p.cpu_s, p.cpu_s / t.cpu_s);
  }
  // The share of load_mesh that is not parsing: the same cleaning on the mesh in memory.
  const Timing c = timed([&] { (void)clean_mesh(grid, "grid"); });
  fmt::print("clean_mesh alone (weld, duplicates, orientation, topology) on the same grid: {:.2f} CPU-s\n", c.cpu_s);
  std::error_code ec;
  fs::remove_all(dir, ec);
}
