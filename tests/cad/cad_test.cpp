#include <doctest/doctest.h>

#include <Eigen/Dense>

#include <cmath>
#include <map>
#include <set>

#include "cad/cad_reader.h"
#include "cad/example_model.h"
#include "core/blade.h"
#include "core/errors.h"
#include "tests/test_util.h"

using namespace flankcam;

namespace {

// The analytic blade the example model approximates (the same options, so the same surface).
Blade analytic_blade(const ExampleModelOptions& o) {
  BladeOptions b = o.blade;
  b.grid_chord = b.grid_span = 2;
  return make_blade(b);
}

struct SurfacePoint {
  double distance_mm, u, v;
};

// Distance from x to the blade surface over chord fractions [u0, u1] and the whole span: the span
// fraction is z / span exactly (the sections are twisted about +z), then Gauss-Newton in (u, v).
SurfacePoint distance_to_blade(const Blade& b, const Eigen::Vector3d& x, double u0, double u1) {
  double v = std::clamp(x.z() / b.options.span, 0.0, 1.0), u = u0, best = 1e300;
  for (int i = 0; i <= 32; ++i) {
    const double ui = u0 + (u1 - u0) * i / 32, d = (b.point(ui, v) - x).squaredNorm();
    if (d < best) best = d, u = ui;
  }
  for (int it = 0; it < 20; ++it) {
    const double h = 1e-6;
    const Eigen::Vector3d r = b.point(u, v) - x;
    Eigen::Matrix<double, 3, 2> J;
    J.col(0) = (b.point(std::min(u + h, 1.0), v) - b.point(u - h, v)) / (std::min(u + h, 1.0) - (u - h));
    J.col(1) = (b.point(u, v + h) - b.point(u, v - h)) / (2 * h);
    const Eigen::Vector2d step = (J.transpose() * J).ldlt().solve(-J.transpose() * r);
    u = std::clamp(u + step.x(), u0, u1);
    v = std::clamp(v + step.y(), 0.0, 1.0);
    if (step.norm() < 1e-12) break;
  }
  return {(b.point(u, v) - x).norm(), u, v};
}

std::string error_of(const std::function<void()>& f) {
  try {
    f();
  } catch (const InputError& e) {
    return e.what();
  }
  return "(no error)";
}

const std::string kFormats[] = {"model.step", "model.igs"};

}  // namespace

TEST_CASE("STEP and IGES blade faces tessellate within the chordal deflection of the analytic blade") {
  const test::ScratchDir dir("cad-blade");
  const ExampleModelOptions model;
  const Blade blade = analytic_blade(model);
  const BladeOptions& bo = model.blade;
  for (const std::string& name : kFormats) {
    CAPTURE(name);
    const std::string path = dir.file(name);
    write_example_model(path, model);
    for (double deflection : {0.05, 0.01}) {
      CAPTURE(deflection);
      CadOptions o;
      o.faces = {1, 2};
      o.chordal_deflection_mm = deflection;
      const CadMesh cad = load_cad(path, o);
      const TriMesh& m = cad.loaded.mesh;
      CHECK(cad.faces_in_file == 4);
      CHECK(cad.note.empty());
      // The two halves share the mid-chord edge: sewn and welded into one piece, nothing flipped.
      CHECK(cad.loaded.report.components == 1);
      CHECK(cad.loaded.report.flipped_to_orient == 0);
      REQUIRE(cad.triangle_face.size() == m.faces.size());
      CHECK(std::set<int>(cad.triangle_face.begin(), cad.triangle_face.end()) == std::set<int>{1, 2});

      double vertex_max = 0, centroid_max = 0, umin = 1, umax = 0;
      for (const auto& p : m.vertices) {
        const SurfacePoint s = distance_to_blade(blade, p, bo.chord_from, bo.chord_to);
        vertex_max = std::max(vertex_max, s.distance_mm);
        umin = std::min(umin, s.u), umax = std::max(umax, s.u);
      }
      int misoriented = 0;
      for (size_t t = 0; t < m.faces.size(); ++t) {
        const Eigen::Vector3d c =
            (m.vertices[size_t(m.faces[t][0])] + m.vertices[size_t(m.faces[t][1])] + m.vertices[size_t(m.faces[t][2])]) / 3;
        const SurfacePoint s = distance_to_blade(blade, c, bo.chord_from, bo.chord_to);
        centroid_max = std::max(centroid_max, s.distance_mm);
        if (face_normal(m, int(t)).dot(blade.normal(s.u, s.v)) <= 0) ++misoriented;
      }
      MESSAGE(name << " deflection " << deflection << " mm: " << m.faces.size() << " triangles, vertices within "
                   << vertex_max << " mm, centroids within " << centroid_max << " mm of the analytic blade");
      // Vertices lie on the B-spline faces, which fit the analytic blade to well under a micrometre.
      CHECK(vertex_max < 1e-3);
      // Triangle interiors: BRepMesh's chordal deflection.
      CHECK(centroid_max <= deflection);
      // Outward normals (towards the tool) although the B-spline's own normal points into the blade.
      CHECK(misoriented == 0);
      // The whole chord range is covered.
      CHECK(umin == doctest::Approx(bo.chord_from).epsilon(1e-6));
      CHECK(umax == doctest::Approx(bo.chord_to).epsilon(1e-6));
    }
  }
}

TEST_CASE("the part keeps the flank at the surface deflection and the rest coarse") {
  const test::ScratchDir dir("cad-part");
  const ExampleModelOptions model;
  const Blade blade = analytic_blade(model);
  const std::string path = dir.file("model.step");
  write_example_model(path, model);
  const double fine = 0.01, coarse = 0.5;
  const CadMesh part = load_part_file(path, path, {1, 2}, coarse, fine);
  CadOptions o;
  o.faces = {1, 2};
  o.chordal_deflection_mm = fine;
  const CadMesh flank = load_cad(path, o);
  const TriMesh& m = part.loaded.mesh;
  REQUIRE(part.triangle_face.size() == m.faces.size());
  CHECK(part.loaded.report.components == 2);
  std::map<int, int> count;
  double worst = 0;
  for (size_t t = 0; t < m.faces.size(); ++t) {
    ++count[part.triangle_face[t]];
    if (part.triangle_face[t] > 2) continue;
    const Eigen::Vector3d c =
        (m.vertices[size_t(m.faces[t][0])] + m.vertices[size_t(m.faces[t][1])] + m.vertices[size_t(m.faces[t][2])]) / 3;
    worst = std::max(worst, distance_to_blade(blade, c, model.blade.chord_from, model.blade.chord_to).distance_mm);
  }
  CHECK(worst <= fine);
  CHECK(count[1] + count[2] == int(flank.loaded.mesh.faces.size()));  // the same triangles as the surface alone
  // A different file is a different model: every face coarse.
  const std::string copy = dir.file("copy.step");
  std::filesystem::copy_file(path, copy);
  const CadMesh other = load_part_file(copy, path, {1, 2}, coarse, fine);
  CHECK(other.loaded.mesh.faces.size() < m.faces.size() / 2);
  CHECK(error_of([&] { (void)load_part_file(path, path, {7}, coarse, fine); }).find("face 7 out of range") != std::string::npos);
}

TEST_CASE("faces are numbered in explode order with their type, area, box and neighbours") {
  const test::ScratchDir dir("cad-list");
  const ExampleModelOptions model;
  const double r = model.hole_radius_mm;
  for (const std::string& name : kFormats) {
    CAPTURE(name);
    const std::string path = dir.file(name);
    write_example_model(path, model);
    const CadFaces faces = list_faces(path);
    REQUIRE(faces.faces.size() == 4);
    CHECK(faces.note.empty());
    std::vector<std::string> types;
    for (const FaceInfo& f : faces.faces) types.push_back(f.surface);
    // IGES has no cylinder entity: OCCT writes the bore as a surface of revolution (type 120).
    const std::string bore = name.find(".igs") != std::string::npos ? "revolution" : "cylinder";
    CHECK(types == std::vector<std::string>{"bspline", "bspline", "plane", bore});
    for (int k = 0; k < 4; ++k) CHECK(faces.faces[size_t(k)].number == k + 1);
    CHECK(faces.faces[0].neighbours == std::vector<int>{2});
    CHECK(faces.faces[1].neighbours == std::vector<int>{1});
    CHECK(faces.faces[2].neighbours == std::vector<int>{4});
    CHECK(faces.faces[3].neighbours == std::vector<int>{3});
    const double floor = (model.floor_x1_mm - model.floor_x0_mm) * (model.floor_y1_mm - model.floor_y0_mm) - M_PI * r * r;
    CHECK(faces.faces[2].area_mm2 == doctest::Approx(floor).epsilon(1e-6));
    CHECK(faces.faces[3].area_mm2 == doctest::Approx(2 * M_PI * r * model.hole_depth_mm).epsilon(1e-6));
    CHECK(faces.faces[2].box.min.x() == doctest::Approx(model.floor_x0_mm));
    CHECK(faces.faces[2].box.max.y() == doctest::Approx(model.floor_y1_mm));
    CHECK(faces.faces[2].box.min.z() == doctest::Approx(model.floor_z_mm));
    CHECK(faces.faces[3].box.min.z() == doctest::Approx(model.floor_z_mm - model.hole_depth_mm));
    CHECK(faces.faces[3].centroid_mm.x() == doctest::Approx(model.hole_x_mm));
    // The blade faces: hub at z = 0, tip at the span; together the area of the analytic suction side.
    CHECK(faces.faces[0].box.min.z() == doctest::Approx(0).epsilon(1e-6));
    CHECK(faces.faces[1].box.max.z() == doctest::Approx(model.blade.span));
    BladeOptions fine = model.blade;
    fine.grid_chord = 400, fine.grid_span = 60;
    CHECK(faces.faces[0].area_mm2 + faces.faces[1].area_mm2 ==
          doctest::Approx(surface_area(make_blade(fine).mesh)).epsilon(1e-3));
  }
}

TEST_CASE("a trimmed floor keeps its bore and is welded to the bore wall, normals out of the material") {
  const test::ScratchDir dir("cad-trim");
  const ExampleModelOptions model;
  const double r = model.hole_radius_mm, deflection = 0.01;
  for (const std::string& name : kFormats) {
    CAPTURE(name);
    const std::string path = dir.file(name);
    write_example_model(path, model);
    CadOptions o;
    o.faces = {4, 3};  // order of the list does not matter
    o.chordal_deflection_mm = deflection;
    const CadMesh cad = load_cad(path, o);
    const TriMesh& m = cad.loaded.mesh;
    CHECK(cad.loaded.report.components == 1);  // the bore's rim edge is shared
    REQUIRE(cad.triangle_face.size() == m.faces.size());
    const Eigen::Vector2d axis(model.hole_x_mm, model.hole_y_mm);
    double floor_area = 0, wall_area = 0, inside = 0;
    int wrong_normal = 0;
    for (size_t t = 0; t < m.faces.size(); ++t) {
      const Eigen::Vector3d c =
          (m.vertices[size_t(m.faces[t][0])] + m.vertices[size_t(m.faces[t][1])] + m.vertices[size_t(m.faces[t][2])]) / 3;
      const Eigen::Vector3d n = face_normal(m, int(t));
      const Eigen::Vector2d radial = c.head<2>() - axis;
      if (cad.triangle_face[t] == 3) {
        floor_area += face_area(m, int(t));
        inside = std::max(inside, r - radial.norm());  // > 0: a floor triangle over the hole
        if (n.z() < 0.999) ++wrong_normal;
      } else {
        wall_area += face_area(m, int(t));
        if (n.head<2>().dot(radial) >= 0) ++wrong_normal;  // must point to the axis
      }
    }
    CHECK(inside <= 0);
    CHECK(wrong_normal == 0);
    const double floor = (model.floor_x1_mm - model.floor_x0_mm) * (model.floor_y1_mm - model.floor_y0_mm) - M_PI * r * r;
    // Chords of the circle cut at most `deflection` off: the area difference is bounded by it.
    CHECK(std::abs(floor_area - floor) <= 2 * M_PI * r * deflection);
    CHECK(std::abs(wall_area - 2 * M_PI * r * model.hole_depth_mm) <= 2 * M_PI * model.hole_depth_mm * deflection);
  }
}

TEST_CASE("an inch file is read in mm and the note says so") {
  const test::ScratchDir dir("cad-inch");
  ExampleModelOptions mm, inch;
  inch.unit = "INCH";
  for (const std::string ext : {".step", ".igs"}) {
    CAPTURE(ext);
    write_example_model(dir.file("mm" + ext), mm);
    write_example_model(dir.file("inch" + ext), inch);
    const CadFaces a = list_faces(dir.file("mm" + ext)), b = list_faces(dir.file("inch" + ext));
    if (ext == ".step") CHECK(test::read_text(dir.file("inch.step")).find("'INCH'") != std::string::npos);
    CHECK((b.units == "INCH" || b.units == "IN"));  // STEP's conversion-based unit, IGES's unit name
    CHECK(a.note.empty());
    CHECK(b.note == "lengths in " + b.units + ", converted to mm");
    REQUIRE(a.faces.size() == b.faces.size());
    for (size_t k = 0; k < a.faces.size(); ++k) {
      CHECK(b.faces[k].area_mm2 == doctest::Approx(a.faces[k].area_mm2).epsilon(1e-6));
      CHECK((b.faces[k].box.min - a.faces[k].box.min).norm() < 1e-4);
      CHECK((b.faces[k].box.max - a.faces[k].box.max).norm() < 1e-4);
    }
    CadOptions o;
    o.faces = {3};
    const CadMesh floor = load_cad(dir.file("inch" + ext), o);
    CHECK(floor.note == b.note);
    const BoundingBox box = bounding_box(floor.loaded.mesh.vertices);
    CHECK(box.min.x() == doctest::Approx(mm.floor_x0_mm));
    CHECK(box.max.x() == doctest::Approx(mm.floor_x1_mm));
    CHECK(box.min.z() == doctest::Approx(mm.floor_z_mm));
  }
}

TEST_CASE("bad face numbers and unreadable files are one-line input errors naming file and face") {
  const test::ScratchDir dir("cad-errors");
  const std::string step = dir.file("model.step"), iges = dir.file("model.igs");
  write_example_model(step, {});
  write_example_model(iges, {});
  const auto load = [](const std::string& path, std::vector<int> faces) {
    return [path, faces] {
      CadOptions o;
      o.faces = faces;
      (void)load_cad(path, o);
    };
  };
  for (const std::string& path : {step, iges}) {
    CAPTURE(path);
    const std::string zero = error_of(load(path, {0}));
    CHECK(zero.find(path) == 0);
    CHECK(zero.find("face 0 out of range (the model has 4 faces, numbered from 1)") != std::string::npos);
    CHECK(error_of(load(path, {1, 5})).find("face 5 out of range") != std::string::npos);
    CHECK(error_of(load(path, {2, 2})).find("face 2 listed twice") != std::string::npos);
  }
  test::write_text(dir.file("garbage.step"), "this is not ISO-10303-21\n");
  test::write_text(dir.file("garbage.igs"), "neither is this an IGES file\x01\x02\n");
  test::write_text(dir.file("empty.stp"), "");
  test::write_text(dir.file("mesh.obj"), "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n");
  CHECK(error_of(load(dir.file("garbage.step"), {})).find(dir.file("garbage.step") + ": not a readable STEP file") == 0);
  CHECK(error_of(load(dir.file("garbage.igs"), {})).find(dir.file("garbage.igs") + ": ") == 0);
  CHECK(error_of(load(dir.file("empty.stp"), {})) == dir.file("empty.stp") + ": file is empty");
  CHECK(error_of(load(dir.file("missing.step"), {})) == dir.file("missing.step") + ": file not found");
  CHECK(error_of(load(dir.file("mesh.obj"), {})).find("unknown CAD format '.obj'") != std::string::npos);
  CHECK(error_of([&] { (void)list_faces(dir.file("garbage.step")); }).find("not a readable STEP file") != std::string::npos);
  CHECK(error_of([&] { (void)load_surface_file(dir.file("mesh.obj"), {1}, 0.01); }).find("faces: only STEP or IGES") !=
        std::string::npos);
  CHECK(load_surface_file(dir.file("mesh.obj"), {}, 0.01).loaded.mesh.faces.size() == 1);
  CHECK(load_surface_file(step, {3}, 0.01).triangle_face.front() == 3);
  CadOptions bad;
  bad.chordal_deflection_mm = 0;
  CHECK(error_of([&] { (void)load_cad(step, bad); }).find("chordal_deflection") != std::string::npos);
  for (const std::string& e : {error_of(load(dir.file("garbage.igs"), {})), error_of(load(step, {0}))})
    CHECK(e.find('\n') == std::string::npos);
}

TEST_CASE("the same model gives the same triangles every time") {
  const test::ScratchDir dir("cad-repeat");
  write_example_model(dir.file("model.step"), {});
  CadOptions o;
  o.chordal_deflection_mm = 0.02;
  const CadMesh a = load_cad(dir.file("model.step"), o), b = load_cad(dir.file("model.step"), o);
  CHECK(a.loaded.mesh.vertices == b.loaded.mesh.vertices);
  CHECK(a.loaded.mesh.faces == b.loaded.mesh.faces);
  CHECK(a.triangle_face == b.triangle_face);
  CHECK(a.loaded.report.components == 2);  // blade, floor with its bore
}

TEST_CASE("flankcam faces prints the table and draws every face numbered") {
  const test::ScratchDir dir("cad-cli");
  write_example_model(dir.file("model.igs"), {});
  const std::string out = dir.file("overview");
  const std::string cmd = std::string(FLANKCAM_BINARY) + " faces " + dir.file("model.igs") + " --out " + out + " > " +
                          dir.file("stdout.txt") + " 2> " + dir.file("stderr.txt");
  REQUIRE(std::system(cmd.c_str()) == 0);
  const std::string table = test::read_text(dir.file("stdout.txt"));
  CHECK(table.find("4 faces, mm") != std::string::npos);
  CHECK(table.find("    3  plane") != std::string::npos);
  CHECK(table.find("    4  revolution") != std::string::npos);
  CHECK(test::read_text(dir.file("stderr.txt")).empty());  // OCCT's own chatter stays quiet
  const std::string svg = test::read_text(out + "/faces.svg");
  for (int k = 1; k <= 4; ++k) CHECK(svg.find(">" + std::to_string(k) + "</text>") != std::string::npos);
  CHECK(test::read_text(out + "/faces.html").find("<svg") != std::string::npos);

  const test::RunResult bad = test::run_flankcam("faces " + dir.file("nothing.step") + " --out " + dir.file("x"), dir);
  CHECK(bad.code == 2);
  CHECK(bad.err == "flankcam: error: " + dir.file("nothing.step") + ": file not found\n");
  CHECK(!std::filesystem::exists(dir.file("x")));
}
