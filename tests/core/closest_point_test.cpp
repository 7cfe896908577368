#include "core/closest_point.h"

#include <doctest/doctest.h>
#include <omp.h>

#include <cmath>
#include <limits>
#include <numeric>
#include <random>

#include "core/envelope.h"
#include "core/check_surface.h"
#include "tests/test_util.h"

using namespace flankcam;

namespace {

// Same footpoint as brute force, bit for bit: same face (ties go to the lower index in both),
// hence the same point, distance and normal.
void check_matches_brute_force(const SurfaceIndex& index, const std::vector<Eigen::Vector3d>& queries) {
  int mismatches = 0;
  for (const auto& q : queries) {
    const Footpoint fast = index.closest(q), slow = index.closest_brute_force(q);
    const bool same = fast.face == slow.face && fast.distance == slow.distance && fast.point == slow.point &&
                      fast.normal == slow.normal && fast.on_boundary == slow.on_boundary;
    if (!same) {
      ++mismatches;
      CAPTURE(q.transpose());
      CHECK(fast.face == slow.face);
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

// One sliver 300 mm long in all three axes beside 20,000 faces 0.01 mm wide: the cell grid (cells a
// leaf wide) cannot hold it, and deciding so once walked the sliver's box, (300 / 0.02)^3 cells (a
// wild candidate's machined surface on NASA rotor 37 held a fit over 10 minutes). The index is built and answers exactly.
TEST_CASE("a sliver spanning the whole box beside fine faces is indexed, and answers as brute force") {
  TriMesh m = test::wavy_grid(101, 101, 1.0, 1.0, 0.02);
  const int base = int(m.vertices.size());
  for (const Eigen::Vector3d& v : {Eigen::Vector3d(0, 0, 0), Eigen::Vector3d(300, 300, 300), Eigen::Vector3d(300, 300.001, 300)})
    m.vertices.push_back(v);
  m.faces.push_back({base, base + 1, base + 2});
  const SurfaceIndex index(m);
  check_matches_brute_force(index, random_points(index.mesh(), 1, 300, 21));
  const Footpoint on_sliver = index.closest({150, 150.0005, 150.3});
  CHECK(on_sliver.face == int(m.faces.size()) - 1);
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

namespace {
// Points at a given distance from random points of random faces, along the face normal, both sides.
std::vector<Eigen::Vector3d> offset_points(const TriMesh& m, double offset, int count, unsigned seed) {
  std::mt19937 rng(seed);
  std::uniform_int_distribution<int> face(0, int(m.faces.size()) - 1);
  std::uniform_real_distribution<double> u(0, 1);
  std::vector<Eigen::Vector3d> out;
  for (int i = 0; i < count; ++i) {
    const int f = face(rng);
    const auto& F = m.faces[size_t(f)];
    double b1 = u(rng), b2 = u(rng);
    if (b1 + b2 > 1) b1 = 1 - b1, b2 = 1 - b2;
    const Eigen::Vector3d &a = m.vertices[size_t(F[0])], &b = m.vertices[size_t(F[1])], &c = m.vertices[size_t(F[2])];
    out.push_back(a + b1 * (b - a) + b2 * (c - a) + (u(rng) < 0.5 ? -offset : offset) * face_normal(m, f));
  }
  return out;
}
}  // namespace

TEST_CASE("closest points equal brute force on a 13k-face envelope at the distances a fit queries") {
  // Big enough for the hierarchy's upper nodes (which enclose their children's boxes) to matter.
  const EnvelopeGrid g = envelope_grid(analytic_motion({}), cone_profile(6, 9), 40, 170, 1);
  const TriMesh mesh = transformed(g.mesh, unit_diagonal_frame(g.mesh));
  REQUIRE(mesh.faces.size() > 12000);
  const SurfaceIndex index(mesh);
  for (double offset : {0.0, 1e-9, 0.01, 0.05, 0.3}) {
    CAPTURE(offset);
    check_matches_brute_force(index, offset_points(mesh, offset, 150, 21));
  }
  // Queries exactly at vertices and edge midpoints: many faces at distance 0, the lowest index wins.
  std::vector<Eigen::Vector3d> shared;
  for (size_t f = 0; f < mesh.faces.size(); f += 97) {
    const auto& F = mesh.faces[f];
    shared.push_back(mesh.vertices[size_t(F[0])]);
    shared.push_back(0.5 * (mesh.vertices[size_t(F[1])] + mesh.vertices[size_t(F[2])]));
  }
  check_matches_brute_force(index, shared);
}

TEST_CASE("the batch call equals brute force bit for bit on dense queries, each started from the last answer, on 1 and 2 threads") {
  // 2000 queries on 2,000 faces: in Morton order consecutive queries share faces and leaves, so the
  // search mostly starts from the previous answer's leaf; vertices and edge midpoints add ties.
  const EnvelopeGrid g = envelope_grid(analytic_motion({}), cone_profile(6, 9), 20, 50, 1);
  const TriMesh mesh = transformed(g.mesh, unit_diagonal_frame(g.mesh));
  const SurfaceIndex index(mesh);
  for (double offset : {0.0, 0.01, 0.05}) {
    CAPTURE(offset);
    std::vector<Eigen::Vector3d> queries = offset_points(mesh, offset, 2000, 41);
    for (size_t f = 0; f < mesh.faces.size(); f += 14) {
      queries.push_back(mesh.vertices[size_t(mesh.faces[f][0])]);
      queries.push_back(0.5 * (mesh.vertices[size_t(mesh.faces[f][1])] + mesh.vertices[size_t(mesh.faces[f][2])]));
    }
    const int threads = omp_get_max_threads();
    omp_set_num_threads(1);
    const auto one = index.closest(queries);
    omp_set_num_threads(2);
    const auto two = index.closest(queries);
    omp_set_num_threads(threads);
    REQUIRE(one.size() == queries.size());
    int differ = 0;
    for (size_t i = 0; i < queries.size(); ++i) {
      const Footpoint slow = index.closest_brute_force(queries[i]);
      for (const Footpoint* fast : {&one[i], &two[i]})
        if (fast->face != slow.face || fast->distance != slow.distance || fast->point != slow.point ||
            fast->normal != slow.normal || fast->on_boundary != slow.on_boundary)
          ++differ;
    }
    CHECK(differ == 0);
  }
}

TEST_CASE("a query that is not finite has no footpoint and does not crash (issue 12, item 1)") {
  const SurfaceIndex index(test::wavy_grid(20, 20, 100, 100, 3));
  const double nan = std::numeric_limits<double>::quiet_NaN(), inf = std::numeric_limits<double>::infinity();
  for (const Eigen::Vector3d& q : {Eigen::Vector3d(nan, 0, 0), Eigen::Vector3d(0, inf, 0), Eigen::Vector3d(-inf, 1, nan)}) {
    CAPTURE(q.transpose());
    for (const Footpoint& f : {index.closest(q), index.closest_brute_force(q), index.closest(std::vector<Eigen::Vector3d>{q})[0]}) {
      CHECK(f.face == -1);
      CHECK(f.distance == inf);
      CHECK(f.on_boundary);
      CHECK(std::isnan(f.point.x()));
    }
  }
  // Finite but so far away that squared distances overflow: still the same face as brute force.
  const std::vector<Eigen::Vector3d> far = {{1e308, 0, 0}, {-1e308, 1e308, 5}, {1e200, 1e200, 1e200}};
  for (const auto& q : far) {
    CAPTURE(q.transpose());
    const Footpoint f = index.closest(q), slow = index.closest_brute_force(q);
    CHECK(f.face >= 0);
    CHECK(f.face == slow.face);
    CHECK(f.face < int(index.mesh().faces.size()));
  }
  // A batch mixing good and bad points answers each on its own.
  const auto batch = index.closest(std::vector<Eigen::Vector3d>{{50, 50, 10}, {nan, nan, nan}, {10, 20, -4}});
  CHECK(batch[0].face >= 0);
  CHECK(batch[1].face == -1);
  CHECK(batch[2].face == index.closest_brute_force({10, 20, -4}).face);
}

TEST_CASE("closest points equal brute force far from the origin, at tiny scale and on one or two faces") {
  // The search bounds boxes and faces in float with an error allowance relative to the coordinates:
  // a surface 1e5 mm from the origin, one a micrometre across, and meshes smaller than one leaf.
  const EnvelopeGrid g = envelope_grid(analytic_motion({}), cone_profile(6, 9), 20, 60, 1);
  for (const double scale : {1.0, 1e-6}) {
    for (const Eigen::Vector3d& shift : {Eigen::Vector3d(1e5, -2e5, 3e4), Eigen::Vector3d(0, 0, 0)}) {
      CAPTURE(scale);
      CAPTURE(shift.transpose());
      TriMesh m = g.mesh;
      for (auto& v : m.vertices) v = v * scale + shift;
      const SurfaceIndex index(m);
      const double diag = bounding_box(m.vertices).diagonal();
      for (double offset : {0.0, 1e-7, 0.01, 0.05}) check_matches_brute_force(index, offset_points(m, offset * diag, 120, 5));
      check_matches_brute_force(index, random_points(m, 0.2 * diag, 200, 6));
    }
  }
  for (int faces : {1, 2, 5}) {
    CAPTURE(faces);
    const TriMesh m = random_soup(faces, 9);
    const SurfaceIndex index(m);
    check_matches_brute_force(index, random_points(m, 20, 300, 10));
    check_matches_brute_force(index, offset_points(m, 0.0, 50, 11));
  }
}

TEST_CASE("the index of a 40k-face mesh is the same on 1 and 2 threads: normals, topology, footpoints") {
  // Big enough for every parallel part of the build (normals, edge sorting, subtrees of the tree).
  const EnvelopeGrid g = envelope_grid(analytic_motion({}), cone_profile(6, 9), 60, 350, 1);
  const TriMesh mesh = transformed(g.mesh, unit_diagonal_frame(g.mesh));
  REQUIRE(mesh.faces.size() > 40000);
  const int threads = omp_get_max_threads();
  omp_set_num_threads(1);
  const SurfaceIndex one(mesh);
  omp_set_num_threads(2);
  const SurfaceIndex two(mesh);
  omp_set_num_threads(threads);
  CHECK(one.normals() == two.normals());
  CHECK(one.normals() == vertex_normals(mesh));
  CHECK(one.topology().boundary_edge == two.topology().boundary_edge);
  CHECK(one.topology().component == two.topology().component);
  CHECK(one.covering_radius() == two.covering_radius());
  const auto queries = offset_points(mesh, 0.05, 2000, 31);
  const auto a = one.closest(queries), b = two.closest(queries);
  int differ = 0;
  for (size_t i = 0; i < queries.size(); ++i)
    if (a[i].face != b[i].face || a[i].point != b[i].point || a[i].normal != b[i].normal) ++differ;
  CHECK(differ == 0);
  check_matches_brute_force(one, std::vector<Eigen::Vector3d>(queries.begin(), queries.begin() + 100));
}

TEST_CASE("the batch call equals brute force where faces that share no corner are closer than an edge") {
  // Two wavy sheets 0.3 apart with edges of 1 (the second shifted by 0.37, 0.21): the faces nearest
  // a point on one sheet include faces of the other, which share no corner with it. The batch call's
  // local certificates (a leaf's corner-sharing neighbourhood and its reach) must see them.
  TriMesh mesh;
  const int nx = 40, ny = 30;
  for (int sheet = 0; sheet < 2; ++sheet) {
    const int base = int(mesh.vertices.size());
    for (int j = 0; j < ny; ++j)
      for (int i = 0; i < nx; ++i) {
        const double x = i + 0.37 * sheet, y = j + 0.21 * sheet;
        mesh.vertices.emplace_back(x, y, 0.3 * sheet + 0.05 * std::sin(0.7 * x) * std::cos(0.4 * y));
      }
    for (int j = 0; j + 1 < ny; ++j)
      for (int i = 0; i + 1 < nx; ++i) {
        const int v = base + j * nx + i;
        mesh.faces.push_back({v, v + 1, v + nx + 1});
        mesh.faces.push_back({v, v + nx + 1, v + nx});
      }
  }
  const SurfaceIndex index(mesh);
  std::mt19937 rng(5);
  std::uniform_real_distribution<double> u(0, 1);
  std::vector<Eigen::Vector3d> queries;
  for (int k = 0; k < 2400; ++k) {
    // On a face (either sheet), or between the sheets at any height.
    const auto& F = mesh.faces[size_t(std::uniform_int_distribution<int>(0, int(mesh.faces.size()) - 1)(rng))];
    double b1 = u(rng), b2 = u(rng);
    if (b1 + b2 > 1) b1 = 1 - b1, b2 = 1 - b2;
    const Eigen::Vector3d &a = mesh.vertices[size_t(F[0])], &b = mesh.vertices[size_t(F[1])], &c = mesh.vertices[size_t(F[2])];
    Eigen::Vector3d q = a + b1 * (b - a) + b2 * (c - a);
    if (k % 3 == 2) q.z() = 0.35 * u(rng) - 0.02;
    queries.push_back(q);
  }
  for (size_t v = 0; v < mesh.vertices.size(); v += 15) queries.push_back(mesh.vertices[v]);
  const auto fast = index.closest(queries);
  int differ = 0, upper = 0, lower = 0;
  const int faces_per_sheet = int(mesh.faces.size()) / 2;
  for (size_t i = 0; i < queries.size(); ++i) {
    const Footpoint slow = index.closest_brute_force(queries[i]);
    if (fast[i].face != slow.face || fast[i].distance != slow.distance || fast[i].point != slow.point ||
        fast[i].normal != slow.normal || fast[i].on_boundary != slow.on_boundary)
      ++differ;
    if (i < 2400 && i % 3 == 2) ++(slow.face < faces_per_sheet ? lower : upper);
  }
  CHECK(differ == 0);
  // The queries between the sheets are answered by both sheets, many by a face that shares no
  // corner with the face the query was made on.
  MESSAGE("between the sheets: " << lower << " answered by the lower sheet, " << upper << " by the upper");
  CHECK(upper > 200);
  CHECK(lower > 200);
}

namespace {
// Footpoints of the batch call on 1 and on 2 threads that differ from brute force in any bit
// (face, point, distance, normal, boundary flag).
int batch_differences(const SurfaceIndex& index, const std::vector<Eigen::Vector3d>& queries) {
  const int threads = omp_get_max_threads();
  omp_set_num_threads(1);
  const auto one = index.closest(queries);
  omp_set_num_threads(2);
  const auto two = index.closest(queries);
  omp_set_num_threads(threads);
  std::vector<int> differ(queries.size(), 0);
#pragma omp parallel for schedule(dynamic, 16)
  for (long i = 0; i < long(queries.size()); ++i) {
    const Footpoint slow = index.closest_brute_force(queries[size_t(i)]);
    for (const Footpoint* fast : {&one[size_t(i)], &two[size_t(i)]})
      if (fast->face != slow.face || fast->distance != slow.distance || fast->point != slow.point ||
          fast->normal != slow.normal || fast->on_boundary != slow.on_boundary)
        differ[size_t(i)] = 1;
  }
  return std::accumulate(differ.begin(), differ.end(), 0);
}

// Two wavy sheets `gap` apart (edges of 1, the second shifted in the plane), as in the test above.
TriMesh two_sheets(double gap) {
  const auto sheet = [gap](int k) {
    return test::grid_mesh(40, 30, [gap, k](int i, int j) {
      const double x = i + 0.37 * k, y = j + 0.21 * k;
      return Eigen::Vector3d(x, y, gap * k + 0.05 * std::sin(0.7 * x) * std::cos(0.4 * y));
    });
  };
  return merged(sheet(0), sheet(1));
}
}  // namespace

TEST_CASE("the cell grid answers as brute force on a 160k-face envelope: on the surface, at vertices and edges, and around its reach" * doctest::test_suite("heavy")) {
  // Over 131k faces: no local certificates, so every query on or next to the surface is settled by
  // its cell (reach: a tenth of a leaf's width, here about 5e-4) or by the tree after it.
  const EnvelopeGrid g = envelope_grid(analytic_motion({}), cone_profile(6, 9), 200, 400, 1);
  const TriMesh mesh = transformed(g.mesh, unit_diagonal_frame(g.mesh));
  REQUIRE(mesh.faces.size() > 140000);
  const SurfaceIndex index(mesh);
  std::vector<Eigen::Vector3d> queries = offset_points(mesh, 0.0, 400, 3);
  for (double offset : {1e-9, 1e-4, 3e-4, 5e-4, 7e-4, 1e-3, 3e-3}) {
    const auto more = offset_points(mesh, offset, 60, 4);
    queries.insert(queries.end(), more.begin(), more.end());
  }
  // Ties: corners shared by up to six faces and edges shared by two (the lowest index wins).
  for (size_t f = 0; f < mesh.faces.size(); f += 1201) {
    const auto& F = mesh.faces[f];
    queries.push_back(mesh.vertices[size_t(F[0])]);
    queries.push_back(0.5 * (mesh.vertices[size_t(F[1])] + mesh.vertices[size_t(F[2])]));
  }
  CHECK(batch_differences(index, queries) == 0);
  // Single queries take the grid too (no previous answer).
  check_matches_brute_force(index, std::vector<Eigen::Vector3d>(queries.begin(), queries.begin() + 100));
}

TEST_CASE("the cell grid answers as brute force where two sheets are closer than its reach") {
  // Sheets 0.02 apart with edges of 1 (the grid's reach is about 0.15): a cell lists leaves of both
  // sheets, and a query on one sheet may be nearest to the other.
  const TriMesh mesh = two_sheets(0.02);
  const SurfaceIndex index(mesh);
  std::mt19937 rng(9);
  std::uniform_real_distribution<double> u(0, 1);
  std::vector<Eigen::Vector3d> queries = offset_points(mesh, 0.0, 1500, 8);
  for (auto q : offset_points(mesh, 0.0, 500, 10)) queries.push_back(q + Eigen::Vector3d(0, 0, 0.03 * u(rng) - 0.005));
  for (size_t v = 0; v < mesh.vertices.size(); v += 6) queries.push_back(mesh.vertices[v]);
  int other_sheet = 0;
  const int faces_per_sheet = int(mesh.faces.size()) / 2;
  for (size_t i = 1500; i < 2000; ++i) other_sheet += index.closest_brute_force(queries[i]).face >= faces_per_sheet;
  MESSAGE(other_sheet << " of 500 queries off the lower sheet are nearest to the upper one");
  CHECK(other_sheet > 50);
  CHECK(batch_differences(index, queries) == 0);
}

TEST_CASE("closest points equal brute force on a mesh of tiny faces and a few huge ones (coarsened or no cell grid)" *
          doctest::test_suite("heavy")) {
  // A 60 x 60 grid of 0.01-wide faces under three triangles 100 wide: the huge faces would fill
  // thousands of cells the size of a tiny leaf, so the grid is coarsened or left out; either way
  // the answers are brute force's.
  TriMesh mesh = test::wavy_grid(60, 60, 0.6, 0.6, 0.002);
  const int base = int(mesh.vertices.size());
  for (int k = 0; k < 3; ++k) {
    const double z = 0.05 + 0.1 * k;
    mesh.vertices.emplace_back(-50, -50, z);
    mesh.vertices.emplace_back(50, -50, z + 0.01);
    mesh.vertices.emplace_back(0, 50, z);
    mesh.faces.push_back({base + 3 * k, base + 3 * k + 1, base + 3 * k + 2});
  }
  const SurfaceIndex index(mesh);
  std::vector<Eigen::Vector3d> queries = offset_points(mesh, 0.0, 1500, 12);
  for (const auto& q : random_points(mesh, 1.0, 500, 13)) queries.push_back(q);
  CHECK(batch_differences(index, queries) == 0);
}

TEST_CASE("the cell grid answers as brute force just inside and just beyond its reach on a 26k-face envelope" * doctest::test_suite("heavy")) {
  // The reach is a tenth of a leaf's width (here about 5e-4): a query that far off the surface is
  // settled by its cell only if the cell lists every face that near, which the widening of each
  // face's box and plane by the reach ensures (without it, about one query in 400 here is wrong).
  const EnvelopeGrid g = envelope_grid(analytic_motion({}), cone_profile(6, 9), 66, 200, 1);
  const TriMesh mesh = transformed(g.mesh, unit_diagonal_frame(g.mesh));
  const SurfaceIndex index(mesh);
  std::vector<Eigen::Vector3d> queries;
  for (double offset : {1e-4, 2e-4, 3e-4, 5e-4, 7e-4}) {
    const auto more = offset_points(mesh, offset, 1000, 17);
    queries.insert(queries.end(), more.begin(), more.end());
  }
  CHECK(batch_differences(index, queries) == 0);
  int differ = 0;
#pragma omp parallel for schedule(dynamic, 16) reduction(+ : differ)
  for (long i = 0; i < long(queries.size()); ++i) {
    const Footpoint fast = index.closest(queries[size_t(i)]), slow = index.closest_brute_force(queries[size_t(i)]);
    differ += fast.face != slow.face || fast.distance != slow.distance || fast.point != slow.point;
  }
  CHECK(differ == 0);
}

TEST_CASE("the pseudo-normal tells outside from inside next to a knife edge, where the closest face's normal cannot") {
  // A closed wedge 1 mm thick at its base and 20 mm high (a thin blade's edge, sides 1.4 degrees
  // off each other's opposite), 60 mm long, faces outward.
  TriMesh w;
  w.vertices = {{0, 0, 0}, {1, 0, 0}, {0.5, 0, 20}, {0, 60, 0}, {1, 60, 0}, {0.5, 60, 20}};
  w.faces = {{0, 1, 2}, {3, 5, 4}, {0, 3, 4}, {0, 4, 1}, {0, 2, 5}, {0, 5, 3}, {1, 4, 5}, {1, 5, 2}};
  const SurfaceIndex index(w);
  const Eigen::Vector3d apex(0.5, 30, 20);
  int face_wrong = 0;
  for (int deg = 5; deg <= 175; deg += 5) {  // around the apex edge, above the wedge: all outside
    CAPTURE(deg);
    const double a = deg * M_PI / 180;
    const Eigen::Vector3d p = apex + 5 * Eigen::Vector3d(std::cos(a), 0, std::sin(a));
    const Footpoint f = index.closest(p);
    CHECK((f.point - apex).norm() < 1e-9);  // the closest point is on the edge
    CHECK((p - f.point).dot(index.pseudo_normal(f)) > 0);
    if ((p - f.point).dot(face_normal(w, f.face)) < 0) ++face_wrong;
  }
  CHECK(face_wrong > 0);  // the closest face's own normal calls some of them inside
  // Inside, near the apex and near the base: the pseudo-normal says so.
  for (const Eigen::Vector3d& p : {Eigen::Vector3d(0.5, 30, 19.5), Eigen::Vector3d(0.5, 30, 0.2), Eigen::Vector3d(0.9, 59.9, 0.1)}) {
    CAPTURE(p.transpose());
    const Footpoint f = index.closest(p);
    CHECK((p - f.point).dot(index.pseudo_normal(f)) < 0);
  }
  // Beyond the apex's end corner (a vertex): outside, by the angle-weighted vertex normal.
  const Eigen::Vector3d corner(0.5, 60, 20);
  for (const Eigen::Vector3d& d : {Eigen::Vector3d(3, 3, 3), Eigen::Vector3d(-3, 3, 3), Eigen::Vector3d(0, 3, 0.5)}) {
    const Footpoint f = index.closest(corner + d);
    CHECK((f.point - corner).norm() < 1e-9);
    CHECK(d.dot(index.pseudo_normal(f)) > 0);
  }
}

TEST_CASE("the closest point within a slab equals brute force, lies in the slab, and is the closest point when the slab holds all") {
  const SurfaceIndex wavy(test::wavy_grid(40, 30, 120, 80, 8));
  const SurfaceIndex soup(clean_mesh(random_soup(400, 6), "soup").mesh);
  std::mt19937 rng(21);
  std::normal_distribution<double> g(0, 1);
  std::uniform_real_distribution<double> width(0.2, 6);
  int checked = 0, empty = 0, mismatches = 0;
  for (const SurfaceIndex* index : {&wavy, &soup}) {
    for (const Eigen::Vector3d& p : random_points(index->mesh(), 15, 400, 22)) {
      const Eigen::Vector3d n = Eigen::Vector3d(g(rng), g(rng), g(rng)).normalized();
      // Slabs through p, beside it and far from it: the clipped faces' nearest point is off the
      // global footpoint in most of them.
      const double lo = n.dot(p) + 10 * g(rng), hi = lo + width(rng);
      const Footpoint fast = index->closest_in_slab(p, n, lo, hi), slow = index->closest_in_slab_brute_force(p, n, lo, hi);
      ++checked;
      if (slow.face < 0) {
        ++empty;
        CHECK(fast.face < 0);
        continue;
      }
      if (!(fast.face == slow.face && fast.distance == slow.distance && fast.point == slow.point)) ++mismatches;
      const double h = n.dot(fast.point);
      CHECK(h >= lo - 1e-9);
      CHECK(h <= hi + 1e-9);
      CHECK(fast.distance >= index->closest(p).distance - 1e-12);
      // The footpoint lies on its face: its barycentric coordinates rebuild it.
      const auto& F = index->mesh().faces[size_t(fast.face)];
      Eigen::Vector3d rebuilt = Eigen::Vector3d::Zero();
      for (int k = 0; k < 3; ++k) rebuilt += fast.barycentric[k] * index->mesh().vertices[size_t(F[size_t(k)])];
      CHECK((rebuilt - fast.point).norm() < 1e-9);
    }
    // A slab that holds the whole mesh: the closest point itself.
    for (const Eigen::Vector3d& p : random_points(index->mesh(), 15, 100, 23)) {
      const Footpoint all = index->closest_in_slab(p, Eigen::Vector3d::UnitZ(), -1e4, 1e4), global = index->closest(p);
      CHECK(all.face == global.face);
      CHECK(all.distance == doctest::Approx(global.distance).epsilon(1e-12));
    }
  }
  CHECK(mismatches == 0);
  // Most slabs meet the mesh; some miss it (no footpoint, as for a query that is not finite).
  CHECK(empty > 0);
  CHECK(empty < checked / 4);
  const Footpoint none = wavy.closest_in_slab({0, 0, 0}, Eigen::Vector3d::UnitZ(), 1e3, 1e3 + 1);
  CHECK(none.face < 0);
  CHECK(std::isinf(none.distance));
}
