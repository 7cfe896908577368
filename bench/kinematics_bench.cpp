// Poses per second through inverse kinematics + path choice + linearisation (issues 4 and 16 goal:
// >= 1,000,000 poses/s on 2 cores), on a flank-like motion for every shipped machine, the blocks
// checked against the motion itself and against the interpolation between poses (the post's call).
#include <fmt/format.h>

#include <chrono>
#include <ctime>
#include <omp.h>

#include "kinematics/path.h"

using namespace flankcam;

int main() {
  for (const char* name : {"xyzac-trt", "xyzbc-trt", "xyzbc-head-table", "xyzca-head-head", "xyzbc-nutating"}) {
    const Machine m = load_machine(std::string(FLANKCAM_SOURCE_DIR) + "/machines/" + name + ".yaml");
    // 200,000 poses along 400 mm: tilt 10..35 deg, azimuth over 120 deg, 2 µm apart.
    const int n = 200000;
    const IntendedMotion motion = [](double t) {
      const double tilt = (10 + 25 * t) * M_PI / 180, az = (120 * t) * M_PI / 180;
      return ToolPose{Eigen::Vector3d(-200 + 400 * t, 30 * std::sin(3 * t), 10),
                      Eigen::Vector3d(std::sin(tilt) * std::cos(az), std::sin(tilt) * std::sin(az), std::cos(tilt))};
    };
    std::vector<ToolPose> poses;
    std::vector<double> ts;
    for (int i = 0; i < n; ++i) ts.push_back(double(i) / (n - 1)), poses.push_back(motion(ts.back()));
    PathOptions o;
    o.tool_length_mm = 80;
    // With the intended motion (checked against it), and without (checked against the straight
    // tip and great-circle axis between poses: how flankcam's post calls it).
    for (const bool with_motion : {true, false}) {
      const auto t0 = std::chrono::steady_clock::now();
      const std::clock_t c0 = std::clock();
      const JointPath p = with_motion ? solve_path(m, poses, ts, o, motion) : solve_path(m, poses, ts, o);
      const double s = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
      const double cpu = double(std::clock() - c0) / CLOCKS_PER_SEC;
      fmt::print("kinematics {:<17} {:<14} {} poses, {} inserted, reachable {}: {:.0f} poses/s ({:.0f} per CPU-s) on {} threads "
                 "[goal >= 1,000,000 on 2 cores]\n",
                 name, with_motion ? "motion" : "between poses", n, p.inserted, p.reachable, n / s, n / cpu,
                 omp_get_max_threads());
    }
  }
}
