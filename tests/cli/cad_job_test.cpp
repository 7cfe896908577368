// A job whose surface and part are a STEP/IGES model, through the real binary: the flank's faces
// picked by number, the whole model as the part, the fit equal to the one on the same faces
// tessellated and handed over as a mesh.
#include <doctest/doctest.h>

#include <nlohmann/json.hpp>

#include "cad/cad_reader.h"
#include "cad/example_model.h"
#include "core/mesh.h"
#include "tests/test_util.h"

using namespace flankcam;

namespace {
const char* job_tail =
    "tool: {shape: general}\ntolerance: 0.015\nclearance: 1\n"
    "patches:\n  - name: blade\n    init: lines\n    lines:\n"  // examples/blade/job-1-patch.yaml
    "      - [-6.301, 9.054, -0.782, -7.942, 5.966, 61.189]\n"
    "      - [2.496, 10.322, -1.014, -1.515, 9.512, 61.002]\n"
    "      - [10.691, 10.006, -1.233, 4.819, 11.629, 60.825]\n"
    "      - [18.454, 8.933, -1.447, 10.988, 13.031, 60.649]\n"
    "      - [26.078, 7.273, -1.648, 17.213, 13.952, 60.482]\n";
}  // namespace

TEST_CASE("a job on a STEP and an IGES model fits the flank faces against the whole model, as on the same faces as a mesh" * doctest::test_suite("heavy")) {
  test::ScratchDir dir("cad-job");
  double eps_step = 0;
  for (const char* ext : {"step", "igs"}) {
    CAPTURE(ext);
    const std::string model = dir.file(std::string("blade.") + ext);
    write_example_model(model, {});
    test::write_text(dir.file(std::string("job-") + ext + ".yaml"),
                     std::string("surface: {file: blade.") + ext + ", faces: [1, 2]}\npart: blade." + ext + "\n" + job_tail);
    const auto r = test::run_flankcam(std::string("fit ") + dir.file(std::string("job-") + ext + ".yaml") + " --out " +
                                          dir.file(std::string("out-") + ext),
                                      dir);
    INFO(r.err);
    REQUIRE(r.code == 0);  // no collision with the floor, the bore or the flank's own faces in the part
    const auto report = nlohmann::json::parse(test::read_text(dir.file(std::string("out-") + ext + "/report.json")));
    const auto& patch = report["patches"][0];
    CHECK(patch["collisions"].size() == 0);
    CHECK(double(patch["eps_opt_mm"]) < 0.015);
    CHECK(double(patch["coverage"]) > 0.8);
    if (std::string(ext) == "step") {
      eps_step = patch["eps_opt_mm"];
      // The same faces tessellated by the reader, written as OBJ and fitted as a mesh: the same fit.
      const CadMesh m = load_cad(model, {{1, 2}, surface_deflection_mm(0.015), 0.1, 0.01, {}, 0});
      write_obj(dir.file("flank.obj"), m.loaded.mesh, "flank faces 1-2");
      test::write_text(dir.file("job-obj.yaml"), std::string("surface: flank.obj\n") + job_tail);
      const auto o = test::run_flankcam("fit " + dir.file("job-obj.yaml") + " --out " + dir.file("out-obj"), dir);
      INFO(o.err);
      REQUIRE(o.code == 0);
      const auto mesh_report = nlohmann::json::parse(test::read_text(dir.file("out-obj/report.json")));
      CHECK(double(mesh_report["patches"][0]["eps_opt_mm"]) == doctest::Approx(eps_step).epsilon(1e-6));
    } else {
      CHECK(double(patch["eps_opt_mm"]) == doctest::Approx(eps_step).epsilon(0.05));  // IGES: its own tessellation
    }
  }
}
