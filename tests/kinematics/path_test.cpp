#include "kinematics/path.h"

#include <doctest/doctest.h>

#include <Eigen/Geometry>
#include <omp.h>

#include "core/errors.h"

using namespace flankcam;

namespace {
Machine shipped_machine(const std::string& name) { return load_machine(std::string(FLANKCAM_SOURCE_DIR) + "/machines/" + name + ".yaml"); }

Eigen::Vector3d tilted(double tilt_deg, double azimuth_deg) {
  const double t = tilt_deg * M_PI / 180, a = azimuth_deg * M_PI / 180;
  return {std::sin(t) * std::cos(a), std::sin(t) * std::sin(a), std::cos(t)};
}

double max_jump(const JointPath& p, int axis) {
  double worst = 0;
  for (size_t i = 1; i < p.joints.size(); ++i)
    worst = std::max(worst, std::abs(p.joints[i].rotary[size_t(axis)] - p.joints[i - 1].rotary[size_t(axis)]));
  return worst;
}

void check_reproduces(const Machine& m, const JointPath& p, double tool) {
  for (size_t i = 0; i < p.joints.size(); ++i) {
    const ToolPose back = forward(m, p.joints[i], tool);
    CHECK((back.tip - p.poses[i].tip).norm() < 1e-9);
    CHECK((back.axis - p.poses[i].axis).norm() < 1e-9);
  }
}
}  // namespace

TEST_CASE("a continuous C axis is unwound over three turns: no 360 degree jumps, values beyond 360") {
  const Machine m = shipped_machine("xyzac-trt");
  std::vector<ToolPose> poses;
  for (int i = 0; i <= 360; ++i) poses.push_back({Eigen::Vector3d(50 * std::cos(i * M_PI / 60), 50 * std::sin(i * M_PI / 60), 10), tilted(30, 3.0 * i)});
  PathOptions o;
  o.tool_length_mm = 80;
  const JointPath p = solve_path(m, poses, {}, o);
  REQUIRE(p.reachable);
  CHECK(p.branch_changes == 0);
  const int c = m.rotary[0].name == "C" ? 0 : 1;
  const double travel = p.joints.back().rotary[size_t(c)] - p.joints.front().rotary[size_t(c)];
  MESSAGE("C travel " << travel << " deg, largest step " << max_jump(p, c));
  CHECK(std::abs(travel) == doctest::Approx(1080).epsilon(1e-9));
  CHECK(max_jump(p, c) < 3.5);
  for (size_t i = 0; i < p.joints.size(); ++i)  // A holds the tilt at the input poses (slerp between them tilts less)
    if (p.input_index[i] >= 0) CHECK(std::abs(p.joints[i].rotary[size_t(1 - c)] - p.joints[0].rotary[size_t(1 - c)]) < 1e-9);
  check_reproduces(m, p, o.tool_length_mm);
}

TEST_CASE("the IK branch is chosen per path: one branch covers the sweep, so it never flips") {
  for (const std::string name : {"xyzbc-trt", "xyzbc-head-table", "xyzca-head-head", "xyzbc-nutating"}) {
    CAPTURE(name);
    const Machine m = shipped_machine(name);
    std::vector<ToolPose> poses;
    for (int i = 0; i <= 200; ++i) poses.push_back({Eigen::Vector3d(-60 + 0.6 * i, 20, 5), tilted(25 + 15 * std::sin(i * 0.05), 40 + 0.4 * i)});
    PathOptions o;
    o.tool_length_mm = 60;
    const JointPath p = solve_path(m, poses, {}, o);
    REQUIRE(p.reachable);
    CHECK(p.branch_changes == 0);
    CHECK(max_jump(p, 0) < 10);
    CHECK(max_jump(p, 1) < 10);
    check_reproduces(m, p, o.tool_length_mm);
  }
}

TEST_CASE("through the singular pose the free angle stays continuous and the pose is reported") {
  const Machine m = shipped_machine("xyzac-trt");
  // The tool axis swings through the vertical (C free there) in the plane at azimuth 30 degrees.
  std::vector<ToolPose> poses;
  for (int i = -50; i <= 50; ++i) poses.push_back({Eigen::Vector3d(i, 0, 0), tilted(0.4 * i, 30)});
  PathOptions o;
  o.tool_length_mm = 50;
  const JointPath p = solve_path(m, poses, {}, o);
  REQUIRE(p.reachable);
  CHECK(!p.singular.empty());
  const int c = m.rotary[0].name == "C" ? 0 : 1;
  MESSAGE("largest C step " << max_jump(p, c) << ", largest A step " << max_jump(p, 1 - c) << ", singular poses "
                            << p.singular.size());
  CHECK(max_jump(p, c) < 1e-6);  // the plane of the swing does not turn: C holds
  CHECK(max_jump(p, 1 - c) < 0.5);
  check_reproduces(m, p, o.tool_length_mm);
}

TEST_CASE("out of reach: a tilt beyond the A limits names the pose and the axis") {
  const Machine m = shipped_machine("xyzac-trt");  // A in [-120, 30]: the tool tilts up to 120 deg one way, 30 the other
  std::vector<ToolPose> poses;
  for (int i = 0; i <= 20; ++i) poses.push_back({Eigen::Vector3d::Zero(), tilted(5.0 * i, 0)});
  poses.push_back({Eigen::Vector3d::Zero(), Eigen::Vector3d(0, 0, -1)});  // pointing up from below: A = 180
  const JointPath p = solve_path(m, poses, {}, {});
  CHECK_FALSE(p.reachable);
  CHECK(p.failed_pose == 21);
  CHECK(p.why.find("rotary axis A") != std::string::npos);
  try {
    require_reachable(p, poses, "flank-2");
    FAIL("no error");
  } catch (const MachineError& e) {
    CHECK(std::string(e.what()).find("patch 'flank-2': pose 21 (tip 0.000, 0.000, 0.000 mm) is out of reach: rotary axis A") == 0);
  }

  // A path marked reachable whose joints are not all finite numbers is refused too, naming the block.
  JointPath bad = solve_path(m, std::vector<ToolPose>(poses.begin(), poses.begin() + 5), {}, {});
  REQUIRE(bad.reachable);
  REQUIRE(bad.joints.size() >= 4);
  bad.joints[3].rotary[0] = INFINITY;
  try {
    require_reachable(bad, poses, "flank-3");
    FAIL("no error");
  } catch (const MachineError& e) {
    CHECK(std::string(e.what()).find("patch 'flank-3': block 3 (tip ") == 0);
    CHECK(std::string(e.what()).find("not a finite number") != std::string::npos);
  }

  std::vector<ToolPose> far = {{Eigen::Vector3d(0, 0, 0), Eigen::Vector3d::UnitZ()}, {Eigen::Vector3d(900, 0, 0), Eigen::Vector3d::UnitZ()}};
  const JointPath q = solve_path(m, far, {}, {});
  CHECK_FALSE(q.reachable);
  CHECK(q.failed_pose == 1);
  CHECK(q.why.find("X = 900") != std::string::npos);
}

TEST_CASE("linearisation keeps every intermediate tip within the tolerance through large rotary moves") {
  for (const std::string name : {"xyzac-trt", "xyzbc-head-table", "xyzca-head-head", "xyzbc-nutating"}) {
    CAPTURE(name);
    const Machine m = shipped_machine(name);
    // 8 poses only: tilt 0 -> 28 deg while the azimuth turns 150 deg, tip on a line 100 mm off the pivots.
    const IntendedMotion motion = [](double t) {
      return ToolPose{Eigen::Vector3d(100 + 40 * t, -30 + 60 * t, 20), tilted(1 + 27 * t, 150 * t)};
    };
    std::vector<ToolPose> poses;
    std::vector<double> ts;
    for (int i = 0; i <= 7; ++i) ts.push_back(i / 7.0), poses.push_back(motion(i / 7.0));
    PathOptions o;
    o.tool_length_mm = 70;
    o.tolerance_mm = 0.005;
    const JointPath p = solve_path(m, poses, ts, o, motion);
    REQUIRE(p.reachable);
    CHECK(p.unresolved_blocks == 0);
    CHECK(p.inserted > 20);
    double worst = 0, worst_angle = 0;
    for (size_t i = 1; i < p.joints.size(); ++i)
      for (int s = 1; s < 40; ++s) {  // far finer than the linearisation's own checks
        const double f = s / 40.0;
        Joints q;
        q.linear = (1 - f) * p.joints[i - 1].linear + f * p.joints[i].linear;
        for (int k = 0; k < 2; ++k) q.rotary[size_t(k)] = (1 - f) * p.joints[i - 1].rotary[size_t(k)] + f * p.joints[i].rotary[size_t(k)];
        const ToolPose got = forward(m, q, o.tool_length_mm), want = motion((1 - f) * p.t[i - 1] + f * p.t[i]);
        worst = std::max(worst, (got.tip - want.tip).norm());
        worst_angle = std::max(worst_angle, std::acos(std::min(1.0, got.axis.dot(want.axis))) * 180 / M_PI);
      }
    MESSAGE(name << ": " << p.inserted << " poses inserted, worst tip error " << worst << " mm, axis " << worst_angle << " deg");
    CHECK(worst <= o.tolerance_mm);
    CHECK(worst_angle <= o.angle_tolerance_deg);
    check_reproduces(m, p, o.tool_length_mm);
  }
}

TEST_CASE("inverse-time feed: the programmed tip feed unless an axis would exceed its maximum speed") {
  const Machine m = shipped_machine("xyzac-trt");
  std::vector<ToolPose> poses = {{Eigen::Vector3d(0, 0, 0), Eigen::Vector3d::UnitZ()},
                                 {Eigen::Vector3d(10, 0, 0), Eigen::Vector3d::UnitZ()},
                                 {Eigen::Vector3d(10.1, 0, 0), tilted(30, 90)}};
  PathOptions o;
  o.tolerance_mm = 1e3;  // no linearisation here
  o.angle_tolerance_deg = 90;
  const JointPath p = solve_path(m, poses, {}, o);
  REQUIRE(p.joints.size() == 3);
  const auto feeds = block_feeds(m, p, 1000);
  CHECK(feeds[1].minutes == doctest::Approx(10.0 / 1000));
  CHECK(feeds[1].limiting_axis == -1);
  CHECK(feeds[1].inverse_time == doctest::Approx(100));
  // 30 deg of A at 5400 deg/min takes 1/180 min, far longer than 0.1 mm at 1000 mm/min.
  const int a = m.rotary[0].name == "A" ? 0 : 1;
  CHECK(feeds[2].limiting_axis == 3 + a);
  CHECK(feeds[2].minutes == doctest::Approx(30.0 / 5400).epsilon(1e-6));
}

TEST_CASE("passing close to the singular pose: C swings fast there and the feed is slowed by C's speed limit") {
  const Machine m = shipped_machine("xyzac-trt");
  // The axis passes 0.2 deg beside the vertical: the azimuth, and so C, turns 180 deg within a few poses.
  std::vector<ToolPose> poses;
  for (int i = -40; i <= 40; ++i) {
    const Eigen::Vector3d k = Eigen::Vector3d(0.05 * i * M_PI / 180, 0.2 * M_PI / 180, 1).normalized();
    poses.push_back({Eigen::Vector3d(0.5 * i, 0, 0), k});
  }
  PathOptions o;
  o.tolerance_mm = 1e3;
  o.angle_tolerance_deg = 90;
  const JointPath p = solve_path(m, poses, {}, o);
  REQUIRE(p.reachable);
  CHECK(!p.singular.empty());
  const auto feeds = block_feeds(m, p, 2000);
  const int c = m.rotary[0].name == "C" ? 0 : 1;
  int slowed = 0;
  for (size_t i = 1; i < feeds.size(); ++i)
    if (feeds[i].limiting_axis == 3 + c) {
      ++slowed;
      CHECK(std::find(p.singular.begin(), p.singular.end(), int(i)) != p.singular.end());
      CHECK(feeds[i].tip_feed_mm_min < 2000);
    }
  MESSAGE(slowed << " blocks slowed by C near the singular pose, " << p.singular.size() << " poses near it");
  CHECK(slowed > 0);
}

TEST_CASE("programmed coordinates: tip and angles with TCP, machine joints without") {
  const ToolPose pose{Eigen::Vector3d(12, -7, 3), tilted(20, 45)};
  for (const std::string name : {"xyzac-trt", "xyzbc-head-table"}) {
    CAPTURE(name);
    const Machine m = shipped_machine(name);
    const Joints q = inverse(m, pose, 90).front();
    const Joints p = programmed(m, q, pose);
    CHECK(p.rotary == q.rotary);
    if (m.controller.tcp)
      CHECK((p.linear - pose.tip).norm() == 0);
    else
      CHECK((p.linear - q.linear).norm() == 0);
    CHECK((q.linear - pose.tip).norm() > 1);  // joints and tip differ for a tilted tool away from the pivots
  }
}

TEST_CASE("solve_path breaks a tie between mirror branches the same way whatever the round-off") {
  // A tilted axis turning about Z: both A/C branches (A, C) and (-A, C + 180) travel exactly alike.
  const Machine m = shipped_machine("xyzac-trt");
  for (double noise : {0.0, 1e-13, -1e-13}) {
    CAPTURE(noise);
    std::vector<ToolPose> poses;
    for (int i = 0; i < 20; ++i) {
      const double a = 0.05 * i;
      poses.push_back({Eigen::Vector3d(50, 10 * i, 0), Eigen::Vector3d(0.2 * std::cos(a) + noise * i, 0.2 * std::sin(a), 0.98).normalized()});
    }
    const JointPath p = solve_path(m, poses, {}, PathOptions{});
    REQUIRE(p.reachable);
    // The A table's range is [-120, 30]: the branch nearer its middle tilts negative.
    for (const Joints& j : p.joints) CHECK(j.rotary[0] < 0);
  }
}

TEST_CASE("solve_path gives the same joints, inserted poses and singular poses on 1 and 2 threads") {
  const Machine m = shipped_machine("xyzac-trt");
  // Coarse poses (the linearisation inserts) passing near the singular A = 0.
  const IntendedMotion motion = [](double t) {
    return ToolPose{Eigen::Vector3d(-100 + 200 * t, 20 * std::sin(3 * t), 10), tilted(0.2 + 20 * t, 400 * t)};
  };
  std::vector<ToolPose> poses;
  std::vector<double> ts;
  for (int i = 0; i < 150; ++i) ts.push_back(i / 149.0), poses.push_back(motion(ts.back()));
  PathOptions o;
  o.tool_length_mm = 80;
  const int threads = omp_get_max_threads();
  omp_set_num_threads(1);
  const JointPath a = solve_path(m, poses, ts, o, motion);
  omp_set_num_threads(2);
  const JointPath b = solve_path(m, poses, ts, o, motion);
  omp_set_num_threads(threads);
  REQUIRE(a.reachable);
  CHECK(a.inserted > 0);
  CHECK(!a.singular.empty());
  REQUIRE(a.joints.size() == b.joints.size());
  int differ = 0;
  for (size_t i = 0; i < a.joints.size(); ++i)
    if (a.joints[i].linear != b.joints[i].linear || a.joints[i].rotary != b.joints[i].rotary || a.t[i] != b.t[i] ||
        a.input_index[i] != b.input_index[i] || a.poses[i].tip != b.poses[i].tip)
      ++differ;
  CHECK(differ == 0);
  CHECK(a.singular == b.singular);
  CHECK(a.inserted == b.inserted);
  check_reproduces(m, a, 80);
}

TEST_CASE("a tilt of 100 degrees on an A table limited to [-120, 30]: one branch is out of reach at every pose, and the path is the other, every joint finite") {
  // The mirror branch (+100) is beyond A's 30: its state has no cost. The choice at the last pose
  // must not take it because its unset angle (0) sits nearer the middle of A's range (-45) than -100
  // does; the HECC impeller's flank set up upside down (A near -109) once got joints that were not
  // numbers from that.
  const Machine m = shipped_machine("xyzac-trt");
  for (double azimuth : {0.0, 90.0, 180.0, 270.0, 33.0}) {
    CAPTURE(azimuth);
    std::vector<ToolPose> poses;
    for (int i = 0; i < 10; ++i) poses.push_back({Eigen::Vector3d(20, 5.0 * i, 10), tilted(100 + 0.5 * i, azimuth + 2.0 * i)});
    const JointPath p = solve_path(m, poses, {}, PathOptions{});
    REQUIRE(p.reachable);
    for (const Joints& j : p.joints) {
      REQUIRE(j.linear.allFinite());
      CHECK(j.rotary[0] < -99.9);
      CHECK(j.rotary[0] > -105.1);
      CHECK(std::isfinite(j.rotary[1]));
    }
    check_reproduces(m, p, PathOptions{}.tool_length_mm);
    CHECK_NOTHROW(require_reachable(p, poses, "tilted"));
  }
}

TEST_CASE("passing beside the singular pose, far from the C axis: every block's joint interpolation stays on the motion") {
  // The HECC diffuser turned over ([180, 0, 0]): the axis passed 0.03 deg beside the vertical between
  // two poses 280 mm from the C axis; the linearisation's inserted poses took the IK branch nearest
  // the block's start, and the last sub-block turned C by 180 deg while A changed sign (the same
  // axis at both ends): the table swung the part under the tool, a 0.446 mm gouge. Beside by 0.03
  // deg and 0.01 deg (within the angle tolerance: crossing A = 0 is fine), by 0.3 deg (near-singular)
  // and by 2 and 5 deg (C must turn), in coarse and fine steps. (Not covered: passing within the
  // tolerance in steps of 8 deg, where A's limits forbid the crossing and C must turn its half turn
  // while the axis is within 0.1 deg of the vertical: blocks are left off tolerance there.)
  const Machine m = shipped_machine("xyzac-trt");
  for (const double beside_deg : {0.01, 0.03, 0.3, 2.0, 5.0})
    for (const double step_deg : {0.7, 1.5, 8.0}) {
      if (beside_deg < 0.05 && step_deg > 2) continue;
      CAPTURE(beside_deg);
      CAPTURE(step_deg);
      std::vector<ToolPose> poses;
      for (int i = -5; i <= 6; ++i) {
        const double x = std::tan(step_deg * (i - 0.37) * M_PI / 180), y = std::tan(beside_deg * M_PI / 180);
        poses.push_back({Eigen::Vector3d(-190 + 0.5 * i, -203, -130), Eigen::Vector3d(x, y, 1).normalized()});
      }
      PathOptions o;
      const JointPath p = solve_path(m, poses, {}, o);
      REQUIRE(p.reachable);
      CHECK(p.unresolved_blocks == 0);
      // Every pose's tip exactly; the axis exactly at the given poses, within 0.8 of the angle
      // tolerance at those inserted near the vertical (their free angle follows the block).
      for (size_t i = 0; i < p.joints.size(); ++i) {
        const ToolPose back = forward(m, p.joints[i], o.tool_length_mm);
        CHECK((back.tip - p.poses[i].tip).norm() < 1e-9);
        if (p.input_index[i] >= 0) CHECK((back.axis - p.poses[i].axis).norm() < 1e-9);
        else CHECK(std::acos(std::min(1.0, back.axis.dot(p.poses[i].axis))) * 180 / M_PI < 0.8 * o.angle_tolerance_deg + 1e-6);
      }
      // Between every pair of consecutive poses (inserted ones too), the controller's joint
      // interpolation against the straight tip and great-circle axis: within the tolerances (plus
      // what the checks between samples allow).
      double worst_mm = 0, worst_deg = 0;
      for (size_t i = 1; i < p.joints.size(); ++i)
        for (int s = 1; s < 16; ++s) {
          const double f = s / 16.0;
          Joints q;
          q.linear = (1 - f) * p.joints[i - 1].linear + f * p.joints[i].linear;
          for (size_t k = 0; k < 2; ++k) q.rotary[k] = (1 - f) * p.joints[i - 1].rotary[k] + f * p.joints[i].rotary[k];
          const ToolPose want = interpolate(p.poses[i - 1], p.poses[i], f), got = forward(m, q, o.tool_length_mm);
          worst_mm = std::max(worst_mm, (got.tip - want.tip).norm());
          worst_deg = std::max(worst_deg, std::acos(std::min(1.0, got.axis.dot(want.axis))) * 180 / M_PI);
        }
      CAPTURE(worst_mm);
      CAPTURE(worst_deg);
      CHECK(worst_mm < 1.2 * o.tolerance_mm);
      CHECK(worst_deg < 1.2 * o.angle_tolerance_deg);
      if (beside_deg >= 2) CHECK(p.branch_changes == 0);  // C turns; A never passes 0
    }
}
