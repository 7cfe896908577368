// A 5-axis machine as data: three linear axes and two rotary axes, each rotary axis carrying
// either the table (it turns the part) or the head (it turns the tool), plus controller facts.
// Read from machines/*.yaml; every number a user writes is in mm, degrees, mm/min and deg/min.
#pragma once
#include <Eigen/Core>
#include <array>
#include <optional>
#include <string>
#include <vector>

namespace flankcam {

enum class Carrier { Table, Head };

struct RotaryAxis {
  std::string name;                                   // A, B or C
  Carrier carries = Carrier::Table;
  // A positive angle turns the carried body (part or tool) right-handed about this unit direction.
  // ISO tables turn the other way round from heads, so an ISO A table has direction -X.
  Eigen::Vector3d direction = Eigen::Vector3d::UnitZ();
  // A point on the rotation axis at zero angles: tables in part (work) coordinates; heads
  // relative to the head's pivot point (gauge_length above the spindle nose), usually 0.
  Eigen::Vector3d pivot = Eigen::Vector3d::Zero();
  bool continuous = false;                            // no limits, values are unwound (may exceed ±360)
  double min_deg = -360, max_deg = 360;
  double max_speed_deg_min = 3600;
};

struct LinearAxis {
  std::string name;  // X, Y, Z
  double min_mm = -1e9, max_mm = 1e9;
  double max_speed_mm_min = 10000;
};

struct Controller {
  bool tcp = false;             // G43.4 / TRAORI / M128: the controller takes tip + angles
  // A name of postproc's dialect table (postproc checks it: kinematics does not depend on postproc).
  std::string dialect = "iso";
  int dialect_line = 0;         // its line in the machine file (0: the default, or built in code)
  bool inverse_time = true;     // G93 for simultaneous moves
  bool linuxcnc_trt = false;    // LinuxCNC with trt kinematics active: programs give tip + angles
};

// Where the tool-change macro takes the machine, in machine joints (mm, deg): first Z, then X and Y,
// then the rotary axes; an axis not given stays where it is. Default (nothing given): Z to the top of
// its travel, everything else unchanged.
struct ToolChangePosition {
  std::array<std::optional<double>, 5> joints;  // X, Y, Z, rotary[0], rotary[1]
  int line = 0;                                 // its line in the machine file (0: the default)
};

struct Machine {
  std::string name, description;
  std::string file;  // where it came from (for messages)
  std::array<LinearAxis, 3> linear;
  // In chain order from the machine base outward: tables from the bed to the part, heads from the
  // ram to the spindle. Joint values keep this order.
  std::array<RotaryAxis, 2> rotary;
  Eigen::Vector3d spindle_direction = Eigen::Vector3d::UnitZ();  // tool axis (tip -> spindle) at zero angles
  double gauge_length_mm = 0;  // head's pivot point to the spindle nose, along the spindle
  Controller controller;
  ToolChangePosition tool_change;

  [[nodiscard]] std::string kind() const;  // "table-table", "head-table" or "head-head"
  [[nodiscard]] int tables() const;
};

// Sane ranges of what a machine file may say (beyond them a value is a typo or an attack, and
// would post nonsense such as F0.0000).
struct MachineRanges {
  static constexpr double position_mm = 1e6;            // |linear limit|, |pivot|: 1 km
  static constexpr double rotary_deg = 36000;            // |rotary limit|: 100 turns
  static constexpr double linear_speed_mm_min[2] = {1, 1e6};    // 1 mm/min .. 1 km/min
  static constexpr double rotary_speed_deg_min[2] = {1, 1e7};   // up to ~28000 rpm
  static constexpr double gauge_length_mm = 1e4;         // 10 m
};

// Reads and validates a machine file. Throws MachineError "FILE:LINE: FIELD: what" for a missing
// field, a value outside MachineRanges, a zero direction, limits in the wrong order, parallel
// rotary axes, and the like. controller.dialect is kept as written (postproc checks the name).
[[nodiscard]] Machine load_machine(const std::string& path);
// Checks a machine built in code; throws MachineError naming the field.
void validate(const Machine& m);

}  // namespace flankcam
