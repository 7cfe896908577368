#include "postproc/apt.h"

#include <doctest/doctest.h>

#include <Eigen/Geometry>

#include "core/errors.h"
#include "tests/postproc/small_patch.h"
#include "tests/test_util.h"

using namespace flankcam;

using test::small_patch;

TEST_CASE("APT golden file for a small fixed patch") {
  const std::string text = apt_text(small_patch());
  const std::string golden = std::string(TEST_DATA) + "/golden/small-patch.apt";
  if (std::getenv("FLANKCAM_UPDATE_GOLDEN")) test::write_text(golden, text);
  CHECK(text == test::read_text(golden));
  for (size_t a = 0, b; a < text.size(); a = b + 1) {  // ISO 4343: data before column 72
    b = text.find('\n', a);
    CHECK(b - a <= 72);
  }
}

TEST_CASE("APT round trip: the moves, feeds, cutter and profile read back") {
  const ClProgram p = small_patch();
  test::ScratchDir dir("apt");
  write_apt(dir.file("p.apt"), p);
  const ClProgram q = read_apt(dir.file("p.apt"));
  REQUIRE(q.moves.size() == p.moves.size());
  for (size_t k = 0; k < p.moves.size(); ++k) {
    CAPTURE(k);
    CHECK((q.moves[k].pose.tip - p.moves[k].pose.tip).norm() < 1e-6);
    CHECK((q.moves[k].pose.axis - p.moves[k].pose.axis).norm() < 2e-9);
    CHECK(q.moves[k].rapid == p.moves[k].rapid);
    CHECK(q.moves[k].feed_mm_min == p.moves[k].feed_mm_min);
  }
  // Approach along the first axis: clearance, lead-in, then the cut.
  CHECK(p.moves[0].rapid);
  CHECK((p.moves[0].pose.tip - p.moves[2].pose.tip).norm() == doctest::Approx(50));
  CHECK((p.moves[1].pose.tip - p.moves[2].pose.tip).norm() == doctest::Approx(5));
  CHECK(q.cutter.d == doctest::Approx(12));
  CHECK(q.cutter.beta_deg == doctest::Approx(std::atan(3.0 / 40) * 180 / M_PI).epsilon(1e-6));
  CHECK(q.cutter.h == doctest::Approx(40));
  CHECK(q.profile.size() == 5);
  CHECK(q.spindle_rpm == 12000);
  CHECK(q.partno == "SMALL-PATCH");
  CHECK(cl_csv(p).find("2,feed,100.000000,0.000000,-5.500000,") != std::string::npos);
}

TEST_CASE("APT reader: other posts' orders and continuations are accepted, junk names its line") {
  const ClProgram p = parse_apt("PARTNO/X\nUNITS/MM\nSPINDL/RPM,9000,CCLW\nFEDRAT/MMPM,450\nGOTO/1,2,3,$\n  0,0,1\n"
                                "RAPID\nGOTO/4,5,6\n$$ a comment\nFEDRAT/300.5,MMPM\nGOTO/7,8,9,0.6,0,0.8\nEND\nFINI\n",
                                "other.apt");
  REQUIRE(p.moves.size() == 3);
  CHECK(p.spindle_rpm == 9000);
  CHECK_FALSE(p.clockwise);
  CHECK(p.moves[0].feed_mm_min == 450);
  CHECK(p.moves[1].rapid);
  CHECK(p.moves[1].pose.axis == Eigen::Vector3d::UnitZ());  // 3 values keep the last axis
  CHECK(p.moves[2].feed_mm_min == 300.5);
  CHECK(p.moves[2].pose.axis.x() == doctest::Approx(0.6));

  const auto error = [](const std::string& text) {
    try {
      (void)parse_apt(text, "bad.apt");
    } catch (const InputError& e) {
      return std::string(e.what());
    }
    return std::string("accepted");
  };
  CHECK(error("UNITS/MM\nFEDRAT/100\nGOTO/1,2\n") == "bad.apt:3: GOTO: expected 3 or 6 values, got 2");
  CHECK(error("FEDRAT/100\nGOTO/1,2,x3\n") == "bad.apt:2: GOTO z: 'x3' is not a number");
  CHECK(error("GOTO/1,2,3\n") == "bad.apt:1: GOTO: a feed move before any FEDRAT");
  CHECK(error("UNITS/INCHES\n") == "bad.apt:1: UNITS: only MM is supported, got 'INCHES'");
  CHECK(error("FEDRAT/100\nGOTO/1,2,3,0,0,2\n") == "bad.apt:2: GOTO: the tool axis (i, j, k) is not a unit vector");
  CHECK(error("FEDRAT/100\nGOTO/1,2,$\n") == "bad.apt:2: the file ends inside a statement continued with $");
  CHECK(error("PARTNO/X\n") == "bad.apt: no GOTO moves");
}

// Issue 12 item 8: LOADTL/1e300 became T-2147483648 (undefined behaviour), FEDRAT/1e-300 posted
// F0.0000, SPINDL/1e300 a 301-digit S word.
TEST_CASE("APT reader: every value has a range, and a value outside it names its line") {
  const auto error = [](const std::string& text) {
    try {
      (void)parse_apt(text, "bad.apt");
    } catch (const InputError& e) {
      return std::string(e.what());
    }
    return std::string("accepted");
  };
  const std::string moves = "FEDRAT/100\nGOTO/1,2,3\n";
  CHECK(error("LOADTL/1e300\n" + moves) == "bad.apt:1: LOADTL: '1e300' is outside 0..99999");
  CHECK(error("LOADTL/2.5\n" + moves) == "bad.apt:1: LOADTL: '2.5' is not a whole number");
  CHECK(error("LOADTL/-1\n" + moves) == "bad.apt:1: LOADTL: '-1' is outside 0..99999");
  CHECK(error("FEDRAT/1e-300\nGOTO/1,2,3\n") == "bad.apt:1: FEDRAT: '1e-300' is outside 0.1..1e+06 mm/min");
  CHECK(error("SPINDL/1e300,RPM\n" + moves) == "bad.apt:1: SPINDL: '1e300' is outside 0..1e+06 rpm");
  CHECK(error("FEDRAT/100\nGOTO/1e300,2,3\n") == "bad.apt:2: GOTO x: '1e300' is outside -1e+06..1e+06 mm");
  CHECK(error("FEDRAT/100\nGOTO/1,2,3,1e308,1e308,0\n") == "bad.apt:2: GOTO i: '1e308' is outside -2..2");
  CHECK(error("CUTTER/1e300\n" + moves) == "bad.apt:1: CUTTER: '1e300' is outside 0..10000 mm");
  CHECK(error("PPRINT/'PROFILE 0 1e300'\n" + moves) == "bad.apt:1: PPRINT 'PROFILE: z 0, r 1e+300 outside +-10000 mm");
  CHECK(error("PARTNO/X\nFEDRAT/1\nGOTO/1,2,3\n") == "accepted");
  // The bounds themselves are accepted.
  const ClProgram p = parse_apt("LOADTL/99999\nSPINDL/1e6,RPM\nFEDRAT/0.1\nGOTO/-1e6,1e6,0\n", "edge.apt");
  CHECK(p.tool == 99999);
  CHECK(p.spindle_rpm == 1e6);
  CHECK(p.moves.at(0).feed_mm_min == 0.1);
  CHECK(p.moves.at(0).pose.tip.x() == -1e6);
}
