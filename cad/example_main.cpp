// flankcam_cad_example OUT [TOLERANCE_MM CLEARANCE_MM]: the acceptance driver for STEP/IGES input
// until the job reader takes CAD files itself. Writes OUT/blade_part.step and .igs (core/blade.h's blade
// as two B-spline faces, a floor with a bore), reads faces 1-2 (the flank) at tolerance/20 and every
// face (the part) at clearance/10 through load_surface_file exactly as a job would, and writes them
// as OBJ beside a tessellation made without OCCT (the analytic blade on a grid fine enough for the
// same chordal deviation) so that `flankcam fit` can be run on both and compared.
#include <cmath>
#include <cstdio>
#include <exception>
#include <filesystem>
#include <string>

#include "cad/cad_reader.h"
#include "cad/example_model.h"
#include "core/blade.h"
#include "core/errors.h"

using namespace flankcam;

namespace {
// Largest distance from a triangle centroid of the analytic grid to the analytic surface at the same
// (u, v): the grid's chordal deviation, measured rather than assumed.
double grid_deviation(const Blade& b) {
  const BladeOptions& o = b.options;
  double worst = 0;
  for (int j = 0; j + 1 < o.grid_span; ++j)
    for (int i = 0; i + 1 < o.grid_chord; ++i) {
      const double u0 = o.chord_from + (o.chord_to - o.chord_from) * i / (o.grid_chord - 1);
      const double u1 = o.chord_from + (o.chord_to - o.chord_from) * (i + 1) / (o.grid_chord - 1);
      const double v0 = double(j) / (o.grid_span - 1), v1 = double(j + 1) / (o.grid_span - 1);
      const Eigen::Vector3d mid = (b.point(u0, v0) + b.point(u1, v0) + b.point(u1, v1) + b.point(u0, v1)) / 4;
      worst = std::max(worst, (mid - b.point(0.5 * (u0 + u1), 0.5 * (v0 + v1))).norm());
    }
  return worst;
}
}  // namespace

int main(int argc, char** argv) {
  if (argc < 2) {
    std::fprintf(stderr, "usage: flankcam_cad_example OUT [TOLERANCE_MM CLEARANCE_MM]\n");
    return 1;
  }
  try {
    const std::string out = argv[1];
    const double tolerance = argc > 2 ? std::stod(argv[2]) : 0.015, clearance = argc > 3 ? std::stod(argv[3]) : 1.0;
    std::filesystem::create_directories(out);
    const ExampleModelOptions model;
    for (const char* name : {"blade_part.step", "blade_part.igs"}) write_example_model(out + "/" + name, model);
    for (const char* name : {"blade_part.step", "blade_part.igs"}) {
      const std::string path = out + "/" + name, stem = std::filesystem::path(name).extension().string().substr(1);
      const CadMesh flank = load_surface_file(path, {1, 2}, surface_deflection_mm(tolerance));
      const CadMesh part = load_part_file(path, path, {1, 2}, part_deflection_mm(clearance), surface_deflection_mm(tolerance));
      write_obj(out + "/flank-" + stem + ".obj", flank.loaded.mesh, path + " faces 1 2");
      write_obj(out + "/part-" + stem + ".obj", part.loaded.mesh, path + " every face");
      std::printf("%s: flank %zu triangles at %.5f mm, part %zu triangles at %.3f mm (faces 1 2 at %.5f mm)\n", name, flank.loaded.mesh.faces.size(),
                  surface_deflection_mm(tolerance), part.loaded.mesh.faces.size(), part_deflection_mm(clearance),
                  surface_deflection_mm(tolerance));
    }
    // The same blade side tessellated without OCCT: refine the grid until it deviates no more.
    BladeOptions bo = model.blade;
    for (bo.grid_chord = 80, bo.grid_span = 40;; bo.grid_chord *= 2, bo.grid_span = bo.grid_span * 3 / 2) {
      const Blade b = make_blade(bo);
      const double dev = grid_deviation(b);
      if (dev <= surface_deflection_mm(tolerance) || bo.grid_chord > 5000) {
        write_obj(out + "/flank-grid.obj", b.mesh, "analytic blade grid");
        std::printf("analytic grid %d x %d: %zu triangles, chordal deviation %.6f mm\n", bo.grid_chord, bo.grid_span,
                    b.mesh.faces.size(), dev);
        break;
      }
    }
  } catch (const InputError& e) {
    std::fprintf(stderr, "flankcam_cad_example: error: %s\n", e.what());
    return 2;
  } catch (const std::exception& e) {
    std::fprintf(stderr, "flankcam_cad_example: internal error: %s\n", e.what());
    return 3;
  }
  return 0;
}
