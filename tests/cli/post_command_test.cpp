#include <doctest/doctest.h>

#include <filesystem>

#include "kinematics/machine.h"
#include "postproc/gcode.h"
#include "tests/test_util.h"

using namespace flankcam;

namespace {
const std::string kApt = std::string(TEST_DATA) + "/golden/small-patch.apt";
}

TEST_CASE("flankcam post: APT from a file through a shipped machine, read back onto the CL poses") {
  test::ScratchDir dir("post");
  test::write_text(dir.file("b.apt"), test::read_text(kApt));
  const auto r = test::run_flankcam("post " + kApt + " " + dir.file("b.apt") + " --machine xyzbc-trt --out " + dir.file("out"), dir);
  INFO(r.err);
  REQUIRE(r.code == 0);
  for (const char* f : {"small-patch.nc", "b.nc", "all.nc", "small-patch-tool.stl"}) CHECK(std::filesystem::exists(dir.file(std::string("out/") + f)));
  // The program's feed end points are the APT's GOTOs, through the machine's forward kinematics.
  const Machine m = load_machine(std::string(FLANKCAM_SOURCE_DIR) + "/machines/xyzbc-trt.yaml");
  const ClProgram cl = read_apt(kApt);
  const auto points = parse_nc(test::read_text(dir.file("out/small-patch.nc")), Dialect::Iso, {"B", "C"}, "small-patch.nc");
  size_t next = 2;  // CL moves 0, 1: clearance and lead-in rapids; 2..: the feed moves
  for (const NcPoint& p : points) {
    if (p.rapid || next >= cl.moves.size()) continue;
    const ToolPose pose = programmed_pose(m, p.at, 0);
    if ((pose.tip - cl.moves[next].pose.tip).norm() < 2e-4 && (pose.axis - cl.moves[next].pose.axis).norm() < 1e-5) ++next;
  }
  CHECK(next == cl.moves.size() - 1);  // every feed GOTO reached, in order (the last is the rapid retract)
  const std::string all = test::read_text(dir.file("out/all.nc"));
  CHECK(all.find("(patch small-patch)") < all.find("(patch b)"));
}

TEST_CASE("flankcam post: errors name the file, line or option, and write no program") {
  test::ScratchDir dir("post-errors");
  const auto fails = [&](const std::string& args, const std::string& message) {
    const auto r = test::run_flankcam("post " + args + " --out " + dir.file("out"), dir);
    CAPTURE(args);
    CHECK(r.code == 2);
    CHECK(r.err.find(message) != std::string::npos);
    CHECK(std::count(r.err.begin(), r.err.end(), '\n') == 1);
    CHECK(!std::filesystem::exists(dir.file("out/small-patch.ngc")));
  };
  fails(kApt + " --machine nosuch", "machine 'nosuch': no such file, and not one of the shipped machines (xyzac-trt,");
  fails(kApt + " --machine xyzbc-head-table", "--tool-length: machine xyzbc-head-table turns the head");
  fails(kApt + " --machine xyzac-trt --dialect fanucc", "dialect: 'fanucc' is not one of");
  test::write_text(dir.file("bad.apt"), "PARTNO/X\nFEDRAT/100\nGOTO/1,2,zz\n");
  fails(dir.file("bad.apt") + " --machine xyzac-trt", "bad.apt:3: GOTO z: 'zz' is not a number");
  // A pose the A table cannot tilt to (axis pointing down): the patch and pose are named.
  test::write_text(dir.file("steep.apt"), "PARTNO/X\nFEDRAT/100\nGOTO/1,2,3,0,0,1\nGOTO/1,2,3,0,-0.8,-0.6\n");
  fails(dir.file("steep.apt") + " --machine xyzac-trt", "patch 'steep': pose 1 (tip 1.000, 2.000, 3.000 mm) is out of reach");
  CHECK(!std::filesystem::exists(dir.file("out/steep.ngc")));
}
