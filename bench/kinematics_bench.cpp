// Poses per second through inverse kinematics + path choice + linearisation (issues 4 and 16 goal:
// >= 1,000,000 poses/s on 2 cores), on a flank-like motion for every shipped machine, the blocks
// checked against the motion itself and against the interpolation between poses (the post's call).
//
// Three figures per run, all from the same single solve_path call (after one untimed call that
// warms the process up):
//  - wall: poses / elapsed seconds. On a shared machine this is what the load leaves over.
//  - per CPU-s: poses / process CPU seconds (all threads, spin-waiting included).
//  - 2 cores: poses / the largest CPU time of any one OpenMP thread during the call, i.e. the wall
//    time the call takes when each of its threads has a core of its own (serial parts run on the
//    master thread and count in full; a worker waiting in a spin loop counts as busy). This is the
//    figure for the goal when the machine is shared; on an idle machine it matches `wall`.
#include <fmt/format.h>
#include <omp.h>
#include <time.h>

#include <algorithm>
#include <chrono>
#include <ctime>
#include <vector>

#include "kinematics/path.h"

using namespace flankcam;

namespace {
// CPU seconds used so far by each thread of the OpenMP team (index: thread number).
std::vector<double> team_cpu_s() {
  std::vector<double> out(size_t(omp_get_max_threads()), 0.0);
#pragma omp parallel
  {
    timespec ts{};
    clock_gettime(CLOCK_THREAD_CPUTIME_ID, &ts);
    out[size_t(omp_get_thread_num())] = double(ts.tv_sec) + 1e-9 * double(ts.tv_nsec);
  }
  return out;
}
}  // namespace

int main() {
  fmt::print("kinematics_bench: {} threads; poses/s wall | per CPU-s (all threads) | on 2 cores (n / the busiest thread's CPU s)\n",
             omp_get_max_threads());
  bool warm = false;
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
    // One untimed call first: the first call of the process starts OpenMP's threads and grows the
    // heap (page faults that later calls do not pay), which the first line alone used to carry.
    if (!warm) (void)solve_path(m, poses, ts, o, motion), warm = true;
    for (const bool with_motion : {true, false}) {
      const std::vector<double> team0 = team_cpu_s();
      const auto t0 = std::chrono::steady_clock::now();
      const std::clock_t c0 = std::clock();
      const JointPath p = with_motion ? solve_path(m, poses, ts, o, motion) : solve_path(m, poses, ts, o);
      const double s = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
      const double cpu = double(std::clock() - c0) / CLOCKS_PER_SEC;
      const std::vector<double> team1 = team_cpu_s();
      double busiest = 0;
      for (size_t k = 0; k < team0.size(); ++k) busiest = std::max(busiest, team1[k] - team0[k]);
      fmt::print("kinematics {:<17} {:<14} {} poses, {} inserted, reachable {}: {:>8.0f} poses/s wall | {:>8.0f} per CPU-s | "
                 "{:>8.0f} on {} cores [goal >= 1,000,000 on 2 cores]\n",
                 name, with_motion ? "motion" : "between poses", n, p.inserted, p.reachable, n / s, n / cpu, n / busiest,
                 omp_get_max_threads());
    }
  }
}
