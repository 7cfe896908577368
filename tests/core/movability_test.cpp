#include "core/movability.h"

#include <doctest/doctest.h>

#include <Eigen/Geometry>

#include "core/envelope.h"
#include "tests/test_util.h"

using namespace flankcam;

namespace {
struct Exact {
  LineMotion motion;
  Similarity frame;
  SurfaceIndex surface;
};
Exact exact_envelope(const char* kind, const RadiusProfile& profile) {
  test::ExactEnvelope e = test::exact_envelope(kind, profile);
  return {e.motion, e.frame, SurfaceIndex(std::move(e.unit_mesh))};
}
}  // namespace

TEST_CASE("the true axis of an exact envelope is movable and its best field is the true velocity up to scale") {
  for (const char* kind : {"twist", "arc", "helix", "s-curve"}) {
    const std::string name = kind;
    CAPTURE(name);
    const Exact ex = exact_envelope(kind, cone_profile(6, 9));
    for (double t : {0.3, 0.5, 0.7}) {
      const Eigen::Vector3d a = ex.frame.to_unit(ex.motion.a(t)), b = ex.frame.to_unit(ex.motion.b(t));
      const Movability m = line_movability(ex.surface, a, b);
      CHECK(m.movable);
      CHECK(m.F < 5e-5);  // ~0 up to the tessellation (mesh normals tilt by ~h/2R)
      // Compare the parts normal to the line (sliding along itself is not a motion of the line).
      const Eigen::Vector3d e = (b - a).normalized();
      const auto normal_part = [&](const Eigen::Vector3d& v) { return Eigen::Vector3d(v - v.dot(e) * e); };
      const Eigen::Vector3d ta = normal_part(ex.motion.da(t)), tb = normal_part(ex.motion.db(t));
      const double scale = 0.5 * (ta + tb).norm();
      const Eigen::Vector3d fa = normal_part(m.v_a), fb = normal_part(m.v_b);
      const double sign = fa.dot(ta) >= 0 ? 1 : -1;
      CHECK((sign * fa - ta / scale).norm() < 0.08);
      CHECK((sign * fb - tb / scale).norm() < 0.08);
    }
  }
}

TEST_CASE("a line tilted off the axis is less movable than the true axis") {
  const Exact ex = exact_envelope("s-curve", barrel_profile(6, 1.5));
  const Eigen::Vector3d a = ex.frame.to_unit(ex.motion.a(0.5)), b = ex.frame.to_unit(ex.motion.b(0.5));
  const Movability good = line_movability(ex.surface, a, b);
  const Eigen::Vector3d tilt = (b - a).cross(Eigen::Vector3d::UnitZ()).normalized() * 0.02;
  const Movability bad = line_movability(ex.surface, a + tilt, b - tilt);
  CHECK(bad.F > 100 * good.F);
}

TEST_CASE("Remark 1: a line whose footpoints jump between two sheets is not movable") {
  // Two parallel plates 20 mm apart; a line crossing the mid-plane sees both.
  TriMesh m;
  m.vertices = {{0, 0, 0}, {100, 0, 0}, {100, 100, 0}, {0, 100, 0}, {0, 0, 20}, {100, 0, 20}, {100, 100, 20}, {0, 100, 20}};
  m.faces = {{0, 1, 2}, {0, 2, 3}, {4, 6, 5}, {4, 7, 6}};
  const SurfaceIndex s(m);
  const Movability crossing = line_movability(s, {50, 30, 5}, {50, 70, 15});
  CHECK_FALSE(crossing.movable);
  const Movability single = line_movability(s, {50, 30, 5}, {50, 70, 5});
  CHECK(single.movable);
}

TEST_CASE("exploration improves a perturbed line and propagation sweeps the surface to its boundary") {
  const Exact ex = exact_envelope("helix", cylinder_profile(6));
  const Eigen::Vector3d a = ex.frame.to_unit(ex.motion.a(0.5)), b = ex.frame.to_unit(ex.motion.b(0.5));
  const Eigen::Vector3d off = (b - a).cross(Eigen::Vector3d::UnitX()).normalized() * 0.01;
  const ExploredLine best = explore_line(ex.surface, a + off, b + 0.5 * off);
  CHECK(best.movability.F <= best.F_start);
  CHECK(best.lines_evaluated > 1);
  const LineTrajectory tr = propagate_line(ex.surface, best.a, best.b);
  CHECK(tr.stop_backward == PropagationStop::Boundary);
  CHECK(tr.stop_forward == PropagationStop::Boundary);
  CHECK(tr.a.size() > 300);  // 0.001 steps over most of the surface
  for (size_t k = 0; k < tr.a.size(); ++k) CHECK((tr.b[k] - tr.a[k]).norm() == doctest::Approx((best.b - best.a).norm()));
}
