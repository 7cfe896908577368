// Exact closest-point queries per second on a 13,200-vertex exact envelope
// (unit bounding-box diagonal), query points within 10% of the diagonal.
// Goal (issue 2): >= 1,000,000 queries/s on 2 cores.
#include <fmt/format.h>
#include <omp.h>

#include <chrono>
#include <random>

#include "core/closest_point.h"
#include "core/envelope.h"

using namespace flankcam;

int main() {
  const EnvelopeGrid g = envelope_grid(analytic_motion({}), cone_profile(6, 9), 66, 200, 1);
  const TriMesh mesh = transformed(g.mesh, unit_diagonal_frame(g.mesh));
  const auto t_build = std::chrono::steady_clock::now();
  const SurfaceIndex index(mesh);
  const double build_s = std::chrono::duration<double>(std::chrono::steady_clock::now() - t_build).count();

  std::mt19937 rng(1);
  std::uniform_int_distribution<int> face(0, int(mesh.faces.size()) - 1);
  std::uniform_real_distribution<double> u(0, 1);
  std::normal_distribution<double> gauss;
  const int n = 1'000'000;
  std::vector<Eigen::Vector3d> queries(n);
  for (auto& q : queries) {
    const auto& F = mesh.faces[face(rng)];
    double b1 = u(rng), b2 = u(rng);
    if (b1 + b2 > 1) b1 = 1 - b1, b2 = 1 - b2;
    const Eigen::Vector3d on = mesh.vertices[F[0]] + b1 * (mesh.vertices[F[1]] - mesh.vertices[F[0]]) +
                               b2 * (mesh.vertices[F[2]] - mesh.vertices[F[0]]);
    q = on + 0.1 * u(rng) * Eigen::Vector3d(gauss(rng), gauss(rng), gauss(rng)).normalized();
  }
  (void)index.closest(std::vector<Eigen::Vector3d>(queries.begin(), queries.begin() + 10000));  // warm up
  const auto t0 = std::chrono::steady_clock::now();
  const auto result = index.closest(queries);
  const double seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  double checksum = 0;
  for (const auto& f : result) checksum += f.distance;
  fmt::print("closest_point: {} vertices, {} triangles, index built in {:.3f} s\n", mesh.vertices.size(),
             mesh.faces.size(), build_s);
  fmt::print("closest_point: {:.0f} exact queries/s on {} threads ({} queries in {:.3f} s, mean distance {:.4f}) "
             "[goal >= 1,000,000/s on 2 cores]\n",
             n / seconds, omp_get_max_threads(), n, seconds, checksum / n);
  return 0;
}
