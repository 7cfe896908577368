#include "kinematics/kinematics.h"

#include <doctest/doctest.h>

#include <Eigen/Geometry>
#include <random>

#include "core/errors.h"
#include "kinematics/machine.h"
#include "tests/test_util.h"

using namespace flankcam;

namespace {
const std::vector<std::string> kMachines = {"xyzac-trt", "xyzbc-trt", "xyzbc-head-table", "xyzca-head-head", "xyzbc-nutating"};

Machine shipped(const std::string& name) { return load_machine(std::string(FLANKCAM_SOURCE_DIR) + "/machines/" + name + ".yaml"); }

double angle_diff(double a, double b) { return std::abs(std::remainder(a - b, 360.0)); }

Eigen::Matrix3d Rx(double deg) { return Eigen::AngleAxisd(deg * M_PI / 180, Eigen::Vector3d::UnitX()).toRotationMatrix(); }
Eigen::Matrix3d Ry(double deg) { return Eigen::AngleAxisd(deg * M_PI / 180, Eigen::Vector3d::UnitY()).toRotationMatrix(); }
Eigen::Matrix3d Rz(double deg) { return Eigen::AngleAxisd(deg * M_PI / 180, Eigen::Vector3d::UnitZ()).toRotationMatrix(); }
}  // namespace

TEST_CASE("the two-rotation problem: both solutions satisfy R(w1, a) R(w2, b) v = w, also for non-orthogonal axes") {
  std::mt19937 rng(1);
  std::normal_distribution<double> g;
  int solved = 0;
  for (int k = 0; k < 2000; ++k) {
    const Eigen::Vector3d w1 = Eigen::Vector3d(g(rng), g(rng), g(rng)).normalized();
    const Eigen::Vector3d w2 = Eigen::Vector3d(g(rng), g(rng), g(rng)).normalized();
    const Eigen::Vector3d v = Eigen::Vector3d(g(rng), g(rng), g(rng)).normalized();
    const double a0 = g(rng), b0 = g(rng);
    const Eigen::Vector3d w = Eigen::AngleAxisd(a0, w1) * (Eigen::AngleAxisd(b0, w2) * v);
    const auto sols = solve_two_rotations(w1, w2, v, w);
    REQUIRE(!sols.empty());
    bool found = false;
    for (const auto& s : sols) {
      const Eigen::Vector3d got = Eigen::AngleAxisd(s.alpha, w1) * (Eigen::AngleAxisd(s.beta, w2) * v);
      CHECK((got - w).norm() < 1e-9);
      found |= std::abs(std::remainder(s.alpha - a0, 2 * M_PI)) < 1e-7 && std::abs(std::remainder(s.beta - b0, 2 * M_PI)) < 1e-7;
    }
    CHECK(found);
    solved += int(sols.size());
  }
  CHECK(solved > 3900);  // two branches almost everywhere
}

TEST_CASE("forward(inverse(pose)) == pose to 1e-9 for every shipped machine, both branches, random reachable poses") {
  for (const std::string& name : kMachines) {
    CAPTURE(name);
    const Machine m = shipped(name);
    std::mt19937 rng(7);
    std::uniform_real_distribution<double> u(0, 1);
    int branches = 0;
    for (int k = 0; k < 3000; ++k) {
      Joints q;
      for (int a = 0; a < 2; ++a) {
        const RotaryAxis& r = m.rotary[size_t(a)];
        q.rotary[size_t(a)] = r.continuous ? -720 + 1440 * u(rng) : r.min_deg + (r.max_deg - r.min_deg) * u(rng);
      }
      q.linear = Eigen::Vector3d(-200 + 400 * u(rng), -200 + 400 * u(rng), -200 + 400 * u(rng));
      const double tool = 20 + 100 * u(rng);
      const ToolPose pose = forward(m, q, tool);
      CHECK(std::abs(pose.axis.norm() - 1) < 1e-12);
      const std::vector<Joints> sols = inverse(m, pose, tool);
      REQUIRE(!sols.empty());
      branches += int(sols.size());
      bool contains = false;
      for (const Joints& s : sols) {
        const ToolPose back = forward(m, s, tool);
        CHECK((back.tip - pose.tip).norm() < 1e-9);
        CHECK((back.axis - pose.axis).norm() < 1e-9);
        contains |= angle_diff(s.rotary[0], q.rotary[0]) < 1e-7 && angle_diff(s.rotary[1], q.rotary[1]) < 1e-7 &&
                    (s.linear - q.linear).norm() < 1e-7;
      }
      CHECK(contains);
    }
    MESSAGE(name << ": " << branches << " solutions for 3000 poses");
    CHECK(branches > 5500);
  }
}

TEST_CASE("singular poses: the free angle is reported and any value of it reaches the pose") {
  for (const std::string& name : kMachines) {
    CAPTURE(name);
    const Machine m = shipped(name);
    // The axis that frees an angle: for tables the inner (carried) table axis in part coordinates;
    // for heads the outer head axis.
    Eigen::Vector3d axis = m.tables() == 2 ? m.rotary[1].direction : m.rotary[0].direction;
    if (axis.dot(m.spindle_direction) < 0) axis = -axis;
    const auto sols = rotary_solutions(m, axis);
    REQUIRE(!sols.empty());
    CHECK(singularity_angle_deg(m, axis) < 1e-6);
    CHECK(singularity_angle_deg(m, (axis + 0.1 * axis.unitOrthogonal()).normalized()) > 5);
    bool any_free = false;
    for (const auto& s : sols) {
      any_free |= s.free[0] || s.free[1];
      for (double free_value : {0.0, 37.0, -123.0}) {
        Joints q;
        q.rotary = s.deg;
        for (int k = 0; k < 2; ++k)
          if (s.free[size_t(k)]) q.rotary[size_t(k)] = free_value;
        const ToolPose pose{Eigen::Vector3d(10, -20, 30), axis};
        q.linear = linear_joints(m, pose, q.rotary, 50);
        const ToolPose back = forward(m, q, 50);
        CHECK((back.tip - pose.tip).norm() < 1e-9);
        CHECK((back.axis - axis).norm() < 1e-9);
      }
    }
    CHECK(any_free);
  }
}

TEST_CASE("xyzac-trt and xyzbc-trt match LinuxCNC's trt kinematics (trtfuncs.c) with the direction convention mapped") {
  // LinuxCNC turns the table by +a/+c right-handed about +X/+Z; our machine files are ISO
  // (direction -X/-Y/-Z), so a_linuxcnc = -A, b_linuxcnc = -B, c_linuxcnc = -C.
  std::mt19937 rng(11);
  std::uniform_real_distribution<double> u(-1, 1);
  for (const std::string name : {"xyzac-trt", "xyzbc-trt"}) {
    CAPTURE(name);
    const Machine m = shipped(name);
    const bool ac = name == "xyzac-trt";
    // r: the C axis point; d: the tilt axis point relative to it (x- or y-offset unused by LinuxCNC).
    const Eigen::Vector3d r = m.rotary[1].pivot, d = m.rotary[0].pivot - m.rotary[1].pivot;
    REQUIRE(std::abs(ac ? d.x() : d.y()) < 1e-12);
    double worst_joint = 0, worst_axis = 0;
    for (int k = 0; k < 2000; ++k) {
      const Eigen::Vector3d P(200 * u(rng), 200 * u(rng), 100 * u(rng));
      const double tilt = 100 * u(rng), c = 180 * u(rng);  // LinuxCNC degrees
      Eigen::Vector3d J, K;
      if (ac) {
        J = r + Rx(tilt) * Rz(c) * (P - r) + (Eigen::Matrix3d::Identity() - Rx(tilt)) * d;
        K = Eigen::Vector3d(std::sin(tilt * M_PI / 180) * std::sin(c * M_PI / 180), std::sin(tilt * M_PI / 180) * std::cos(c * M_PI / 180),
                            std::cos(tilt * M_PI / 180));
      } else {
        J = r + Ry(tilt) * Rz(c) * (P - r) + (Eigen::Matrix3d::Identity() - Ry(tilt)) * d;
        K = Eigen::Vector3d(-std::sin(tilt * M_PI / 180) * std::cos(c * M_PI / 180), std::sin(tilt * M_PI / 180) * std::sin(c * M_PI / 180),
                            std::cos(tilt * M_PI / 180));
      }
      // Forward from the mapped joints gives LinuxCNC's tool axis and tip.
      Joints q;
      q.rotary = {-tilt, -c};
      q.linear = J;
      const ToolPose pose = forward(m, q, 0);
      worst_axis = std::max(worst_axis, (pose.axis - K).norm());
      CHECK((pose.tip - P).norm() < 1e-9);
      // Inverse contains LinuxCNC's joints.
      double best = 1e9;
      for (const Joints& s : inverse(m, {P, K}, 0))
        if (angle_diff(s.rotary[0], -tilt) < 1e-7 && angle_diff(s.rotary[1], -c) < 1e-7) best = (s.linear - J).norm();
      worst_joint = std::max(worst_joint, best);
    }
    MESSAGE(name << ": worst joint difference " << worst_joint << " mm, worst axis difference " << worst_axis);
    CHECK(worst_joint < 1e-9);
    CHECK(worst_axis < 1e-12);
  }
}

TEST_CASE("machine files: a missing field, a zero direction, limits in the wrong order are rejected by name") {
  test::ScratchDir dir("machines");
  const std::string good = test::read_text(std::string(FLANKCAM_SOURCE_DIR) + "/machines/xyzac-trt.yaml");
  const auto replaced = [&](const std::string& from, const std::string& to) {
    std::string s = good;
    const size_t at = s.find(from);
    REQUIRE(at != std::string::npos);
    return s.replace(at, from.size(), to);
  };
  struct Bad {
    std::string text, expect;
  };
  const std::vector<Bad> cases = {
      {replaced("spindle: {direction: [0, 0, 1]}", ""), "spindle: missing"},
      {replaced("direction: [-1, 0, 0]", "direction: [0, 0, 0]"), "rotary.A.direction: zero direction"},
      {replaced("limits: [-120, 30]", "limits: [30, -120]"), "rotary.A.limits: min must be below max"},
      {replaced("X: {limits: [-500, 500], speed: 30000}", "X: {limits: [500, -500], speed: 30000}"), "linear.X.limits: min must be below max"},
      {replaced("speed: 5400", "speed: fast"), "rotary.A.speed: expected a number"},
      {replaced("{name: C, carries: table, direction: [0, 0, -1]", "{name: C, carries: table, direction: [-2, 0, 0]"),
       "rotary: the two rotary axes are parallel"},
      {replaced("carries: table, direction: [-1", "carries: bed, direction: [-1"), "rotary.A.carries: must be table or head"},
      {replaced("name: xyzac-trt", "name: xyzac-trt\nspeed: 3"), "speed: unknown key"},
  };
  for (const auto& c : cases) {
    CAPTURE(c.expect);
    test::write_text(dir.file("m.yaml"), c.text);
    try {
      (void)load_machine(dir.file("m.yaml"));
      FAIL("accepted");
    } catch (const MachineError& e) {
      CHECK(std::string(e.what()).find(c.expect) != std::string::npos);
      CHECK(std::string(e.what()).find("m.yaml") != std::string::npos);
    }
  }
  CHECK_THROWS_AS((void)load_machine(dir.file("absent.yaml")), MachineError);
}

// Issue 12 items 8 and 9: nonsense values and YAML that yaml-cpp accepts but a reader misreads.
TEST_CASE("machine files: values outside their ranges, duplicate or complex keys, deep nesting name the line and key") {
  test::ScratchDir dir("machines-ranges");
  const std::string good = test::read_text(std::string(FLANKCAM_SOURCE_DIR) + "/machines/xyzac-trt.yaml");
  const auto replaced = [&](const std::string& from, const std::string& to) {
    std::string s = good;
    const size_t at = s.find(from);
    REQUIRE(at != std::string::npos);
    return s.replace(at, from.size(), to);
  };
  struct Bad {
    std::string text, expect;
  };
  const std::vector<Bad> cases = {
      {replaced("X: {limits: [-500, 500], speed: 30000}", "X: {limits: [-500, 500], speed: 1e-300}"),
       "m.yaml:7: linear.X.speed: must be in 1..1e+06 mm/min, got '1e-300'"},
      {replaced("limits: [-120, 30], speed: 5400", "limits: [-120, 30], speed: 1e-300"),
       "m.yaml:11: rotary.A.speed: must be in 1..1e+07 deg/min, got '1e-300'"},
      {replaced("Y: {limits: [-400, 400]", "Y: {limits: [-1e300, 400]"), "m.yaml:8: linear.Y.limits[0]: must be in -1e+06..1e+06 mm"},
      {replaced("limits: [-120, 30]", "limits: [-120, 1e300]"), "m.yaml:11: rotary.A.limits[1]: must be in -36000..36000 deg"},
      {replaced("pivot: [0, 0, -60]", "pivot: [0, 0, -1e300]"), "m.yaml:11: rotary.A.pivot[2]: must be in -1e+06..1e+06 mm"},
      {good + "gauge_length: 1e300\n", "gauge_length: must be in 0..10000 mm"},
      {good + "name: again\n", "m.yaml:15: name: duplicate key (first at line 4, again at line 15)"},
      {replaced("X: {limits: [-500, 500], speed: 30000}", "X: {limits: [-500, 500], speed: 30000, speed: 1}"),
       "m.yaml:7: linear.X.speed: duplicate key (first at line 7, again at line 7)"},
      {"? [a, b]\n: 1\n" + good, "m.yaml:1: top level: a key must be a plain name, not a list or mapping"},
      {"name: " + std::string(3000, '[') + std::string(3000, ']') + "\n", "m.yaml:1: nested too deeply"},
      {"name: &x [1, *x]\n", "m.yaml:1: name: expected a string"},  // an alias cycle: no hang
      {replaced("speed: 5400", "speed: \"54\\n00\""), "rotary.A.speed: expected a number, got '54\\n00'"},
  };
  for (const auto& c : cases) {
    CAPTURE(c.expect);
    test::write_text(dir.file("m.yaml"), c.text);
    try {
      (void)load_machine(dir.file("m.yaml"));
      FAIL("accepted");
    } catch (const MachineError& e) {
      const std::string what = e.what();
      CHECK(what.find(c.expect) != std::string::npos);
      CHECK(what.find('\n') == std::string::npos);  // one line
    }
  }
}

TEST_CASE("machine files: the dialect is kept as written with its line, for postproc to check") {
  test::ScratchDir dir("machines-dialect");
  std::string text = test::read_text(std::string(FLANKCAM_SOURCE_DIR) + "/machines/xyzac-trt.yaml");
  text.replace(text.find("dialect: linuxcnc"), 17, "dialect: fanuc");
  test::write_text(dir.file("m.yaml"), text);
  const Machine m = load_machine(dir.file("m.yaml"));
  CHECK(m.controller.dialect == "fanuc");
  CHECK(m.controller.dialect_line == 14);
  Machine built = m;
  built.controller.dialect.clear();
  CHECK_THROWS_WITH_AS(validate(built), doctest::Contains("controller.dialect: empty"), MachineError);
}

TEST_CASE("forward from prepared chains and the angles' cosines and sines equals forward() to 1e-10 mm for every shipped machine") {
  std::mt19937 rng(5);
  std::uniform_real_distribution<double> deg(-400, 400), mm(-300, 300);
  for (const char* name : {"xyzac-trt", "xyzbc-trt", "xyzbc-head-table", "xyzca-head-head", "xyzbc-nutating"}) {
    CAPTURE(name);
    const Machine m = load_machine(std::string(FLANKCAM_SOURCE_DIR) + "/machines/" + name + ".yaml");
    for (double tool : {0.0, 80.0}) {
      const PreparedForward f = prepare_forward(m, tool);
      double worst = 0;
      for (int i = 0; i < 200; ++i) {
        Joints q;
        q.linear = {mm(rng), mm(rng), mm(rng)};
        q.rotary = {deg(rng), deg(rng)};
        const std::array<double, 2> c{std::cos(q.rotary[0] * M_PI / 180), std::cos(q.rotary[1] * M_PI / 180)};
        const std::array<double, 2> s{std::sin(q.rotary[0] * M_PI / 180), std::sin(q.rotary[1] * M_PI / 180)};
        const ToolPose a = forward(m, q, tool), b = forward(f, q.linear, c, s);
        worst = std::max({worst, (a.tip - b.tip).norm(), (a.axis - b.axis).norm()});
      }
      CHECK(worst < 1e-10);
    }
  }
}
