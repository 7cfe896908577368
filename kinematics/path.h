// Joint values along a whole tool path: choosing the IK branch per path, unwinding continuous
// axes, handling singular poses, linearisation (the controller interpolates joints linearly) and
// inverse-time feeds clamped by the axes' speeds.
#pragma once
#include <functional>
#include <string>
#include <vector>

#include "kinematics/kinematics.h"

namespace flankcam {

struct PathOptions {
  double tool_length_mm = 0;        // spindle nose to tip (head axes)
  double tolerance_mm = 0.005;      // linearisation: tip off the intended motion
  double angle_tolerance_deg = 0.05;  // linearisation: axis off the intended motion
  int checks_per_block = 4;         // FK samples inside each block
  int max_depth = 12;               // bisection depth per block
  double singular_deg = 0.5;        // tool axis within this of the primary rotary axis: near-singular
  std::string validate() const;
};

// Intended pose at a path parameter (e.g. the fitted rails); empty: linear tip, slerp axis between poses.
using IntendedMotion = std::function<ToolPose(double t)>;

struct JointPath {
  bool reachable = true;
  int failed_pose = -1;    // first pose no solution reaches (index into the input poses)
  std::string why;         // which limit or tilt range
  std::vector<ToolPose> poses;  // intended poses, input ones plus those the linearisation inserted
  std::vector<double> t;        // their path parameters
  std::vector<Joints> joints;
  std::vector<int> input_index;  // per output pose: index of the input pose, -1 if inserted
  std::vector<int> singular;     // output poses where a rotary angle was free or near-free (filled)
  int branch_changes = 0;        // changes of IK branch along the path (0 when one branch covers it)
  int inserted = 0;              // poses added by linearisation
  int unresolved_blocks = 0;     // blocks still off tolerance at max_depth
};

// Solves the whole path: for each pose every IK solution within limits, then the sequence with
// the least rotary motion (dynamic programming), so the branch is chosen per path; then
// linearises. `t` must increase (same size as `poses`); empty: 0, 1, 2, ...
[[nodiscard]] JointPath solve_path(const Machine& m, const std::vector<ToolPose>& poses, std::vector<double> t,
                                   const PathOptions& options, const IntendedMotion& motion = {});

// Throws MachineError "patch 'NAME': pose I (tip x, y, z mm) is out of reach: WHY" when the path is not reachable.
void require_reachable(const JointPath& path, const std::vector<ToolPose>& poses, const std::string& patch);

// What a program states for a pose: with TCP (G43.4, TCPM, TRAORI, LinuxCNC trt kinematics) the tip
// in part coordinates and the rotary angles; without, the machine joints.
[[nodiscard]] Joints programmed(const Machine& m, const Joints& joints, const ToolPose& pose);
// The pose a program's values stand for (the inverse of `programmed`): forward kinematics of the
// joints, or with TCP the tip as written and the axis the rotary angles give.
[[nodiscard]] ToolPose programmed_pose(const Machine& m, const Joints& programmed, double tool_length_mm);

// A stretch of consecutive blocks where the rotary axes travel far more than the tool axis turns:
// near a singular orientation the free angle swings (xyzac-trt near A = 0: C turns 89.5 deg while
// the axis turns 3.1 deg). Poses index JointPath::poses; block i runs from pose i-1 to pose i.
struct SingularStretch {
  int first_pose = 0, last_pose = 0;
  double rotary_deg = 0;      // |dR1| + |dR2| summed over the stretch
  double axis_turn_deg = 0;   // the tool axis' turn over the stretch (summed per block)
};
// Block i of a path (i >= 1): the rotary travel |dR1| + |dR2| and the tool axis' turn, degrees.
struct BlockTurn {
  double rotary_deg = 0, axis_turn_deg = 0;
};
[[nodiscard]] BlockTurn block_turn(const JointPath& path, size_t i);
// Blocks whose rotary travel exceeds `ratio` degrees per degree of axis turn, merged into stretches,
// kept when they travel at least `min_rotary_deg`.
[[nodiscard]] std::vector<SingularStretch> singular_stretches(const JointPath& path, double ratio = 5,
                                                              double min_rotary_deg = 5);

struct BlockFeed {
  double minutes = 0;       // duration of the block (from the previous pose)
  double inverse_time = 0;  // G93 F word: 1 / minutes
  double tip_feed_mm_min = 0;  // achieved feed at the tip
  int limiting_axis = -1;   // -1: the programmed feed; 0..2 X, Y, Z; 3, 4 the rotary axes
};
// Per block i (pose i-1 -> i; entry 0 is empty): time at the programmed tip feed, stretched where an
// axis would exceed its maximum speed.
[[nodiscard]] std::vector<BlockFeed> block_feeds(const Machine& m, const JointPath& path, double feed_mm_min);
// Same with a programmed feed per block (entry i for the block ending at pose i; entry 0 unused).
[[nodiscard]] std::vector<BlockFeed> block_feeds(const Machine& m, const JointPath& path,
                                                 const std::vector<double>& feed_mm_min);

}  // namespace flankcam
