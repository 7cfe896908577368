#include "cad/cad_reader.h"

#include <Eigen/Geometry>

#include <BRepAdaptor_Surface.hxx>
#include <BRepBndLib.hxx>
#include <BRepBuilderAPI_Sewing.hxx>
#include <BRepGProp.hxx>
#include <BRepMesh_IncrementalMesh.hxx>
#include <BRepTools.hxx>
#include <BRep_Builder.hxx>
#include <BRep_Tool.hxx>
#include <Bnd_Box.hxx>
#include <GProp_GProps.hxx>
#include <IFSelect_ReturnStatus.hxx>
#include <IGESControl_Reader.hxx>
#include <IGESData_GlobalSection.hxx>
#include <IGESData_IGESModel.hxx>
#include <Poly_Triangulation.hxx>
#include <STEPControl_Reader.hxx>
#include <Standard_Failure.hxx>
#include <TColStd_SequenceOfAsciiString.hxx>
#include <TCollection_HAsciiString.hxx>
#include <TopExp.hxx>
#include <TopExp_Explorer.hxx>
#include <TopLoc_Location.hxx>
#include <TopTools_IndexedDataMapOfShapeListOfShape.hxx>
#include <TopTools_IndexedMapOfShape.hxx>
#include <TopTools_ListOfShape.hxx>
#include <TopTools_MapOfShape.hxx>
#include <TopoDS.hxx>
#include <TopoDS_Compound.hxx>
#include <TopoDS_Face.hxx>
#include <fmt/format.h>

#include <algorithm>
#include <array>
#include <cctype>
#include <cmath>
#include <filesystem>
#include <fstream>
#include <map>
#include <set>
#include <tuple>
#include <unordered_map>

#include "cad/occt_quiet.h"
#include "core/errors.h"

namespace flankcam {

namespace {

std::string lower_extension(const std::string& path) {
  std::string ext = std::filesystem::path(path).extension().string();
  for (char& c : ext) c = char(std::tolower(static_cast<unsigned char>(c)));
  return ext;
}

bool is_step(const std::string& ext) { return ext == ".step" || ext == ".stp"; }
bool is_iges(const std::string& ext) { return ext == ".iges" || ext == ".igs"; }

struct Model {
  std::string path;
  std::vector<TopoDS_Face> faces;  // explode order
  std::string units, note;
};

std::string occt_message(const Standard_Failure& e) {
  const char* m = e.GetMessageString();
  return m && *m ? m : e.DynamicType()->Name();
}

// Millimetre spellings in STEP (SI prefix + METRE) and IGES (unit flag 2, "MM").
bool is_millimetre(std::string u) {
  for (char& c : u) c = char(std::toupper(static_cast<unsigned char>(c)));
  return u == "MM" || u == "MILLIMETRE" || u == "MILLIMETER" || u == ".MILLI.METRE";
}

Model read_model(const std::string& path) {
  namespace fs = std::filesystem;
  std::error_code ec;
  if (!fs::exists(path, ec)) throw InputError(path + ": file not found");
  if (!fs::is_regular_file(path, ec)) throw InputError(path + ": not a regular file");
  {
    std::ifstream probe(path, std::ios::binary);
    if (!probe) throw InputError(path + ": cannot read file");
    if (probe.peek() == std::ifstream::traits_type::eof()) throw InputError(path + ": file is empty");
  }
  const std::string ext = lower_extension(path);
  if (!is_step(ext) && !is_iges(ext))
    throw InputError(path + ": unknown CAD format '" + ext + "' (use .step, .stp, .iges or .igs)");

  Model model;
  model.path = path;
  TopoDS_Shape shape;
  const detail::QuietOcct quiet;
  try {
    // The readers convert lengths to OCCT's session unit, millimetres (xstep.cascade.unit = MM).
    if (is_step(ext)) {
      STEPControl_Reader reader;
      if (reader.ReadFile(path.c_str()) != IFSelect_RetDone) throw InputError(path + ": not a readable STEP file");
      TColStd_SequenceOfAsciiString lengths, angles, solid_angles;
      reader.FileUnits(lengths, angles, solid_angles);
      if (!lengths.IsEmpty()) model.units = lengths.First().ToCString();
      reader.TransferRoots();
      shape = reader.OneShape();
    } else {
      IGESControl_Reader reader;
      if (reader.ReadFile(path.c_str()) != IFSelect_RetDone) throw InputError(path + ": not a readable IGES file");
      const Handle(TCollection_HAsciiString) unit = reader.IGESModel()->GlobalSection().UnitName();
      if (!unit.IsNull()) model.units = unit->ToCString();
      reader.TransferRoots();
      shape = reader.OneShape();
    }
  } catch (const Standard_Failure& e) {
    throw InputError(path + ": cannot read the model (" + occt_message(e) + ")");
  }
  if (shape.IsNull()) throw InputError(path + ": the file holds no shape");
  // DRAW's explode: explorer order, each face once.
  TopTools_MapOfShape seen;
  for (TopExp_Explorer it(shape, TopAbs_FACE); it.More(); it.Next())
    if (seen.Add(it.Current())) model.faces.push_back(TopoDS::Face(it.Current()));
  if (model.faces.empty()) throw InputError(path + ": the file holds no faces (only curves or points?)");
  if (!model.units.empty() && !is_millimetre(model.units))
    model.note = "lengths in " + model.units + ", converted to mm";
  return model;
}

// Sews the faces (joins edges closer than `tol_mm`) and tells, for every face of the result, which
// input face (0-based index into `faces`) it came from.
struct Sewn {
  TopoDS_Shape shape;
  std::vector<std::pair<TopoDS_Face, int>> faces;  // oriented as placed in the sewn shells
};

Sewn sew(const std::vector<TopoDS_Face>& faces, double tol_mm) {
  Sewn out;
  if (faces.size() == 1) {
    out.shape = faces[0];
    out.faces.emplace_back(faces[0], 0);
    return out;
  }
  BRepBuilderAPI_Sewing sewing(tol_mm);
  for (const auto& f : faces) sewing.Add(f);
  sewing.Perform();
  out.shape = sewing.SewedShape();
  TopTools_IndexedMapOfShape sewn_of_input;  // IsSame-keyed: orientation does not matter
  std::vector<int> input_of;
  for (size_t i = 0; i < faces.size(); ++i) {
    const TopoDS_Shape& m = sewing.IsModified(faces[i]) ? sewing.Modified(faces[i]) : faces[i];
    if (m.IsNull() || m.ShapeType() != TopAbs_FACE) continue;  // dropped as degenerate
    if (sewn_of_input.Add(m) > int(input_of.size())) input_of.push_back(int(i));
  }
  TopTools_MapOfShape seen;
  for (TopExp_Explorer it(out.shape, TopAbs_FACE); it.More(); it.Next()) {
    if (!seen.Add(it.Current())) continue;
    const int k = sewn_of_input.FindIndex(it.Current());
    if (k > 0) out.faces.emplace_back(TopoDS::Face(it.Current()), input_of[size_t(k - 1)]);
  }
  return out;
}

// Joins vertices closer than `tol` (the triangulations of sewn faces meet on the same edge nodes;
// periodic faces repeat the nodes of their seam). First-come representative: deterministic.
std::vector<int> weld(const std::vector<Eigen::Vector3d>& points, double tol) {
  std::unordered_map<long long, std::vector<int>> cells;
  const auto key = [](long long i, long long j, long long k) { return (i * 73856093LL) ^ (j * 19349663LL) ^ (k * 83492791LL); };
  std::vector<int> rep(points.size());
  for (size_t n = 0; n < points.size(); ++n) {
    const Eigen::Vector3d c = (points[n] / tol).array().floor();
    const long long ci = (long long)c.x(), cj = (long long)c.y(), ck = (long long)c.z();
    int found = -1;
    for (long long di = -1; di <= 1 && found < 0; ++di)
      for (long long dj = -1; dj <= 1 && found < 0; ++dj)
        for (long long dk = -1; dk <= 1 && found < 0; ++dk) {
          const auto it = cells.find(key(ci + di, cj + dj, ck + dk));
          if (it == cells.end()) continue;
          for (int m : it->second)
            if ((points[size_t(m)] - points[n]).norm() <= tol) {
              found = m;
              break;
            }
        }
    if (found >= 0) {
      rep[n] = found;
    } else {
      rep[n] = int(n);
      cells[key(ci, cj, ck)].push_back(int(n));
    }
  }
  return rep;
}

std::string surface_name(GeomAbs_SurfaceType t) {
  switch (t) {
    case GeomAbs_Plane: return "plane";
    case GeomAbs_Cylinder: return "cylinder";
    case GeomAbs_Cone: return "cone";
    case GeomAbs_Sphere: return "sphere";
    case GeomAbs_Torus: return "torus";
    case GeomAbs_BezierSurface: return "bezier";
    case GeomAbs_BSplineSurface: return "bspline";
    case GeomAbs_SurfaceOfRevolution: return "revolution";
    case GeomAbs_SurfaceOfExtrusion: return "extrusion";
    case GeomAbs_OffsetSurface: return "offset";
    default: return "other";
  }
}

}  // namespace

std::string CadOptions::validate() const {
  if (!(chordal_deflection_mm > 0) || !std::isfinite(chordal_deflection_mm)) return "chordal_deflection: must be > 0 mm";
  if (!(angular_deflection_rad > 0 && angular_deflection_rad < M_PI)) return "angular_deflection: must be in (0, pi) rad";
  if (!(sewing_tolerance_mm > 0) || !std::isfinite(sewing_tolerance_mm)) return "sewing_tolerance: must be > 0 mm";
  if (!fine_faces.empty() && !(fine_deflection_mm > 0 && fine_deflection_mm <= chordal_deflection_mm))
    return "fine_deflection: must be > 0 mm and at most chordal_deflection";
  return {};
}

bool is_cad_file(const std::string& path) {
  const std::string ext = lower_extension(path);
  return is_step(ext) || is_iges(ext);
}

CadMesh load_cad(const std::string& path, const CadOptions& options) {
  if (std::string why = options.validate(); !why.empty()) throw InputError(path + ": " + why);
  const Model model = read_model(path);
  const int n = int(model.faces.size());

  std::vector<int> numbers = options.faces;
  if (numbers.empty())
    for (int k = 1; k <= n; ++k) numbers.push_back(k);
  std::set<int> listed;
  std::vector<TopoDS_Face> chosen;
  for (int k : numbers) {
    if (k < 1 || k > n)
      throw InputError(fmt::format("{}: face {} out of range (the model has {} faces, numbered from 1)", path, k, n));
    if (!listed.insert(k).second) throw InputError(fmt::format("{}: face {} listed twice", path, k));
    chosen.push_back(model.faces[size_t(k - 1)]);
  }

  for (int k : options.fine_faces)
    if (k < 1 || k > n)
      throw InputError(fmt::format("{}: face {} out of range (the model has {} faces, numbered from 1)", path, k, n));

  CadMesh out;
  out.faces_in_file = n;
  out.units = model.units;
  out.note = model.note;
  TriMesh raw;
  std::vector<int> raw_face;
  const detail::QuietOcct quiet;
  try {
    const Sewn sewn = sew(chosen, options.sewing_tolerance_mm);
    BRepTools::Clean(sewn.shape);  // tessellate at our deflection, not at one stored in the file
    IMeshTools_Parameters p;
    p.Deflection = options.chordal_deflection_mm;
    p.Angle = options.angular_deflection_rad;
    p.Relative = Standard_False;
    p.InParallel = Standard_False;  // same triangles at any thread count
    if (!options.fine_faces.empty()) {
      // The fine faces first: BRepMesh keeps a triangulation finer than it is asked for, and the
      // coarse faces around them take over the nodes of their shared edges.
      TopoDS_Compound fine;
      BRep_Builder builder;
      builder.MakeCompound(fine);
      const std::set<int> wanted(options.fine_faces.begin(), options.fine_faces.end());
      for (const auto& [face, input] : sewn.faces)
        if (wanted.count(numbers[size_t(input)])) builder.Add(fine, face);
      IMeshTools_Parameters pf = p;
      pf.Deflection = options.fine_deflection_mm;
      BRepMesh_IncrementalMesh fine_mesher(fine, pf);
    }
    BRepMesh_IncrementalMesh mesher(sewn.shape, p);
    std::vector<char> got(chosen.size(), 0);
    for (const auto& [face, input] : sewn.faces) {
      const int number = numbers[size_t(input)];
      TopLoc_Location loc;
      const Handle(Poly_Triangulation) tri = BRep_Tool::Triangulation(face, loc);
      if (tri.IsNull() || tri->NbTriangles() == 0)
        throw InputError(fmt::format("{}: face {} does not tessellate (BRepMesh made no triangles)", path, number));
      got[size_t(input)] = 1;
      const gp_Trsf trsf = loc.Transformation();
      const int base = int(raw.vertices.size());
      for (int i = 1; i <= tri->NbNodes(); ++i) {
        const gp_Pnt q = tri->Node(i).Transformed(trsf);
        raw.vertices.emplace_back(q.X(), q.Y(), q.Z());
      }
      // Triangles are counter-clockwise about the surface normal; a reversed face turns them over.
      const bool reversed = face.Orientation() == TopAbs_REVERSED;
      for (int t = 1; t <= tri->NbTriangles(); ++t) {
        int a = 0, b = 0, c = 0;
        tri->Triangle(t).Get(a, b, c);
        if (reversed) std::swap(b, c);
        raw.faces.push_back({base + a - 1, base + b - 1, base + c - 1});
        raw_face.push_back(number);
      }
    }
    for (size_t i = 0; i < chosen.size(); ++i)
      if (!got[i])
        throw InputError(fmt::format("{}: face {} does not tessellate (lost when sewing: degenerate?)", path, numbers[i]));
  } catch (const Standard_Failure& e) {
    throw InputError(fmt::format("{}: tessellation failed ({})", path, occt_message(e)));
  }

  // Weld the shared edge nodes, then drop what clean_mesh would drop so triangle_face stays aligned.
  const double diag = bounding_box(raw.vertices).diagonal();
  const std::vector<int> rep = weld(raw.vertices, std::max(1e-9, 1e-7 * diag));
  const double min_area = 1e-14 * diag * diag;
  std::set<std::array<int, 3>> seen;
  TriMesh welded;
  welded.vertices = raw.vertices;
  int degenerate = 0, duplicate = 0;
  for (size_t t = 0; t < raw.faces.size(); ++t) {
    std::array<int, 3> f = raw.faces[t];
    for (int& i : f) i = rep[size_t(i)];
    const Eigen::Vector3d& a = raw.vertices[size_t(f[0])];
    if (f[0] == f[1] || f[1] == f[2] || f[0] == f[2] ||
        !(0.5 * (raw.vertices[size_t(f[1])] - a).cross(raw.vertices[size_t(f[2])] - a).norm() > min_area)) {
      ++degenerate;
      continue;
    }
    std::array<int, 3> s = f;
    std::sort(s.begin(), s.end());
    if (!seen.insert(s).second) {
      ++duplicate;
      continue;
    }
    welded.faces.push_back(f);
    out.triangle_face.push_back(raw_face[t]);
  }
  if (welded.faces.empty()) throw InputError(path + ": the chosen faces tessellate to no triangles");
  out.loaded = clean_mesh(std::move(welded), path);
  out.loaded.report.dropped_degenerate += degenerate;
  out.loaded.report.dropped_duplicate += duplicate;
  if (out.loaded.mesh.faces.size() != out.triangle_face.size()) out.triangle_face.clear();  // not expected
  return out;
}

CadFaces list_faces(const std::string& path, double sewing_tolerance_mm) {
  if (!(sewing_tolerance_mm > 0)) throw InputError(path + ": sewing_tolerance: must be > 0 mm");
  const Model model = read_model(path);
  CadFaces out;
  out.units = model.units;
  out.note = model.note;
  const detail::QuietOcct quiet;
  try {
    const Sewn sewn = sew(model.faces, sewing_tolerance_mm);
    TopTools_IndexedDataMapOfShapeListOfShape edge_faces;
    TopExp::MapShapesAndAncestors(sewn.shape, TopAbs_EDGE, TopAbs_FACE, edge_faces);
    TopTools_IndexedMapOfShape sewn_faces;
    std::vector<int> number_of;
    for (const auto& [face, input] : sewn.faces)
      if (sewn_faces.Add(face) > int(number_of.size())) number_of.push_back(input + 1);
    std::vector<std::set<int>> neighbours(model.faces.size());
    for (int e = 1; e <= edge_faces.Extent(); ++e) {
      std::vector<int> users;
      for (TopTools_ListOfShape::Iterator it(edge_faces(e)); it.More(); it.Next())
        if (const int k = sewn_faces.FindIndex(it.Value()); k > 0) users.push_back(number_of[size_t(k - 1)]);
      for (int a : users)
        for (int b : users)
          if (a != b) neighbours[size_t(a - 1)].insert(b);
    }
    for (size_t i = 0; i < model.faces.size(); ++i) {
      const TopoDS_Face& face = model.faces[i];
      FaceInfo info;
      info.number = int(i) + 1;
      info.surface = surface_name(BRepAdaptor_Surface(face).GetType());
      GProp_GProps props;
      BRepGProp::SurfaceProperties(face, props);
      info.area_mm2 = props.Mass();
      const gp_Pnt c = props.CentreOfMass();
      info.centroid_mm = {c.X(), c.Y(), c.Z()};
      Bnd_Box box;
      BRepBndLib::AddOptimal(face, box, Standard_False, Standard_False);
      if (!box.IsVoid()) {
        double x0, y0, z0, x1, y1, z1;
        box.Get(x0, y0, z0, x1, y1, z1);
        info.box = {{x0, y0, z0}, {x1, y1, z1}};
      } else {
        info.box = {info.centroid_mm, info.centroid_mm};
      }
      info.neighbours.assign(neighbours[i].begin(), neighbours[i].end());
      out.faces.push_back(std::move(info));
    }
  } catch (const Standard_Failure& e) {
    throw InputError(fmt::format("{}: cannot analyse the faces ({})", path, occt_message(e)));
  }
  return out;
}

CadMesh load_part_file(const std::string& part, const std::string& surface, const std::vector<int>& surface_faces,
                       double part_deflection_mm, double surface_deflection_mm) {
  if (!is_cad_file(part)) return load_surface_file(part, {}, part_deflection_mm);
  CadOptions o;
  o.chordal_deflection_mm = std::max(part_deflection_mm, surface_deflection_mm);
  std::error_code ec;
  if (std::filesystem::equivalent(part, surface, ec)) {
    o.fine_faces = surface_faces;
    if (o.fine_faces.empty())
      for (int k = 1; k <= int(list_faces(part).faces.size()); ++k) o.fine_faces.push_back(k);
    o.fine_deflection_mm = surface_deflection_mm;
  }
  return load_cad(part, o);
}

CadMesh load_surface_file(const std::string& path, const std::vector<int>& faces, double chordal_deflection_mm) {
  if (is_cad_file(path)) {
    CadOptions o;
    o.faces = faces;
    o.chordal_deflection_mm = chordal_deflection_mm;
    return load_cad(path, o);
  }
  if (!faces.empty()) throw InputError(path + ": faces: only STEP or IGES models have faces to pick");
  CadMesh out;
  out.loaded = load_mesh(path);
  return out;
}

}  // namespace flankcam
