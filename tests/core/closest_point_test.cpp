#include "core/closest_point.h"

#include <doctest/doctest.h>

#include <random>

#include "core/envelope.h"
#include "tests/test_util.h"

using namespace flankcam;

namespace {

// Same footpoint as brute force: distance to rounding, same point (ties may pick another face).
void check_matches_brute_force(const SurfaceIndex& index, const std::vector<Eigen::Vector3d>& queries) {
  int mismatches = 0;
  for (const auto& q : queries) {
    const Footpoint fast = index.closest(q), slow = index.closest_brute_force(q);
    const bool same = std::abs(fast.distance - slow.distance) <= 1e-12 * (1 + slow.distance) &&
                      (fast.point - slow.point).norm() <= 1e-9 * (1 + slow.distance);
    if (!same) {
      ++mismatches;
      CAPTURE(q.transpose());
      CHECK(fast.distance == doctest::Approx(slow.distance));
    }
  }
  CHECK(mismatches == 0);
}

std::vector<Eigen::Vector3d> random_points(const TriMesh& m, double spread, int count, unsigned seed) {
  std::mt19937 rng(seed);
  const BoundingBox b = bounding_box(m.vertices);
  const Eigen::Vector3d lo = b.min - Eigen::Vector3d::Constant(spread), hi = b.max + Eigen::Vector3d::Constant(spread);
  std::vector<Eigen::Vector3d> out;
  for (int i = 0; i < count; ++i) {
    Eigen::Vector3d p;
    for (int k = 0; k < 3; ++k) p[k] = std::uniform_real_distribution<double>(lo[k], hi[k])(rng);
    out.push_back(p);
  }
  return out;
}

TriMesh random_soup(int triangles, unsigned seed) {
  std::mt19937 rng(seed);
  std::uniform_real_distribution<double> u(0, 100), small(-8, 8);
  TriMesh m;
  for (int i = 0; i < triangles; ++i) {
    const Eigen::Vector3d c(u(rng), u(rng), u(rng));
    for (int k = 0; k < 3; ++k) m.vertices.push_back(c + Eigen::Vector3d(small(rng), small(rng), small(rng)));
    m.faces.push_back({3 * i, 3 * i + 1, 3 * i + 2});
  }
  return m;
}

}  // namespace

TEST_CASE("closest points equal brute force on an open wavy surface, near and far") {
  const SurfaceIndex index(test::wavy_grid(40, 30, 120, 80, 8));
  check_matches_brute_force(index, random_points(index.mesh(), 5, 1500, 1));
  check_matches_brute_force(index, random_points(index.mesh(), 60, 500, 2));
  // Very far away: the footpoint is on the rim.
  check_matches_brute_force(index, {{1e5, 3e4, -2e4}, {-1e6, 0, 0}, {60, 40, 1e5}});
}

TEST_CASE("closest points equal brute force on random triangle soups") {
  for (unsigned seed : {3u, 4u, 5u}) {
    CAPTURE(seed);
    const SurfaceIndex index(clean_mesh(random_soup(400, seed), "soup").mesh);
    check_matches_brute_force(index, random_points(index.mesh(), 20, 800, seed + 10));
  }
}

TEST_CASE("closest points equal brute force on a mesh with holes and skinny triangles") {
  TriMesh grid = test::wavy_grid(60, 8, 200, 20, 5);  // long thin triangles
  std::vector<std::array<int, 3>> kept;
  for (size_t f = 0; f < grid.faces.size(); ++f)
    if (f % 17 != 3 && f % 23 != 5) kept.push_back(grid.faces[f]);
  grid.faces = kept;
  const SurfaceIndex index(clean_mesh(grid, "holes").mesh);
  check_matches_brute_force(index, random_points(index.mesh(), 10, 1500, 7));
}

TEST_CASE("a footpoint carries consistent barycentrics, a unit normal and the boundary flag") {
  const SurfaceIndex index(test::wavy_grid(20, 20, 100, 100, 0));  // the plane z = 0, normals +z
  const Footpoint inside = index.closest({37.3, 41.9, 5.0});
  CHECK(inside.distance == doctest::Approx(5.0));
  CHECK(inside.normal.z() == doctest::Approx(1.0));
  CHECK_FALSE(inside.on_boundary);
  const auto& F = index.mesh().faces[inside.face];
  const Eigen::Vector3d rebuilt = inside.barycentric[0] * index.mesh().vertices[F[0]] +
                                  inside.barycentric[1] * index.mesh().vertices[F[1]] +
                                  inside.barycentric[2] * index.mesh().vertices[F[2]];
  CHECK((rebuilt - inside.point).norm() < 1e-12);
  const Footpoint outside = index.closest({130.0, 50.0, 2.0});  // beyond the x = 100 rim
  CHECK(outside.on_boundary);
  CHECK(outside.point.x() == doctest::Approx(100.0));
  CHECK(outside.distance == doctest::Approx(std::sqrt(30.0 * 30.0 + 4.0)));
}

TEST_CASE("the batch call returns the same footpoints as single queries") {
  const SurfaceIndex index(test::wavy_grid(30, 30, 100, 100, 6));
  const auto pts = random_points(index.mesh(), 10, 3000, 11);
  const auto batch = index.closest(pts);
  REQUIRE(batch.size() == pts.size());
  for (size_t i = 0; i < pts.size(); ++i) {
    const Footpoint one = index.closest(pts[i]);
    CHECK(batch[i].face == one.face);
    CHECK(batch[i].distance == one.distance);
  }
}

TEST_CASE("closest points equal brute force on an exact envelope") {
  AnalyticMotionOptions o;
  o.kind = "arc";
  const EnvelopeGrid g = envelope_grid(analytic_motion(o), cone_profile(5, 8), 20, 50, 1);
  const SurfaceIndex index(g.mesh);
  check_matches_brute_force(index, random_points(index.mesh(), 15, 1000, 12));
}
