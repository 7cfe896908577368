#include "cad/example_model.h"

#include <BRepBuilderAPI_MakeEdge.hxx>
#include <BRepBuilderAPI_MakeFace.hxx>
#include <BRepBuilderAPI_MakePolygon.hxx>
#include <BRepBuilderAPI_MakeWire.hxx>
#include <BRep_Builder.hxx>
#include <GeomAPI_PointsToBSplineSurface.hxx>
#include <Geom_BSplineSurface.hxx>
#include <IGESControl_Controller.hxx>
#include <IGESControl_Writer.hxx>
#include <Interface_Static.hxx>
#include <STEPControl_Controller.hxx>
#include <STEPControl_Writer.hxx>
#include <ShapeFix_Face.hxx>
#include <Standard_Failure.hxx>
#include <TColgp_Array2OfPnt.hxx>
#include <TopoDS.hxx>
#include <TopoDS_Compound.hxx>
#include <TopoDS_Face.hxx>
#include <gp_Circ.hxx>
#include <gp_Cylinder.hxx>
#include <gp_Pln.hxx>

#include <algorithm>
#include <cctype>
#include <cmath>
#include <filesystem>

#include "cad/occt_quiet.h"
#include "core/errors.h"

namespace flankcam {

namespace {

// Bicubic approximation of the blade between chord fractions u0 and u1 over the whole span;
// reversed so that its normal points out of the blade (+y side, Blade::normal).
TopoDS_Face blade_face(const Blade& blade, double u0, double u1, const ExampleModelOptions& o) {
  TColgp_Array2OfPnt points(1, o.points_chord, 1, o.points_span);
  for (int i = 1; i <= o.points_chord; ++i)
    for (int j = 1; j <= o.points_span; ++j) {
      const double u = u0 + (u1 - u0) * (i - 1) / (o.points_chord - 1), v = double(j - 1) / (o.points_span - 1);
      const Eigen::Vector3d p = blade.point(u, v);
      points.SetValue(i, j, gp_Pnt(p.x(), p.y(), p.z()));
    }
  GeomAPI_PointsToBSplineSurface fit;
  fit.Interpolate(points);  // bicubic through every sample (the least-squares variant overshoots here)
  const Handle(Geom_BSplineSurface) surface = fit.Surface();
  // The surface's du x dv points into the blade (chord along +x, span along +z): turn the face over.
  TopoDS_Face face = BRepBuilderAPI_MakeFace(surface, 1e-7).Face();
  face.Reverse();
  return face;
}

TopoDS_Face floor_face(const ExampleModelOptions& o) {
  const double z = o.floor_z_mm;
  BRepBuilderAPI_MakePolygon outer(gp_Pnt(o.floor_x0_mm, o.floor_y0_mm, z), gp_Pnt(o.floor_x1_mm, o.floor_y0_mm, z),
                                   gp_Pnt(o.floor_x1_mm, o.floor_y1_mm, z), gp_Pnt(o.floor_x0_mm, o.floor_y1_mm, z), true);
  BRepBuilderAPI_MakeFace make(gp_Pln(gp_Pnt(0, 0, z), gp_Dir(0, 0, 1)), outer.Wire());
  const gp_Circ circle(gp_Ax2(gp_Pnt(o.hole_x_mm, o.hole_y_mm, z), gp_Dir(0, 0, 1)), o.hole_radius_mm);
  TopoDS_Wire hole = BRepBuilderAPI_MakeWire(BRepBuilderAPI_MakeEdge(circle).Edge()).Wire();
  hole.Reverse();  // an inner wire runs clockwise about the face normal
  make.Add(hole);
  ShapeFix_Face fix(make.Face());
  fix.Perform();
  return fix.Face();
}

TopoDS_Face bore_face(const ExampleModelOptions& o) {
  const gp_Cylinder cylinder(gp_Ax3(gp_Pnt(o.hole_x_mm, o.hole_y_mm, o.floor_z_mm - o.hole_depth_mm), gp_Dir(0, 0, 1)),
                             o.hole_radius_mm);
  TopoDS_Face face = BRepBuilderAPI_MakeFace(cylinder, 0, 2 * M_PI, 0, o.hole_depth_mm).Face();
  face.Reverse();  // material outside the bore: the outward normal points to the axis
  return face;
}

std::string lowercase_extension(const std::string& path) {
  std::string ext = std::filesystem::path(path).extension().string();
  for (char& c : ext) c = char(std::tolower(static_cast<unsigned char>(c)));
  return ext;
}

}  // namespace

std::string ExampleModelOptions::validate() const {
  if (std::string why = blade.validate(); !why.empty()) return "blade: " + why;
  if (points_chord < 4 || points_span < 4) return "points: at least 4 x 4 per blade face";
  if (!(floor_z_mm < 0)) return "floor_z: must be below the blade (< 0 mm)";
  if (!(floor_x0_mm < floor_x1_mm && floor_y0_mm < floor_y1_mm)) return "floor: empty rectangle";
  if (!(hole_radius_mm > 0 && hole_depth_mm > 0)) return "hole: radius and depth must be > 0 mm";
  if (!(hole_x_mm - hole_radius_mm > floor_x0_mm && hole_x_mm + hole_radius_mm < floor_x1_mm &&
        hole_y_mm - hole_radius_mm > floor_y0_mm && hole_y_mm + hole_radius_mm < floor_y1_mm))
    return "hole: must lie inside the floor";
  if (unit != "MM" && unit != "INCH") return "unit: MM or INCH";
  return {};
}

void write_example_model(const std::string& path, const ExampleModelOptions& o) {
  if (std::string why = o.validate(); !why.empty()) throw InputError("example model: " + why);
  const std::string ext = lowercase_extension(path);
  const bool step = ext == ".step" || ext == ".stp", iges = ext == ".iges" || ext == ".igs";
  if (!step && !iges) throw InputError(path + ": example model: write .step, .stp, .iges or .igs");
  BladeOptions bo = o.blade;
  const Blade blade = make_blade([&] {
    bo.grid_chord = bo.grid_span = 2;  // only the analytic surface is used
    return bo;
  }());
  const double middle = 0.5 * (bo.chord_from + bo.chord_to);
  const detail::QuietOcct quiet;
  try {
    TopoDS_Compound model;
    BRep_Builder builder;
    builder.MakeCompound(model);
    builder.Add(model, blade_face(blade, bo.chord_from, middle, o));
    builder.Add(model, blade_face(blade, middle, bo.chord_to, o));
    builder.Add(model, floor_face(o));
    builder.Add(model, bore_face(o));
    bool ok = false;
    if (step) {
      STEPControl_Controller::Init();
      // write.step.unit is a session-wide OCCT setting: set for this write, then put back.
      const std::string before = Interface_Static::CVal("write.step.unit");
      Interface_Static::SetCVal("write.step.unit", o.unit == "INCH" ? "INCH" : "MM");
      STEPControl_Writer writer;
      ok = writer.Transfer(model, STEPControl_AsIs) == IFSelect_RetDone && writer.Write(path.c_str()) == IFSelect_RetDone;
      Interface_Static::SetCVal("write.step.unit", before.c_str());
    } else {
      IGESControl_Controller::Init();
      IGESControl_Writer writer(o.unit == "INCH" ? "IN" : "MM", 0);  // faces as trimmed surfaces (type 144)
      ok = writer.AddShape(model) && writer.Write(path.c_str());
    }
    if (!ok) throw InputError(path + ": cannot write the example model");
  } catch (const Standard_Failure& e) {
    throw InputError(path + ": cannot build the example model (" + std::string(e.GetMessageString()) + ")");
  }
}

}  // namespace flankcam
